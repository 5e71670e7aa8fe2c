#include "mesh_input.hpp"

#include <array>
#include <chrono>
#include <filesystem>
#include <stdexcept>

#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#ifdef LDIMESH_WITH_VTU
#include "ldimesh/core/field/hex_source.hpp"
#endif

namespace ldimesh::cli {

std::string colour_name(const MeshArgs& args) {
  if (args.grid.empty()) return args.colour_by;
  return std::filesystem::path(args.colour_by).stem().string();
}

void load_input(const MeshArgs& args, int rank, int ranks, Input& input) {
  if (int(!args.surface.empty()) + int(!args.grid.empty()) + int(!args.vtu.empty()) != 1)
    throw std::runtime_error(
        "give one of --surface NAME, --grid FILE --dims NX,NY,NZ, --vtu FILE --field NAME");
  if (!args.vtu.empty()) {
#ifdef LDIMESH_WITH_VTU
    ldimesh::quiet_vtk_logging();  // the error comes back as one line
    const ldimesh::Status status =
        ldimesh::read_vtu_isolated(args.vtu, args.field, input.elements, args.colour_by);
    if (!status) throw std::runtime_error(status.message());
    input.name = args.vtu;
    // Every rank holds every element (the file's); it casts only its block of the domain.
    const auto start = std::chrono::steady_clock::now();
    for (const ldimesh::VtuElements::Group& g : input.elements.groups)
      input.sources.push_back(ldimesh::make_vtu_source(g));
    input.prepare_seconds = seconds_since(start);
    // The sources' bounds hold the curved cells (their Bernstein hulls), not only the points.
    ldimesh::Box whole = input.sources.front()->bounds();
    for (const auto& source : input.sources)
      whole = {glm::min(whole.lo, source->bounds().lo), glm::max(whole.hi, source->bounds().hi)};
    input.subdomain = {ldimesh::decompose_box(whole, ranks)[rank], whole};
    input.default_isovalue = 0.5 * (input.elements.min_value + input.elements.max_value);
    return;
#else
    throw std::runtime_error("--vtu: this ldimesh was built without VTK (libvtk9-dev)");
#endif
  }
  if (!args.surface.empty()) {
    if (!args.colour_by.empty())
      throw std::runtime_error(
          "--colour-by needs --grid or --vtu (a built-in surface has no other field)");
    const ldimesh::SurfaceInfo* surface = ldimesh::find_surface(args.surface);
    if (!surface)
      throw std::runtime_error("unknown surface '" + args.surface + "' (see 'ldimesh surfaces')");
    input.name = surface->name;
    // Every rank can evaluate the whole field; it casts only its block of the domain.
    input.sources.push_back(ldimesh::make_surface_source(surface->name, args.bricks));
    input.subdomain = {ldimesh::decompose_box(surface->domain, ranks)[rank], surface->domain};
    input.default_isovalue = surface->isovalue;
    return;
  }
  if (args.dims.size() != 3) throw std::runtime_error("--grid needs --dims NX,NY,NZ");
  const ldimesh::ScalarType type =
      args.type == "float64" ? ldimesh::ScalarType::float64 : ldimesh::ScalarType::float32;
  const ldimesh::Status status =
      ldimesh::read_raw_volume(args.grid, {args.dims[0], args.dims[1], args.dims[2]}, type,
                               {args.origin[0], args.origin[1], args.origin[2]},
                               {args.spacing[0], args.spacing[1], args.spacing[2]}, input.volume);
  if (!status) throw std::runtime_error(status.message());
  if (!args.colour_by.empty()) {
    // The field to colour by: a second file of the same layout.
    const ldimesh::Status colour =
        ldimesh::read_raw_volume(args.colour_by, {args.dims[0], args.dims[1], args.dims[2]}, type,
                                 {args.origin[0], args.origin[1], args.origin[2]},
                                 {args.spacing[0], args.spacing[1], args.spacing[2]}, input.colour);
    if (!colour) throw std::runtime_error("--colour-by: " + colour.message());
    input.volume.block.colour = input.colour.block.values;
    input.volume.block.colour_type = input.colour.block.type;
  }
  input.name = args.grid;
  // Each rank reads the file and takes its block of cells (with the ghost layer it needs),
  // as a solver's rank would hold its own block.
  const ldimesh::Box whole = ldimesh::GridSource(input.volume.block).bounds();
  const std::array<int, 3> blocks = ldimesh::block_grid(whole, ranks);
  const std::array<int, 3> index{rank % blocks[0], (rank / blocks[0]) % blocks[1],
                                 rank / (blocks[0] * blocks[1])};
  const ldimesh::GridPart part = ldimesh::grid_part(input.volume.block, blocks, index);
  input.sources.push_back(std::make_unique<ldimesh::GridSource>(part.block));
  input.subdomain = {part.owned, whole};
  // Without --iso: the middle of the value range.
  input.default_isovalue = 0.5 * (input.volume.min_value + input.volume.max_value);
}

}  // namespace ldimesh::cli

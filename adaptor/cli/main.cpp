// ldimesh: the command line of the pipeline, in one process or over MPI ranks.
//   ldimesh surfaces
//   ldimesh mesh --surface barth --res 512 --views xyz --r 0.5 --out out/barth.ply [--json]
//   ldimesh mesh --surface marschner-lobb --res 128 --refine 2 --out out/ml.ply
//   mpiexec -n 4 ldimesh mesh --surface barth --res 256 --out out/barth.ply
//   ldimesh serve --dir out/steps [--port 8080] [--bind 127.0.0.1]
//   ldimesh distance A.ply B.ply [--samples N] [--json]
//   ldimesh distance A.ply --surface NAME [--isovalue v] [--samples N] [--json]
//   ldimesh distance A.ply --vtu FILE.vtu --field NAME [--isovalue v] [--samples N] [--json]
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <mpi.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#include "ldimesh/core/io/raw_volume.hpp"
#ifdef LDIMESH_WITH_VTU
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/io/vtu.hpp"
#endif
#include "ldimesh/core/metrics/distance.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "ldimesh/transport/step_package.hpp"
#include "serve.hpp"

namespace {

using ldimesh::FaceType;
using ldimesh::seconds_since;

struct MeshArgs {
  std::string surface;
  std::string grid;   // raw volume file
  std::string vtu;    // VTK XML unstructured grid (.vtu, .pvtu)
  std::string field;  // its point array
  // The field to colour by: a --vtu file's point array, or a raw volume of --grid's layout.
  std::string colour_by;
  std::vector<std::int64_t> dims;
  std::string type = "float32";
  std::vector<double> spacing{1.0, 1.0, 1.0};
  std::vector<double> origin{0.0, 0.0, 0.0};
  int res = 256;
  std::string views = "xyz";
  double r = 0.5;
  std::string out;
  bool quads = false;
  int threads = 0;
  bool json = false;
  int bricks = 32;
  std::string caster = "auto";
  int repeat = 1;
  std::optional<double> isovalue;
  double max_cost = ldimesh::MatchOptions{}.max_cost;
  bool lossless = false;
  std::string steps_dir;
  std::uint64_t step = 1;
  double time = 0.0;
  int depth_bits = ldimesh::FragmentEncoding{}.depth_bits;
  int normal_bits = ldimesh::FragmentEncoding{}.normal_bits;
  ldimesh::StepGlbSettings glb;
  ldimesh::RefinementOptions refinement;
  bool no_grow = false;
  bool merge = false;
};

// Fails early, before any work, if `path` cannot be written (creating missing parent folders).
void check_writable(const std::string& path) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  std::error_code ec;
  if (p.has_parent_path()) fs::create_directories(p.parent_path(), ec);
  if (ec)
    throw std::runtime_error("cannot create folder '" + p.parent_path().string() +
                             "': " + ec.message());
  std::FILE* f = std::fopen(path.c_str(), "ab");
  if (!f) throw std::runtime_error("cannot write '" + path + "': " + std::strerror(errno));
  std::fclose(f);
}

// Whether `path` ends in `ext` (".ply"), in any letter case.
bool has_extension(const std::string& path, const std::string& ext) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e)
    c = char(std::tolower(static_cast<unsigned char>(c)));
  return e == ext;
}

int run_surfaces() {
  for (const ldimesh::SurfaceInfo& s : ldimesh::builtin_surfaces()) {
    std::printf("%-15s %s\n", s.name.c_str(), s.formula.c_str());
    std::printf("%-15s domain [%g, %g] x [%g, %g] x [%g, %g], isovalue %g\n", "", s.domain.lo.x,
                s.domain.hi.x, s.domain.lo.y, s.domain.hi.y, s.domain.lo.z, s.domain.hi.z,
                s.isovalue);
  }
  return 0;
}

// What this rank meshes: a built-in surface, a raw volume or a VTU file's elements, its sources
// (for a volume: this rank's part of it; elements: one source per order), its subdomain and the
// default isovalue.
struct Input {
  std::string name;
  std::vector<std::unique_ptr<ldimesh::FieldSource>> sources;
  ldimesh::Subdomain subdomain;
  double default_isovalue = 0.0;
  // Of a --vtu input: building the element sources from the cells read (their geometry's
  // Bernstein form, the Jacobian checks), part of "load".
  double prepare_seconds = 0.0;
  ldimesh::RawVolume volume;  // owns the values of a --grid input
  ldimesh::RawVolume colour;  // and of its --colour-by volume
#ifdef LDIMESH_WITH_VTU
  ldimesh::VtuElements elements;  // owns the arrays of a --vtu input
#endif
  std::vector<const ldimesh::FieldSource*> source_list() const {
    std::vector<const ldimesh::FieldSource*> list;
    for (const auto& s : sources)
      list.push_back(s.get());
    return list;
  }
};

// The name of the field the mesh is coloured by: --colour-by's point array, or for --grid the
// colour file's name without folder and extension.
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

// Runs `step` on every rank; if it throws on any, every rank throws the first failing rank's
// message (so that no rank waits in a collective call the others never reach).
template <class Step>
void on_all_ranks(MPI_Comm comm, Step step) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  std::string error;
  try {
    step();
  } catch (...) {
    error = ldimesh::status_from_current_exception("").message();
    if (error.empty()) error = "unknown error";
  }
  int failed = error.empty() ? size : rank, first = size;
  MPI_Allreduce(&failed, &first, 1, MPI_INT, MPI_MIN, comm);
  if (first == size) return;
  int length = int(error.size());
  MPI_Bcast(&length, 1, MPI_INT, first, comm);
  error.resize(std::size_t(length));
  MPI_Bcast(error.data(), length, MPI_CHAR, first, comm);
  throw std::runtime_error(size > 1 && first != 0 ? "rank " + std::to_string(first) + ": " + error
                                                  : error);
}

int run_mesh(const MeshArgs& args) {
  const MPI_Comm comm = MPI_COMM_WORLD;
  int rank = 0, ranks = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &ranks);
  const bool root = rank == 0;

  on_all_ranks(comm, [&] {
    if (!root || args.out.empty()) return;
    if (!has_extension(args.out, ".ply") && !has_extension(args.out, ".obj") &&
        !has_extension(args.out, ".glb"))
      throw std::runtime_error("cannot tell the format of '" + args.out +
                               "': use a .ply, .obj or .glb file name");
    check_writable(args.out);
  });

  const int threads = args.threads > 0 ? args.threads : tbb::info::default_concurrency();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));

  auto start = std::chrono::steady_clock::now();
  Input input;
  std::unique_ptr<ldimesh::RayCaster> caster;
  std::vector<ldimesh::View> views;
  double iso = 0.0, load_seconds = 0.0, scene_seconds = 0.0;
  // The bind of a time step (again for --repeat: the caster of the same values).
  const auto bind = [&] {
    caster.reset();
    start = std::chrono::steady_clock::now();
    ldimesh::RayCasterOptions caster_options;
    caster_options.path =
        args.caster == "embree" ? ldimesh::CastPath::embree : ldimesh::CastPath::automatic;
    const std::vector<const ldimesh::FieldSource*> sources = input.source_list();
    caster = std::make_unique<ldimesh::RayCaster>(sources, iso, caster_options);
    scene_seconds = seconds_since(start);
  };
  on_all_ranks(comm, [&] {
    load_input(args, rank, ranks, input);
    load_seconds = seconds_since(start);
    iso = args.isovalue.value_or(input.default_isovalue);
    views = ldimesh::make_axis_views(input.subdomain.global, args.res, args.views);
    bind();
  });

  ldimesh::DistributedOptions options;
  options.encoding.lossless = args.lossless;
  options.encoding.depth_bits = args.depth_bits;
  options.encoding.normal_bits = args.normal_bits;
  options.meshing.r = args.r;
  options.meshing.faces = args.quads ? FaceType::quads : FaceType::triangles;
  options.meshing.matching.max_cost = args.max_cost;
  options.meshing.refinement = args.refinement;
  options.meshing.refinement.grow = !args.no_grow;
  options.meshing.merging.enabled = args.merge;
  // --repeat: the whole step again on the same data, as the time steps of a running simulation
  // would run it (warm caches and allocator); every run's figures are reported, the mesh is the
  // last run's.
  ldimesh::DistributedResult step;
  double max_scene = 0.0;
  nlohmann::json repeats = nlohmann::json::array();
  for (int run = 0; run < args.repeat; ++run) {
    if (run > 0) on_all_ranks(comm, bind);
    step = {};
    const ldimesh::Status status =
        ldimesh::mesh_distributed(comm, *caster, input.subdomain, views, options, step);
    if (!status) throw std::runtime_error(status.message());
    MPI_Reduce(&scene_seconds, &max_scene, 1, MPI_DOUBLE, MPI_MAX, 0, comm);
    repeats.push_back(
        {{"scene", max_scene}, {"raycast", step.seconds.cast}, {"reduce", step.seconds.reduce}});
    if (root && args.repeat > 1 && !args.json)
      std::fprintf(stderr, "ldimesh: run %d of %d: scene %.4f s, ray cast %.4f s, reduce %.4f s\n",
                   run + 1, args.repeat, max_scene, step.seconds.cast, step.seconds.reduce);
  }
  if (!root) return 0;

  ldimesh::MeshingResult& result = step.meshing;
  const double r_used = ldimesh::trim_r(options.meshing);
  const bool want_glb = has_extension(args.out, ".glb") || !args.steps_dir.empty();
  // The step as the adaptor packages it (step_package.hpp): vertices where the colour field has
  // no finite value (NaN/Inf in it) take the lowest colour; the GLB and the metadata.
  ldimesh::StepDescription description;
  description.step = args.step;
  description.time = args.time;
  description.isovalues = {iso};
  description.views = views;
  description.r = r_used;
  if (!args.colour_by.empty()) description.colour_fields = {colour_name(args)};
  description.glb = args.glb;
  description.encode = want_glb;
  ldimesh::PackagedStep packaged;
  {
    std::vector<ldimesh::MeshingResult> one(1);
    one[0].mesh = std::move(result.mesh);
    one[0].samples = result.samples;
    one[0].quads = result.quads;
    if (const ldimesh::Status s = ldimesh::package_step(description, std::move(one), packaged); !s)
      throw std::runtime_error(s.message());
  }
  result.mesh = std::move(packaged.mesh);
  const std::size_t uncoloured = packaged.uncoloured;
  if (uncoloured > 0 && !args.json)
    std::fprintf(stderr,
                 "ldimesh: warning: %zu vertices without a finite colour value (NaN/Inf in the "
                 "--colour-by field), given the lowest colour\n",
                 uncoloured);
  double write_seconds = 0.0;
  const std::vector<std::uint8_t>& glb = packaged.glb;
  if (!args.out.empty()) {
    start = std::chrono::steady_clock::now();
    if (has_extension(args.out, ".glb")) {
      std::FILE* f = std::fopen(args.out.c_str(), "wb");
      const bool ok = f && std::fwrite(glb.data(), 1, glb.size(), f) == glb.size();
      if (f && std::fclose(f) != 0) throw std::runtime_error("writing '" + args.out + "' failed");
      if (!ok) throw std::runtime_error("cannot write '" + args.out + "'");
    } else if (const ldimesh::Status s = ldimesh::write_mesh(args.out, result.mesh); !s) {
      throw std::runtime_error(s.message());
    }
    write_seconds = seconds_since(start);
  }
  if (!args.steps_dir.empty()) {
    // A step as the job's server would publish it, for `ldimesh-serve --dir`.
    ldimesh::StepMetadata meta = std::move(packaged.metadata);
    meta.seconds.insert({{"cast", step.seconds.cast},
                         {"encode", step.seconds.encode},
                         {"reduce", step.seconds.reduce},
                         {"decode", step.seconds.decode},
                         {"mesh", step.seconds.mesh}});
    const ldimesh::Snapshot snapshot =
        ldimesh::make_snapshot(std::move(meta), std::move(packaged.glb));
    std::filesystem::create_directories(args.steps_dir);
    if (const ldimesh::Status s = ldimesh::write_step_files(args.steps_dir, snapshot); !s)
      throw std::runtime_error(s.message());
  }

  std::size_t rays = 0;
  for (const ldimesh::View& view : views)
    rays += view.pixel_count();
  const auto& m = result.mesh;
  const auto& t = step.seconds;
  const ldimesh::RefinementStats& refined = result.refinement;
  std::size_t refine_rays = 0;
  for (std::size_t n : refined.rays_per_pass)
    refine_rays += n;
  if (args.json) {
    nlohmann::json j;
    j[!args.vtu.empty() ? "vtu" : args.grid.empty() ? "surface" : "grid"] = input.name;
#ifdef LDIMESH_WITH_VTU
    if (!args.vtu.empty()) {
      j["cells"] = input.elements.cells;
      j["ghost_cells"] = input.elements.ghost_cells;
    }
#endif
    j["isovalue"] = iso;
    j["resolution"] = args.res;
    j["views"] = args.views;
    j["r"] = r_used;
    j["ranks"] = ranks;
    j["threads"] = threads;
    j["caster"] = args.caster;
    j["encoding"] = args.lossless ? "lossless" : "quantized";
    j["rays"] = rays;
    j["samples"] = result.samples;
    j["quads_untrimmed"] = result.quads_untrimmed;
    j["quads"] = result.quads;
    j["triangles"] = m.triangle_count();
    j["vertices"] = m.vertex_count();
    j["faces"] = m.face_count();
    j["face_type"] = args.quads ? "quads" : "triangles";
    if (!m.scalars.empty()) {
      const auto [lo, hi] = std::minmax_element(m.scalars.begin(), m.scalars.end());
      j["colour"] = {{"field", colour_name(args)},
                     {"min", *lo},
                     {"max", *hi},
                     {"uncoloured_vertices", uncoloured}};
    }
    j["bytes_to_root"] = step.bytes_to_root;
    j["bytes_moved"] = step.bytes_moved;
    j["refinement"] = {{"levels", options.meshing.refinement.levels},
                       {"min_normal_dot", options.meshing.refinement.min_normal_dot},
                       {"grow", options.meshing.refinement.grow},
                       {"passes", refined.passes},
                       {"round_trips", refined.round_trips},
                       {"rays", refine_rays},
                       {"rays_per_pass", refined.rays_per_pass},
                       {"seconds_per_pass", refined.seconds_per_pass},
                       {"grown_cells", refined.grown_cells},
                       {"subdivided_cells", refined.subdivided_cells},
                       {"invalid_vertices", refined.invalid_vertices},
                       {"removed_faces", refined.removed_faces},
                       {"trimmed_faces", refined.trimmed_faces},
                       {"seconds", refined.seconds},
                       {"sample_seconds", refined.sample_seconds}};
    const ldimesh::MergeStats& merged = result.merging;
    j["merging"] = {{"enabled", args.merge},
                    {"region_faces", merged.region_faces},
                    {"dropped_faces", merged.dropped_faces},
                    {"boundary_faces", merged.boundary_faces},
                    {"patches", merged.patches},
                    {"bridge_pairs", merged.bridge_pairs},
                    {"bridges", merged.bridges},
                    {"holes", merged.holes},
                    {"fill_triangles", merged.fill_triangles},
                    {"unfilled_holes", merged.unfilled_holes},
                    {"split_quads", merged.split_quads},
                    {"flips", merged.flips},
                    {"merges", merged.merges},
                    {"split_edges", merged.split_edges},
                    {"projected", merged.projected},
                    {"crossings_undone", merged.crossings_undone},
                    {"split_passes", merged.split_passes},
                    {"components", merged.components}};
    if (args.merge && args.quads) {
      const ldimesh::QuadStats& q = merged.quads;
      j["merging"]["quads"] = {{"input_triangles", q.input_triangles},
                               {"input_quads", q.input_quads},
                               {"paired", q.paired},
                               {"region_faces", q.region_faces},
                               {"paths", q.paths},
                               {"path_rounds", q.path_rounds},
                               {"path_splits", q.path_splits},
                               {"turns", q.turns},
                               {"quad_merges", q.quad_merges},
                               {"flips", q.flips},
                               {"boundary_splits", q.boundary_splits},
                               {"leftover_triangles", q.leftover_triangles},
                               {"projected", q.projected},
                               {"crossings_undone", q.crossings_undone},
                               {"output_quads", q.output_quads},
                               {"seconds", q.seconds},
                               {"stage_seconds",
                                {{"setup", q.setup_seconds},
                                 {"pair", q.pair_seconds},
                                 {"paths", q.path_seconds},
                                 {"cleanup", q.cleanup_seconds},
                                 {"smooth", q.smooth_seconds}}}};
    }
    j["output"] = args.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(args.out);
    j["repeats"] = repeats;
    j["seconds"] = {{"load", load_seconds},
                    {"prepare", input.prepare_seconds},
                    {"scene", max_scene},
                    {"raycast", t.cast},
                    {"encode", t.encode},
                    {"reduce", t.reduce},
                    {"decode", t.decode},
                    {"match", result.seconds.match},
                    {"trim", result.seconds.trim},
                    {"refine", result.seconds.refine},
                    {"assemble", result.seconds.assemble},
                    {"bridge", result.seconds.bridge},
                    {"sew", result.seconds.sew},
                    {"quality", result.seconds.quality},
                    {"write", write_seconds}};
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("ldimesh: %s, isovalue %g, views %s at %d px, r = %g, %d rank%s x %d threads\n",
              input.name.c_str(), iso, args.views.c_str(), args.res, r_used, ranks,
              ranks == 1 ? "" : "s", threads);
  if (!args.grid.empty())
    std::printf("  load       %8.3f s  %lldx%lldx%lld %s, values in [%g, %g]\n", load_seconds,
                (long long)args.dims[0], (long long)args.dims[1], (long long)args.dims[2],
                args.type.c_str(), input.volume.min_value, input.volume.max_value);
#ifdef LDIMESH_WITH_VTU
  if (!args.vtu.empty())
    std::printf(
        "  load       %8.3f s  %zu cells in %zu block%s, %zu ghost cells skipped, values in "
        "[%g, %g]\n",
        load_seconds, input.elements.cells, input.elements.groups.size(),
        input.elements.groups.size() == 1 ? "" : "s", input.elements.ghost_cells,
        input.elements.min_value, input.elements.max_value);
#endif
  std::printf("  scene      %8.3f s  (slowest rank)\n", max_scene);
  std::printf("  ray cast   %8.3f s  %zu rays, %zu samples (%.2f M rays/s)\n", t.cast, rays,
              result.samples, rays / t.cast * 1e-6);
  std::printf("  encode     %8.3f s  %s\n", t.encode,
              args.lossless ? "lossless" : "quantized depths and normals, zstd");
  std::printf("  reduce     %8.3f s  %llu bytes moved, %llu to the root (%.2f bytes/sample)\n",
              t.reduce, (unsigned long long)step.bytes_moved,
              (unsigned long long)step.bytes_to_root,
              result.samples ? double(step.bytes_moved) / double(result.samples) : 0.0);
  std::printf("  decode     %8.3f s\n", t.decode);
  std::printf("  mesh       %8.3f s  %zu quads\n", result.seconds.match, result.quads_untrimmed);
  std::printf("  trim       %8.3f s  %zu quads kept\n", result.seconds.trim, result.quads);
  if (options.meshing.refinement.levels > 0)
    std::printf(
        "  refine     %8.3f s  %d pass%s, %zu ray stretches requested (%.3f s sampling), %zu cells "
        "grown, "
        "%zu faces removed\n",
        result.seconds.refine, refined.passes, refined.passes == 1 ? "" : "es", refine_rays,
        refined.sample_seconds, refined.grown_cells, refined.removed_faces);
  if (args.merge) {
    const ldimesh::MergeStats& merged = result.merging;
    std::printf("  bridge     %8.3f s  %zu boundary faces removed, %zu patches, %zu bridges\n",
                result.seconds.bridge, merged.boundary_faces, merged.patches, merged.bridges);
    std::printf("  sew        %8.3f s  %zu holes, %zu triangles added, %zu holes left open\n",
                result.seconds.sew, merged.holes, merged.fill_triangles, merged.unfilled_holes);
    std::printf(
        "  quality    %8.3f s  %zu quads split, %zu flips, %zu 3-to-1 merges, %zu edges split "
        "(%zu new vertices on the surface, %zu round trips); %zu piece%s\n",
        result.seconds.quality, merged.split_quads, merged.flips, merged.merges, merged.split_edges,
        merged.projected, merged.split_passes, merged.components,
        merged.components == 1 ? "" : "s");
    if (args.quads) {
      const ldimesh::QuadStats& q = merged.quads;
      std::printf(
          "  quads      %8.3f s  (in quality) %zu triangle pairs, %zu paths (%zu turns, %zu open "
          "edges split), %zu quad merges, %zu flips; %zu triangles left\n",
          q.seconds, q.paired, q.paths, q.turns, q.boundary_splits, q.quad_merges, q.flips,
          q.leftover_triangles);
    }
  }
  std::printf("  assemble   %8.3f s  %zu vertices, %zu %s\n", result.seconds.assemble,
              m.vertex_count(), m.face_count(), args.quads ? "quads" : "triangles");
  std::printf("  mesh+trim  %8.3f s\n", result.seconds.match + result.seconds.trim);
  if (!args.out.empty()) std::printf("  wrote      %8.3f s  %s\n", write_seconds, args.out.c_str());
  return 0;
}

struct DistanceArgs {
  std::vector<std::string> files;  // A, or A and B
  std::string surface;
  std::string vtu, field;  // or the isosurface of a VTU file's field
  std::optional<double> isovalue;
  std::uint64_t samples = 0;
  int threads = 0;
  bool json = false;
};

// A PLY mesh, or a GLB as ldimesh writes and publishes it (a step's .glb: Draco, decoded and
// checked by decode_glb in a child process with a CPU limit: decode_glb_isolated).
ldimesh::Mesh read_mesh_file(const std::string& path) {
  ldimesh::Mesh mesh;
  if (has_extension(path, ".glb")) {
    std::vector<std::uint8_t> bytes;
    if (ldimesh::Status s = ldimesh::read_file(path, bytes); !s)
      throw std::runtime_error(s.message());
    if (ldimesh::Status s = ldimesh::decode_glb_isolated(bytes, mesh); !s)
      throw std::runtime_error("'" + path + "': " + s.message());
  } else if (has_extension(path, ".ply")) {
    if (const ldimesh::Status s = ldimesh::read_ply(path, mesh); !s)
      throw std::runtime_error(s.message());
  } else {
    throw std::runtime_error("cannot read '" + path + "': give a PLY or GLB mesh");
  }
  if (mesh.face_count() == 0) throw std::runtime_error("'" + path + "' has no faces");
  return mesh;
}

nlohmann::json stats_json(const ldimesh::DistanceStats& s, double diagonal) {
  const double scale = diagonal > 0.0 ? 1.0 / diagonal : 0.0;
  return {{"samples", s.samples.total()},
          {"vertex_samples", s.samples.vertices},
          {"edge_samples", s.samples.edges},
          {"face_samples", s.samples.faces},
          {"mean", s.mean},
          {"rms", s.rms},
          {"max", s.max},
          {"mean_relative", s.mean * scale},
          {"rms_relative", s.rms * scale},
          {"max_relative", s.max * scale},
          {"max_at", {s.max_at.x, s.max_at.y, s.max_at.z}}};
}

void print_stats(const char* label, const ldimesh::DistanceStats& s, double diagonal) {
  const double percent = diagonal > 0.0 ? 100.0 / diagonal : 0.0;
  std::printf("  %-18s mean %.4e (%.4f %%)  rms %.4e (%.4f %%)  max %.4e (%.4f %%)\n", label,
              s.mean, s.mean * percent, s.rms, s.rms * percent, s.max, s.max * percent);
  std::printf("  %-18s %llu samples: %llu vertices, %llu on edges, %llu on faces\n", "",
              (unsigned long long)s.samples.total(), (unsigned long long)s.samples.vertices,
              (unsigned long long)s.samples.edges, (unsigned long long)s.samples.faces);
}

std::string describe_mesh(const std::string& path, const ldimesh::Mesh& m) {
  return path + " (" + std::to_string(m.vertex_count()) + " vertices, " +
         std::to_string(m.face_count()) + " faces)";
}

// `ldimesh distance`: Metro-style distances between two meshes (PLY or GLB), or from one to a
// built-in surface (core/distance.hpp, docs/method.md "Distances").
int run_distance(const DistanceArgs& args) {
  const bool to_surface = !args.surface.empty() || !args.vtu.empty();
  if (!args.surface.empty() && !args.vtu.empty())
    throw std::runtime_error("give --surface NAME or --vtu FILE --field NAME, not both");
  if (args.isovalue && !to_surface)
    throw std::runtime_error("--isovalue is the isovalue of --surface or --vtu: give one");
  if (to_surface && args.files.size() != 1)
    throw std::runtime_error(
        "give one mesh with --surface or --vtu: ldimesh distance A.ply --surface NAME");
  if (!to_surface && args.files.size() != 2)
    throw std::runtime_error(
        "give two meshes (A.ply B.ply), or one mesh and --surface NAME or --vtu FILE --field NAME");
  const int threads = args.threads > 0 ? args.threads : tbb::info::default_concurrency();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  ldimesh::DistanceOptions options;
  options.samples = args.samples;

  // The surface: a built-in one, or the exact isosurface of a VTU file's cells (their
  // polynomials, looked up per point).
  ldimesh::ImplicitSurface surface;
  double default_isovalue = 0.0;
#ifdef LDIMESH_WITH_VTU
  ldimesh::VtuField data;  // owns what the surface's field reads
#endif
  if (!args.vtu.empty()) {
#ifdef LDIMESH_WITH_VTU
    if (args.field.empty()) throw std::runtime_error("--vtu needs --field NAME");
    ldimesh::quiet_vtk_logging();
    if (const ldimesh::Status st = ldimesh::read_vtu_field(args.vtu, args.field, data); !st)
      throw std::runtime_error(st.message());
    const ldimesh::Box bounds = data.lookup->bounds();
    surface.name = args.vtu + ":" + args.field;
    surface.field = data.lookup->field();
    // The cells' boxes, and a little beyond: where the lookup extrapolates.
    const glm::dvec3 pad = 1e-6 * (bounds.hi - bounds.lo);
    surface.domain = {bounds.lo - pad, bounds.hi + pad};
    default_isovalue = 0.5 * (data.elements.min_value + data.elements.max_value);
#else
    throw std::runtime_error("--vtu: this ldimesh was built without VTK (libvtk9-dev)");
#endif
  } else if (to_surface) {
    const ldimesh::SurfaceInfo* info = ldimesh::find_surface(args.surface);
    if (!info)
      throw std::runtime_error("unknown surface '" + args.surface + "' (see 'ldimesh surfaces')");
    surface = {info->name, info->field, info->domain, info->clip_radius};
    default_isovalue = info->isovalue;
  }

  const ldimesh::Mesh a = read_mesh_file(args.files[0]);
  if (to_surface) {
    const double iso = args.isovalue.value_or(default_isovalue);
    const auto start = std::chrono::steady_clock::now();
    const ldimesh::SurfaceDistance d = ldimesh::surface_distance(a, surface, iso, options);
    const double seconds = seconds_since(start);
    if (args.json) {
      nlohmann::json j;
      j["a"] = args.files[0];
      j["surface"] = surface.name;
      j["isovalue"] = iso;
      j["diagonal"] = d.diagonal;
      j["forward"] = stats_json(d.forward, d.diagonal);
      j["not_converged"] = d.not_converged;
      j["outside_clip"] = d.outside_clip;
      j["threads"] = threads;
      j["seconds"] = seconds;
      std::cout << j.dump(2) << "\n";
      return 0;
    }
    std::printf("ldimesh distance: A = %s to the surface %s, isovalue %g\n",
                describe_mesh(args.files[0], a).c_str(), surface.name.c_str(), iso);
    std::printf("  relative figures: %% of A's bounding box diagonal %g\n", d.diagonal);
    print_stats("forward A -> surf", d.forward, d.diagonal);
    std::printf(
        "  %-18s %llu samples left out: %llu not converged%s, %llu outside the clip region\n", "",
        (unsigned long long)(d.not_converged + d.outside_clip), (unsigned long long)d.not_converged,
        args.vtu.empty() ? "" : " or left the cells", (unsigned long long)d.outside_clip);
    std::printf("  time %.3f s, %d thread%s\n", seconds, threads, threads == 1 ? "" : "s");
    return 0;
  }
  const ldimesh::Mesh b = read_mesh_file(args.files[1]);
  const auto start = std::chrono::steady_clock::now();
  const ldimesh::MeshDistance d = ldimesh::mesh_distance(a, b, options);
  const double seconds = seconds_since(start);
  if (args.json) {
    nlohmann::json j;
    j["a"] = args.files[0];
    j["b"] = args.files[1];
    j["diagonal"] = d.diagonal;
    j["forward"] = stats_json(d.forward, d.diagonal);
    j["backward"] = stats_json(d.backward, d.diagonal);
    j["max"] = d.max();
    j["max_relative"] = d.diagonal > 0.0 ? d.max() / d.diagonal : 0.0;
    j["threads"] = threads;
    j["seconds"] = seconds;
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("ldimesh distance: A = %s, B = %s\n", describe_mesh(args.files[0], a).c_str(),
              describe_mesh(args.files[1], b).c_str());
  std::printf("  relative figures: %% of the bounding box diagonal of A and B, %g\n", d.diagonal);
  print_stats("forward  A -> B", d.forward, d.diagonal);
  print_stats("backward B -> A", d.backward, d.diagonal);
  const double percent = d.diagonal > 0.0 ? 100.0 / d.diagonal : 0.0;
  std::printf("  %-18s max  %.4e (%.4f %%)  (sampled Hausdorff distance)\n", "symmetric", d.max(),
              d.max() * percent);
  std::printf("  time %.3f s, %d thread%s\n", seconds, threads, threads == 1 ? "" : "s");
  return 0;
}

}  // namespace

// The CLI's guard: runs body() (which returns the exit code) and turns what it throws into a
// message on stderr (where `print`: the root only under MPI) and an exit code — help: CLI11's,
// a usage error: 2, anything else: 1 (its cause, as the adaptor's API names it).
template <class Body>
int guarded_main(CLI::App& app, bool print, Body&& body) {
  try {
    return body();
  } catch (const CLI::Success& e) {  // --help, --help-all
    return print ? app.exit(e) : 0;
  } catch (const CLI::ParseError& e) {
    if (print) std::fprintf(stderr, "ldimesh: error: %s\n", e.what());
    return 2;
  } catch (...) {
    const ldimesh::Status s = ldimesh::status_from_current_exception("");
    if (print) std::fprintf(stderr, "ldimesh: error: %s\n", s.message().c_str());
    return 1;
  }
}

int main(int argc, char** argv) {
  CLI::App app{"ldimesh: isosurface meshes from Layered Depth Images (Frey, Sadlo, Ertl)"};
  app.require_subcommand(1);
  CLI::App* surfaces = app.add_subcommand("surfaces", "list the built-in analytic surfaces");
  CLI::App* mesh =
      app.add_subcommand("mesh", "ray cast a surface into LDIs and mesh them (paper §3)");
  CLI::App* serve = app.add_subcommand(
      "serve", "serve the steps a run wrote into a folder with the job's API and web viewer");
  ldimesh::ServeArgs serve_args;
  ldimesh::add_serve_options(*serve, serve_args);
  CLI::App* distance = app.add_subcommand(
      "distance",
      "Metro-style distances between two meshes (PLY or GLB), or from one to a surface");
  DistanceArgs distance_args;
  distance->add_option("meshes", distance_args.files, "A [B]: .ply or .glb (a published step) each")
      ->required()
      ->expected(1, 2);
  distance->add_option("--surface", distance_args.surface,
                       "measure A against this built-in surface instead of B");
  CLI::Option* distance_vtu = distance->add_option(
      "--vtu", distance_args.vtu,
      "measure A against the exact isosurface of a VTU file's cells instead of B (needs --field)");
  distance->add_option("--field", distance_args.field, "point array of --vtu")->needs(distance_vtu);
  distance->add_option(
      "--isovalue,--iso", distance_args.isovalue,
      "isovalue of --surface or --vtu (default: the surface's; for --vtu the middle "
      "of the field's range)");
  distance
      ->add_option("--samples", distance_args.samples,
                   "samples per mesh (default: ten per triangle of the larger mesh)")
      ->check(CLI::Range(std::uint64_t(1), std::uint64_t(10000000000)));
  distance->add_option("--threads", distance_args.threads, "threads (default: all cores)")
      ->check(CLI::Range(1, 4096));
  distance->add_flag("--json", distance_args.json, "print the figures as JSON");
  MeshArgs args;
  CLI::Option* surface_opt =
      mesh->add_option("--surface", args.surface, "built-in surface (see 'ldimesh surfaces')");
  mesh->add_option("--grid", args.grid, "raw volume file: point values, x fastest, little-endian")
      ->excludes(surface_opt);
  mesh->add_option("--dims", args.dims, "points per axis of --grid, NX,NY,NZ")
      ->delimiter(',')
      ->expected(3);
  mesh->add_option("--type", args.type, "value type of --grid")
      ->check(CLI::IsMember({"float32", "float64"}))
      ->capture_default_str();
  mesh->add_option("--spacing", args.spacing, "point spacing of --grid, SX,SY,SZ (default 1,1,1)")
      ->delimiter(',')
      ->expected(3)
      ->check(CLI::PositiveNumber);
  mesh->add_option("--origin", args.origin, "position of the first point of --grid (default 0,0,0)")
      ->delimiter(',')
      ->expected(3);
  mesh->add_option("--vtu", args.vtu,
                   "VTK XML unstructured grid (.vtu, .pvtu) of hexahedra, tetrahedra, wedges "
                   "and pyramids (linear, quadratic, Lagrange), meshed exactly (needs --field)");
  mesh->add_option("--field", args.field, "point array of --vtu to mesh");
  mesh->add_option("--colour-by", args.colour_by,
                   "colour the isosurface by a second field: a point array of --vtu, or for "
                   "--grid a raw volume file of the same layout (kept per vertex: GLB _SCALAR, "
                   "docs/api.md; PLY property 'value')");
  mesh->add_option("--res", args.res, "pixels along the longer side of each view")
      ->check(CLI::Range(1, 16384))
      ->capture_default_str();
  mesh->add_option("--views", args.views, "view axes, a subset of xyz")->capture_default_str();
  mesh->add_option("--r", args.r, "trimming parameter r (§3)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  mesh->add_option(
      "--out", args.out,
      "write the mesh to this file: .ply (binary), .obj or .glb (Draco-compressed glTF)");
  mesh->add_option("--steps-dir", args.steps_dir,
                   "also write the mesh as a published step (step_NNNNNN.glb + .json) into this "
                   "folder, for ldimesh-serve --dir");
  mesh->add_option("--step", args.step, "step number for --steps-dir")->capture_default_str();
  mesh->add_option("--time", args.time, "simulation time for --steps-dir")->capture_default_str();
  bool triangles = false;
  CLI::Option* quad_flag = mesh->add_flag("--quad", args.quads, "output quads");
  mesh->add_flag("--tri", triangles,
                 "output triangles, each quad split along its shorter diagonal (default)")
      ->excludes(quad_flag);
  mesh->add_option("--threads", args.threads, "threads (default: all cores)")
      ->check(CLI::Range(1, 4096));
  mesh->add_flag("--json", args.json, "print a machine-readable summary");
  mesh->add_option("--bricks", args.bricks, "culling bricks per axis")
      ->check(CLI::Range(1, 512))
      ->capture_default_str();
  mesh->add_option("--caster", args.caster,
                   "ray caster for axis views: auto (the coherent casters of grids and elements "
                   "where the source has one) or embree (Embree for every ray, the reference)")
      ->check(CLI::IsMember({"auto", "embree"}))
      ->capture_default_str();
  mesh->add_option("--repeat", args.repeat,
                   "run the step (bind, cast, reduce, mesh) this many times on the same data, as "
                   "time steps would, and report every run's seconds (JSON \"repeats\"); the "
                   "output is the last run's")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  mesh->add_option("--iso", args.isovalue,
                   "isovalue (default: the surface's; for --grid the middle of the value range)");
  mesh->add_option("--max-cost", args.max_cost, "§3 match rejection threshold in pixels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  mesh->add_option("--refine", args.refinement.levels,
                   "§4 adaptive refinement: at most LEVELS subdivisions of a cell, one sampling "
                   "round trip each (0: off)")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  mesh->add_option("--refine-dot", args.refinement.min_normal_dot,
                   "§4: refine a cell whose corner normals have a dot product below this")
      ->check(CLI::Range(-1.0, 1.0))
      ->capture_default_str();
  mesh->add_flag("--no-grow", args.no_grow,
                 "§4: no growth of the mesh across its boundaries and silhouettes");
  mesh->add_flag("--merge", args.merge,
                 "§5: merge the views into one mesh (trims with r = 1, bridges, hole filling, "
                 "enhancement; with --quad converted to quads only)");

  mesh->add_flag("--lossless", args.lossless,
                 "send fragments to the root losslessly (default: quantized depths and normals)");
  mesh->add_option("--depth-bits", args.depth_bits, "bits per quantized depth")
      ->check(CLI::Range(1, 24))
      ->capture_default_str();
  mesh->add_option("--normal-bits", args.normal_bits, "bits per octahedral normal coordinate")
      ->check(CLI::Range(2, 16))
      ->capture_default_str();
  mesh->add_option("--glb-level", args.glb.compression_level,
                   "Draco compression level of a .glb (--out, --steps-dir)")
      ->check(CLI::Range(0, 10))
      ->capture_default_str();
  mesh->add_option("--glb-normal-bits", args.glb.normal_bits,
                   "octahedral normal bits of a .glb (largest error 3·√2 / (2^n − 2) rad)")
      ->check(CLI::Range(2, 16))
      ->capture_default_str();
  mesh->add_option("--glb-scalar-bits", args.glb.scalar_bits,
                   "bits of a .glb's _SCALAR (--colour-by; largest error 1 / (2·(2^s − 1)) of "
                   "the range)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();

  // `ldimesh serve` is a plain server process and `ldimesh distance` a plain tool: no MPI.
  if (argc > 1 && (std::string(argv[1]) == "serve" || std::string(argv[1]) == "distance")) {
    return guarded_main(app, true, [&] {
      app.parse(argc, argv);
      if (*distance) return run_distance(distance_args);
      return ldimesh::run_serve(serve_args, "ldimesh serve");
    });
  }

  // MPI is initialised for every other command, so that `mpiexec -n N ldimesh mesh …` splits
  // the work; run without mpiexec it is a job of one rank. Only the root prints.
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const int code = guarded_main(app, rank == 0, [&] {
    app.parse(argc, argv);
    if (*surfaces) return rank == 0 ? run_surfaces() : 0;
    return run_mesh(args);
  });
  MPI_Finalize();
  return code;
}

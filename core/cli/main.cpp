// ldimesh: the command-line front end of the core pipeline.
//   ldimesh surfaces
//   ldimesh mesh --surface barth --res 512 --views xyz --r 0.5 --out out/barth.ply [--json]
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "ldimesh/core/mesh_io.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raw_volume.hpp"
#include "ldimesh/core/raycaster.hpp"
#include "ldimesh/core/surfaces.hpp"

namespace {

using ldimesh::FaceType;

struct MeshArgs {
  std::string surface;
  std::string grid;  // raw volume file
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
  std::optional<double> isovalue;
  double max_cost = ldimesh::MatchOptions{}.max_cost;
};

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

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

int run_surfaces() {
  for (const ldimesh::SurfaceInfo& s : ldimesh::builtin_surfaces()) {
    std::printf("%-15s %s\n", s.name.c_str(), s.formula.c_str());
    std::printf("%-15s domain [%g, %g] x [%g, %g] x [%g, %g], isovalue %g\n", "", s.domain.lo.x,
                s.domain.hi.x, s.domain.lo.y, s.domain.hi.y, s.domain.lo.z, s.domain.hi.z,
                s.isovalue);
  }
  return 0;
}

// What is meshed: a built-in surface or a raw volume, with its source and default isovalue.
struct Input {
  std::string name;
  std::unique_ptr<ldimesh::FieldSource> source;
  double default_isovalue = 0.0;
  ldimesh::RawVolume volume;  // owns the values of a --grid input
};

void load_input(const MeshArgs& args, Input& input) {
  if (args.surface.empty() == args.grid.empty())
    throw std::runtime_error("give either --surface NAME or --grid FILE --dims NX,NY,NZ");
  if (!args.surface.empty()) {
    const ldimesh::SurfaceInfo* surface = ldimesh::find_surface(args.surface);
    if (!surface)
      throw std::runtime_error("unknown surface '" + args.surface + "' (see 'ldimesh surfaces')");
    input.name = surface->name;
    input.source = ldimesh::make_surface_source(surface->name, args.bricks);
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
  input.name = args.grid;
  input.source = std::make_unique<ldimesh::GridSource>(input.volume.block);
  // Without --iso: the middle of the value range.
  input.default_isovalue = 0.5 * (input.volume.min_value + input.volume.max_value);
}

int run_mesh(const MeshArgs& args) {
  if (!args.out.empty()) {
    std::string ext = std::filesystem::path(args.out).extension().string();
    for (char& c : ext)
      c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext != ".ply" && ext != ".obj")
      throw std::runtime_error("cannot tell the format of '" + args.out +
                               "': use a .ply or .obj file name");
    check_writable(args.out);
  }

  const int threads = args.threads > 0 ? args.threads : tbb::info::default_concurrency();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));

  auto start = std::chrono::steady_clock::now();
  Input input;
  load_input(args, input);
  const double load_seconds = seconds_since(start);
  const double iso = args.isovalue.value_or(input.default_isovalue);
  const std::vector<ldimesh::View> views =
      ldimesh::make_axis_views(input.source->bounds(), args.res, args.views);

  start = std::chrono::steady_clock::now();
  const ldimesh::RayCaster caster(*input.source, iso);
  const double scene_seconds = seconds_since(start);

  start = std::chrono::steady_clock::now();
  std::vector<ldimesh::Ldi> ldis;
  std::size_t rays = 0;
  for (const ldimesh::View& view : views) {
    ldis.push_back(caster.cast(view));
    rays += view.pixel_count();
  }
  const double cast_seconds = seconds_since(start);

  ldimesh::MeshingOptions options;
  options.r = args.r;
  options.faces = args.quads ? FaceType::quads : FaceType::triangles;
  options.matching.max_cost = args.max_cost;
  const ldimesh::MeshingResult result = ldimesh::mesh_ldis(ldis, options);

  double write_seconds = 0.0;
  if (!args.out.empty()) {
    start = std::chrono::steady_clock::now();
    if (const ldimesh::Status s = ldimesh::write_mesh(args.out, result.mesh); !s)
      throw std::runtime_error(s.message());
    write_seconds = seconds_since(start);
  }

  const auto& m = result.mesh;
  const double mesh_trim = result.seconds.match + result.seconds.trim;
  if (args.json) {
    nlohmann::json j;
    j[args.grid.empty() ? "surface" : "grid"] = input.name;
    j["isovalue"] = iso;
    j["resolution"] = args.res;
    j["views"] = args.views;
    j["r"] = args.r;
    j["threads"] = threads;
    j["bricks"] = caster.primitive_count();
    j["rays"] = rays;
    j["samples"] = result.samples;
    j["quads_untrimmed"] = result.quads_untrimmed;
    j["quads"] = result.quads;
    j["triangles"] = m.triangle_count();
    j["vertices"] = m.vertex_count();
    j["faces"] = m.face_count();
    j["face_type"] = args.quads ? "quads" : "triangles";
    j["output"] = args.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(args.out);
    j["seconds"] = {{"load", load_seconds},        {"scene", scene_seconds},
                    {"raycast", cast_seconds},     {"match", result.seconds.match},
                    {"trim", result.seconds.trim}, {"assemble", result.seconds.assemble},
                    {"write", write_seconds}};
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("ldimesh: %s, isovalue %g, views %s at %d px, r = %g, %d threads\n",
              input.name.c_str(), iso, args.views.c_str(), args.res, args.r, threads);
  if (!args.grid.empty())
    std::printf("  load       %8.3f s  %lldx%lldx%lld %s, values in [%g, %g]\n", load_seconds,
                (long long)args.dims[0], (long long)args.dims[1], (long long)args.dims[2],
                args.type.c_str(), input.volume.min_value, input.volume.max_value);
  std::printf("  scene      %8.3f s  %zu bricks hold the isovalue\n", scene_seconds,
              caster.primitive_count());
  std::printf("  ray cast   %8.3f s  %zu rays, %zu samples (%.2f M rays/s, %.2f M hits/s)\n",
              cast_seconds, rays, result.samples, rays / cast_seconds * 1e-6,
              result.samples / cast_seconds * 1e-6);
  std::printf("  mesh       %8.3f s  %zu quads\n", result.seconds.match, result.quads_untrimmed);
  std::printf("  trim       %8.3f s  %zu quads kept\n", result.seconds.trim, result.quads);
  std::printf("  assemble   %8.3f s  %zu vertices, %zu %s\n", result.seconds.assemble,
              m.vertex_count(), m.face_count(), args.quads ? "quads" : "triangles");
  std::printf("  mesh+trim  %8.3f s\n", mesh_trim);
  if (!args.out.empty()) std::printf("  wrote      %8.3f s  %s\n", write_seconds, args.out.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ldimesh: isosurface meshes from Layered Depth Images (Frey, Sadlo, Ertl)"};
  app.require_subcommand(1);
  CLI::App* surfaces = app.add_subcommand("surfaces", "list the built-in analytic surfaces");
  CLI::App* mesh =
      app.add_subcommand("mesh", "ray cast a surface into LDIs and mesh them (paper §3)");
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
  mesh->add_option("--res", args.res, "pixels along the longer side of each view")
      ->check(CLI::Range(1, 16384))
      ->capture_default_str();
  mesh->add_option("--views", args.views, "view axes, a subset of xyz")->capture_default_str();
  mesh->add_option("--r", args.r, "trimming parameter r (§3)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  mesh->add_option("--out", args.out, "write the mesh to this .ply or .obj file");
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
  mesh->add_option("--iso", args.isovalue,
                   "isovalue (default: the surface's; for --grid the middle of the value range)");
  mesh->add_option("--max-cost", args.max_cost, "§3 match rejection threshold in pixels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "ldimesh: error: %s\n", e.what());
    return 2;
  }
  try {
    if (*surfaces) return run_surfaces();
    return run_mesh(args);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ldimesh: error: %s\n", e.what());
    return 1;
  }
}

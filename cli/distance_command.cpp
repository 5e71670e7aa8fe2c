#include "distance_command.hpp"

#include <chrono>
#include <cstdio>
#include <iostream>
#include <stdexcept>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <nlohmann/json.hpp>

#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#ifdef LDIMESH_WITH_VTU
#include "ldimesh/core/io/vtu.hpp"
#endif
#include "ldimesh/core/metrics/distance.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "support.hpp"

namespace ldimesh::cli {
namespace {

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

}  // namespace

void add_distance_options(CLI::App& distance, DistanceArgs& args) {
  distance.add_option("meshes", args.files, "A [B]: .ply or .glb (a published step) each")
      ->required()
      ->expected(1, 2);
  distance.add_option("--surface", args.surface,
                      "measure A against this built-in surface instead of B");
  CLI::Option* distance_vtu = distance.add_option(
      "--vtu", args.vtu,
      "measure A against the exact isosurface of a VTU file's cells instead of B (needs --field)");
  distance.add_option("--field", args.field, "point array of --vtu")->needs(distance_vtu);
  distance.add_option(
      "--isovalue,--iso", args.isovalue,
      "isovalue of --surface or --vtu (default: the surface's; for --vtu the middle "
      "of the field's range)");
  distance
      .add_option("--samples", args.samples,
                  "samples per mesh (default: ten per triangle of the larger mesh)")
      ->check(CLI::Range(std::uint64_t(1), std::uint64_t(10000000000)));
  distance.add_option("--threads", args.threads, "threads (default: all cores)")
      ->check(CLI::Range(1, 4096));
  distance.add_flag("--json", args.json, "print the figures as JSON");
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

}  // namespace ldimesh::cli

#include "mesh_command.hpp"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>

#include <tbb/global_control.h>
#include <tbb/info.h>

#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "ldimesh/transport/step_package.hpp"
#include "mesh_report.hpp"
#include "support.hpp"

namespace ldimesh::cli {
namespace {

DistributedOptions distributed_options(const MeshArgs& args) {
  DistributedOptions options;
  options.encoding.lossless = args.lossless;
  options.encoding.depth_bits = args.depth_bits;
  options.encoding.normal_bits = args.normal_bits;
  options.meshing.r = args.r;
  options.meshing.faces = args.quads ? FaceType::quads : FaceType::triangles;
  options.meshing.matching.max_cost = args.max_cost;
  options.meshing.refinement = args.refinement;
  options.meshing.refinement.grow = !args.no_grow;
  options.meshing.merging.enabled = args.merge;
  return options;
}

// The root: the step packaged as the adaptor packages it (step_package.hpp) — vertices where
// the colour field has no finite value (NaN/Inf in it) take the lowest colour; the GLB and the
// metadata — and written to --out and --steps-dir.
void write_outputs(const MeshArgs& args, MeshRun& run) {
  MeshingResult& result = run.step.meshing;
  StepDescription description;
  description.step = args.step;
  description.time = args.time;
  description.isovalues = {run.iso};
  description.views = run.views;
  description.r = run.r_used;
  if (!args.colour_by.empty()) description.colour_fields = {colour_name(args)};
  description.glb = args.glb;
  description.encode = has_extension(args.out, ".glb") || !args.steps_dir.empty();
  PackagedStep packaged;
  {
    std::vector<StepSurface> one(1);
    one[0] = {std::move(result.mesh), result.samples, result.quads};
    if (const Status s = package_step(description, std::move(one), packaged); !s)
      throw std::runtime_error(s.message());
  }
  result.mesh = std::move(packaged.mesh);
  run.uncoloured = packaged.uncoloured;
  if (run.uncoloured > 0 && !args.json)
    std::fprintf(stderr,
                 "ldimesh: warning: %zu vertices without a finite colour value (NaN/Inf in the "
                 "--colour-by field), given the lowest colour\n",
                 run.uncoloured);
  // The step folder's files (a step as the job's server would publish it, for `ldimesh-serve
  // --dir`); a folder this made is removed again if they fail.
  const auto write_steps = [&] {
    if (args.steps_dir.empty()) return;
    const DistributedTimes& t = run.step.seconds;
    StepMetadata meta = std::move(packaged.metadata);
    meta.seconds.insert({{"cast", t.cast},
                         {"encode", t.encode},
                         {"reduce", t.reduce},
                         {"decode", t.decode},
                         {"mesh", t.mesh}});
    const Snapshot snapshot = make_snapshot(std::move(meta), std::move(packaged.glb));
    std::error_code ec;
    const bool existed = std::filesystem::exists(args.steps_dir, ec);
    std::filesystem::create_directories(args.steps_dir, ec);
    const Status s =
        ec ? Status::io("cannot create folder '" + args.steps_dir + "': " + ec.message())
           : write_step_files(args.steps_dir, snapshot);
    if (!s) {
      if (!existed) std::filesystem::remove(args.steps_dir, ec);  // only if still empty
      throw std::runtime_error(s.message());
    }
  };
  if (args.out.empty()) return write_steps();
  // --out last, once the step folder is written: a failure leaves it as it was.
  write_atomically(
      args.out,
      [&](const std::string& temporary) {
        const auto start = std::chrono::steady_clock::now();
        Status s = Status::ok();
        if (!has_extension(args.out, ".glb")) {
          s = write_mesh(temporary, result.mesh);
        } else {
          const std::vector<std::uint8_t>& glb = packaged.glb;
          std::FILE* f = std::fopen(temporary.c_str(), "wb");
          bool ok = f && std::fwrite(glb.data(), 1, glb.size(), f) == glb.size();
          if (f && std::fclose(f) != 0) ok = false;
          if (!ok) s = Status::io("cannot write '" + args.out + "'");
        }
        run.write_seconds = seconds_since(start);
        return s;
      },
      write_steps);
}

}  // namespace

void add_mesh_options(CLI::App& mesh, MeshArgs& args) {
  CLI::Option* surface_opt =
      mesh.add_option("--surface", args.surface, "built-in surface (see 'ldimesh surfaces')");
  mesh.add_option("--grid", args.grid, "raw volume file: point values, x fastest, little-endian")
      ->excludes(surface_opt);
  mesh.add_option("--dims", args.dims, "points per axis of --grid, NX,NY,NZ")
      ->delimiter(',')
      ->expected(3);
  mesh.add_option("--type", args.type, "value type of --grid")
      ->check(CLI::IsMember({"float32", "float64"}))
      ->capture_default_str();
  mesh.add_option("--spacing", args.spacing, "point spacing of --grid, SX,SY,SZ (default 1,1,1)")
      ->delimiter(',')
      ->expected(3)
      ->check(CLI::PositiveNumber);
  mesh.add_option("--origin", args.origin, "position of the first point of --grid (default 0,0,0)")
      ->delimiter(',')
      ->expected(3);
  mesh.add_option("--vtu", args.vtu,
                  "VTK XML unstructured grid (.vtu, .pvtu) of hexahedra, tetrahedra, wedges "
                  "and pyramids (linear, quadratic, Lagrange), meshed exactly (needs --field)");
  mesh.add_option("--field", args.field, "point array of --vtu to mesh");
  mesh.add_option("--colour-by", args.colour_by,
                  "colour the isosurface by a second field: a point array of --vtu, or for "
                  "--grid a raw volume file of the same layout (kept per vertex: GLB _SCALAR, "
                  "docs/api.md; PLY property 'value')");
  mesh.add_option("--res", args.res, "pixels along the longer side of each view")
      ->check(CLI::Range(1, 16384))
      ->capture_default_str();
  mesh.add_option("--views", args.views, "view axes, a subset of xyz")->capture_default_str();
  mesh.add_option("--r", args.r, "trimming parameter r (§3)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  mesh.add_option(
      "--out", args.out,
      "write the mesh to this file: .ply (binary), .obj or .glb (Draco-compressed glTF)");
  mesh.add_option("--steps-dir", args.steps_dir,
                  "also write the mesh as a published step (step_NNNNNN.glb + .json) into this "
                  "folder, for ldimesh-serve --dir");
  mesh.add_option("--step", args.step, "step number for --steps-dir")->capture_default_str();
  mesh.add_option("--time", args.time, "simulation time for --steps-dir")->capture_default_str();
  CLI::Option* quad_flag = mesh.add_flag("--quad", args.quads, "output quads");
  mesh.add_flag("--tri", args.triangles,
                "output triangles, each quad split along its shorter diagonal (default)")
      ->excludes(quad_flag);
  mesh.add_option("--threads", args.threads, "threads (default: all cores)")
      ->check(CLI::Range(1, 4096));
  mesh.add_flag("--json", args.json, "print a machine-readable summary");
  mesh.add_option("--bricks", args.bricks, "culling bricks per axis")
      ->check(CLI::Range(1, 512))
      ->capture_default_str();
  mesh.add_option("--caster", args.caster,
                  "ray caster for axis views: auto (the coherent casters of grids and elements "
                  "where the source has one) or embree (Embree for every ray, the reference)")
      ->check(CLI::IsMember({"auto", "embree"}))
      ->capture_default_str();
  mesh.add_option("--repeat", args.repeat,
                  "run the step (bind, cast, reduce, mesh) this many times on the same data, as "
                  "time steps would, and report every run's seconds (JSON \"repeats\"); the "
                  "output is the last run's")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  mesh.add_option("--iso", args.isovalue,
                  "isovalue (default: the surface's; for --grid the middle of the value range)");
  mesh.add_option("--max-cost", args.max_cost, "§3 match rejection threshold in pixels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  mesh.add_option("--refine", args.refinement.levels,
                  "§4 adaptive refinement: at most LEVELS subdivisions of a cell, one sampling "
                  "round trip each (0: off)")
      ->check(CLI::Range(0, 16))
      ->capture_default_str();
  mesh.add_option("--refine-dot", args.refinement.min_normal_dot,
                  "§4: refine a cell whose corner normals have a dot product below this")
      ->check(CLI::Range(-1.0, 1.0))
      ->capture_default_str();
  mesh.add_flag("--no-grow", args.no_grow,
                "§4: no growth of the mesh across its boundaries and silhouettes");
  mesh.add_flag("--merge", args.merge,
                "§5: merge the views into one mesh (trims with r = 1, bridges, hole filling, "
                "enhancement; with --quad converted to quads only)");

  mesh.add_flag("--lossless", args.lossless,
                "send fragments to the root losslessly (default: quantized depths and normals)");
  mesh.add_option("--depth-bits", args.depth_bits, "bits per quantized depth")
      ->check(CLI::Range(1, 24))
      ->capture_default_str();
  mesh.add_option("--normal-bits", args.normal_bits, "bits per octahedral normal coordinate")
      ->check(CLI::Range(2, 16))
      ->capture_default_str();
  mesh.add_option("--glb-level", args.glb.compression_level,
                  "Draco compression level of a .glb (--out, --steps-dir)")
      ->check(CLI::Range(0, 10))
      ->capture_default_str();
  mesh.add_option("--glb-normal-bits", args.glb.normal_bits,
                  "octahedral normal bits of a .glb (largest error 3·√2 / (2^n − 2) rad)")
      ->check(CLI::Range(2, 16))
      ->capture_default_str();
  mesh.add_option("--glb-scalar-bits", args.glb.scalar_bits,
                  "bits of a .glb's _SCALAR (--colour-by; largest error 1 / (2·(2^s − 1)) of "
                  "the range)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
}

int run_surfaces() {
  for (const SurfaceInfo& s : builtin_surfaces()) {
    std::printf("%-15s %s\n", s.name.c_str(), s.formula.c_str());
    std::printf("%-15s domain [%g, %g] x [%g, %g] x [%g, %g], isovalue %g\n", "", s.domain.lo.x,
                s.domain.hi.x, s.domain.lo.y, s.domain.hi.y, s.domain.lo.z, s.domain.hi.z,
                s.isovalue);
  }
  return 0;
}

int run_mesh(const MeshArgs& args) {
  const MPI_Comm comm = MPI_COMM_WORLD;
  int rank = 0;
  MeshRun run;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &run.ranks);
  const bool root = rank == 0;

  on_all_ranks(comm, [&] {
    if (!root) return;
    if (!args.out.empty()) {
      if (!has_extension(args.out, ".ply") && !has_extension(args.out, ".obj") &&
          !has_extension(args.out, ".glb"))
        throw std::runtime_error("cannot tell the format of '" + args.out +
                                 "': use a .ply, .obj or .glb file name");
      check_writable(args.out);
    }
    if (!args.steps_dir.empty()) check_writable_folder(args.steps_dir);
  });

  run.threads = args.threads > 0 ? args.threads : tbb::info::default_concurrency();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(run.threads));

  std::unique_ptr<RayCaster> caster;
  // The bind of a time step (again for --repeat: the caster of the same values).
  const auto bind = [&] {
    caster.reset();
    const auto start = std::chrono::steady_clock::now();
    RayCasterOptions caster_options;
    caster_options.path = args.caster == "embree" ? CastPath::embree : CastPath::automatic;
    caster = std::make_unique<RayCaster>(run.input.source_list(), run.iso, caster_options);
    run.scene_seconds = seconds_since(start);
  };
  on_all_ranks(comm, [&] {
    const auto start = std::chrono::steady_clock::now();
    load_input(args, rank, run.ranks, run.input);
    run.load_seconds = seconds_since(start);
    run.iso = args.isovalue.value_or(run.input.default_isovalue);
    run.views = make_axis_views(run.input.subdomain.global, args.res, args.views);
    bind();
  });

  run.options = distributed_options(args);
  run.r_used = trim_r(run.options.meshing);
  // --repeat: the whole step again on the same data, as the time steps of a running simulation
  // would run it (warm caches and allocator); every run's figures are reported, the mesh is the
  // last run's.
  for (int i = 0; i < args.repeat; ++i) {
    if (i > 0) on_all_ranks(comm, bind);
    run.step = {};
    const Status status =
        mesh_distributed(comm, *caster, run.input.subdomain, run.views, run.options, run.step);
    if (!status) throw std::runtime_error(status.message());
    MPI_Reduce(&run.scene_seconds, &run.max_scene, 1, MPI_DOUBLE, MPI_MAX, 0, comm);
    const DistributedTimes& t = run.step.seconds;
    run.repeats.push_back({{"scene", run.max_scene}, {"raycast", t.cast}, {"reduce", t.reduce}});
    if (root && args.repeat > 1 && !args.json)
      std::fprintf(stderr, "ldimesh: run %d of %d: scene %.4f s, ray cast %.4f s, reduce %.4f s\n",
                   i + 1, args.repeat, run.max_scene, t.cast, t.reduce);
  }
  if (!root) return 0;
  write_outputs(args, run);
  if (args.json)
    print_mesh_json(args, run);
  else
    print_mesh_text(args, run);
  return 0;
}

}  // namespace ldimesh::cli

// One step of the distributed pipeline per run, under mpiexec: ray casting, encoding,
// reduction, decoding and meshing, and the bytes moved to the root. Prints one Markdown row
// (root only); bench/mpi_bench.sh runs it for 1, 2, 4 and 8 ranks.
//
//   mpiexec -n 4 build/bin/ldimesh_bench_mpi [--surface barth] [--res 512] [--repeat 3]
#include <mpi.h>

#include <algorithm>
#include <cstdio>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <CLI/CLI.hpp>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "ldimesh/transport/distributed.hpp"

int main(int argc, char** argv) {
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);

  CLI::App app{"ldimesh distributed pipeline benchmark"};
  std::string surface = "barth";
  int res = 512, repeat = 3, threads = 0;
  bool header = false, lossless = false;
  app.add_option("--surface", surface);
  app.add_option("--res", res)->check(CLI::Range(8, 8192));
  app.add_option("--repeat", repeat, "runs; the median step is reported")
      ->check(CLI::Range(1, 100));
  app.add_option("--threads", threads, "threads per rank (default: cores / ranks, at least 1)");
  app.add_flag("--header", header, "print the table header first");
  app.add_flag("--lossless", lossless);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (rank == 0) app.exit(e);
    MPI_Finalize();
    return 2;
  }
  if (threads == 0) threads = std::max(1, tbb::info::default_concurrency() / ranks);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));

  const ldimesh::SurfaceInfo* s = ldimesh::find_surface(surface);
  if (!s) {
    if (rank == 0) std::fprintf(stderr, "unknown surface '%s'\n", surface.c_str());
    MPI_Finalize();
    return 1;
  }
  const auto source = ldimesh::make_surface_source(s->name);
  const ldimesh::RayCaster caster(*source, s->isovalue);
  const ldimesh::Subdomain sub{ldimesh::decompose_box(s->domain, ranks)[rank], s->domain};
  const std::vector<ldimesh::View> views = ldimesh::make_axis_views(s->domain, res);
  ldimesh::DistributedOptions options;
  options.encoding.lossless = lossless;

  std::vector<ldimesh::DistributedResult> runs(repeat);
  for (ldimesh::DistributedResult& run : runs) {
    MPI_Barrier(MPI_COMM_WORLD);
    if (const ldimesh::Status st =
            mesh_distributed(MPI_COMM_WORLD, caster, sub, views, options, run);
        !st) {
      if (rank == 0) std::fprintf(stderr, "%s\n", st.message().c_str());
      MPI_Finalize();
      return 1;
    }
  }
  if (rank == 0) {
    auto total = [](const ldimesh::DistributedResult& r) {
      return r.seconds.cast + r.seconds.reduce + r.seconds.decode + r.seconds.mesh;
    };
    std::sort(runs.begin(), runs.end(),
              [&](const auto& a, const auto& b) { return total(a) < total(b); });
    const ldimesh::DistributedResult& r = runs[runs.size() / 2];
    const auto& t = r.seconds;
    if (header) {
      std::printf(
          "| ranks × threads | data | cast s | encode s | reduce s | decode s | mesh s | step s "
          "| bytes moved | bytes to root | bytes/sample | samples | triangles |\n");
      std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    }
    std::printf(
        "| %d × %d | %s %d² %s | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %llu | %llu | %.2f | "
        "%zu | %zu |\n",
        ranks, threads, s->name.c_str(), res, lossless ? "lossless" : "quantized", t.cast, t.encode,
        t.reduce, t.decode, t.mesh, total(r), (unsigned long long)r.bytes_moved,
        (unsigned long long)r.bytes_to_root,
        r.meshing.samples ? double(r.bytes_moved) / double(r.meshing.samples) : 0.0,
        r.meshing.samples, r.meshing.mesh.triangle_count());
  }
  MPI_Finalize();
  return 0;
}

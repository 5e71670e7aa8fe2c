// ldimesh: the command line of the pipeline, in one process or over MPI ranks.
//   ldimesh surfaces
//   ldimesh mesh --surface barth --res 512 --views xyz --r 0.5 --out out/barth.ply [--json]
//   ldimesh mesh --surface marschner-lobb --res 128 --refine 2 --out out/ml.ply
//   mpiexec -n 4 ldimesh mesh --surface barth --res 256 --out out/barth.ply
//   ldimesh serve --dir out/steps [--port 8080] [--bind 127.0.0.1]
//   ldimesh distance A.ply B.ply [--samples N] [--json]
//   ldimesh distance A.ply --surface NAME [--isovalue v] [--samples N] [--json]
//   ldimesh distance A.ply --vtu FILE.vtu --field NAME [--isovalue v] [--samples N] [--json]
//
// One file per subcommand: mesh_command (with mesh_input and mesh_report), distance_command;
// `serve` is viewer/serve's, shared with ldimesh-serve.
#include <cstdio>
#include <string>

#include <mpi.h>
#include <CLI/CLI.hpp>

#include "distance_command.hpp"
#include "ldimesh/core/base/status.hpp"
#include "mesh_command.hpp"
#include "serve.hpp"

namespace {

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

}  // namespace

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
  ldimesh::cli::DistanceArgs distance_args;
  ldimesh::cli::add_distance_options(*distance, distance_args);
  ldimesh::cli::MeshArgs args;
  ldimesh::cli::add_mesh_options(*mesh, args);

  // `ldimesh serve` is a plain server process and `ldimesh distance` a plain tool: no MPI.
  if (argc > 1 && (std::string(argv[1]) == "serve" || std::string(argv[1]) == "distance")) {
    return guarded_main(app, true, [&] {
      app.parse(argc, argv);
      if (*distance) return ldimesh::cli::run_distance(distance_args);
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
    if (*surfaces) return rank == 0 ? ldimesh::cli::run_surfaces() : 0;
    return ldimesh::cli::run_mesh(args);
  });
  MPI_Finalize();
  return code;
}

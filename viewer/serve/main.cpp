// ldimesh-serve: serves the steps a run wrote into a folder (step_N.glb + step_N.json) with
// the job's own API, token rules and web viewer, picking up new steps as they appear.
//   ldimesh-serve --dir out/steps [--port 8080] [--bind 127.0.0.1] [--token T] [--keep 16]
// (the same as `ldimesh serve`).
#include <cstdio>
#include <exception>

#include <CLI/CLI.hpp>

#include "serve.hpp"

int main(int argc, char** argv) {
  CLI::App app{
      "Serves the steps a run wrote into a folder (step_N.glb + step_N.json) with "
      "the job's HTTP API and web viewer; new steps are picked up as they appear."};
  ldimesh::ServeArgs args;
  ldimesh::add_serve_options(app, args);
  try {
    app.parse(argc, argv);
    return ldimesh::run_serve(args, "ldimesh-serve");
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "ldimesh-serve: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ldimesh-serve: error: %s\n", e.what());
    return 1;
  }
}

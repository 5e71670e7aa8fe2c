// Serving the steps a run wrote into a folder (step_N.glb + step_N.json) with the job's own API,
// token rules and web viewer, picking up new steps as they appear. Shared by `ldimesh serve`
// and `ldimesh-serve`.
#pragma once

#include <cstddef>
#include <string>

#include <CLI/CLI.hpp>

namespace ldimesh {

struct ServeArgs {
  std::string dir;
  int port = 8080;
  std::string bind = "127.0.0.1";
  bool allow_remote = false;
  std::string token;
  std::size_t keep = 16;
  std::string static_dir;
  std::string vendor_dir;
};

// Adds --dir, --port, --bind, --allow-remote, --token, --keep, --static-dir and --vendor-dir to
// `app`.
void add_serve_options(CLI::App& app, ServeArgs& args);

// Serves until SIGINT or SIGTERM, then returns 0. Messages start with `program`. Throws
// std::runtime_error for a missing folder or a server that cannot start (port in use).
int run_serve(const ServeArgs& args, const std::string& program);

}  // namespace ldimesh

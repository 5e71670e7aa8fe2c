// ldimesh-serve: serves the steps a run wrote into a folder (step_N.glb + step_N.json) with
// the job's own API, token rules and web viewer, picking up new steps as they appear.
//   ldimesh-serve --dir out/steps [--port 8080] [--bind 127.0.0.1] [--token T] [--keep 16]
#include <pthread.h>
#include <signal.h>

#include <cstdio>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "ldimesh/transport/http_server.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace {

namespace fs = std::filesystem;

struct Args {
  std::string dir;
  int port = 8080;
  std::string bind = "127.0.0.1";
  std::string token;
  std::size_t keep = 16;
  std::string static_dir;
  std::string vendor_dir;
};

// The checkout this binary was built in: build/bin/ldimesh-serve → the repository root.
std::optional<fs::path> repository_root() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return std::nullopt;
  return exe.parent_path().parent_path().parent_path();
}

// `given` when set; otherwise `relative` below the repository root if it is there, or empty
// with a warning (the API works without the viewer).
fs::path locate(const std::string& given, const fs::path& relative, const char* option) {
  if (!given.empty()) return given;
  if (const auto root = repository_root()) {
    std::error_code ec;
    if (fs::is_directory(*root / relative, ec)) return *root / relative;
  }
  std::fprintf(stderr,
               "ldimesh-serve: warning: %s not found next to this binary; the API works, the "
               "viewer needs %s\n",
               relative.string().c_str(), option);
  return {};
}

void print_warnings(ldimesh::DirectoryWatcher& watcher) {
  for (const std::string& w : watcher.take_warnings())
    std::fprintf(stderr, "ldimesh-serve: warning: %s\n", w.c_str());
}

int run(const Args& args) {
  std::error_code ec;
  if (!fs::is_directory(args.dir, ec))
    throw std::runtime_error("'" + args.dir + "' is not a directory");

  // SIGINT and SIGTERM are taken with sigtimedwait by the main thread, between scans; blocked
  // before the server starts, so that none of its threads takes them. A shell starts
  // background jobs with SIGINT ignored: the contract is to stop cleanly on it, so reset.
  ::signal(SIGINT, SIG_DFL);
  ::signal(SIGTERM, SIG_DFL);
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  ldimesh::SnapshotStore store({.max_snapshots = args.keep});
  ldimesh::DirectoryWatcher watcher(args.dir);
  if (ldimesh::Status s = watcher.scan(store); !s) throw std::runtime_error(s.message());
  print_warnings(watcher);

  ldimesh::HttpServerOptions options;
  options.bind_address = args.bind;
  options.port = args.port;
  options.token = args.token;
  options.static_dir = locate(args.static_dir, "viewer/web", "--static-dir");
  options.vendor_three_dir = locate(args.vendor_dir, "node_modules/three", "--vendor-dir");
  ldimesh::HttpServer server(store, options);
  if (ldimesh::Status s = server.start(); !s) throw std::runtime_error(s.message());
  std::printf("ldimesh-serve: serving %zu step(s) from %s at %s\n", store.list().size(),
              args.dir.c_str(), server.url().c_str());
  std::fflush(stdout);

  std::string last_error;  // a scan error is printed when it first appears, not every 0.5 s
  const timespec poll{0, 500'000'000};
  while (sigtimedwait(&stop_signals, nullptr, &poll) < 0) {
    const auto before = store.latest();
    ldimesh::Status s = watcher.scan(store);
    print_warnings(watcher);
    if (!s && s.message() != last_error)
      std::fprintf(stderr, "ldimesh-serve: warning: %s\n", s.message().c_str());
    last_error = s ? "" : s.message();
    for (const auto& snapshot : store.list()) {
      if (!before || snapshot->step > before->step) {
        std::printf("ldimesh-serve: step %llu\n", static_cast<unsigned long long>(snapshot->step));
        std::fflush(stdout);
      }
    }
  }
  server.stop();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Serves the steps a run wrote into a folder (step_N.glb + step_N.json) with "
      "the job's HTTP API and web viewer; new steps are picked up as they appear."};
  Args args;
  app.add_option("--dir", args.dir, "the folder of step files")->required();
  app.add_option("--port", args.port, "the port (0: any free one)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  app.add_option("--bind", args.bind, "the address to listen on")->capture_default_str();
  app.add_option("--token", args.token,
                 "the access token (letters, digits, -._~); default: a random one");
  app.add_option("--keep", args.keep, "how many of the newest steps to serve")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 20))
      ->capture_default_str();
  app.add_option("--static-dir", args.static_dir,
                 "the viewer's files (default: viewer/web of this checkout)");
  app.add_option("--vendor-dir", args.vendor_dir,
                 "three.js (default: node_modules/three of this checkout)");
  try {
    app.parse(argc, argv);
    return run(args);
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

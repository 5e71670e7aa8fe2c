#include "serve.hpp"

#include <pthread.h>
#include <signal.h>

#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "ldimesh/transport/http_server.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh {
namespace {

namespace fs = std::filesystem;

// `given` when set; otherwise `found` (find_viewer_files: the checkout, the installation), or
// empty with a warning (the API works without the viewer).
fs::path locate(const std::string& given, const fs::path& found, const char* what,
                const char* option, const std::string& program) {
  if (!given.empty()) return given;
  if (!found.empty()) return found;
  std::fprintf(stderr,
               "%s: warning: %s not found (neither in the checkout nor installed, nor in "
               "$LDIMESH_DATA_DIR); the API works, the viewer needs %s\n",
               program.c_str(), what, option);
  return {};
}

void print_warnings(ldimesh::DirectoryWatcher& watcher, const std::string& program) {
  for (const std::string& w : watcher.take_warnings())
    std::fprintf(stderr, "%s: warning: %s\n", program.c_str(), w.c_str());
}

}  // namespace

int run_serve(const ServeArgs& args, const std::string& program) {
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
  print_warnings(watcher, program);

  ldimesh::HttpServerOptions options;
  options.bind_address = args.bind;
  options.allow_remote = args.allow_remote;
  options.port = args.port;
  options.token = args.token;
  const ldimesh::ViewerFiles files = ldimesh::find_viewer_files();
  options.static_dir =
      locate(args.static_dir, files.static_dir, "viewer/web", "--static-dir", program);
  options.vendor_three_dir = locate(args.vendor_dir, files.vendor_three_dir, "node_modules/three",
                                    "--vendor-dir", program);
  ldimesh::HttpServer server(store, options);
  if (ldimesh::Status s = server.start(); !s) throw std::runtime_error(s.message());
  if (!ldimesh::is_loopback_address(args.bind))
    std::fprintf(stderr, "%s: %s", program.c_str(),
                 ldimesh::remote_server_warning(args.bind).c_str());
  std::printf("%s: serving %zu step(s) from %s at %s\n", program.c_str(), store.list().size(),
              args.dir.c_str(), server.url().c_str());
  std::fflush(stdout);

  std::string last_error;  // a scan error is printed when it first appears, not every 0.5 s
  const timespec poll{0, 500'000'000};
  while (sigtimedwait(&stop_signals, nullptr, &poll) < 0) {
    const auto before = store.latest();
    ldimesh::Status s = watcher.scan(store);
    print_warnings(watcher, program);
    if (!s && s.message() != last_error)
      std::fprintf(stderr, "%s: warning: %s\n", program.c_str(), s.message().c_str());
    last_error = s ? "" : s.message();
    for (const auto& snapshot : store.list()) {
      if (!before || snapshot->step > before->step) {
        std::printf("%s: step %llu\n", program.c_str(),
                    static_cast<unsigned long long>(snapshot->step));
        std::fflush(stdout);
      }
    }
  }
  server.stop();
  return 0;
}

void add_serve_options(CLI::App& app, ServeArgs& args) {
  app.add_option("--dir", args.dir, "the folder of step files")->required();
  app.add_option("--port", args.port, "the port (0: any free one)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  app.add_option("--bind", args.bind, "the address to listen on")->capture_default_str();
  app.add_flag("--allow-remote", args.allow_remote,
               "allow a --bind address other than loopback (plain HTTP: the token travels "
               "unencrypted)");
  app.add_option("--token", args.token,
                 "the access token (letters, digits, -._~); default: a random one");
  app.add_option("--keep", args.keep, "how many of the newest steps to serve")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 20))
      ->capture_default_str();
  app.add_option("--static-dir", args.static_dir,
                 "the viewer's files (default: viewer/web of this checkout)");
  app.add_option("--vendor-dir", args.vendor_dir,
                 "three.js (default: node_modules/three of this checkout)");
}

}  // namespace ldimesh

// ldimesh-fetch: downloads the steps a running job (or ldimesh-serve) publishes into a folder,
// as step_000042.glb + step_000042.json (the layout ldimesh-serve --dir reads).
//   ldimesh-fetch --url 'http://127.0.0.1:8080/?token=T' --latest -o out/
//   ldimesh-fetch --url http://127.0.0.1:8080 --token T --step 42 -o out/ --ply
//   ldimesh-fetch --url 'http://127.0.0.1:8080/?token=T' --follow [--max-steps K] -o out/
#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/http_client.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace {

namespace fs = std::filesystem;

struct Args {
  std::string url;
  std::string token;
  std::optional<std::uint64_t> step;
  bool latest = false;
  bool follow = false;
  std::uint64_t max_steps = 0;
  int wait = 30;
  std::string out;
  bool ply = false;
};

// SIGINT and SIGTERM, blocked in every thread and taken by a thread of their own: it marks the
// run as interrupted and cancels the request in flight (a long poll may otherwise wait for
// its whole `wait`). Constructed before any other thread exists.
class Interrupts {
 public:
  explicit Interrupts(ldimesh::HttpClient& client) {
    sigemptyset(&signals_);
    sigaddset(&signals_, SIGINT);
    sigaddset(&signals_, SIGTERM);
    // A shell starts background jobs with SIGINT ignored; this tool's contract is to stop
    // cleanly on it, so the inherited disposition is reset.
    ::signal(SIGINT, SIG_DFL);
    ::signal(SIGTERM, SIG_DFL);
    pthread_sigmask(SIG_BLOCK, &signals_, nullptr);
    thread_ = std::thread([this, &client] {
      const timespec slice{0, 50'000'000};
      while (!done_) {
        if (!interrupted_ && sigtimedwait(&signals_, nullptr, &slice) > 0) interrupted_ = true;
        // Cancel until the main thread is done: a request may start just after a cancel.
        if (interrupted_) {
          client.cancel();
          std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
      }
    });
  }
  ~Interrupts() {
    done_ = true;
    thread_.join();
  }
  bool interrupted() const { return interrupted_; }

 private:
  sigset_t signals_{};
  std::atomic<bool> done_{false};
  std::atomic<bool> interrupted_{false};
  std::thread thread_;
};

// Fails early, before any download, if nothing can be written into `dir` (creating it).
void check_writable_folder(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw std::runtime_error("cannot create folder '" + dir.string() + "': " + ec.message());
  const fs::path probe = dir / (".ldimesh-fetch-probe-" + std::to_string(::getpid()));
  std::FILE* f = std::fopen(probe.c_str(), "wb");
  if (!f)
    throw std::runtime_error("cannot write into '" + dir.string() + "': " + std::strerror(errno));
  std::fclose(f);
  fs::remove(probe, ec);
}

// Downloads the GLB of `step`, writes the step's files (and the PLY) and prints its line.
ldimesh::Status fetch_step(ldimesh::HttpClient& client, const ldimesh::RemoteStep& step,
                           const Args& args) {
  const ldimesh::StepMetadata& m = step.metadata;
  std::vector<std::uint8_t> glb;
  if (ldimesh::Status s = client.mesh(m.step, glb, m.bytes ? std::optional(m.bytes) : std::nullopt);
      !s) {
    return s;
  }
  ldimesh::Mesh mesh;
  if (args.ply) {
    if (ldimesh::Status s = ldimesh::decode_glb_isolated(glb, mesh); !s)
      return s.prefixed("step " + std::to_string(m.step) + ": ");
    // Surfaces coloured by different fields, or some by none (metadata "surface_scalars";
    // decode_glb gives NaN where a surface has no _SCALAR): the PLY's one "value" column would
    // mix them, so it has none.
    if (!m.surface_scalars.empty() || std::any_of(mesh.scalars.begin(), mesh.scalars.end(),
                                                  [](float x) { return std::isnan(x); }))
      mesh.scalars.clear();
  }
  ldimesh::Snapshot snapshot;
  snapshot.step = m.step;
  snapshot.metadata_json = step.json;
  snapshot.glb = std::make_shared<const std::vector<std::uint8_t>>(std::move(glb));
  if (ldimesh::Status s = ldimesh::write_step_files(args.out, snapshot); !s) return s;
  const fs::path glb_path = fs::path(args.out) / (ldimesh::step_file_stem(m.step) + ".glb");
  if (args.ply) {
    const fs::path ply = fs::path(args.out) / (ldimesh::step_file_stem(m.step) + ".ply");
    if (ldimesh::Status s = ldimesh::write_ply(ply.string(), mesh); !s) return s;
  }
  double seconds = 0.0;
  for (const auto& [stage, t] : m.seconds)
    seconds += t;
  std::printf("step %llu  time %g  triangles %llu  bytes %zu  seconds %.3f  %s\n",
              static_cast<unsigned long long>(m.step), m.time,
              static_cast<unsigned long long>(m.triangles), snapshot.glb->size(), seconds,
              glb_path.string().c_str());
  std::fflush(stdout);
  return ldimesh::Status::ok();
}

int run(const Args& args) {
  check_writable_folder(args.out);
  ldimesh::HttpClient client(args.url, args.token);  // throws for a malformed URL
  Interrupts interrupts(client);
  const auto fail = [&](const ldimesh::Status& s) -> int {
    if (interrupts.interrupted()) {
      if (args.follow) return 0;
      throw std::runtime_error("interrupted");
    }
    throw std::runtime_error(s.message());
  };

  std::optional<std::uint64_t> last;  // the newest step fetched
  std::uint64_t fetched = 0;
  ldimesh::RemoteStep first;
  ldimesh::Status s = args.step ? client.step(*args.step, first) : client.latest(first);
  const bool no_step_yet = !s && !args.step && s.message() == "the server has no step yet";
  if (!s && !(args.follow && no_step_yet)) return fail(s);  // following waits for the first
  if (s) {
    if (ldimesh::Status f = fetch_step(client, first, args); !f) return fail(f);
    last = first.metadata.step;
    ++fetched;
  }

  while (args.follow && (args.max_steps == 0 || fetched < args.max_steps)) {
    std::optional<ldimesh::RemoteStep> next;
    s = client.wait_for_newer(last, std::chrono::seconds(args.wait), next);
    if (interrupts.interrupted()) return 0;
    if (!s) return fail(s);
    if (!next) continue;  // nothing new within the wait: ask again
    s = fetch_step(client, *next, args);
    if (interrupts.interrupted()) return 0;
    if (!s && s.message().find("is not on the server") != std::string::npos) {
      // A job publishing faster than this download evicted the step: go on with the next.
      std::fprintf(stderr, "ldimesh-fetch: warning: %s\n", s.message().c_str());
    } else if (!s) {
      return fail(s);
    } else {
      ++fetched;
    }
    last = next->metadata.step;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // A server that closes the connection mid-request must give an error, not kill the process.
  ::signal(SIGPIPE, SIG_IGN);
  CLI::App app{
      "Downloads the isosurface meshes a running ldimesh job (or ldimesh-serve) "
      "publishes: step_N.glb (Draco glTF) and step_N.json (metadata) per step."};
  Args args;
  app.add_option("--url", args.url,
                 "the URL the server printed, http://HOST:PORT/?token=TOKEN (the token may "
                 "come with --token instead)")
      ->required();
  app.add_option("--token", args.token, "the access token (replaces the URL's)");
  auto* step = app.add_option("--step", args.step, "fetch this step");
  auto* latest = app.add_flag("--latest", args.latest, "fetch the newest step (the default)");
  step->excludes(latest);
  auto* follow = app.add_flag("--follow", args.follow,
                              "then keep fetching each new step (long poll) until interrupted");
  app.add_option("--max-steps", args.max_steps, "with --follow: stop after this many steps")
      ->needs(follow);
  app.add_option("--wait", args.wait, "with --follow: seconds per long poll (1..60)")
      ->check(CLI::Range(1, 60))
      ->capture_default_str();
  app.add_option("-o,--out", args.out, "the folder to write into (created if missing)")->required();
  app.add_flag("--ply", args.ply, "also write the decoded mesh as step_N.ply");
  try {
    app.parse(argc, argv);
    return run(args);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "ldimesh-fetch: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ldimesh-fetch: error: %s\n", e.what());
    return 1;
  }
}

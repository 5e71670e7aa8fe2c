#include "miniapp.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

namespace ldimesh::miniapp {

MiniApp::MiniApp(std::string name, int& argc, char**& argv) : name_(std::move(name)) {
  int provided = MPI_THREAD_SINGLE;
  // MULTIPLE: the adaptor's background path (the solver waits for a snapshot only); with less
  // the adaptor says so and runs its steps synchronously.
  MPI_Init_thread(&argc, &argv, MPI_THREAD_MULTIPLE, &provided);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
  if (provided < MPI_THREAD_FUNNELED && rank_ == 0)
    std::fprintf(stderr, "%s: warning: MPI provides less than MPI_THREAD_FUNNELED\n",
                 name_.c_str());
}

MiniApp::~MiniApp() {
  MPI_Finalize();
}

void MiniApp::add_common_options(CLI::App& app, CommonArgs& args) const {
  app.add_option("--steps", args.steps, "time steps (each one an execute() call)")
      ->check(CLI::Range(std::uint64_t(1), std::uint64_t(1000000000)))
      ->capture_default_str();
  app.add_option("--options", args.options_path,
                 "the adaptor's options, a JSON file (docs/adaptor.md); default: the file named "
                 "by LDIMESH_OPTIONS, or all defaults");
  app.add_option("--isovalue", args.isovalue,
                 "isovalue (overrides \"isovalues\" of the options; default: the mini-app's)");
  app.add_flag("--report", args.report,
               "print one 'report' line per step: compute time vs. the solver's blocked time");
}

std::optional<int> MiniApp::parse(CLI::App& app, int argc, char** argv) const {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (rank_ == 0) app.exit(e);  // prints the help or the error
    return e.get_exit_code() == 0 ? 0 : kExitUsage;
  }
  return std::nullopt;
}

void MiniApp::print(std::string_view line) const {
  if (rank_ != 0) return;
  std::printf("%.*s\n", int(line.size()), line.data());
  std::fflush(stdout);
}

bool MiniApp::check(const Status& status, std::string_view what) const {
  if (status.is_ok()) return true;
  if (rank_ == 0) {
    std::fprintf(stderr, "%s: %.*s: %s\n", name_.c_str(), int(what.size()), what.data(),
                 status.message().c_str());
    std::fflush(stderr);
  }
  return false;
}

bool MiniApp::create_adaptor(const CommonArgs& args, double default_isovalue,
                             std::unique_ptr<Adaptor>& out) const {
  std::string options;
  if (!check(options_document(args.options_path, args.isovalue, default_isovalue, options),
             "options"))
    return false;
  if (!check(Adaptor::create(comm(), options, out), "in situ adaptor not created")) return false;
  const std::string url = out->url();
  print(url.empty() ? "viewer: none (server disabled)" : "viewer: " + url);
  return true;
}

void MiniApp::run(Adaptor& adaptor, const CommonArgs& args,
                  const std::function<double(std::uint64_t step)>& advance) const {
  using clock = std::chrono::steady_clock;
  for (std::uint64_t step = 1; step <= args.steps; ++step) {
    const auto start = clock::now();
    const double time = advance(step);
    double compute = std::chrono::duration<double>(clock::now() - start).count();
    // An in situ failure is reported and the simulation goes on, as in a real solver.
    check(adaptor.execute(step, time), "step " + std::to_string(step) + ": in situ");
    if (args.report) {
      double slowest = 0.0;
      MPI_Reduce(&compute, &slowest, 1, MPI_DOUBLE, MPI_MAX, 0, comm());
      const StepReport& r = adaptor.last_report();
      // What all ranks' snapshots hold (background path).
      const double mine = double(r.snapshot_bytes) / (1 << 20);
      double snapshots = 0.0;
      MPI_Reduce(&mine, &snapshots, 1, MPI_DOUBLE, MPI_SUM, 0, comm());
      char line[256];
      std::snprintf(line, sizeof line,
                    "report step=%llu time=%g compute_s=%.4f blocked_s=%.4f executed=%d "
                    "skipped_busy=%d replaced=%d snapshot_mb=%.2f",
                    static_cast<unsigned long long>(step), time, slowest, r.max_blocked_seconds,
                    int(r.executed), int(r.skipped_busy), int(r.replaced_pending), snapshots);
      print(line);
    }
  }
  check(adaptor.finalize(), "in situ finalize");
  if (rank_ == 0) {
    print(name_ + ": done, " + std::to_string(args.steps) + " steps, " +
          std::to_string(adaptor.published_steps()) + " published");
  }
}

Status options_document(const std::string& path, std::optional<double> isovalue,
                        double default_isovalue, std::string& out) {
  std::string file = path;
  if (file.empty()) {
    if (const char* env = std::getenv("LDIMESH_OPTIONS")) file = env;
  }
  nlohmann::json doc = nlohmann::json::object();
  if (!file.empty()) {
    std::ifstream in(file, std::ios::binary);
    if (!in) return Status::io("cannot read options file '" + file + "'");
    std::stringstream text;
    text << in.rdbuf();
    doc = nlohmann::json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
    if (doc.is_discarded())
      return Status::invalid_options("options file '" + file + "' is not valid JSON");
    if (!doc.is_object())
      return Status::invalid_options("options file '" + file + "' is not a JSON object");
  }
  if (isovalue) {
    doc["isovalues"] = nlohmann::json::array({*isovalue});
  } else if (!doc.contains("isovalues")) {
    doc["isovalues"] = nlohmann::json::array({default_isovalue});
  }
  out = doc.dump();
  return Status::ok();
}

}  // namespace ldimesh::miniapp

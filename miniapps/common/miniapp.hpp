// What the mini-apps share: MPI start-up with MPI_THREAD_MULTIPLE, the options every mini-app
// takes, the adaptor's options document, and the step loop that calls Adaptor::execute and
// checks every Status. A solver would write the same few lines; they live here once so that each
// mini-app's main.cpp shows only its solver and the data it hands over.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include <mpi.h>
#include <CLI/CLI.hpp>

#include "ldimesh/adaptor.hpp"

namespace ldimesh::miniapp {

// The options every mini-app takes.
struct CommonArgs {
  std::uint64_t steps = 100;
  std::string options_path;        // "" → the file named by LDIMESH_OPTIONS, or all defaults
  std::optional<double> isovalue;  // overrides "isovalues" of the options document
  bool report = false;             // one "report …" line per step on rank 0
};

// Exit codes: 0 also when in situ steps fail (the simulation ran); these only for start-up.
inline constexpr int kExitUsage = 1;    // bad command line
inline constexpr int kExitOptions = 2;  // the adaptor refused its options: nothing was simulated

class MiniApp {
 public:
  // MPI_Init_thread with MPI_THREAD_MULTIPLE (the adaptor's background path: its caster
  // threads call MPI while the solver does); MPI_Finalize on destruction.
  MiniApp(std::string name, int& argc, char**& argv);
  ~MiniApp();
  MiniApp(const MiniApp&) = delete;
  MiniApp& operator=(const MiniApp&) = delete;

  const std::string& name() const { return name_; }
  int rank() const { return rank_; }
  int size() const { return size_; }
  MPI_Comm comm() const { return MPI_COMM_WORLD; }

  // Adds --steps, --options, --isovalue and --report to `app`.
  void add_common_options(CLI::App& app, CommonArgs& args) const;
  // Parses the command line; on --help or an error returns the exit code (messages on rank 0
  // only), otherwise nullopt.
  std::optional<int> parse(CLI::App& app, int argc, char** argv) const;

  // Prints `line` on rank 0 (stdout, flushed).
  void print(std::string_view line) const;
  // On failure prints "name: what: message" on rank 0 (stderr); returns status.is_ok().
  bool check(const Status& status, std::string_view what) const;

  // Creates the adaptor from the options document (options_document) and prints the viewer URL
  // on rank 0. On failure prints the error and returns false: the caller exits kExitOptions on
  // every rank (create fails on every rank alike).
  bool create_adaptor(const CommonArgs& args, double default_isovalue,
                      std::unique_ptr<Adaptor>& out) const;

  // The solver loop: for step = 1 … args.steps, advance(step) computes the step and returns its
  // simulation time, then adaptor.execute(step, time); a failed execute is printed and the
  // loop goes on. With args.report rank 0 prints after each step
  //   report step=S time=T compute_s=C blocked_s=B executed=0|1 skipped_busy=0|1 replaced=0|1
  // (C: the slowest rank's advance(), B: StepReport::max_blocked_seconds). Finalizes the
  // adaptor at the end.
  void run(Adaptor& adaptor, const CommonArgs& args,
           const std::function<double(std::uint64_t step)>& advance) const;

 private:
  std::string name_;
  int rank_ = 0;
  int size_ = 1;
};

// The adaptor's options document: the JSON file `path` (when empty, the file named by the
// environment variable LDIMESH_OPTIONS; when that is unset too, "{}"), with "isovalues" set to
// [isovalue] when one is given, or to [default_isovalue] when the document sets none. Other
// keys pass through unchanged: the adaptor checks them. Fails for an unreadable file or one
// that is not a JSON object.
Status options_document(const std::string& path, std::optional<double> isovalue,
                        double default_isovalue, std::string& out);

}  // namespace ldimesh::miniapp

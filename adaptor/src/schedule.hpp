// The root's schedule of in situ steps: which steps are due (every_steps, every_seconds), and
// whether "merging": "auto" still merges. Whether a due step runs or is skipped also depends on
// the threads being busy, which the adaptor asks them. Internal to the adaptor library.
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>

#include "options.hpp"

namespace ldimesh {

class Schedule {
 public:
  explicit Schedule(const AdaptorOptions& options) : options_(options) {}

  // Root, solver's thread: whether step `step` is due. A due step counts for the time between
  // due steps (merge_stopped).
  bool due(std::uint64_t step);
  // Root, solver's thread: a due step runs now (every_seconds counts from here).
  void run();
  // Root, solver's thread: a due step skipped, busy; and how many were since the last call.
  void skipped() { ++skipped_; }
  std::uint64_t take_skipped();

  // Root, solver's thread, for a due step that runs: whether "merging": "auto" has stopped
  // merging. Each merged step counts once, as slow when it is still being merged at a due step
  // (with "busy": "coalesce" the solver would wait for it) or when its merge took more than
  // kAutoMergeShare of the solver's time between due steps: the merge runs on the root's cores
  // beside the solver, which it slows (docs/performance.md, "In situ cost on Gray–Scott"). After
  // two slow merged steps in a row (one can be a cold start) merging stops for good, and the log
  // says so once.
  bool merge_stopped(std::uint64_t step);
  static constexpr double kAutoMergeShare = 0.25;

  // Root, the caster thread: the merge of step `step` begins; it ended, having taken `seconds`
  // (none: it failed).
  void merge_started(std::uint64_t step);
  void merge_finished(std::optional<double> seconds);

 private:
  using Clock = std::chrono::steady_clock;
  const AdaptorOptions& options_;
  // Solver's thread.
  std::optional<Clock::time_point> last_run_, last_due_;
  double interval_ = 0.0;  // between the last two due steps (0: the first)
  std::uint64_t skipped_ = 0;
  bool merge_stopped_ = false;
  int slow_merges_ = 0;                      // in a row
  std::uint64_t counted_step_ = UINT64_MAX;  // the merged step counted last
  // Shared with the caster thread (mutex_): the merge running and its step, the last merged
  // step and what its merge took.
  mutable std::mutex mutex_;
  bool merging_now_ = false;
  std::uint64_t merging_step_ = 0;
  std::optional<std::uint64_t> merged_step_;
  double last_merge_seconds_ = 0.0;
};

}  // namespace ldimesh

#include "schedule.hpp"

#include <cstdio>
#include <string>

#include "ldimesh/core/base/timing.hpp"

namespace ldimesh {

bool Schedule::due(std::uint64_t step) {
  if (step % options_.every_steps != 0) return false;
  if (options_.every_seconds > 0.0 && last_run_ &&
      seconds_since(*last_run_) < options_.every_seconds)
    return false;
  interval_ = last_due_ ? seconds_since(*last_due_) : 0.0;
  last_due_ = Clock::now();
  return true;
}

void Schedule::run() {
  last_run_ = Clock::now();
}

std::uint64_t Schedule::take_skipped() {
  const std::uint64_t skipped = skipped_;
  skipped_ = 0;
  return skipped;
}

bool Schedule::merge_stopped(std::uint64_t step) {
  // Merges are timed only on the background path (the caster thread).
  if (options_.merging != AdaptorOptions::Merging::automatic) return false;
  if (merge_stopped_) return true;
  std::string why;
  {
    std::lock_guard lock(mutex_);
    if (merging_now_ && merging_step_ != counted_step_) {
      counted_step_ = merging_step_;
      ++slow_merges_;
      why = "step " + std::to_string(merging_step_) + " was still being merged";
    } else if (!merging_now_ && merged_step_ && *merged_step_ != counted_step_ && interval_ > 0.0) {
      counted_step_ = *merged_step_;
      const bool slow = last_merge_seconds_ > kAutoMergeShare * interval_;
      slow_merges_ = slow ? slow_merges_ + 1 : 0;
      char text[160];
      std::snprintf(text, sizeof text,
                    "merging step %llu took %.2f s, over a quarter of the %.2f s between due steps",
                    (unsigned long long)*merged_step_, last_merge_seconds_, interval_);
      why = text;
    }
  }
  if (slow_merges_ >= 2) {
    merge_stopped_ = true;
    if (options_.log)
      std::printf(
          "ldimesh: from step %llu on the views are published trimmed, not merged "
          "(\"merging\": \"auto\"): the root does not keep up (%s); \"merging\": true merges "
          "every step (steps are then skipped while the root merges)\n",
          (unsigned long long)step, why.c_str());
  }
  return merge_stopped_;
}

void Schedule::merge_started(std::uint64_t step) {
  std::lock_guard lock(mutex_);
  merging_now_ = true;
  merging_step_ = step;
}

void Schedule::merge_finished(std::optional<double> seconds) {
  std::lock_guard lock(mutex_);
  merging_now_ = false;
  if (seconds) {
    last_merge_seconds_ = *seconds;
    merged_step_ = merging_step_;
  }
}

}  // namespace ldimesh

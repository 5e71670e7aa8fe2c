// The skeleton the caster thread and the root's worker share: one background thread, a slot for
// one job, and the failures both report to. Internal to the adaptor library.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include "ldimesh/core/base/status.hpp"

namespace ldimesh {

// Puts the calling thread in Linux's SCHED_BATCH class while it waits for work (`waiting`), back
// in the normal class while it works. A JobThread waits so: waking a batch thread does not take
// the core from the thread that wakes it (the solver's, handing a step over at the end of
// execute(); docs/performance.md). Working in the normal class, it does not leave the batch
// class to threads it starts (TBB's workers, which the solver's own TBB work may share). Nothing
// where the system refuses it.
void wait_as_batch_thread(bool waiting);

// This rank's failures, from any of its threads: the last one's message (last_error) and the
// last failure of its background work (what finalize returns).
class Failures {
 public:
  explicit Failures(bool log) : log_(log) {}
  // A failure of an API call: kept as the last error, and returned.
  Status api(Status failure);
  // A failure of the background work (caster or worker thread), prefixed by `prefix`: kept,
  // and logged where `log_it`.
  void background(const Status& failed, const std::string& prefix, bool log_it);
  std::string last_error() const;
  Status background_status() const;

 private:
  bool log_;
  mutable std::mutex mutex_;
  std::string last_error_;
  Status background_ = Status::ok();
};

// A thread that does one job at a time, handed to it through a slot of one: a job handed while
// another waits in the slot replaces it. The job is done by `work` (given to start), which
// reports its own failures and returns whether it succeeded; the thread counts the successes
// under its lock at the moment it becomes idle, so that whoever sees a job counted also sees
// the thread free for the next one.
template <class Job>
class JobThread {
 public:
  JobThread() = default;
  ~JobThread() { stop(); }
  JobThread(const JobThread&) = delete;
  JobThread& operator=(const JobThread&) = delete;

  // Starts the thread (once).
  void start(std::function<bool(Job&)> work) {
    work_ = std::move(work);
    thread_ = std::thread([this] { run(); });
  }
  // Puts `job` in the slot (any thread); where a job still waits there, `replacing(waiting,
  // job)` is called first, under the lock, and hand returns true.
  template <class Replacing>
  bool hand(Job job, Replacing&& replacing) {
    std::lock_guard lock(mutex_);
    const bool replaced = slot_.has_value();
    if (replaced) replacing(*slot_, job);
    slot_ = std::move(job);
    wake_.notify_all();
    return replaced;
  }
  bool hand(Job job) {
    return hand(std::move(job), [](const Job&, Job&) {});
  }
  // Whether a job waits or is being done.
  bool busy() const {
    std::lock_guard lock(mutex_);
    return working_ || slot_.has_value();
  }
  // Jobs done without failure so far.
  std::uint64_t succeeded() const {
    std::lock_guard lock(mutex_);
    return succeeded_;
  }
  // Waits until no job waits or is being done.
  void wait_idle() {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [&] { return !working_ && !slot_.has_value(); });
  }
  // Does what waits, then stops the thread. Idempotent.
  void stop() {
    if (!thread_.joinable()) return;
    {
      std::unique_lock lock(mutex_);
      idle_.wait(lock, [&] { return !working_ && !slot_.has_value(); });
      stopping_ = true;
      wake_.notify_all();
    }
    thread_.join();
  }

 private:
  void run() {
    while (true) {
      std::optional<Job> job;
      wait_as_batch_thread(true);
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [&] { return stopping_ || slot_.has_value(); });
        if (!slot_) return;
        job = std::move(slot_);
        slot_.reset();
        working_ = true;
      }
      wait_as_batch_thread(false);
      const bool ok = work_(*job);
      std::lock_guard lock(mutex_);
      if (ok) ++succeeded_;
      working_ = false;
      idle_.notify_all();
    }
  }

  std::function<bool(Job&)> work_;
  std::thread thread_;
  mutable std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::optional<Job> slot_;
  bool working_ = false;
  bool stopping_ = false;
  std::uint64_t succeeded_ = 0;
};

}  // namespace ldimesh

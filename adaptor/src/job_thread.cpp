#include "job_thread.hpp"

#include <cstdio>

#include <pthread.h>
#include <sched.h>

namespace ldimesh {

void wait_as_batch_thread([[maybe_unused]] bool waiting) {
#ifdef SCHED_BATCH
  sched_param param{};
  param.sched_priority = 0;
  pthread_setschedparam(pthread_self(), waiting ? SCHED_BATCH : SCHED_OTHER, &param);
#endif
}

Status Failures::api(Status failure) {
  std::lock_guard lock(mutex_);
  last_error_ = failure.message();
  return failure;
}

void Failures::background(const Status& failed, const std::string& prefix, bool log_it) {
  std::lock_guard lock(mutex_);
  background_ = failed.prefixed(prefix);
  last_error_ = background_.message();
  if (log_ && log_it) std::fprintf(stderr, "ldimesh: error: %s\n", last_error_.c_str());
}

std::string Failures::last_error() const {
  std::lock_guard lock(mutex_);
  return last_error_;
}

Status Failures::background_status() const {
  std::lock_guard lock(mutex_);
  return background_;
}

}  // namespace ldimesh

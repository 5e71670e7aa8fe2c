// Every rank's caster thread (background path, MPI_THREAD_MULTIPLE): the collective half of each
// snapshotted step on a duplicate of the adaptor's communicator (so that its collectives never
// meet the solver's), the root's meshing where it needs every rank's samples, then (root) the
// hand-off to the root's worker. Internal to the adaptor library.
#pragma once

#include <optional>
#include <utility>

#include <mpi.h>

#include "job_thread.hpp"
#include "root_worker.hpp"
#include "schedule.hpp"
#include "snapshot.hpp"
#include "step.hpp"

namespace ldimesh {

// A snapshotted step for the caster thread.
struct CasterJob {
  Job job;
  std::optional<Box> domain;
  Status status = Status::ok();  // the snapshot failed: the step fails on every rank
  double blocked_seconds = 0.0;  // what the solver waited for (the largest is reported)
};

class CasterThread {
 public:
  // Collective over `comm` (duplicated). It casts from `snapshot`; the root's `worker` (null on
  // the other ranks) publishes, `schedule` (root) times its merges.
  CasterThread(MPI_Comm comm, const AdaptorOptions& options, const BlockSnapshot& snapshot,
               RootWorker* worker, Schedule& schedule, Failures& failures);
  ~CasterThread() { stop(); }
  CasterThread(const CasterThread&) = delete;
  CasterThread& operator=(const CasterThread&) = delete;

  // Waits until the thread has no step (the snapshot can then be taken again).
  void wait_idle() { thread_.wait_idle(); }
  // Gives the thread a step (it must be idle); busy until the step is reduced, meshed where
  // meshing needs the ranks, and handed to the worker.
  void hand(CasterJob job) { thread_.hand(std::move(job)); }
  bool busy() const { return thread_.busy(); }
  // Finishes the step it has, then stops the thread. Idempotent; collective (MPI_Comm_free).
  void stop();

 private:
  bool work(CasterJob& cj);
  Status cast(CasterJob& cj);

  MPI_Comm comm_ = MPI_COMM_NULL;
  int rank_ = 0;
  const AdaptorOptions& options_;
  const BlockSnapshot& snapshot_;
  RootWorker* worker_;
  Schedule& schedule_;
  Failures& failures_;
  JobThread<CasterJob> thread_;  // busy from the hand-off until the step is handed on
};

}  // namespace ldimesh

#include "caster_thread.hpp"

#include <chrono>
#include <string>
#include <utility>

#include "ldimesh/core/base/timing.hpp"

namespace ldimesh {

CasterThread::CasterThread(MPI_Comm comm, const AdaptorOptions& options,
                           const BlockSnapshot& snapshot, RootWorker* worker, Schedule& schedule,
                           Failures& failures)
    : options_(options),
      snapshot_(snapshot),
      worker_(worker),
      schedule_(schedule),
      failures_(failures) {
  MPI_Comm_dup(comm, &comm_);
  MPI_Comm_rank(comm_, &rank_);
  thread_.start([this](CasterJob& cj) { return work(cj); });
}

void CasterThread::stop() {
  if (comm_ == MPI_COMM_NULL) return;
  thread_.stop();
  MPI_Comm_free(&comm_);
}

bool CasterThread::work(CasterJob& cj) {
  const std::uint64_t step = cj.job.step;
  const Status s = guard("", [&] { return cast(cj); });
  if (!s) failures_.background(s, "step " + std::to_string(step) + " skipped: ", rank_ == 0);
  return bool(s);
}

Status CasterThread::cast(CasterJob& cj) {
  StepCasters casters;
  Status s =
      collective_step(comm_, options_, snapshot_.blocks(), cj.domain, cj.status, cj.job, casters);
  double max_blocked = 0.0;
  MPI_Reduce(&cj.blocked_seconds, &max_blocked, 1, MPI_DOUBLE, MPI_MAX, 0, comm_);
  // The snapshot stays until the next step: the ranks serve the root's samples from it.
  if (s && meshing_samples(meshing_options(options_, cj.job.merge))) {
    const bool merging = rank_ == 0 && cj.job.merge;
    if (merging) schedule_.merge_started(cj.job.step);
    const auto merge_start = std::chrono::steady_clock::now();
    s = guard("", [&] { return mesh_with_samples(comm_, options_, casters, cj.job); });
    // What the merge (decoding and meshing, the samples' round trips included) took.
    if (merging)
      schedule_.merge_finished(s ? std::optional<double>(seconds_since(merge_start))
                                 : std::nullopt);
  }
  LDIMESH_RETURN_IF_ERROR(s);
  if (rank_ == 0) {
    cj.job.seconds["blocked"] = max_blocked;
    worker_->hand(std::move(cj.job));
  }
  return Status::ok();
}

}  // namespace ldimesh

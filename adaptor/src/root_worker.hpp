// The root's worker: the second half of each step off the solver's path — meshing (where no
// rank's samples are needed), packaging and publishing — and what it publishes to (the snapshot
// store, the HTTP server, output_dir). Internal to the adaptor library.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "job_thread.hpp"
#include "ldimesh/transport/http_server.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "options.hpp"
#include "step.hpp"

namespace ldimesh {

class RootWorker {
 public:
  RootWorker(const AdaptorOptions& options, Failures& failures);
  ~RootWorker() { stop(); }
  RootWorker(const RootWorker&) = delete;
  RootWorker& operator=(const RootWorker&) = delete;

  // Starts the store, the server (where the options ask for it), output_dir and the thread.
  Status start();
  // Gives `job` to the worker (any thread); true when it replaced a step still waiting, which
  // is then counted as skipped (a job waits while the worker publishes the one before).
  bool hand(Job job);
  // Whether a job waits or is being published.
  bool busy() const { return thread_.busy(); }
  // Steps published so far. A step counts where the worker becomes idle: whoever sees it
  // published also sees the worker free for the next one (a due step is skipped while it is
  // busy; counted earlier, a step due at once could still find it working).
  std::uint64_t published() const { return thread_.succeeded(); }
  // Publishes what waits, then stops the thread and the server. Idempotent.
  void stop();
  std::string url() const { return server_ ? server_->url() : std::string(); }

 private:
  bool work(Job& job);
  Status publish(Job& job);
  void write_step(const Snapshot& snapshot);

  const AdaptorOptions& options_;
  Failures& failures_;
  std::unique_ptr<SnapshotStore> store_;
  std::unique_ptr<HttpServer> server_;
  JobThread<Job> thread_;
  std::uint64_t unwritten_steps_ = 0;  // in a row, not written to output_dir (worker only)
};

}  // namespace ldimesh

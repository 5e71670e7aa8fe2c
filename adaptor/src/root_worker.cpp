#include "root_worker.hpp"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <system_error>
#include <utility>
#include <vector>

#include "ldimesh/transport/step_package.hpp"

namespace ldimesh {
namespace {

// The log line's warnings: steps dropped before this one, non-finite field values, vertices
// without a finite colour.
std::string step_notes(const Job& job, std::size_t uncoloured) {
  std::string notes;
  if (job.skipped_steps > 0)
    notes += "  (" + std::to_string(job.skipped_steps) + " earlier steps skipped: root busy)";
  if (job.nonfinite_values > 0)
    notes += "  warning: " + std::to_string(job.nonfinite_values) +
             " NaN/Inf field values, the cells touching them left out";
  if (uncoloured > 0)
    notes += "  warning: " + std::to_string(uncoloured) +
             " vertices without a finite colour value (NaN/Inf in the colour field), shown at "
             "the lowest colour";
  return notes;
}

}  // namespace

RootWorker::RootWorker(const AdaptorOptions& options, Failures& failures)
    : options_(options), failures_(failures) {}

Status RootWorker::start() {
  store_ =
      std::make_unique<SnapshotStore>(SnapshotStoreLimits{options_.keep, options_.memory_mb << 20});
  if (options_.server) {
    HttpServerOptions o;
    o.bind_address = options_.bind;
    o.allow_remote = options_.allow_remote;
    o.port = options_.port;
    o.token = options_.token;
    // The viewer's files: the checkout the library was built in, or where it is installed.
    const ViewerFiles files = find_viewer_files();
    o.static_dir = files.static_dir;
    o.vendor_three_dir = files.vendor_three_dir;
    server_ = std::make_unique<HttpServer>(*store_, o);
    LDIMESH_RETURN_IF_ERROR(server_->start());
    if (!is_loopback_address(o.bind_address) && options_.log)
      std::fprintf(stderr, "ldimesh: %s", remote_server_warning(o.bind_address).c_str());
  }
  if (!options_.output_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(options_.output_dir, ec);
    if (ec) return Status::io("options: 'output_dir' cannot be created: " + ec.message());
  }
  thread_.start([this](Job& job) { return work(job); });
  return Status::ok();
}

bool RootWorker::hand(Job job) {
  return thread_.hand(std::move(job), [&](const Job& waiting, Job& job) {
    job.skipped_steps += waiting.skipped_steps + 1;
    if (options_.log)
      std::printf("ldimesh: step %llu replaces step %llu, which was still waiting\n",
                  (unsigned long long)job.step, (unsigned long long)waiting.step);
  });
}

void RootWorker::stop() {
  thread_.stop();
  if (server_) server_->stop();
}

// Decode, mesh, encode, publish — off the solver's path.
bool RootWorker::work(Job& job) {
  const Status s = guard("", [&] { return publish(job); });
  if (!s) failures_.background(s, "step " + std::to_string(job.step) + ": ", true);
  return bool(s);
}

// Writes the step's files into output_dir. A failure (disk full, the folder gone or no longer
// writable) does not fail the step: it is published and served from memory like any other,
// and stderr says so once when writing starts failing and once when it works again.
void RootWorker::write_step(const Snapshot& snapshot) {
  const Status s = write_step_files(options_.output_dir, snapshot);
  if (!s) {
    if (unwritten_steps_++ == 0)
      std::fprintf(stderr,
                   "ldimesh: warning: step %llu not written: %s; steps are served from memory "
                   "until writing works again\n",
                   (unsigned long long)snapshot.step, s.message().c_str());
  } else if (unwritten_steps_ > 0) {
    std::fprintf(stderr,
                 "ldimesh: writing steps to '%s' again from step %llu (%llu steps were not "
                 "written)\n",
                 options_.output_dir.c_str(), (unsigned long long)snapshot.step,
                 (unsigned long long)unwritten_steps_);
    unwritten_steps_ = 0;
  }
}

Status RootWorker::publish(Job& job) {
  if (options_.slow_root_seconds > 0.0)
    std::this_thread::sleep_for(std::chrono::duration<double>(options_.slow_root_seconds));
  const MeshingOptions meshing = meshing_options(options_, job.merge);
  // The root half (mesh_step) unless it ran where the samples are: no MPI call here.
  std::vector<MeshingResult> results;
  if (job.meshed)
    results = std::move(*job.meshed);
  else
    LDIMESH_RETURN_IF_ERROR(
        mesh_on_root(options_.isovalues.size(), job.views, meshing, job.cast, results));
  StepDescription description;
  description.step = job.step;
  description.time = job.time;
  description.isovalues = options_.isovalues;
  description.views = job.views;
  description.r = trim_r(meshing);
  description.colour_fields = options_.colour_fields;
  description.surface_field = options_.surface_field;
  description.glb = options_.glb;
  std::vector<StepSurface> surfaces;
  for (MeshingResult& r : results)
    surfaces.push_back({std::move(r.mesh), r.samples, r.quads});
  PackagedStep packaged;
  LDIMESH_RETURN_IF_ERROR(package_step(description, std::move(surfaces), packaged));
  StepMetadata meta = std::move(packaged.metadata);
  meta.seconds.insert(job.seconds.begin(), job.seconds.end());
  meta.seconds["decode"] = job.cast.seconds.decode;
  meta.seconds["mesh"] = job.cast.seconds.mesh;
  meta.skipped_steps = job.skipped_steps;
  meta.nonfinite_values = job.nonfinite_values;
  const std::size_t bytes = packaged.glb.size();
  Snapshot snapshot = make_snapshot(std::move(meta), std::move(packaged.glb));
  if (!options_.output_dir.empty()) write_step(snapshot);
  LDIMESH_RETURN_IF_ERROR(store_->publish(std::move(snapshot)));
  if (options_.log) {
    std::printf(
        "ldimesh: step %llu  t=%g  %zu triangles  %zu bytes  cast %.3f reduce %.3f mesh %.3f glb "
        "%.3f s%s\n",
        (unsigned long long)job.step, job.time, std::size_t(packaged.info.triangles), bytes,
        job.seconds["cast"], job.seconds["reduce"], job.cast.seconds.mesh, packaged.glb_seconds,
        step_notes(job, packaged.uncoloured).c_str());
    std::fflush(stdout);
  }
  return Status::ok();
}

}  // namespace ldimesh

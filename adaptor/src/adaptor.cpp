// The adaptor's API (adaptor.hpp) and one in situ step from execute() on. The parts it drives:
//   block.hpp          the solver's blocks and their colour fields
//   schedule.hpp       which steps are due, whether "auto" still merges (root)
//   snapshot.hpp       the copy of what a step reads (background path)
//   step.hpp           the collective half, on the solver's or the caster thread
//   caster_thread.hpp  every rank's thread for snapshotted steps (background path)
//   root_worker.hpp    the root's thread that meshes, packages and publishes
#include "ldimesh/adaptor.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <type_traits>
#include <vector>

#include "block.hpp"
#include "caster_thread.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "options.hpp"
#include "root_worker.hpp"
#include "schedule.hpp"
#include "snapshot.hpp"
#include "step.hpp"

namespace ldimesh {
namespace {

using Clock = std::chrono::steady_clock;

class AdaptorImpl final : public Adaptor {
 public:
  AdaptorImpl(MPI_Comm comm, AdaptorOptions options)
      : comm_(comm), options_(std::move(options)), failures_(options_.log), schedule_(options_) {
    MPI_Comm_rank(comm_, &rank_);
    // Each colour field's isovalues, as GridSource::needed_bricks_by_isovalue marks them.
    field_bits_.assign(options_.colour_fields.size(), 0);
    for (std::size_t i = 0; i < options_.surface_field.size(); ++i)
      if (options_.surface_field[i] >= 0)
        field_bits_[std::size_t(options_.surface_field[i])] |=
            std::uint8_t(1u << std::min<std::size_t>(i, 7));
  }
  ~AdaptorImpl() override { finalize(); }

  // Root: store, server and worker.
  Status start_root() {
    if (rank_ != 0) return Status::ok();
    int level = MPI_THREAD_SINGLE;
    MPI_Query_thread(&level);
    if (level < MPI_THREAD_FUNNELED && options_.log)
      std::fprintf(stderr,
                   "ldimesh: warning: MPI runs with MPI_THREAD_SINGLE; the root's worker thread "
                   "never calls MPI, but the standard asks for MPI_THREAD_FUNNELED "
                   "(MPI_Init_thread)\n");
    worker_ = std::make_unique<RootWorker>(options_, failures_);
    return worker_->start();
  }

  // Collective, every rank: the background path where MPI allows it (every rank agrees). After
  // start_root (the root's caster thread hands its steps to the worker).
  void start_background() {
    int level = MPI_THREAD_SINGLE;
    MPI_Query_thread(&level);
    int ok = options_.background && level >= MPI_THREAD_MULTIPLE ? 1 : 0;
    MPI_Allreduce(MPI_IN_PLACE, &ok, 1, MPI_INT, MPI_MIN, comm_);
    if (!ok) {
      const bool automatic = options_.merging == AdaptorOptions::Merging::automatic;
      if (!options_.background && rank_ == 0 && options_.log && automatic)
        std::fprintf(stderr,
                     "ldimesh: \"background\": false: in situ steps run synchronously; the views "
                     "are published trimmed, not merged (\"merging\": \"auto\"; true merges "
                     "anyway, the solver then waits for the merge too)\n");
      if (options_.background && rank_ == 0 && options_.log)
        std::fprintf(stderr,
                     "ldimesh: MPI runs without MPI_THREAD_MULTIPLE (MPI_Init_thread gave level "
                     "%d): in situ steps run synchronously, the solver waits for the ray cast and "
                     "the reduction%s\n",
                     level,
                     automatic ? "; the views are published trimmed, not merged (\"merging\": "
                                 "\"auto\"; true merges anyway, the solver then waits for the "
                                 "merge too)"
                               : "");
      return;
    }
    caster_ = std::make_unique<CasterThread>(comm_, options_, snapshot_, worker_.get(), schedule_,
                                             failures_);
  }

  Status set_domain(const Box& global) override {
    if (!global.is_valid()) return fail(Status::invalid_argument("set_domain: the box is empty"));
    domain_ = global;
    return Status::ok();
  }
  Status add_grid_block(const GridBlock& block) override {
    return add_block<GridSource>(block, "add_grid_block");
  }
  Status add_hex_block(const HexBlock& block) override {
    return add_block<HexElementSource>(block, "add_hex_block");
  }
  Status add_cell_block(const CellBlock& block) override {
    return add_block<CellElementSource>(block, "add_cell_block");
  }
  Status add_source(std::shared_ptr<const FieldSource> source, const Box& owned) override {
    last_add_failed_ = !source;
    if (!source) return fail(Status::invalid_argument("add_source: no source"));
    blocks_.push_back({std::move(source), owned, std::nullopt, std::nullopt, std::nullopt, {}});
    return Status::ok();
  }
  Status add_field(std::string_view name, const void* values, ScalarType type) override {
    return fail_if(guard("add_field: ", [&] {
      if (last_add_failed_)
        return Status::invalid_argument(
            "the block added last was refused (the field would belong to the one before)");
      if (blocks_.empty() || !blocks_.back().copyable())
        return Status::invalid_argument(
            blocks_.empty() ? "no block added yet (the field belongs to the block added last)"
                            : "the block added last is a FieldSource (it colours by its own "
                              "bind_scalar)");
      if (name.empty()) return Status::invalid_argument("the field's name is empty");
      if (!values)
        return Status::invalid_argument("field '" + std::string(name) + "': null values");
      if (type != ScalarType::float32 && type != ScalarType::float64)
        return Status::invalid_argument("field '" + std::string(name) + "': unknown scalar type");
      // Only the fields "colour_by" names are read; the others are accepted and left alone.
      const auto& fields = options_.colour_fields;
      const std::size_t f =
          std::size_t(std::find(fields.begin(), fields.end(), name) - fields.begin());
      if (f == fields.size()) return Status::ok();
      Block& b = blocks_.back();
      // The colour field: a source that reads it beside the block's values (an element block's
      // geometry as prepared).
      b.colours[f] = {{values, type}, coloured_source(b, {values, type})};
      return Status::ok();
    }));
  }
  void clear_blocks() override {
    blocks_.clear();
    last_add_failed_ = false;
  }

  // One step: the root decides whether it runs, then each rank either snapshots its blocks for
  // its caster thread (background path) or casts and reduces them on the solver's thread
  // (synchronous path); either way the root's worker publishes it.
  Status execute(std::uint64_t step, double time) override {
    const auto start = Clock::now();
    report_ = {};
    report_.step = step;
    const Decision decision = decide(step);
    if (decision.run != Run::yes) {
      report_.skipped_busy = decision.run == Run::busy;
      if (decision.run == Run::busy && rank_ == 0) {
        schedule_.skipped();
        if (options_.log)
          std::printf("ldimesh: step %llu skipped: still processing an earlier step\n",
                      (unsigned long long)step);
      }
      finish_report(start, /*executed=*/false);
      return Status::ok();
    }
    if (rank_ == 0) schedule_.run();
    Job job;
    job.step = step;
    job.time = time;
    if (rank_ == 0) job.skipped_steps = schedule_.take_skipped();
    // "auto" merges the background steps within its budget (Schedule::merge_stopped); "true"
    // every step.
    job.merge = options_.merging == AdaptorOptions::Merging::on ||
                (options_.merging == AdaptorOptions::Merging::automatic && caster_ &&
                 decision.snapshot && !decision.merge_stopped);
    std::string why = "a rank's blocks cannot be copied (a FieldSource)";
    SyncReason reason = SyncReason::field_source;
    if (caster_ && decision.snapshot) {
      long long largest = 0;
      if (hand_to_background(job, start, largest)) {
        log_path(step, SyncReason::none, "");
        return Status::ok();
      }
      char text[160];
      std::snprintf(text, sizeof text,
                    "a rank's copy of what it reads (%.1f MiB) would exceed memory_mb (%zu)",
                    double(largest) / (1 << 20), options_.memory_mb);
      why = text;
      reason = SyncReason::memory;
      job.merge = options_.merging == AdaptorOptions::Merging::on;
    }
    if (caster_) log_path(step, reason, why);
    return run_synchronously(std::move(job), start);
  }

  Status finalize() override {
    if (finalized_) return Status::ok();
    finalized_ = true;
    if (caster_) caster_->stop();
    if (worker_) worker_->stop();
    return failures_.background_status();
  }

  std::string url() const override { return worker_ ? worker_->url() : std::string(); }
  const StepReport& last_report() const override { return report_; }
  std::string last_error() const override { return failures_.last_error(); }
  std::uint64_t published_steps() const override { return worker_ ? worker_->published() : 0; }

 private:
  // What every rank does with a step: whether it runs, is not due or is skipped while the root
  // is busy (the root's call); whether every rank can snapshot its blocks; whether "auto"
  // merging has stopped (the root's).
  enum class Run { not_due = 0, yes = 1, busy = 2 };  // ordered: the reduction takes the largest
  struct Decision {
    Run run = Run::not_due;
    bool snapshot = false;
    bool merge_stopped = false;
  };
  // Collective: one reduction for the root's decision and whether every rank can snapshot (all
  // must, or the step runs synchronously everywhere).
  Decision decide(std::uint64_t step) {
    int flags[3] = {0, caster_ && !snapshot_copyable() ? 1 : 0, 0};
    if (rank_ == 0 && schedule_.due(step)) {
      // A step still being cast or reduced in the background holds the snapshot buffers, one
      // waiting for the worker or being published holds the worker: the new one is skipped, or
      // with "coalesce" it runs (and waits for the snapshot, hand_to_background), so that the
      // newest due step is always published. The caster first: it hands its step to the worker
      // before it is idle.
      const bool busy = (caster_ && caster_->busy()) || worker_->busy();
      const Run run = busy && !options_.coalesce ? Run::busy : Run::yes;
      flags[0] = int(run);
      if (run == Run::yes) flags[2] = schedule_.merge_stopped(step) ? 1 : 0;
    }
    MPI_Allreduce(MPI_IN_PLACE, flags, 3, MPI_INT, MPI_MAX, comm_);
    return {Run(flags[0]), flags[1] == 0, flags[2] != 0};
  }

  // The synchronous path: the solver waits for the cast and the reduction (and for the
  // meshing, where it needs every rank's samples).
  // With "coalesce" the caster thread may still hold an earlier step: it is handed to the worker
  // first, so that the worker never gets an older step after this one.
  Status run_synchronously(Job job, Clock::time_point start) {
    if (caster_) caster_->wait_idle();
    StepCasters casters;
    Status s = collective_step(comm_, options_, blocks_, domain_, Status::ok(), job, casters);
    if (s && meshing_samples(meshing_options(options_, job.merge)))
      s = mesh_with_samples(comm_, options_, casters, job);
    if (rank_ == 0) report_.nonfinite_values = job.cast.nonfinite_values;
    finish_report(start);
    if (!s) return fail(s.prefixed("step " + std::to_string(job.step) + " skipped: "));
    if (rank_ == 0) {
      job.seconds["blocked"] = report_.max_blocked_seconds;
      report_.replaced_pending = worker_->hand(std::move(job));
    }
    return Status::ok();
  }

  // Why a step on the background path ran synchronously (none: it did not).
  enum class SyncReason { none, field_source, memory };
  // Root's log, where the path of executed steps changes (not at every step): a step that runs
  // synchronously for `reason` (`why`), or in the background again.
  void log_path(std::uint64_t step, SyncReason reason, const std::string& why) {
    if (rank_ != 0 || reason == logged_reason_) return;
    logged_reason_ = reason;
    if (!options_.log) return;
    if (reason == SyncReason::none) {
      std::printf("ldimesh: from step %llu on, steps run in the background again\n",
                  (unsigned long long)step);
      return;
    }
    std::printf(
        "ldimesh: from step %llu on, steps run synchronously: %s%s (the log says when this "
        "changes)\n",
        (unsigned long long)step, why.c_str(),
        options_.merging == AdaptorOptions::Merging::automatic
            ? "; their views are published trimmed, not merged (\"merging\": \"auto\")"
            : "");
  }

  // Whether the domain is set and every block can be copied (grid and element blocks: a
  // FieldSource cannot). Whether the copy fits memory_mb is known once the field is read
  // (hand_to_background).
  bool snapshot_copyable() const {
    if (!domain_) return false;  // the synchronous path fails the step on every rank
    return std::all_of(blocks_.begin(), blocks_.end(), [](const Block& b) { return b.copyable(); });
  }

  // The background path: copies what the step reads of the blocks (BlockSnapshot) and hands the
  // step to this rank's caster thread; the solver waits for the copy only. Every rank does, even
  // after a local failure (the caster thread then sends empty fragments and the step fails
  // everywhere, as on the synchronous path). Collective. Returns false, `job` untouched, where a
  // rank's copy would exceed memory_mb (known once each rank has chosen what to copy; `largest`
  // is the largest copy's bytes): the step then runs synchronously on every rank.
  bool hand_to_background(Job& job, Clock::time_point start, long long& largest) {
    // With "skip" the root decided the step runs because its own caster was idle, and the
    // others' finish the previous step's reduction with it: a short wait. With "coalesce" the
    // solver waits here for the rest of the previous step's cast and reduction.
    caster_->wait_idle();
    StatusOr<BlockSnapshot::Plan> plan =
        BlockSnapshot::plan(blocks_, options_.isovalues, field_bits_);
    const std::size_t planned = plan.ok() ? plan->bytes : 0;
    // Whether some rank's copy exceeds memory_mb, and the largest copy. (A rank that failed
    // goes on: its caster thread fails the step everywhere, as on the synchronous path.)
    long long over[2] = {planned > (options_.memory_mb << 20) ? 1 : 0,
                         static_cast<long long>(planned)};
    MPI_Allreduce(MPI_IN_PLACE, over, 2, MPI_LONG_LONG, MPI_MAX, comm_);
    largest = over[1];
    // Synchronous where some copy is too large (the previous snapshot is no longer needed: the
    // caster is idle), or with none where this rank failed.
    if (over[0] || !plan.ok()) snapshot_.clear();
    if (over[0]) return false;
    const Status copied =
        plan.ok() ? snapshot_.take(blocks_, std::move(plan).value()) : plan.status();
    report_.background = true;
    report_.snapshot_bytes = copied ? snapshot_.bytes() : 0;
    CasterJob cj;
    cj.job = std::move(job);
    cj.domain = domain_;
    cj.status = copied;
    cj.blocked_seconds = seconds_since(start);
    caster_->hand(std::move(cj));
    finish_report(start);
    return true;
  }

  // A grid block's hits belong to its owned region, an element block's to its cells (Block).
  // The block's own colour array is not read: its fields come by name (add_field).
  template <class Source, class Description>
  Status add_block(Description block, const char* what) {
    block.colour = nullptr;
    last_add_failed_ = true;
    return fail_if(guard(std::string(what) + ": ", [&] {
      auto source = std::make_shared<Source>(block);
      std::optional<Box> owned;
      if constexpr (std::is_same_v<Description, GridBlock>) owned = source->bounds();
      Block b{std::move(source), owned, std::nullopt, std::nullopt, std::nullopt, {}};
      b.colours.resize(options_.colour_fields.size());
      if constexpr (std::is_same_v<Description, GridBlock>)
        b.grid = block;
      else if constexpr (std::is_same_v<Description, CellBlock>)
        b.cells = block;
      else
        b.hex = block;
      blocks_.push_back(std::move(b));
      last_add_failed_ = false;
      return Status::ok();
    }));
  }

  // Keeps the failure as the last error and returns it.
  Status fail(Status failure) { return failures_.api(std::move(failure)); }
  Status fail_if(Status s) { return s ? s : fail(std::move(s)); }

  // The report's times; `executed`: the step was due and not skipped (it ran, or failed).
  void finish_report(Clock::time_point start, bool executed = true) {
    report_.blocked_seconds = seconds_since(start);
    MPI_Reduce(&report_.blocked_seconds, &report_.max_blocked_seconds, 1, MPI_DOUBLE, MPI_MAX, 0,
               comm_);
    report_.executed = executed;
  }

  MPI_Comm comm_;
  int rank_ = 0;
  AdaptorOptions options_;
  Failures failures_;
  std::vector<std::uint8_t> field_bits_;  // per colour field, its isovalues' bits (plan_grid)
  std::optional<Box> domain_;
  std::vector<Block> blocks_;
  bool last_add_failed_ = false;  // the last add_*_block call failed: add_field refuses
  StepReport report_;
  bool finalized_ = false;
  Schedule schedule_;                            // root, solver's thread (merges: caster's)
  SyncReason logged_reason_ = SyncReason::none;  // root, solver's thread: log_path
  BlockSnapshot snapshot_;                       // background path: read by the caster thread
  std::unique_ptr<RootWorker> worker_;           // root only
  std::unique_ptr<CasterThread> caster_;         // background path only
};

}  // namespace

Status Adaptor::create(MPI_Comm comm, std::string_view options_json,
                       std::unique_ptr<Adaptor>& out) {
  out.reset();
  int initialized = 0, finalized = 0;
  MPI_Initialized(&initialized);
  MPI_Finalized(&finalized);
  if (!initialized || finalized)
    return Status::invalid_argument("ldimesh: MPI is not initialised (call MPI_Init_thread first)");
  if (comm == MPI_COMM_NULL)
    return Status::invalid_argument("ldimesh: the communicator is MPI_COMM_NULL");
  try {
    AdaptorOptions options;
    Status status = Status::ok();
    if (!options_json.empty()) {
      status = parse_adaptor_options(options_json, options);
    }
    if (status && !options.fault.empty()) {
      int size = 1;
      MPI_Comm_size(comm, &size);
      if (options.fault_rank >= size)
        status = Status::invalid_options(
            "options: 'testing.fault.rank' must be below the communicator's size (" +
            std::to_string(size) + ")");
    }
    // Everyone gets the same verdict (the document is the same on every rank).
    int failed = status ? 0 : 1;
    MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, comm);
    if (failed)
      return status ? Status::invalid_options("options: invalid on another rank") : status;
    auto adaptor = std::make_unique<AdaptorImpl>(comm, std::move(options));
    Status started = adaptor->start_root();
    adaptor->start_background();
    int start_failed = started ? 0 : 1;
    MPI_Bcast(&start_failed, 1, MPI_INT, 0, comm);
    if (start_failed)
      return started ? Status::other_rank("the root could not start (see its message)") : started;
    out = std::move(adaptor);
    return Status::ok();
  } catch (...) {
    return status_from_current_exception("ldimesh: ");
  }
}

Status Adaptor::create_from_file(MPI_Comm comm, const std::string& path,
                                 std::unique_ptr<Adaptor>& out) {
  std::string file = path;
  if (file.empty())
    if (const char* env = std::getenv("LDIMESH_OPTIONS")) file = env;
  if (file.empty()) return create(comm, "", out);
  std::ifstream in(file);
  if (!in) return Status::io("options: cannot read '" + file + "'");
  std::stringstream text;
  text << in.rdbuf();
  return create(comm, text.str(), out);
}

}  // namespace ldimesh

// Published steps as immutable snapshots (metadata JSON + GLB bytes), the store the job's HTTP
// server reads from, and step files on disk (`ldimesh-serve --dir`, `ldimesh-fetch -o`).
//
// The publisher (the root rank's pipeline) only ever calls SnapshotStore::publish, which holds
// a mutex for a few pointer moves: it never waits for a reader, a download or the network.
// Readers get shared_ptrs to immutable snapshots, so a download in progress keeps its snapshot
// alive after the store has evicted it and no reader ever sees a half-written one.
//
// Errors (Status codes): bytes or JSON that do not hold what they should (a metadata object, a
// GLB header, a snapshot whose parts disagree) are corrupt_input; a step that breaks the
// store's order or has no GLB is invalid_argument; a file or folder that cannot be read,
// written or listed is io. Nothing here throws but std::bad_alloc.
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <string_view>
#include <vector>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/base/view.hpp"
#include "ldimesh/transport/glb.hpp"

namespace ldimesh {

// The scalar the mesh carries (the GLB's _SCALAR u = (scalar − min) / (max − min), docs/api.md).
struct ScalarRange {
  std::string name;
  double min = 0.0;
  double max = 0.0;
};

// The typed fields of a step's metadata JSON (docs/api.md, "Step metadata").
struct StepMetadata {
  std::uint64_t step = 0;
  double time = 0.0;  // the simulation's time of the step
  std::vector<double> isovalues;
  std::uint64_t triangles = 0;
  std::uint64_t vertices = 0;
  std::uint64_t samples = 0;
  std::uint64_t quads = 0;
  std::uint64_t bytes = 0;  // size of the GLB
  std::vector<std::array<double, 3>> views;
  std::uint32_t resolution = 0;
  double r = 0.0;
  // The field the mesh is coloured by: absent when it carries no scalar, or when its surfaces
  // are coloured by different fields (option "colour_by" per isovalue).
  std::optional<ScalarRange> scalar;
  // Where the surfaces' colour fields differ (some coloured by another field or not at all):
  // one entry per isovalue, its field and range (absent: that surface carries no scalar).
  std::vector<std::optional<ScalarRange>> surface_scalars;
  std::map<std::string, double> seconds;  // per stage: cast, encode, reduce, decode, mesh, glb…
  // In situ: due steps not published since the previous published step because the root was
  // still busy (skipped or replaced while waiting), and NaN/±Inf values met in the field.
  std::uint64_t skipped_steps = 0;
  std::uint64_t nonfinite_values = 0;
};

// The metadata as one line of JSON with the keys in the order of docs/api.md; `scalar` and
// `surface_scalars` only when present. Non-finite numbers are written as null (JSON has no NaN).
std::string metadata_to_json(const StepMetadata& metadata);

// Parses metadata JSON (one step's object, as served or written by metadata_to_json) into
// `out`. `step` is required; every other documented field is optional (zero or empty when
// absent) but must have the documented type when present (null reads as NaN for a number);
// unknown fields are ignored, so newer servers stay readable. Never throws: malformed input
// returns an error Status ("metadata: …") and leaves `out` unchanged.
Status metadata_from_json(std::string_view json, StepMetadata& out);

// Checks the 12-byte header of a glTF binary container: magic "glTF", version 2 and a total
// length field equal to bytes.size(). Does not look into the chunks. The error message says
// which of the three fails ("not a glTF binary: …").
Status check_glb_header(std::span<const std::uint8_t> bytes);

// One published step. Immutable once in a store (the store hands out shared_ptr<const>).
struct Snapshot {
  std::uint64_t step = 0;
  std::string metadata_json;  // one JSON object, served as is
  std::shared_ptr<const std::vector<std::uint8_t>> glb;

  // What the snapshot holds in memory (GLB + metadata), the figure the memory cap counts.
  std::size_t memory_bytes() const;
};

// The metadata of a step meshed from `views` at `isovalues` with trimming parameter `r`:
// counts from the meshing (`samples`, `quads`) and from the encoded GLB (`glb`), the views'
// directions and resolution (their longer side); `seconds` and `bytes` are left to the caller
// (make_snapshot sets `bytes`).
StepMetadata describe_step(std::uint64_t step, double time, std::vector<double> isovalues,
                           std::span<const View> views, double r, std::size_t samples,
                           std::size_t quads, const GlbInfo& glb);

// A snapshot of `metadata` (its `bytes` field set to glb.size()) and `glb`, moved in.
Snapshot make_snapshot(StepMetadata metadata, std::vector<std::uint8_t> glb);

struct SnapshotStoreLimits {
  // How many steps the store keeps (≥ 1).
  std::size_t max_snapshots = 16;
  // The memory cap over all kept snapshots (memory_bytes); the oldest go first, the newest
  // is kept even when it alone is larger.
  std::size_t max_bytes = std::size_t{512} << 20;
};

// The latest published steps, oldest first. Thread-safe: any number of readers and
// waiters, one or several publishers.
class SnapshotStore {
 public:
  // Throws std::invalid_argument when limits.max_snapshots is 0.
  explicit SnapshotStore(SnapshotStoreLimits limits = {});

  SnapshotStore(const SnapshotStore&) = delete;
  SnapshotStore& operator=(const SnapshotStore&) = delete;

  // Adds `snapshot` as the newest step, then evicts the oldest ones beyond the limits, and
  // wakes every waiter. Errors (the store is unchanged): a step number not greater than the
  // newest one's (invalid_argument); no GLB or one that fails check_glb_header, metadata that
  // does not parse or whose "step" (or "bytes", when present) disagrees with the snapshot
  // (corrupt_input). Holds the store's lock
  // only to move pointers; evicted snapshots are freed after it is released, or later by the
  // last reader still holding them.
  Status publish(Snapshot snapshot);

  // The newest snapshot; null before the first publish.
  std::shared_ptr<const Snapshot> latest() const;
  // The snapshot of `step`; null if the store does not hold it (never published or evicted).
  std::shared_ptr<const Snapshot> find(std::uint64_t step) const;
  // Every snapshot the store holds, oldest first.
  std::vector<std::shared_ptr<const Snapshot>> list() const;

  // Blocks until the newest snapshot's step is greater than `after_step` (any snapshot when
  // it is empty) and returns that newest snapshot; returns at once if there already is one.
  // Returns null when `timeout` passes, `stop` is requested or shutdown() is called before
  // there is one. For long polls and server-sent events; `timeout` is capped at one day.
  std::shared_ptr<const Snapshot> wait_for_newer(std::optional<std::uint64_t> after_step,
                                                 std::chrono::milliseconds timeout,
                                                 std::stop_token stop = {}) const;

  // Wakes every waiter with null and makes later waits return at once (for a job that ends).
  // Publishing and reading keep working.
  void shutdown();
  bool is_shut_down() const;

  SnapshotStoreLimits limits() const { return limits_; }
  // The sum of memory_bytes over the kept snapshots.
  std::size_t memory_bytes() const;

 private:
  const SnapshotStoreLimits limits_;
  mutable std::mutex mutex_;
  mutable std::condition_variable_any published_;
  std::deque<std::shared_ptr<const Snapshot>> snapshots_;  // oldest first
  std::size_t memory_bytes_ = 0;
  bool shut_down_ = false;
};

// "step_000042": the name of a step's files without extension (at least six digits).
std::string step_file_stem(std::uint64_t step);

// Writes DIR/step_NNNNNN.glb and then DIR/step_NNNNNN.json, each to a hidden temporary name
// first and renamed into place, so that a reader never sees a partial file and a step whose
// .json exists has its complete .glb. Creates `dir` if missing. Errors name the file.
Status write_step_files(const std::filesystem::path& dir, const Snapshot& snapshot);

// Reads the step files of `step` from `dir` into `out`, checked like SnapshotStore::publish
// checks a snapshot (GLB header, metadata step and bytes).
Status read_step_files(const std::filesystem::path& dir, std::uint64_t step, Snapshot& out);

// The whole file at `path` into `out` (an io error naming the file when it cannot be read).
Status read_file(const std::filesystem::path& path, std::vector<std::uint8_t>& out);

// Loads step files that appear in a directory into a store (`ldimesh-serve --dir`). Not
// thread-safe: one thread scans (the store it publishes into is).
class DirectoryWatcher {
 public:
  explicit DirectoryWatcher(std::filesystem::path dir);

  // Publishes into `store`, in step order, every complete step (both step_N.glb and
  // step_N.json, valid) newer than the store's newest, at most the newest
  // store.limits().max_snapshots of them. Ignores other names, temporary files and a .glb
  // without its .json (the writer renames the .json last: it is picked up on a later scan).
  // A step that fails to load is skipped with a warning (see take_warnings) and retried only
  // when its files change. Sets `*loaded` to the number of steps published. An error Status
  // only when the directory cannot be listed.
  Status scan(SnapshotStore& store, std::size_t* loaded = nullptr);

  // The warnings of the scans since the last call, then clears them.
  std::vector<std::string> take_warnings();

 private:
  struct FileSizes {
    std::uintmax_t glb = 0;
    std::uintmax_t json = 0;
    std::filesystem::file_time_type json_time{};
    bool operator==(const FileSizes&) const = default;
  };
  std::filesystem::path dir_;
  std::map<std::uint64_t, FileSizes> failed_;  // steps that failed, with their files then
  std::vector<std::string> warnings_;
};

}  // namespace ldimesh

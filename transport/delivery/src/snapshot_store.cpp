#include "ldimesh/transport/snapshot_store.hpp"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <utility>

#include <nlohmann/json.hpp>

namespace ldimesh {

namespace fs = std::filesystem;

namespace {

using ordered_json = nlohmann::ordered_json;
using json = nlohmann::json;

std::uint32_t read_le32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
         std::uint32_t{p[3]} << 24;
}

// Field readers for metadata_from_json: each returns false with `error` naming the field.
bool read_u64(const json& j, const char* key, std::uint64_t& out, std::string& error) {
  const auto it = j.find(key);
  if (it == j.end()) return true;
  if (!it->is_number_unsigned()) {
    error = std::string("\"") + key + "\" is not a non-negative integer";
    return false;
  }
  out = it->get<std::uint64_t>();
  return true;
}

bool read_number(const json& value, double& out) {
  if (value.is_null()) {  // what metadata_to_json writes for NaN and infinities
    out = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  if (!value.is_number()) return false;
  out = value.get<double>();
  return true;
}

bool read_double(const json& j, const char* key, double& out, std::string& error) {
  const auto it = j.find(key);
  if (it == j.end()) return true;
  if (!read_number(*it, out)) {
    error = std::string("\"") + key + "\" is not a number";
    return false;
  }
  return true;
}

Status parse_metadata(const json& j, StepMetadata& m) {
  std::string error;
  if (!j.is_object()) return Status::corrupt_input("metadata: not a JSON object");
  if (!j.contains("step")) return Status::corrupt_input("metadata: no \"step\"");
  std::uint64_t resolution = 0;
  if (!read_u64(j, "step", m.step, error) || !read_double(j, "time", m.time, error) ||
      !read_u64(j, "triangles", m.triangles, error) ||
      !read_u64(j, "vertices", m.vertices, error) || !read_u64(j, "samples", m.samples, error) ||
      !read_u64(j, "quads", m.quads, error) || !read_u64(j, "bytes", m.bytes, error) ||
      !read_u64(j, "resolution", resolution, error) || !read_double(j, "r", m.r, error) ||
      !read_u64(j, "skipped_steps", m.skipped_steps, error) ||
      !read_u64(j, "nonfinite_values", m.nonfinite_values, error)) {
    return Status::corrupt_input("metadata: " + error);
  }
  if (resolution > std::numeric_limits<std::uint32_t>::max())
    return Status::corrupt_input("metadata: \"resolution\" is out of range");
  m.resolution = static_cast<std::uint32_t>(resolution);

  if (const auto it = j.find("isovalues"); it != j.end()) {
    if (!it->is_array()) return Status::corrupt_input("metadata: \"isovalues\" is not an array");
    for (const json& v : *it) {
      double x = 0.0;
      if (!read_number(v, x)) return Status::corrupt_input("metadata: an isovalue is not a number");
      m.isovalues.push_back(x);
    }
  }
  if (const auto it = j.find("views"); it != j.end()) {
    if (!it->is_array()) return Status::corrupt_input("metadata: \"views\" is not an array");
    for (const json& v : *it) {
      std::array<double, 3> d{};
      if (!v.is_array() || v.size() != 3 || !read_number(v[0], d[0]) || !read_number(v[1], d[1]) ||
          !read_number(v[2], d[2])) {
        return Status::corrupt_input("metadata: a view is not an array of three numbers");
      }
      m.views.push_back(d);
    }
  }
  // A field and its range ("scalar", or an entry of "surface_scalars", named `what`).
  const auto read_range = [&](const json& v, const std::string& what, ScalarRange& s) {
    if (!v.is_object()) return Status::corrupt_input("metadata: \"" + what + "\" is not an object");
    if (const auto name = v.find("name"); name != v.end()) {
      if (!name->is_string())
        return Status::corrupt_input("metadata: \"" + what + ".name\" is not a string");
      s.name = name->get<std::string>();
    }
    if (!read_double(v, "min", s.min, error) || !read_double(v, "max", s.max, error))
      return Status::corrupt_input("metadata: " + what + ": " + error);
    return Status::ok();
  };
  if (const auto it = j.find("scalar"); it != j.end() && !it->is_null()) {
    ScalarRange s;
    LDIMESH_RETURN_IF_ERROR(read_range(*it, "scalar", s));
    m.scalar = std::move(s);
  }
  if (const auto it = j.find("surface_scalars"); it != j.end()) {
    if (!it->is_array())
      return Status::corrupt_input("metadata: \"surface_scalars\" is not an array");
    for (const json& v : *it) {
      std::optional<ScalarRange> range;
      if (!v.is_null()) {
        LDIMESH_RETURN_IF_ERROR(read_range(v, "surface_scalars", range.emplace()));
      }
      m.surface_scalars.push_back(std::move(range));
    }
    if (j.contains("isovalues") && m.surface_scalars.size() != m.isovalues.size())
      return Status::corrupt_input("metadata: \"surface_scalars\" needs one entry per isovalue");
  }
  if (const auto it = j.find("seconds"); it != j.end()) {
    if (!it->is_object()) return Status::corrupt_input("metadata: \"seconds\" is not an object");
    for (const auto& [stage, value] : it->items()) {
      double x = 0.0;
      if (!read_number(value, x))
        return Status::corrupt_input("metadata: \"seconds." + stage + "\" is not a number");
      m.seconds[stage] = x;
    }
  }
  return Status::ok();
}

// The checks publish and read_step_files share: the GLB is a glTF binary and the metadata
// describes this step and these bytes.
Status check_snapshot(const Snapshot& s) {
  const std::string what = "step " + std::to_string(s.step) + ": ";
  if (!s.glb) return Status::corrupt_input(what + "no GLB");
  if (Status st = check_glb_header(*s.glb); !st) return st.prefixed(what);
  StepMetadata m;
  if (Status st = metadata_from_json(s.metadata_json, m); !st) return st.prefixed(what);
  if (m.step != s.step)
    return Status::corrupt_input(what + "the metadata is of step " + std::to_string(m.step));
  if (m.bytes != 0 && m.bytes != s.glb->size()) {
    return Status::corrupt_input(what + "the metadata says " + std::to_string(m.bytes) +
                                 " GLB bytes, the GLB has " + std::to_string(s.glb->size()));
  }
  return Status::ok();
}

// Writes `bytes` to `path` through a hidden temporary file in the same directory and a
// rename, which POSIX makes atomic: readers see the old file or the whole new one.
Status write_atomically(const fs::path& path, const void* bytes, std::size_t size) {
  static std::atomic<unsigned> counter{0};
  const fs::path tmp =
      path.parent_path() / ("." + path.filename().string() + ".tmp." + std::to_string(::getpid()) +
                            "." + std::to_string(counter++));
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return Status::io("cannot write '" + path.string() + "': " + std::strerror(errno));
  const bool written = std::fwrite(bytes, 1, size, f) == size;
  const int write_errno = errno;
  const bool closed = std::fclose(f) == 0;
  if (!written || !closed) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    return Status::io("cannot write '" + path.string() +
                      "': " + std::strerror(written ? errno : write_errno));
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    return Status::io("cannot write '" + path.string() + "': " + ec.message());
  }
  return Status::ok();
}

// The step of "step_<digits>.glb" / ".json", with which extension; nullopt for other names.
std::optional<std::uint64_t> parse_step_file_name(const std::string& name, bool& is_glb) {
  constexpr std::string_view prefix = "step_";
  std::string_view rest(name);
  if (!rest.starts_with(prefix)) return std::nullopt;
  rest.remove_prefix(prefix.size());
  if (rest.ends_with(".glb")) {
    is_glb = true;
    rest.remove_suffix(4);
  } else if (rest.ends_with(".json")) {
    is_glb = false;
    rest.remove_suffix(5);
  } else {
    return std::nullopt;
  }
  if (rest.empty() ||
      !std::all_of(rest.begin(), rest.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::nullopt;
  }
  std::uint64_t step = 0;
  const auto [end, ec] = std::from_chars(rest.data(), rest.data() + rest.size(), step);
  if (ec != std::errc() || end != rest.data() + rest.size()) return std::nullopt;
  return step;
}

}  // namespace

Status read_file(const fs::path& path, std::vector<std::uint8_t>& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::io("cannot read '" + path.string() + "'");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) return Status::io("cannot read '" + path.string() + "'");
  in.seekg(0);
  out.resize(static_cast<std::size_t>(size));
  if (!in.read(reinterpret_cast<char*>(out.data()), size))
    return Status::io("cannot read '" + path.string() + "' (changed while reading?)");
  return Status::ok();
}

std::string metadata_to_json(const StepMetadata& m) {
  ordered_json j;
  j["step"] = m.step;
  j["time"] = m.time;
  j["isovalues"] = m.isovalues;
  j["triangles"] = m.triangles;
  j["vertices"] = m.vertices;
  j["samples"] = m.samples;
  j["quads"] = m.quads;
  j["bytes"] = m.bytes;
  j["views"] = ordered_json::array();
  for (const auto& v : m.views)
    j["views"].push_back({v[0], v[1], v[2]});
  j["resolution"] = m.resolution;
  j["r"] = m.r;
  const auto range = [](const ScalarRange& s) {
    return ordered_json{{"name", s.name}, {"min", s.min}, {"max", s.max}};
  };
  if (m.scalar) j["scalar"] = range(*m.scalar);
  if (!m.surface_scalars.empty()) {
    j["surface_scalars"] = ordered_json::array();
    for (const auto& s : m.surface_scalars)
      j["surface_scalars"].push_back(s ? range(*s) : ordered_json());
  }
  // The pipeline's stages in the order they run (docs/api.md), then any others by name.
  j["seconds"] = ordered_json::object();
  static constexpr const char* stages[] = {"cast", "encode", "reduce", "decode", "mesh", "glb"};
  for (const char* stage : stages) {
    if (const auto it = m.seconds.find(stage); it != m.seconds.end())
      j["seconds"][stage] = it->second;
  }
  for (const auto& [stage, s] : m.seconds) {
    if (std::find(std::begin(stages), std::end(stages), stage) == std::end(stages))
      j["seconds"][stage] = s;
  }
  j["skipped_steps"] = m.skipped_steps;
  j["nonfinite_values"] = m.nonfinite_values;
  // Replace invalid UTF-8 in names rather than throw: metadata must never fail a step.
  return j.dump(-1, ' ', false, nlohmann::detail::error_handler_t::replace);
}

Status metadata_from_json(std::string_view text, StepMetadata& out) {
  try {
    const json j = json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded()) return Status::corrupt_input("metadata: not valid JSON");
    StepMetadata m;
    if (Status s = parse_metadata(j, m); !s) return s;
    out = std::move(m);
    return Status::ok();
  } catch (const std::exception& e) {  // allocation failure, a number nlohmann cannot hold
    return Status::corrupt_input(std::string("metadata: ") + e.what());
  }
}

Status check_glb_header(std::span<const std::uint8_t> bytes) {
  if (bytes.size() < 12) {
    return Status::corrupt_input("not a glTF binary: " + std::to_string(bytes.size()) +
                                 " bytes, shorter than the 12-byte header");
  }
  if (std::memcmp(bytes.data(), "glTF", 4) != 0)
    return Status::corrupt_input("not a glTF binary: no \"glTF\" magic");
  if (const std::uint32_t version = read_le32(bytes.data() + 4); version != 2)
    return Status::corrupt_input("not a glTF binary: version " + std::to_string(version) +
                                 ", not 2");
  if (const std::uint32_t length = read_le32(bytes.data() + 8); length != bytes.size()) {
    return Status::corrupt_input("not a glTF binary: the header says " + std::to_string(length) +
                                 " bytes, there are " + std::to_string(bytes.size()));
  }
  return Status::ok();
}

std::size_t Snapshot::memory_bytes() const {
  return sizeof(Snapshot) + metadata_json.capacity() + (glb ? glb->capacity() : 0);
}

StepMetadata describe_step(std::uint64_t step, double time, std::vector<double> isovalues,
                           std::span<const View> views, double r, std::size_t samples,
                           std::size_t quads, const GlbInfo& glb) {
  StepMetadata meta;
  meta.step = step;
  meta.time = time;
  meta.isovalues = std::move(isovalues);
  meta.triangles = glb.triangles;
  meta.vertices = glb.vertices;
  meta.samples = samples;
  meta.quads = quads;
  for (const View& v : views) {
    meta.views.push_back({v.dir.x, v.dir.y, v.dir.z});
    meta.resolution = std::max(meta.resolution, std::uint32_t(std::max(v.width, v.height)));
  }
  meta.r = r;
  return meta;
}

Snapshot make_snapshot(StepMetadata metadata, std::vector<std::uint8_t> glb) {
  metadata.bytes = glb.size();
  Snapshot s;
  s.step = metadata.step;
  s.metadata_json = metadata_to_json(metadata);
  s.glb = std::make_shared<const std::vector<std::uint8_t>>(std::move(glb));
  return s;
}

SnapshotStore::SnapshotStore(SnapshotStoreLimits limits) : limits_(limits) {
  if (limits.max_snapshots == 0)
    throw std::invalid_argument("SnapshotStore: max_snapshots must be at least 1");
}

Status SnapshotStore::publish(Snapshot snapshot) {
  // Validation and the allocation of the shared snapshot happen before the lock.
  if (Status s = check_snapshot(snapshot); !s) return s;
  auto entry = std::make_shared<const Snapshot>(std::move(snapshot));
  const std::size_t size = entry->memory_bytes();
  std::vector<std::shared_ptr<const Snapshot>> evicted;  // freed after the lock is released
  {
    std::lock_guard lock(mutex_);
    if (!snapshots_.empty() && entry->step <= snapshots_.back()->step) {
      return Status::invalid_argument("step " + std::to_string(entry->step) +
                                      " is not newer than the latest published step " +
                                      std::to_string(snapshots_.back()->step));
    }
    snapshots_.push_back(std::move(entry));
    memory_bytes_ += size;
    while (snapshots_.size() > limits_.max_snapshots ||
           (memory_bytes_ > limits_.max_bytes && snapshots_.size() > 1)) {
      memory_bytes_ -= snapshots_.front()->memory_bytes();
      evicted.push_back(std::move(snapshots_.front()));
      snapshots_.pop_front();
    }
  }
  published_.notify_all();
  return Status::ok();
}

std::shared_ptr<const Snapshot> SnapshotStore::latest() const {
  std::lock_guard lock(mutex_);
  return snapshots_.empty() ? nullptr : snapshots_.back();
}

std::shared_ptr<const Snapshot> SnapshotStore::find(std::uint64_t step) const {
  std::lock_guard lock(mutex_);
  // Steps increase along the deque: binary search.
  const auto it = std::lower_bound(
      snapshots_.begin(), snapshots_.end(), step,
      [](const std::shared_ptr<const Snapshot>& s, std::uint64_t v) { return s->step < v; });
  return it != snapshots_.end() && (*it)->step == step ? *it : nullptr;
}

std::vector<std::shared_ptr<const Snapshot>> SnapshotStore::list() const {
  std::lock_guard lock(mutex_);
  return {snapshots_.begin(), snapshots_.end()};
}

std::shared_ptr<const Snapshot> SnapshotStore::wait_for_newer(
    std::optional<std::uint64_t> after_step, std::chrono::milliseconds timeout,
    std::stop_token stop) const {
  const auto newer = [&] {
    return !snapshots_.empty() && (!after_step || snapshots_.back()->step > *after_step);
  };
  timeout = std::clamp(timeout, std::chrono::milliseconds(0),
                       std::chrono::milliseconds(std::chrono::hours(24)));
  std::unique_lock lock(mutex_);
  published_.wait_for(lock, stop, timeout, [&] { return shut_down_ || newer(); });
  return newer() ? snapshots_.back() : nullptr;
}

void SnapshotStore::shutdown() {
  {
    std::lock_guard lock(mutex_);
    shut_down_ = true;
  }
  published_.notify_all();
}

bool SnapshotStore::is_shut_down() const {
  std::lock_guard lock(mutex_);
  return shut_down_;
}

std::size_t SnapshotStore::memory_bytes() const {
  std::lock_guard lock(mutex_);
  return memory_bytes_;
}

std::string step_file_stem(std::uint64_t step) {
  char name[32];
  std::snprintf(name, sizeof name, "step_%06llu", static_cast<unsigned long long>(step));
  return name;
}

Status write_step_files(const fs::path& dir, const Snapshot& snapshot) {
  if (!snapshot.glb)
    return Status::invalid_argument("step " + std::to_string(snapshot.step) + ": no GLB");
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::io("cannot create folder '" + dir.string() + "': " + ec.message());
  const std::string stem = step_file_stem(snapshot.step);
  // The .json last: its presence tells DirectoryWatcher that the .glb is complete.
  if (Status s =
          write_atomically(dir / (stem + ".glb"), snapshot.glb->data(), snapshot.glb->size());
      !s) {
    return s;
  }
  return write_atomically(dir / (stem + ".json"), snapshot.metadata_json.data(),
                          snapshot.metadata_json.size());
}

Status read_step_files(const fs::path& dir, std::uint64_t step, Snapshot& out) {
  const std::string stem = step_file_stem(step);
  std::vector<std::uint8_t> glb;
  std::vector<std::uint8_t> json_bytes;
  if (Status s = read_file(dir / (stem + ".json"), json_bytes); !s) return s;
  if (Status s = read_file(dir / (stem + ".glb"), glb); !s) return s;
  Snapshot snapshot;
  snapshot.step = step;
  snapshot.metadata_json.assign(json_bytes.begin(), json_bytes.end());
  // Served as one line, whatever the file's formatting.
  while (!snapshot.metadata_json.empty() &&
         (snapshot.metadata_json.back() == '\n' || snapshot.metadata_json.back() == '\r')) {
    snapshot.metadata_json.pop_back();
  }
  snapshot.glb = std::make_shared<const std::vector<std::uint8_t>>(std::move(glb));
  if (Status s = check_snapshot(snapshot); !s) return s;
  out = std::move(snapshot);
  return Status::ok();
}

DirectoryWatcher::DirectoryWatcher(fs::path dir) : dir_(std::move(dir)) {}

Status DirectoryWatcher::scan(SnapshotStore& store, std::size_t* loaded) {
  if (loaded) *loaded = 0;
  struct Found {
    bool glb = false;
    bool json = false;
  };
  std::map<std::uint64_t, Found> found;
  std::error_code ec;
  fs::directory_iterator it(dir_, ec);
  if (ec) return Status::io("cannot list '" + dir_.string() + "': " + ec.message());
  for (; it != fs::directory_iterator(); it.increment(ec)) {
    bool is_glb = false;
    const auto step = parse_step_file_name(it->path().filename().string(), is_glb);
    if (!step) continue;  // other files, the writer's hidden temporaries
    (is_glb ? found[*step].glb : found[*step].json) = true;
  }
  if (ec) return Status::io("cannot list '" + dir_.string() + "': " + ec.message());

  const auto newest = store.latest();
  std::vector<Snapshot> picked;  // newest first
  for (auto f = found.rbegin(); f != found.rend(); ++f) {
    const std::uint64_t step = f->first;
    if (newest && step <= newest->step) break;
    if (picked.size() == store.limits().max_snapshots) break;
    if (!f->second.glb || !f->second.json) continue;  // its partner comes on a later scan
    const std::string stem = step_file_stem(step);
    FileSizes sizes;
    std::error_code size_ec;
    sizes.glb = fs::file_size(dir_ / (stem + ".glb"), size_ec);
    sizes.json = fs::file_size(dir_ / (stem + ".json"), size_ec);
    sizes.json_time = fs::last_write_time(dir_ / (stem + ".json"), size_ec);
    if (const auto failed = failed_.find(step); failed != failed_.end() && failed->second == sizes)
      continue;  // warned about already; unchanged since
    Snapshot snapshot;
    if (Status s = read_step_files(dir_, step, snapshot); !s) {
      failed_[step] = sizes;
      warnings_.push_back("skipping " + (dir_ / stem).string() + ".*: " + s.message());
      continue;
    }
    failed_.erase(step);
    picked.push_back(std::move(snapshot));
  }
  std::erase_if(failed_, [&](const auto& f) { return !found.contains(f.first); });

  for (auto s = picked.rbegin(); s != picked.rend(); ++s) {
    if (Status st = store.publish(std::move(*s)); !st) {
      warnings_.push_back(st.message());  // another publisher got there first
      continue;
    }
    if (loaded) ++*loaded;
  }
  return Status::ok();
}

std::vector<std::string> DirectoryWatcher::take_warnings() {
  return std::exchange(warnings_, {});
}

}  // namespace ldimesh

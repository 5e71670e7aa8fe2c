#include "ldimesh/transport/distributed.hpp"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstring>
#include <stdexcept>
#include <string>
#include <tuple>

#include "ldimesh/core/timing.hpp"

namespace ldimesh {
namespace {

// What every rank learns after the reduction, in one allreduce (the minima of ok, levels,
// -levels, projects and -projects): whether it succeeded everywhere, and whether all ranks
// refine and project alike (a rank that serves requests the root never sends, or the reverse,
// would wait forever).
struct Agreement {
  bool reduced = false;
  bool same_levels = false;
  bool same_projection = false;
};

Agreement agree(MPI_Comm comm, bool reduced, int levels, bool projects) {
  const long long mine[5] = {reduced ? 1 : 0, levels, -static_cast<long long>(levels),
                             projects ? 1 : 0, projects ? -1 : 0};
  long long all[5] = {0, 0, 0, 0, 0};
  MPI_Allreduce(mine, all, 5, MPI_LONG_LONG, MPI_MIN, comm);
  return {all[0] == 1, all[1] == -all[2], all[3] == -all[4]};
}

double max_over_ranks(MPI_Comm comm, double v) {
  double out = 0.0;
  MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_MAX, comm);
  return out;
}

// The root's `status` on every rank (collective).
Status root_status(MPI_Comm comm, const Status& status) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::string message = status ? std::string() : status.message().substr(0, 65536);
  if (!status && message.empty()) message = "meshing failed on the root";
  int length = rank == 0 && !status ? int(message.size()) : -1;
  MPI_Bcast(&length, 1, MPI_INT, 0, comm);
  if (length < 0) return Status::ok();
  message.resize(std::size_t(length));
  MPI_Bcast(message.data(), length, MPI_CHAR, 0, comm);
  return Status::error(std::move(message));
}

}  // namespace

double merge_tolerance(const FragmentEncoding& encoding, const View& view, double domain_diagonal) {
  return std::max(1e-9 * domain_diagonal,
                  2.0 * depth_error_bound(encoding, 0.0, view.depth_extent));
}

Status mesh_distributed(MPI_Comm comm, const RayCaster& caster, const Subdomain& sub,
                        std::span<const View> views, const DistributedOptions& options,
                        DistributedResult& result) {
  result = {};
  int rank = 0;
  MPI_Comm_rank(comm, &rank);

  auto start = std::chrono::steady_clock::now();
  std::vector<LdiFragment> fragments;
  double tolerance = 0.0;
  for (std::size_t v = 0; v < views.size(); ++v) {
    fragments.push_back(caster.cast_fragment(views[v], std::uint32_t(v), sub));
    tolerance =
        std::max(tolerance, merge_tolerance(options.encoding, views[v], sub.global.diagonal()));
  }
  const double cast_seconds = seconds_since(start);

  ReductionStats stats;
  const Status reduced = reduce_fragments(comm, 0, fragments, options.encoding, tolerance, stats);
  result.seconds.cast = max_over_ranks(comm, cast_seconds);
  result.seconds.encode = max_over_ranks(comm, stats.encode_seconds);
  std::uint64_t sent = stats.bytes_sent;
  MPI_Reduce(&sent, &result.bytes_moved, 1, MPI_UINT64_T, MPI_SUM, 0, comm);
  // Every rank learns whether the step failed anywhere, so all return the same status.
  const int levels = options.meshing.refinement.levels;
  // §5 merging moves new vertices onto the surface with samples, too.
  const bool projects = merging_projects(options.meshing.merging);
  const Agreement agreed = agree(comm, bool(reduced), levels, projects);
  if (!agreed.reduced) {
    return reduced ? Status::error("reduction failed on another rank") : reduced;
  }
  if (!agreed.same_levels) return Status::error("refinement levels differ between ranks");
  if (!agreed.same_projection) return Status::error("merging options differ between ranks");
  // levels != 0, as mesh_ldis tests it: negative levels fail in refinement, on every rank.
  const bool serve = levels != 0 || projects;
  if (rank != 0 && !serve) return Status::ok();

  const auto mesh_on_root = [&](SampleSource* samples) {
    result.bytes_to_root = stats.bytes_received;
    result.seconds.reduce = stats.wall_seconds;
    start = std::chrono::steady_clock::now();
    for (std::size_t v = 0; v < views.size(); ++v)
      result.ldis.push_back(ldi_from_fragment(fragments[v], views[v]));
    result.seconds.decode = stats.decode_seconds + seconds_since(start);
    start = std::chrono::steady_clock::now();
    result.meshing = mesh_ldis(result.ldis, options.meshing, samples);
    result.seconds.mesh = seconds_since(start);
  };
  if (!serve) {
    mesh_on_root(nullptr);
    return Status::ok();
  }

  // §4 and §5: the root refines and merges, the other ranks cast the extra samples in their
  // subdomains. The root ends the serving whatever happens, then tells every rank how it went.
  MpiSampleSource source(comm, caster, sub, std::vector<View>(views.begin(), views.end()),
                         tolerance);
  if (rank != 0) {
    source.serve();
    return root_status(comm, Status::ok());
  }
  Status status = Status::ok();
  try {
    mesh_on_root(&source);
  } catch (const std::exception& e) {
    status = Status::error(e.what());
  } catch (...) {
    status = Status::error("meshing failed on the root");
  }
  source.finish();
  if (!status) result.meshing = {};
  return root_status(comm, status);
}

MpiSampleSource::MpiSampleSource(MPI_Comm comm, const RayCaster& caster, Subdomain sub,
                                 std::vector<View> views, double tolerance)
    : comm_(comm), caster_(caster), sub_(sub), views_(std::move(views)), tolerance_(tolerance) {}

namespace {

// Request header broadcast by the root: command, ray count. The rays follow as three doubles
// each (view index, x, y): view indices below 2^32 are exact in a double.
constexpr std::uint64_t kDone = 0, kBatch = 1;
struct Request {
  std::uint64_t command, rays;
};
// A ray on the wire: view, image position x, y, depth_min, depth_max.
constexpr std::size_t kDoublesPerRay = 5;
constexpr std::size_t kMaxRays = INT_MAX / kDoublesPerRay;  // one MPI_Bcast for all rays

// An answer starts with its kind: hits, or the error that kept the rank from answering.
constexpr std::uint64_t kHits = 0, kError = 1;

std::vector<std::uint8_t> serialize(const RayHitList& hits) {
  const std::uint64_t rays = hits.offsets.size() - 1, samples = hits.depth.size();
  const std::uint64_t scalar = hits.scalar.empty() ? 0 : 1;
  std::vector<std::uint8_t> out(32 + 4 * (rays + 1) + samples * (4 + 12 + 4 * scalar));
  std::uint8_t* p = out.data();
  auto put = [&](const void* src, std::size_t n) {
    std::memcpy(p, src, n);
    p += n;
  };
  put(&kHits, 8);
  put(&rays, 8);
  put(&samples, 8);
  put(&scalar, 8);
  put(hits.offsets.data(), 4 * (rays + 1));
  put(hits.depth.data(), 4 * samples);
  put(hits.normal.data(), 12 * samples);
  if (scalar) put(hits.scalar.data(), 4 * samples);
  return out;
}

std::vector<std::uint8_t> serialize_error(const std::string& message) {
  std::vector<std::uint8_t> out(8 + message.size());
  std::memcpy(out.data(), &kError, 8);
  std::memcpy(out.data() + 8, message.data(), message.size());
  return out;
}

// The error message in an error answer; empty for any other answer.
std::string error_of(std::span<const std::uint8_t> in) {
  std::uint64_t kind = kHits;
  if (in.size() >= 8) std::memcpy(&kind, in.data(), 8);
  if (kind != kError) return {};
  std::string message(in.begin() + 8, in.end());
  return message.empty() ? "unknown error" : message;
}

// Ranks of one job run the same binary on the same kind of machine (homogeneous MPI), so raw
// floats travel as they are; sizes are still checked.
bool deserialize(std::span<const std::uint8_t> in, std::uint64_t rays, RayHitList& hits) {
  if (in.size() < 32) return false;
  std::uint64_t kind = 0, n = 0, samples = 0, scalar = 0;
  std::memcpy(&kind, in.data(), 8);
  std::memcpy(&n, in.data() + 8, 8);
  std::memcpy(&samples, in.data() + 16, 8);
  std::memcpy(&scalar, in.data() + 24, 8);
  if (kind != kHits || n != rays || scalar > 1 || samples > in.size()) return false;
  if (in.size() != 32 + 4 * (rays + 1) + samples * (16 + 4 * scalar)) return false;
  const std::uint8_t* p = in.data() + 32;
  hits.offsets.resize(rays + 1);
  std::memcpy(hits.offsets.data(), p, 4 * (rays + 1));
  p += 4 * (rays + 1);
  if (hits.offsets[0] != 0 || hits.offsets[rays] != samples) return false;
  for (std::uint64_t k = 0; k < rays; ++k)
    if (hits.offsets[k] > hits.offsets[k + 1]) return false;
  hits.depth.resize(samples);
  std::memcpy(hits.depth.data(), p, 4 * samples);
  p += 4 * samples;
  hits.normal.resize(samples);
  std::memcpy(hits.normal.data(), p, 12 * samples);
  p += 12 * samples;
  hits.scalar.resize(scalar ? samples : 0);
  if (scalar) std::memcpy(hits.scalar.data(), p, 4 * samples);
  return true;
}

// Gathers every rank's serialized answer (each at most INT_MAX bytes) to rank 0. Every rank
// learns all lengths first, so that all skip the transfer alike when the total does not fit
// an MPI count; the root then throws, after the collectives, so the ranks stay in step.
std::vector<std::vector<std::uint8_t>> gather(MPI_Comm comm,
                                              const std::vector<std::uint8_t>& mine) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const int length = int(mine.size());
  std::vector<int> lengths(size), displacements(size);
  MPI_Allgather(&length, 1, MPI_INT, lengths.data(), 1, MPI_INT, comm);
  long long total = 0;
  for (int r = 0; r < size; ++r) {
    displacements[r] = int(std::min<long long>(total, INT_MAX));
    total += lengths[r];
  }
  if (total > INT_MAX) {
    if (rank == 0) throw std::runtime_error("sample answers over 2 GiB are not supported");
    return {};
  }
  std::vector<std::uint8_t> all(rank == 0 ? std::size_t(total) : 0);
  MPI_Gatherv(mine.data(), length, MPI_BYTE, all.data(), lengths.data(), displacements.data(),
              MPI_BYTE, 0, comm);
  std::vector<std::vector<std::uint8_t>> parts;
  if (rank == 0)
    for (int r = 0; r < size; ++r)
      parts.emplace_back(all.begin() + displacements[r],
                         all.begin() + displacements[r] + lengths[r]);
  return parts;
}

}  // namespace

std::vector<std::uint8_t> MpiSampleSource::answer(std::span<const SamplePoint> points) const {
  try {
    std::vector<std::uint8_t> bytes = serialize(cast_sample_points(caster_, views_, points, &sub_));
    if (bytes.size() > std::size_t(INT_MAX)) return serialize_error("its answer is over 2 GiB");
    return bytes;
  } catch (const std::exception& e) {
    return serialize_error(e.what());
  }
}

RayHitList MpiSampleSource::sample(std::span<const SamplePoint> points) {
  // Checked before anything is sent: the other ranks never see a bad request.
  for (const SamplePoint& p : points)
    if (p.view >= views_.size()) throw std::out_of_range("sample request for an unknown view");
  if (points.size() > kMaxRays) throw std::invalid_argument("too many sample requests");
  int ranks = 1;
  MPI_Comm_size(comm_, &ranks);
  std::vector<RayHitList> answers;
  if (ranks == 1) {
    // Alone: the own answer as it is, without the trip through bytes (the same hits).
    try {
      answers.push_back(cast_sample_points(caster_, views_, points, &sub_));
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string("sampling failed on rank 0: ") + e.what());
    }
  } else {
    answers = ask_all(points);
  }
  return merge_answers(answers, points.size());
}

std::vector<RayHitList> MpiSampleSource::ask_all(std::span<const SamplePoint> points) {
  std::vector<double> rays(kDoublesPerRay * points.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    double* ray = &rays[kDoublesPerRay * k];
    ray[0] = double(points[k].view);
    ray[1] = points[k].position.x;
    ray[2] = points[k].position.y;
    ray[3] = points[k].depth_min;
    ray[4] = points[k].depth_max;
  }
  Request request{kBatch, points.size()};
  MPI_Bcast(&request, 2, MPI_UINT64_T, 0, comm_);
  MPI_Bcast(rays.data(), int(rays.size()), MPI_DOUBLE, 0, comm_);
  const std::vector<std::vector<std::uint8_t>> parts = gather(comm_, answer(points));

  std::vector<RayHitList> answers(parts.size());
  for (std::size_t r = 0; r < parts.size(); ++r) {
    if (const std::string error = error_of(parts[r]); !error.empty())
      throw std::runtime_error("sampling failed on rank " + std::to_string(r) + ": " + error);
    if (!deserialize(parts[r], points.size(), answers[r]))
      throw std::runtime_error("sample answer of rank " + std::to_string(r) + " is malformed");
  }
  return answers;
}

RayHitList MpiSampleSource::merge_answers(const std::vector<RayHitList>& answers,
                                          std::size_t rays) const {
  const bool with_scalar = std::any_of(answers.begin(), answers.end(),
                                       [](const RayHitList& a) { return !a.scalar.empty(); });
  struct Hit {
    float depth;
    glm::vec3 normal;
    float scalar;
  };
  RayHitList merged;
  merged.offsets.reserve(rays + 1);
  merged.offsets.push_back(0);
  std::vector<Hit> hits;
  for (std::size_t k = 0; k < rays; ++k) {
    hits.clear();
    for (const RayHitList& a : answers)
      for (std::uint32_t s = a.offsets[k]; s < a.offsets[k + 1]; ++s)
        hits.push_back({a.depth[s], a.normal[s], a.scalar.empty() ? 0.0f : a.scalar[s]});
    std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
      return std::tie(a.depth, a.normal.x, a.normal.y, a.normal.z) <
             std::tie(b.depth, b.normal.x, b.normal.y, b.normal.z);
    });
    std::uint32_t kept = 0;
    for (const Hit& h : hits) {
      if (kept > 0 && double(h.depth) - double(merged.depth.back()) <= tolerance_) continue;
      merged.depth.push_back(h.depth);
      merged.normal.push_back(h.normal);
      if (with_scalar) merged.scalar.push_back(h.scalar);
      ++kept;
    }
    merged.offsets.push_back(merged.offsets.back() + kept);
  }
  return merged;
}

void MpiSampleSource::finish() {
  Request request{kDone, 0};
  MPI_Bcast(&request, 2, MPI_UINT64_T, 0, comm_);
}

void MpiSampleSource::serve() {
  std::vector<double> rays;
  std::vector<SamplePoint> points;
  while (true) {
    Request request{};
    MPI_Bcast(&request, 2, MPI_UINT64_T, 0, comm_);
    if (request.command == kDone) return;
    rays.resize(kDoublesPerRay * request.rays);
    MPI_Bcast(rays.data(), int(rays.size()), MPI_DOUBLE, 0, comm_);
    points.resize(request.rays);
    for (std::size_t k = 0; k < points.size(); ++k) {
      const double* ray = &rays[kDoublesPerRay * k];
      const double view = ray[0];
      // The root sent only known views; anything else becomes an unknown view, answered as
      // an error rather than cast.
      points[k].view = view >= 0.0 && view < double(views_.size()) ? std::uint32_t(view)
                                                                   : std::uint32_t(UINT32_MAX);
      points[k].position = {ray[1], ray[2]};
      points[k].depth_min = ray[3];
      points[k].depth_max = ray[4];
    }
    gather(comm_, answer(points));
  }
}

}  // namespace ldimesh

#include "ldimesh/transport/distributed.hpp"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstring>
#include <exception>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>

#include <tbb/parallel_for.h>

#include "ldimesh/core/base/timing.hpp"

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
  return rank == 0 ? status : Status::other_rank(std::move(message));
}

}  // namespace

double reduction_tolerance(const FragmentEncoding& encoding, const View& view,
                           double domain_diagonal) {
  return std::max(1e-9 * domain_diagonal,
                  2.0 * depth_error_bound(encoding, 0.0, view.depth_extent));
}

bool meshing_samples(const MeshingOptions& options) {
  // levels != 0, as mesh_ldis tests it: negative levels fail in refinement, on every rank.
  return options.refinement.levels != 0 || merging_projects(options.merging);
}

Status cast_and_reduce(MPI_Comm comm, const StepBlocks& blocks, std::span<const View> views,
                       const FragmentEncoding& encoding, double tolerance, const Status& local,
                       bool defer, CastStep& step, double bind_seconds,
                       const ReductionFaults& faults) {
  step = {};
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const std::size_t nv = views.size();
  std::vector<LdiFragment> fragments;
  std::uint64_t nonfinite = 0;
  const auto start = std::chrono::steady_clock::now();
  const Status cast = !local ? local : guard("ray casting: ", [&] {
    for (std::size_t i = 0; i < blocks.size(); ++i) {
      // The values are the same for every isovalue: count them once.
      if (i == 0)
        for (const CastBlock& b : blocks[0])
          nonfinite += b.caster->nonfinite_values();
      // The views side by side: a view's tasks are uneven, and its last ones (then putting its
      // runs together, on one thread) left the other thread idle, where now the next view's
      // tasks fill it. Each fragment is the same as cast alone. What the casts build on first
      // use is built before, so that no thread waits on it from inside the parallel loop.
      for (std::size_t v = 0; v < nv; ++v)
        for (const CastBlock& b : blocks[i])
          b.caster->prepare(views[v]);
      // A view's failure is kept and rethrown after the loop (the first view's, whatever the
      // timing), not let out of it: TBB would cancel the other views' nested loops, which then
      // return without an exception and with tasks not run.
      const std::size_t first = fragments.size();
      fragments.resize(first + nv);
      std::vector<std::exception_ptr> failures(nv);
      tbb::parallel_for(std::size_t(0), nv, [&](std::size_t v) {
        try {
          const std::uint32_t index = std::uint32_t(i * nv + v);
          std::vector<LdiFragment> parts;
          for (const CastBlock& b : blocks[i])
            parts.push_back(b.caster->cast_fragment(views[v], index, b.sub));
          if (parts.empty())
            fragments[first + v] = make_empty_fragment(views[v], index);
          else if (parts.size() == 1)
            fragments[first + v] = std::move(parts.front());
          else
            fragments[first + v] = combine_fragments(parts, tolerance, glm::vec3(views[v].dir));
        } catch (...) {
          failures[v] = std::current_exception();
        }
      });
      for (const std::exception_ptr& failure : failures)
        if (failure) std::rethrow_exception(failure);
    }
    return Status::ok();
  });
  const double cast_seconds = bind_seconds + seconds_since(start);
  // A failure anywhere fails the step everywhere before the reduction, whose fragment counts
  // would no longer agree.
  int failed = cast ? 0 : 1, any_failed = 0;
  MPI_Allreduce(&failed, &any_failed, 1, MPI_INT, MPI_MAX, comm);
  if (any_failed) return cast ? Status::other_rank("another rank failed to ray cast") : cast;

  ReductionStats stats;
  DuplicateRule rule{tolerance, {}};
  for (std::size_t k = 0; k < fragments.size(); ++k)
    rule.dirs.push_back(glm::vec3(views[k % views.size()].dir));
  const Status reduced = reduce_fragments(comm, 0, fragments, encoding, rule, stats,
                                          defer && rank == 0 ? &step.pending : nullptr, faults);
  // Every rank learns whether the reduction failed anywhere (and the slowest rank's times); the
  // root the totals.
  double maxima[3] = {reduced ? 0.0 : 1.0, cast_seconds, stats.encode_seconds};
  MPI_Allreduce(MPI_IN_PLACE, maxima, 3, MPI_DOUBLE, MPI_MAX, comm);
  static_assert(sizeof(unsigned long long) == sizeof(std::uint64_t));
  const unsigned long long mine[2] = {stats.bytes_sent, nonfinite};
  unsigned long long sums[2] = {0, 0};
  MPI_Reduce(mine, sums, 2, MPI_UNSIGNED_LONG_LONG, MPI_SUM, 0, comm);
  if (maxima[0] != 0.0) {
    step = {};
    return reduced ? Status::other_rank("the reduction failed on another rank") : reduced;
  }
  step.seconds.cast = maxima[1];
  step.seconds.encode = maxima[2];
  if (rank == 0) {
    step.fragments = std::move(fragments);
    step.seconds.reduce = stats.wall_seconds;
    step.seconds.decode = stats.decode_seconds;
    step.bytes_to_root = stats.bytes_received;
    step.bytes_moved = sums[0];
    step.nonfinite_values = sums[1];
  }
  return Status::ok();
}

namespace {

// The root's half of a step (mesh_step, mesh_on_root): what a deferred reduction left, then each
// isovalue's LDIs and mesh. `open_samples(i, samples)` gives isovalue i its sample source, or
// leaves `samples` empty where meshing asks for none. Makes no MPI call of its own.
template <class OpenSamples>
Status mesh_isovalues(std::size_t isovalues, std::span<const View> views,
                      const MeshingOptions& options, CastStep& step,
                      std::vector<MeshingResult>& results, std::vector<std::vector<Ldi>>* ldis,
                      OpenSamples&& open_samples) {
  const std::size_t nv = views.size();
  Status status = Status::ok();
  if (!step.pending.messages.empty()) {
    const auto start = std::chrono::steady_clock::now();
    ReductionStats stats;
    status = finish_reduction(step.pending, step.fragments, stats);
    step.seconds.decode += seconds_since(start);
  }
  if (status && step.fragments.size() != isovalues * nv)
    status = Status::internal("the step has " + std::to_string(step.fragments.size()) +
                              " fragments for " + std::to_string(isovalues) + " isovalues of " +
                              std::to_string(nv) + " views");
  for (std::size_t i = 0; i < isovalues; ++i) {
    std::optional<MpiSampleSource> samples;
    open_samples(i, samples);
    if (status) {
      try {
        auto start = std::chrono::steady_clock::now();
        std::vector<Ldi> isovalue_ldis;
        for (std::size_t v = 0; v < nv; ++v)
          isovalue_ldis.push_back(ldi_from_fragment(step.fragments[i * nv + v], views[v]));
        step.seconds.decode += seconds_since(start);
        start = std::chrono::steady_clock::now();
        results.push_back(mesh_ldis(isovalue_ldis, options, samples ? &*samples : nullptr));
        step.seconds.mesh += seconds_since(start);
        if (ldis) ldis->push_back(std::move(isovalue_ldis));
      } catch (...) {
        status = status_from_current_exception("");
      }
    }
    // The other ranks serve every isovalue: end each one, also after a failure.
    if (samples) samples->finish();
  }
  if (!status) {
    results.clear();
    if (ldis) ldis->clear();
  }
  return status;
}

}  // namespace

Status mesh_step(MPI_Comm comm, const StepBlocks& blocks, std::span<const View> views,
                 double tolerance, const MeshingOptions& options, CastStep& step,
                 std::vector<MeshingResult>& results, std::vector<std::vector<Ldi>>* ldis) {
  results.clear();
  if (ldis) ldis->clear();
  const bool collective = meshing_samples(options);
  int rank = 0;  // without samples only the root calls, and no MPI call is made
  if (collective) MPI_Comm_rank(comm, &rank);
  if (rank != 0) {
    if (!collective) return Status::ok();
    // Answer the root's requests, isovalue after isovalue, as it meshes them.
    for (const std::vector<CastBlock>& mine : blocks)
      MpiSampleSource(comm, mine, std::vector<View>(views.begin(), views.end()), tolerance).serve();
    return root_status(comm, Status::ok());
  }
  const Status status =
      mesh_isovalues(blocks.size(), views, options, step, results, ldis,
                     [&](std::size_t i, std::optional<MpiSampleSource>& samples) {
                       if (collective)
                         samples.emplace(comm, blocks[i],
                                         std::vector<View>(views.begin(), views.end()), tolerance);
                     });
  return collective ? root_status(comm, status) : status;
}

Status mesh_on_root(std::size_t isovalues, std::span<const View> views,
                    const MeshingOptions& options, CastStep& step,
                    std::vector<MeshingResult>& results) {
  if (meshing_samples(options))
    return Status::invalid_argument(
        "mesh_on_root: refinement or projecting merging asks every rank for samples (mesh_step)");
  results.clear();
  return mesh_isovalues(isovalues, views, options, step, results, nullptr,
                        [](std::size_t, std::optional<MpiSampleSource>&) {});
}

Status mesh_distributed(MPI_Comm comm, const RayCaster& caster, const Subdomain& sub,
                        std::span<const View> views, const DistributedOptions& options,
                        DistributedResult& result) {
  result = {};
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  double tolerance = 0.0;
  for (const View& view : views)
    tolerance =
        std::max(tolerance, reduction_tolerance(options.encoding, view, sub.global.diagonal()));
  const StepBlocks blocks{{CastBlock{&caster, sub}}};
  CastStep step;
  Status status =
      cast_and_reduce(comm, blocks, views, options.encoding, tolerance, Status::ok(), false, step);
  // Ranks that would serve requests the root never sends, or the reverse, would wait forever.
  const int levels = options.meshing.refinement.levels;
  const bool projects = merging_projects(options.meshing.merging);
  const Agreement agreed = agree(comm, bool(status), levels, projects);
  if (!agreed.reduced)
    return status ? Status::other_rank("the step failed on another rank") : status;
  if (!agreed.same_levels)
    return Status::invalid_argument("refinement levels differ between ranks");
  if (!agreed.same_projection)
    return Status::invalid_argument("merging options differ between ranks");

  std::vector<MeshingResult> meshed;
  std::vector<std::vector<Ldi>> ldis;
  // Without samples the root meshes alone.
  if (rank == 0 || meshing_samples(options.meshing))
    status = mesh_step(comm, blocks, views, tolerance, options.meshing, step, meshed, &ldis);
  result.seconds = step.seconds;
  result.bytes_to_root = step.bytes_to_root;
  result.bytes_moved = step.bytes_moved;
  if (status && rank == 0) {
    result.meshing = std::move(meshed.front());
    result.ldis = std::move(ldis.front());
  }
  return status;
}

MpiSampleSource::MpiSampleSource(MPI_Comm comm, const RayCaster& caster, Subdomain sub,
                                 std::vector<View> views, double tolerance)
    : MpiSampleSource(comm, {CastBlock{&caster, sub}}, std::move(views), tolerance) {}

MpiSampleSource::MpiSampleSource(MPI_Comm comm, std::vector<CastBlock> blocks,
                                 std::vector<View> views, double tolerance)
    : comm_(comm), blocks_(std::move(blocks)), views_(std::move(views)), tolerance_(tolerance) {}

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

// memcpy of n bytes that allows an empty vector's data() (null) when n is 0: memcpy itself
// must not be given a null pointer even then.
void copy_bytes(void* to, const void* from, std::size_t n) {
  if (n > 0) std::memcpy(to, from, n);
}

std::vector<std::uint8_t> serialize(const RayHitList& hits) {
  const std::uint64_t rays = hits.offsets.size() - 1, samples = hits.depth.size();
  const std::uint64_t scalar = hits.scalar.empty() ? 0 : 1;
  std::vector<std::uint8_t> out(32 + 4 * (rays + 1) + samples * (4 + 12 + 4 * scalar));
  std::uint8_t* p = out.data();
  auto put = [&](const void* src, std::size_t n) {
    copy_bytes(p, src, n);
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
  copy_bytes(out.data() + 8, message.data(), message.size());
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
  copy_bytes(hits.depth.data(), p, 4 * samples);
  p += 4 * samples;
  hits.normal.resize(samples);
  copy_bytes(hits.normal.data(), p, 12 * samples);
  p += 12 * samples;
  hits.scalar.resize(scalar ? samples : 0);
  if (scalar) copy_bytes(hits.scalar.data(), p, 4 * samples);
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

// Per ray, the hits of all answers by depth; each run of hits within `tolerance` of its first
// (a hit on a shared face, seen by two ranks or two blocks) becomes the one kept_before chooses,
// as one caster collapses its own duplicates, so that a ray lying in a face plane between ranks,
// which both answer, keeps the hit that one process keeps.
RayHitList combine_hit_lists(const std::vector<RayHitList>& answers,
                             std::span<const SamplePoint> points, std::span<const View> views,
                             double tolerance) {
  const bool with_scalar = std::any_of(answers.begin(), answers.end(),
                                       [](const RayHitList& a) { return !a.scalar.empty(); });
  struct Hit {
    float depth;
    glm::vec3 normal;
    float scalar;
  };
  RayHitList merged;
  merged.offsets.reserve(points.size() + 1);
  merged.offsets.push_back(0);
  std::vector<Hit> hits;
  for (std::size_t k = 0; k < points.size(); ++k) {
    hits.clear();
    for (const RayHitList& a : answers)
      for (std::uint32_t s = a.offsets[k]; s < a.offsets[k + 1]; ++s)
        hits.push_back({a.depth[s], a.normal[s], a.scalar.empty() ? 0.0f : a.scalar[s]});
    const std::size_t kept = collapse_duplicate_hits(
        std::span<Hit>(hits), tolerance, glm::vec3(views[points[k].view].dir),
        [](const Hit& a, const Hit& b) {
          return a.depth != b.depth ? a.depth < b.depth : normal_less(a.normal, b.normal);
        },
        [](const Hit& h) { return h.depth; }, [](const Hit& h) { return h.normal; });
    for (std::size_t i = 0; i < kept; ++i) {
      merged.depth.push_back(hits[i].depth);
      merged.normal.push_back(hits[i].normal);
      if (with_scalar) merged.scalar.push_back(hits[i].scalar);
    }
    merged.offsets.push_back(std::uint32_t(merged.depth.size()));
  }
  return merged;
}

}  // namespace

RayHitList MpiSampleSource::cast_here(std::span<const SamplePoint> points) const {
  if (blocks_.size() == 1)
    return cast_sample_points(*blocks_.front().caster, views_, points, &blocks_.front().sub, true);
  for (const SamplePoint& p : points)  // as cast_sample_points checks it
    if (p.view >= views_.size()) throw std::out_of_range("sample request for an unknown view");
  std::vector<RayHitList> answers;
  for (const CastBlock& b : blocks_)
    answers.push_back(cast_sample_points(*b.caster, views_, points, &b.sub, true));
  if (answers.empty()) {
    RayHitList none;
    none.offsets.assign(points.size() + 1, 0);
    return none;
  }
  return combine_hit_lists(answers, points, views_, tolerance_);
}

std::vector<std::uint8_t> MpiSampleSource::answer(std::span<const SamplePoint> points) const {
  try {
    std::vector<std::uint8_t> bytes = serialize(cast_here(points));
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
      answers.push_back(cast_here(points));
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string("sampling failed on rank 0: ") + e.what());
    }
  } else {
    answers = ask_all(points);
  }
  return combine_hit_lists(answers, points, views_, tolerance_);
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

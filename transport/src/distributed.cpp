#include "ldimesh/transport/distributed.hpp"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstring>
#include <stdexcept>
#include <tuple>

namespace ldimesh {
namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Whether `ok` holds on every rank.
bool all_ranks(MPI_Comm comm, bool ok) {
  int mine = ok ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, comm);
  return all == 1;
}

double max_over_ranks(MPI_Comm comm, double v) {
  double out = 0.0;
  MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_MAX, comm);
  return out;
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
  if (!all_ranks(comm, bool(reduced))) {
    return reduced ? Status::error("reduction failed on another rank") : reduced;
  }
  if (rank != 0) return Status::ok();

  result.bytes_to_root = stats.bytes_received;
  result.seconds.reduce = stats.wall_seconds;
  start = std::chrono::steady_clock::now();
  for (std::size_t v = 0; v < views.size(); ++v)
    result.ldis.push_back(ldi_from_fragment(fragments[v], views[v]));
  result.seconds.decode = stats.decode_seconds + seconds_since(start);
  start = std::chrono::steady_clock::now();
  result.meshing = mesh_ldis(result.ldis, options.meshing);
  result.seconds.mesh = seconds_since(start);
  return Status::ok();
}

MpiSampleSource::MpiSampleSource(MPI_Comm comm, const RayCaster& caster, Subdomain sub,
                                 std::vector<View> views, double tolerance)
    : comm_(comm), caster_(caster), sub_(sub), views_(std::move(views)), tolerance_(tolerance) {}

RayHitList MpiSampleSource::answer(std::uint32_t view_index,
                                   std::span<const glm::dvec2> positions) {
  return caster_.cast_points(views_.at(view_index), positions, &sub_);
}

namespace {

// Request header broadcast by the root: command (0 = done, 1 = batch), view, ray count.
struct Request {
  std::uint64_t command, view, rays;
};

std::vector<std::uint8_t> serialize(const RayHitList& hits) {
  const std::uint64_t rays = hits.offsets.size() - 1, samples = hits.depth.size();
  const std::uint64_t scalar = hits.scalar.empty() ? 0 : 1;
  std::vector<std::uint8_t> out(24 + 4 * (rays + 1) + samples * (4 + 12 + 4 * scalar));
  std::uint8_t* p = out.data();
  auto put = [&](const void* src, std::size_t n) {
    std::memcpy(p, src, n);
    p += n;
  };
  put(&rays, 8);
  put(&samples, 8);
  put(&scalar, 8);
  put(hits.offsets.data(), 4 * (rays + 1));
  put(hits.depth.data(), 4 * samples);
  put(hits.normal.data(), 12 * samples);
  if (scalar) put(hits.scalar.data(), 4 * samples);
  return out;
}

// Ranks of one job run the same binary on the same kind of machine (homogeneous MPI), so raw
// floats travel as they are; sizes are still checked.
bool deserialize(std::span<const std::uint8_t> in, std::uint64_t rays, RayHitList& hits) {
  if (in.size() < 24) return false;
  std::uint64_t n = 0, samples = 0, scalar = 0;
  std::memcpy(&n, in.data(), 8);
  std::memcpy(&samples, in.data() + 8, 8);
  std::memcpy(&scalar, in.data() + 16, 8);
  if (n != rays || scalar > 1 || samples > in.size()) return false;
  if (in.size() != 24 + 4 * (rays + 1) + samples * (16 + 4 * scalar)) return false;
  const std::uint8_t* p = in.data() + 24;
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

// Gathers every rank's serialized answer to rank 0.
std::vector<std::vector<std::uint8_t>> gather(MPI_Comm comm,
                                              const std::vector<std::uint8_t>& mine) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const int length = int(std::min<std::size_t>(mine.size(), INT_MAX));
  std::vector<int> lengths(size), displacements(size);
  MPI_Gather(&length, 1, MPI_INT, lengths.data(), 1, MPI_INT, 0, comm);
  std::vector<std::uint8_t> all;
  if (rank == 0) {
    long long total = 0;
    for (int r = 0; r < size; ++r) {
      displacements[r] = int(total);
      total += lengths[r];
    }
    if (total > INT_MAX) throw std::runtime_error("sample answers over 2 GiB are not supported");
    all.resize(std::size_t(total));
  }
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

RayHitList MpiSampleSource::sample(std::uint32_t view_index,
                                   std::span<const glm::dvec2> positions) {
  if (view_index >= views_.size()) throw std::out_of_range("sample request for an unknown view");
  if (positions.size() > std::size_t(INT_MAX / 2))
    throw std::invalid_argument("too many sample requests");
  Request request{1, view_index, positions.size()};
  MPI_Bcast(&request, 3, MPI_UINT64_T, 0, comm_);
  std::vector<glm::dvec2> rays(positions.begin(), positions.end());
  MPI_Bcast(rays.data(), int(2 * rays.size()), MPI_DOUBLE, 0, comm_);
  const std::vector<std::vector<std::uint8_t>> parts =
      gather(comm_, serialize(answer(view_index, rays)));

  std::vector<RayHitList> answers(parts.size());
  for (std::size_t r = 0; r < parts.size(); ++r)
    if (!deserialize(parts[r], rays.size(), answers[r]))
      throw std::runtime_error("sample answer of rank " + std::to_string(r) + " is malformed");
  const bool with_scalar = std::any_of(answers.begin(), answers.end(),
                                       [](const RayHitList& a) { return !a.scalar.empty(); });
  struct Hit {
    float depth;
    glm::vec3 normal;
    float scalar;
  };
  RayHitList merged;
  merged.offsets.push_back(0);
  std::vector<Hit> hits;
  for (std::size_t k = 0; k < rays.size(); ++k) {
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
  Request request{0, 0, 0};
  MPI_Bcast(&request, 3, MPI_UINT64_T, 0, comm_);
}

void MpiSampleSource::serve() {
  while (true) {
    Request request{};
    MPI_Bcast(&request, 3, MPI_UINT64_T, 0, comm_);
    if (request.command == 0) return;
    std::vector<glm::dvec2> rays(request.rays);
    MPI_Bcast(rays.data(), int(2 * rays.size()), MPI_DOUBLE, 0, comm_);
    gather(comm_, serialize(answer(std::uint32_t(request.view), rays)));
  }
}

}  // namespace ldimesh

#include "ldimesh/core/raycaster.hpp"
#include "ldimesh/core/timing.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace ldimesh {
namespace {

// Sorts one ray's hits by depth and merges hits closer than `tolerance` (a root found by both
// primitives that share a face). Ties in depth are broken by the normal so that the result
// does not depend on the order in which Embree visited the primitives.
void sort_and_merge(std::vector<RayHit>& hits, double tolerance) {
  std::sort(hits.begin(), hits.end(), [](const RayHit& a, const RayHit& b) {
    if (a.t != b.t) return a.t < b.t;
    if (a.normal.x != b.normal.x) return a.normal.x < b.normal.x;
    if (a.normal.y != b.normal.y) return a.normal.y < b.normal.y;
    return a.normal.z < b.normal.z;
  });
  std::size_t kept = 0;
  for (std::size_t k = 0; k < hits.size(); ++k)
    if (kept == 0 || hits[k].t - hits[kept - 1].t > tolerance) hits[kept++] = hits[k];
  hits.resize(kept);
}

}  // namespace

RayCaster::RayCaster(const FieldSource& source, double isovalue)
    : RayCaster(std::span<const FieldSource* const>(std::array{&source}), isovalue) {}

RayCaster::RayCaster(std::span<const FieldSource* const> sources, double isovalue) {
  if (sources.empty()) throw std::invalid_argument("ray caster needs at least one field source");
  const auto start = std::chrono::steady_clock::now();
  device_ = rtcNewDevice(nullptr);
  if (!device_) throw std::runtime_error("Embree: cannot create a device");
  scene_ = rtcNewScene(device_);
  if (!scene_) {
    rtcReleaseDevice(device_);
    throw std::runtime_error("Embree: cannot create a scene");
  }
  rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
  try {
    for (const FieldSource* source : sources) {
      bindings_.push_back(source->bind(device_, isovalue));
      rtcAttachGeometry(scene_, bindings_.back()->geometry());
      has_scalar_ = has_scalar_ || bindings_.back()->has_scalar();
      duplicate_tolerance_ = std::max(duplicate_tolerance_, source->duplicate_tolerance());
    }
    rtcCommitScene(scene_);
    if (const RTCError error = rtcGetDeviceError(device_); error != RTC_ERROR_NONE)
      throw std::runtime_error("Embree: scene build failed (RTCError " +
                               std::to_string(int(error)) + ")");
  } catch (...) {
    rtcReleaseScene(scene_);
    bindings_.clear();
    rtcReleaseDevice(device_);
    throw;
  }
  build_seconds_ = seconds_since(start);
}

RayCaster::~RayCaster() {
  rtcReleaseScene(scene_);
  bindings_.clear();
  rtcReleaseDevice(device_);
}

std::size_t RayCaster::primitive_count() const {
  std::size_t n = 0;
  for (const auto& b : bindings_)
    n += b->primitive_count();
  return n;
}

std::uint64_t RayCaster::nonfinite_values() const {
  std::uint64_t n = 0;
  for (const auto& b : bindings_)
    n += b->nonfinite_values();
  return n;
}

bool subdomain_segment(const Subdomain& sub, glm::dvec3 o, glm::dvec3 d, RaySegment& segment) {
  // Where the ray leaves the global box: the end of the last segment is closed there.
  double g0 = -INFINITY, g1 = INFINITY;
  if (!clip_ray_to_box(o, d, sub.global.lo, sub.global.hi, g0, g1)) return false;
  double t0 = -INFINITY, t1 = INFINITY;
  for (int a = 0; a < 3; ++a) {
    const bool closed_hi = sub.box.hi[a] >= sub.global.hi[a];
    if (d[a] == 0.0) {
      // A ray in a face plane: the spatial rule decides.
      if (o[a] < sub.box.lo[a] || o[a] > sub.box.hi[a] || (o[a] == sub.box.hi[a] && !closed_hi))
        return false;
      continue;
    }
    // The same expression as clip_ray_to_box, so that the value at a shared face is the same
    // double in both subdomains.
    const double inv = 1.0 / d[a];
    double ta = (sub.box.lo[a] - o[a]) * inv, tb = (sub.box.hi[a] - o[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  segment.t0 = std::max(t0, g0);
  segment.t1 = std::min(t1, g1);
  segment.closed_end = segment.t1 >= g1;
  return segment.t0 < segment.t1 || (segment.closed_end && segment.t0 == segment.t1);
}

void RayCaster::trace(const View& view, glm::dvec2 image_position, const RaySegment& segment,
                      std::vector<RayHit>& hits) const {
  hits.clear();
  RayQuery q;
  rtcInitIntersectContext(&q.context);
  q.context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  q.org = view.point(image_position.x, image_position.y, 0.0);
  q.dir = view.dir;
  q.t_min = segment.t0;
  q.t_max = segment.t1;
  q.hits = &hits;

  RTCRayHit rh;
  rh.ray.org_x = float(q.org.x), rh.ray.org_y = float(q.org.y), rh.ray.org_z = float(q.org.z);
  rh.ray.dir_x = float(q.dir.x), rh.ray.dir_y = float(q.dir.y), rh.ray.dir_z = float(q.dir.z);
  // Embree traverses in float: widen its segment a little; the callbacks clip in double.
  const float pad = float(1e-6 * (1.0 + view.depth_extent));
  rh.ray.tnear = std::max(0.0f, float(segment.t0) - pad);
  rh.ray.tfar = float(segment.t1) + pad;
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;  // Debian's Embree is built with ray masks: 0 would hit nothing
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene_, &q.context, &rh);
  sort_and_merge(hits, duplicate_tolerance_);
  // Sources report roots on the closed segment; the half-open rule keeps a root on the face
  // two subdomains share in exactly one of them.
  std::erase_if(hits, [&](const RayHit& h) {
    return h.t < segment.t0 || h.t > segment.t1 || (h.t == segment.t1 && !segment.closed_end);
  });
}

template <class Segment>
std::vector<RayCaster::HitRun> RayCaster::cast_rows(const View& view, Segment segment_of) const {
  std::vector<RayCaster::HitRun> rows(view.height);
  tbb::parallel_for(tbb::blocked_range<int>(0, view.height),
                    [&](const tbb::blocked_range<int>& range) {
                      std::vector<RayHit> hits;
                      for (int j = range.begin(); j != range.end(); ++j)
                        for (int i = 0; i < view.width; ++i) {
                          const glm::dvec2 position{i + 0.5, j + 0.5};
                          RaySegment segment;
                          if (segment_of(position, segment)) {
                            trace(view, position, segment, hits);
                          } else {
                            hits.clear();
                          }
                          rows[j].append(hits, has_scalar_);
                        }
                    });
  return rows;
}

Ldi RayCaster::cast(const View& view) const {
  const std::vector<RayCaster::HitRun> rows = cast_rows(view, [&](glm::dvec2, RaySegment& segment) {
    segment = {0.0, view.depth_extent, true};
    return true;
  });
  // Concatenate rows in order: the LDI is the same whatever the thread count.
  Ldi ldi = make_empty_ldi(view);
  std::size_t total = 0;
  for (const RayCaster::HitRun& row : rows)
    total += row.depth.size();
  if (total > UINT32_MAX) throw std::runtime_error("LDI has more than 2^32 samples");
  ldi.depth.reserve(total);
  ldi.normal.reserve(total);
  if (has_scalar_) ldi.scalar.reserve(total);
  std::uint32_t offset = 0;
  for (int j = 0; j < view.height; ++j) {
    const RayCaster::HitRun& row = rows[j];
    for (int i = 0; i < view.width; ++i) {
      ldi.offsets[std::size_t(j) * view.width + i] = offset;
      offset += row.counts[i];
    }
    ldi.depth.insert(ldi.depth.end(), row.depth.begin(), row.depth.end());
    ldi.normal.insert(ldi.normal.end(), row.normal.begin(), row.normal.end());
    ldi.scalar.insert(ldi.scalar.end(), row.scalar.begin(), row.scalar.end());
  }
  ldi.offsets[view.pixel_count()] = offset;
  return ldi;
}

LdiFragment RayCaster::cast_fragment(const View& view, std::uint32_t view_index,
                                     const Subdomain& sub) const {
  const std::vector<RayCaster::HitRun> rows =
      cast_rows(view, [&](glm::dvec2 position, RaySegment& segment) {
        return subdomain_segment(sub, view.point(position.x, position.y, 0.0), view.dir, segment);
      });
  LdiFragment fragment = make_empty_fragment(view, view_index);
  for (int j = 0; j < view.height; ++j) {
    const RayCaster::HitRun& row = rows[j];
    for (int i = 0; i < view.width; ++i)
      if (row.counts[i] > 0) {
        fragment.pixels.push_back(std::uint32_t(std::size_t(j) * view.width + i));
        fragment.counts.push_back(row.counts[i]);
      }
    fragment.depth.insert(fragment.depth.end(), row.depth.begin(), row.depth.end());
    fragment.normal.insert(fragment.normal.end(), row.normal.begin(), row.normal.end());
    fragment.scalar.insert(fragment.scalar.end(), row.scalar.begin(), row.scalar.end());
  }
  return fragment;
}

RayHitList RayCaster::cast_points(const View& view, std::span<const glm::dvec2> image_positions,
                                  const Subdomain* sub,
                                  std::span<const glm::dvec2> depth_ranges) const {
  const std::size_t n = image_positions.size();
  if (!depth_ranges.empty() && depth_ranges.size() != n)
    throw std::invalid_argument("cast_points: one depth range per ray, or none");
  constexpr std::size_t kChunk = 256;
  std::vector<RayCaster::HitRun> chunks((n + kChunk - 1) / kChunk);
  tbb::parallel_for(std::size_t(0), chunks.size(), [&](std::size_t c) {
    std::vector<RayHit> hits;
    for (std::size_t k = c * kChunk; k < std::min(n, (c + 1) * kChunk); ++k) {
      const glm::dvec2 position = image_positions[k];
      RaySegment segment{0.0, view.depth_extent, true};
      bool crosses = !sub || subdomain_segment(*sub, view.point(position.x, position.y, 0.0),
                                               view.dir, segment);
      if (crosses && !depth_ranges.empty()) {
        // The range is closed at both ends. Where it ends before the segment, the end is
        // closed; otherwise the segment's own rule (half-open at a shared face) stays.
        const glm::dvec2 range = depth_ranges[k];
        if (range.y < segment.t1) segment = {segment.t0, range.y, true};
        segment.t0 = std::max(segment.t0, range.x);
        crosses = segment.t0 < segment.t1 || (segment.closed_end && segment.t0 == segment.t1);
      }
      if (crosses) {
        trace(view, position, segment, hits);
      } else {
        hits.clear();
      }
      chunks[c].append(hits, has_scalar_);
    }
  });
  RayHitList out;
  out.offsets.reserve(n + 1);
  out.offsets.push_back(0);
  for (const RayCaster::HitRun& run : chunks) {
    for (std::uint32_t c : run.counts)
      out.offsets.push_back(out.offsets.back() + c);
    out.depth.insert(out.depth.end(), run.depth.begin(), run.depth.end());
    out.normal.insert(out.normal.end(), run.normal.begin(), run.normal.end());
    out.scalar.insert(out.scalar.end(), run.scalar.begin(), run.scalar.end());
  }
  return out;
}

}  // namespace ldimesh

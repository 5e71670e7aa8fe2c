#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/core/base/timing.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

namespace ldimesh {

void AxisHits::grow() {
  const std::size_t capacity = std::max<std::size_t>(1024, 2 * capacity_);
  std::unique_ptr<std::uint32_t[]> rays(new std::uint32_t[capacity]);
  std::unique_ptr<RayHit[]> hits(new RayHit[capacity]);
  std::copy(rays_.get(), rays_.get() + size_, rays.get());
  std::copy(hits_.get(), hits_.get() + size_, hits.get());
  rays_ = std::move(rays);
  hits_ = std::move(hits);
  capacity_ = capacity;
}

namespace {

// Sorts one ray's hits by depth and collapses hits closer than `tolerance` (a root found by both
// primitives that share a face, or two roots closer than rounding can tell apart) by the
// duplicate rule (collapse_duplicate_hits).
std::size_t sort_and_collapse(std::span<RayHit> hits, double tolerance, glm::dvec3 dir) {
  return collapse_duplicate_hits(
      hits, tolerance, glm::vec3(dir),
      [](const RayHit& a, const RayHit& b) {
        return a.t != b.t ? a.t < b.t : normal_less(a.normal, b.normal);
      },
      [](const RayHit& h) { return h.t; }, [](const RayHit& h) { return h.normal; });
}

// Per-thread buffers of the axis casts, kept between tasks: a task's arrays are large enough
// that allocating them afresh each time costs page faults.
struct AxisScratch {
  std::vector<AxisRay> rays;
  std::vector<RaySegment> segments;
  AxisHits hits;
  std::vector<RayHit> ray_hits;
  std::vector<std::uint32_t> first, next, order;
};
AxisScratch& axis_scratch() {
  thread_local AxisScratch scratch;
  return scratch;
}

// Rows per task of an axis view's cast: about 16384 rays, so that sources that loop over their
// primitives' pixels (elements) or their cells (grids) see each in few tasks and read the cells'
// bits for few slabs, but at least 16 tasks per view for the threads to share. The split does
// not depend on the thread count (nor, since each ray's hits are sorted, do the hits).
int rows_per_task(const View& view) {
  const int height = std::max(view.height, 1);
  const int rows = std::min(16384 / std::max(view.width, 1), (height + 15) / 16);
  return std::clamp(rows, 1, height);
}

// Columns per task where tasks are blocks of columns: rows_per_task with the axes swapped.
int columns_per_task(const View& view) {
  const int width = std::max(view.width, 1);
  const int columns = std::min(16384 / std::max(view.height, 1), (width + 15) / 16);
  return std::clamp(columns, 1, width);
}

}  // namespace

// The runs of tasks that were blocks of `per_task` columns (each run's rays row after row within
// its block), as one run per row of the view, in pixel order; rows in parallel.
std::vector<RayCaster::HitRun> RayCaster::rows_from_column_blocks(const View& view,
                                                                  const std::vector<HitRun>& blocks,
                                                                  int per_task) const {
  const std::size_t height = std::size_t(std::max(view.height, 0));
  // Block t's width (the last may be narrower).
  const auto width_of = [&](std::size_t t) {
    return std::size_t(std::min(per_task, view.width - int(t) * per_task));
  };
  // Per block: where each of its rows' samples start.
  std::vector<std::vector<std::size_t>> starts(blocks.size());
  for (std::size_t t = 0; t < blocks.size(); ++t) {
    const std::size_t w = width_of(t);
    std::vector<std::size_t>& first = starts[t];
    first.assign(height + 1, 0);
    std::size_t sum = 0, k = 0;
    for (std::size_t j = 0; j < height; ++j) {
      first[j] = sum;
      for (std::size_t i = 0; i < w; ++i)
        sum += blocks[t].counts[k++];
    }
    first[height] = sum;
  }
  std::vector<HitRun> rows(height);
  tbb::parallel_for(std::size_t(0), height, [&](std::size_t j) {
    HitRun& row = rows[j];
    std::size_t samples = 0;
    for (std::size_t t = 0; t < blocks.size(); ++t)
      samples += starts[t][j + 1] - starts[t][j];
    row.counts.reserve(std::size_t(view.width));
    row.depth.reserve(samples);
    row.normal.reserve(samples);
    if (has_scalar_) row.scalar.reserve(samples);
    for (std::size_t t = 0; t < blocks.size(); ++t) {
      const HitRun& b = blocks[t];
      const std::size_t w = width_of(t);
      row.counts.insert(row.counts.end(), b.counts.begin() + std::ptrdiff_t(j * w),
                        b.counts.begin() + std::ptrdiff_t((j + 1) * w));
      const auto s0 = std::ptrdiff_t(starts[t][j]), s1 = std::ptrdiff_t(starts[t][j + 1]);
      row.depth.insert(row.depth.end(), b.depth.begin() + s0, b.depth.begin() + s1);
      row.normal.insert(row.normal.end(), b.normal.begin() + s0, b.normal.begin() + s1);
      if (has_scalar_)
        row.scalar.insert(row.scalar.end(), b.scalar.begin() + s0, b.scalar.begin() + s1);
    }
  });
  return rows;
}

RayCaster::RayCaster(const FieldSource& source, double isovalue, RayCasterOptions options)
    : RayCaster(std::span<const FieldSource* const>(std::array{&source}), isovalue, options) {}

RayCaster::RayCaster(std::span<const FieldSource* const> sources, double isovalue,
                     RayCasterOptions options)
    : sources_(sources.begin(), sources.end()), isovalue_(isovalue) {
  if (sources.empty()) throw std::invalid_argument("ray caster needs at least one field source");
  const auto start = std::chrono::steady_clock::now();
  for (const FieldSource* source : sources_)
    duplicate_tolerance_ = std::max(duplicate_tolerance_, source->duplicate_tolerance());
  if (options.path == CastPath::automatic) {
    for (const FieldSource* source : sources_) {
      std::unique_ptr<AxisCaster> caster = source->bind_axis(isovalue);
      if (!caster) {  // one source without: Embree for all, so that roots collapse alike
        axis_casters_.clear();
        break;
      }
      axis_casters_.push_back(std::move(caster));
    }
  }
  if (options.scalars)
    for (const FieldSource* source : sources_) {
      scalar_probes_.push_back(source->bind_scalar());
      has_scalar_ = has_scalar_ || scalar_probes_.back() != nullptr;
    }
  axis_seconds_ = seconds_since(start);
  if (axis_casters_.empty()) ensure_scene();
}

void RayCaster::ensure_scene() const {
  std::call_once(scene_once_, [this] {
    const auto start = std::chrono::steady_clock::now();
    device_ = make_embree_device();
    scene_ = rtcNewScene(device_);
    if (!scene_) {
      rtcReleaseDevice(device_);
      device_ = nullptr;
      throw std::runtime_error("Embree: cannot create a scene");
    }
    rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
    try {
      for (const FieldSource* source : sources_) {
        bindings_.push_back(source->bind(device_, isovalue_));
        rtcAttachGeometry(scene_, bindings_.back()->geometry());
      }
      rtcCommitScene(scene_);
      if (const std::string failure = embree_failure(device_, "building the scene");
          !failure.empty())
        throw std::runtime_error(failure);
    } catch (...) {
      rtcReleaseScene(scene_);
      bindings_.clear();
      rtcReleaseDevice(device_);
      scene_ = nullptr;
      device_ = nullptr;
      throw;
    }
    scene_seconds_ = seconds_since(start);
  });
}

RayCaster::~RayCaster() {
  if (scene_) rtcReleaseScene(scene_);
  bindings_.clear();
  if (device_) rtcReleaseDevice(device_);
}

double RayCaster::build_seconds() const {
  return axis_seconds_ + scene_seconds_;
}

void RayCaster::prepare_axis_casters(const View& view) const {
  for (const auto& caster : axis_casters_)
    caster->prepare(exact_axis(view.dir));
}

void RayCaster::prepare(const View& view) const {
  if (uses_axis_casters(view))
    prepare_axis_casters(view);
  else
    ensure_scene();
}

bool RayCaster::uses_axis_casters(const View& view) const {
  return !axis_casters_.empty() && exact_axis(view.dir) >= 0 && exact_axis(view.u) >= 0 &&
         exact_axis(view.v) >= 0;
}

bool RayCaster::carries_scalars() const {
  return has_scalar_ && std::all_of(scalar_probes_.begin(), scalar_probes_.end(),
                                    [](const auto& probe) { return probe != nullptr; });
}

std::size_t RayCaster::primitive_count() const {
  std::size_t n = 0;
  if (!axis_casters_.empty()) {
    for (const auto& b : axis_casters_)
      n += b->primitive_count();
    return n;
  }
  for (const auto& b : bindings_)
    n += b->primitive_count();
  return n;
}

std::uint64_t RayCaster::nonfinite_values() const {
  std::uint64_t n = 0;
  if (!axis_casters_.empty()) {
    for (const auto& b : axis_casters_)
      n += b->nonfinite_values();
    return n;
  }
  for (const auto& b : bindings_)
    n += b->nonfinite_values();
  return n;
}

bool subdomain_segment(const Subdomain& sub, glm::dvec3 o, glm::dvec3 d, RaySegment& segment,
                       bool closed_planes) {
  // Where the ray leaves the global box: the end of the last segment is closed there.
  double g0 = -INFINITY, g1 = INFINITY;
  if (!clip_ray_to_box(o, d, sub.global.lo, sub.global.hi, g0, g1)) return false;
  double t0 = -INFINITY, t1 = INFINITY;
  for (int a = 0; a < 3; ++a) {
    const bool closed_hi = sub.box.hi[a] >= sub.global.hi[a];
    if (d[a] == 0.0) {
      // A ray in a face plane: the spatial rule decides.
      if (o[a] < sub.box.lo[a] || o[a] > sub.box.hi[a] ||
          (o[a] == sub.box.hi[a] && !closed_hi && !closed_planes))
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
  ensure_scene();
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
  hits.resize(finish_ray(segment, q.org, view.dir, hits));
}

std::size_t RayCaster::finish_ray(const RaySegment& segment, glm::dvec3 org, glm::dvec3 dir,
                                  std::span<RayHit> hits) const {
  const std::size_t n = sort_and_collapse(hits, duplicate_tolerance_, dir);
  // Sources report roots on the closed segment; the half-open rule keeps a root on the face
  // two subdomains share in exactly one of them.
  std::size_t kept = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const RayHit& h = hits[k];
    if (h.t < segment.t0 || h.t > segment.t1 || (h.t == segment.t1 && !segment.closed_end))
      continue;
    hits[kept++] = h;
  }
  // The colour field at each hit: from the first source that holds the point (on a face two
  // sources share, a continuous field has the same value in both), else from the first that
  // is near it.
  if (has_scalar_)
    for (std::size_t k = 0; k < kept; ++k) {
      const glm::dvec3 p = org + hits[k].t * dir;
      double v = std::numeric_limits<double>::quiet_NaN();
      for (const auto& probe : scalar_probes_)
        if (probe && std::isfinite(v = probe->at(p))) break;
      if (!std::isfinite(v))
        for (const auto& probe : scalar_probes_)
          if (probe && std::isfinite(v = probe->near(p))) break;
      hits[k].scalar = float(v);
    }
  return kept;
}

void RayCaster::cast_axis_rays(const AxisRays& rays, std::span<const RaySegment> segments,
                               HitRun& run) const {
  AxisScratch& x = axis_scratch();
  x.hits.clear();
  for (const auto& caster : axis_casters_)
    caster->cast(rays, x.hits);
  const std::size_t n = rays.rays.size();
  run.counts.reserve(run.counts.size() + n);
  run.depth.reserve(run.depth.size() + x.hits.size());
  run.normal.reserve(run.normal.size() + x.hits.size());
  if (has_scalar_) run.scalar.reserve(run.scalar.size() + x.hits.size());
  // Each ray's hits are sorted by depth below, so the order in which the sources reported them
  // does not matter; grouped by ray first (counting sort) unless they came so.
  const std::span<const std::uint32_t> ray_of = x.hits.rays();
  const std::span<const RayHit> found = x.hits.hits();
  if (!std::is_sorted(ray_of.begin(), ray_of.end())) {
    x.first.assign(n + 1, 0);
    for (const std::uint32_t r : ray_of)
      ++x.first[r + 1];
    for (std::size_t k = 0; k < n; ++k)
      x.first[k + 1] += x.first[k];
    // The hits' indices by ray (small: the scatter stays in cache), then each ray's hits
    // gathered (independent loads, which overlap) — scattering the hits themselves missed the
    // cache on most writes.
    x.order.resize(found.size());
    x.next.assign(x.first.begin(), x.first.end() - 1);
    for (std::uint32_t m = 0; m < std::uint32_t(found.size()); ++m)
      x.order[x.next[ray_of[m]]++] = m;
    for (std::size_t k = 0; k < n; ++k) {
      x.ray_hits.clear();
      for (std::uint32_t j = x.first[k]; j < x.first[k + 1]; ++j)
        x.ray_hits.push_back(found[x.order[j]]);
      const std::span<RayHit> hits(x.ray_hits);
      run.append(
          hits.first(hits.empty() ? 0 : finish_ray(segments[k], rays.rays[k].org, rays.dir, hits)),
          has_scalar_);
    }
    return;
  }
  std::size_t h = 0;
  for (std::size_t k = 0; k < n; ++k) {
    x.ray_hits.clear();
    for (; h < found.size() && ray_of[h] == k; ++h)
      x.ray_hits.push_back(found[h]);
    const std::span<RayHit> hits(x.ray_hits);
    run.append(
        hits.first(hits.empty() ? 0 : finish_ray(segments[k], rays.rays[k].org, rays.dir, hits)),
        has_scalar_);
  }
}

template <class Segment>
std::vector<RayCaster::HitRun> RayCaster::cast_rows(const View& view, Segment segment_of) const {
  if (uses_axis_casters(view)) {
    prepare_axis_casters(view);
    // Tasks of several rows, each cast by the axis casters as one lattice of pixel rays — or of
    // several columns (all rows) where every source prefers them (a grid whose fastest memory
    // axis runs along the view's v axis: a block of rows would be a slab a few cells thin along
    // it, reading a line or two of every grid row), the runs then put back in row order.
    bool by_columns = !axis_casters_.empty();
    for (const auto& caster : axis_casters_)
      by_columns = by_columns && caster->prefers_column_tasks(view);
    const int span = by_columns ? view.width : view.height;
    const int per_task = by_columns ? columns_per_task(view) : rows_per_task(view);
    const int tasks = (span + per_task - 1) / per_task;
    std::vector<RayCaster::HitRun> runs(tasks);
    // One task at a time to the threads (simple partitioner): the tasks' work is uneven (where
    // the surface lies), and the default partitioner's halves left a thread idle
    // (docs/history/benchmarks-log.md, "Ray casting beside Flying Edges").
    const auto cast_task = [&](int task) {
      int i0 = 0, i1 = view.width, j0 = 0, j1 = view.height;
      (by_columns ? i0 : j0) = task * per_task;
      (by_columns ? i1 : j1) = std::min(span, task * per_task + per_task);
      const int w = i1 - i0;
      const std::size_t n = std::size_t(j1 - j0) * std::size_t(w);
      AxisScratch& x = axis_scratch();
      std::vector<AxisRay>& rays = x.rays;
      std::vector<RaySegment>& segments = x.segments;
      rays.assign(n, AxisRay{});
      segments.resize(n);
      for (int j = j0; j < j1; ++j)
        for (int i = i0; i < i1; ++i) {
          const std::size_t k = std::size_t(j - j0) * std::size_t(w) + std::size_t(i - i0);
          const glm::dvec2 position{i + 0.5, j + 0.5};
          AxisRay& ray = rays[k];
          ray.org = view.point(position.x, position.y, 0.0);
          if (segment_of(position, segments[k])) {
            ray.t0 = segments[k].t0;
            ray.t1 = segments[k].t1;
          } else {
            segments[k] = {0.0, -1.0, false};
          }
        }
      AxisRays query;
      query.axis = exact_axis(view.dir);
      query.dir = view.dir;
      query.rays = rays;
      query.lattice = &view;
      query.row_begin = j0;
      query.column_begin = i0;
      query.columns = w;
      cast_axis_rays(query, segments, runs[task]);
    };
    tbb::parallel_for(
        tbb::blocked_range<int>(0, tasks, 1),
        [&](const tbb::blocked_range<int>& range) {
          for (int task = range.begin(); task != range.end(); ++task)
            cast_task(task);
        },
        tbb::simple_partitioner());
    // Not a conditional expression: with `runs` as one of its operands it copied every run.
    if (by_columns) return rows_from_column_blocks(view, runs, per_task);
    return runs;
  }
  ensure_scene();
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
  const std::vector<RayCaster::HitRun> runs = cast_rows(view, [&](glm::dvec2, RaySegment& segment) {
    segment = {0.0, view.depth_extent, true};
    return true;
  });
  // Concatenate the runs (consecutive rows) in order: the LDI is the same whatever the thread
  // count.
  Ldi ldi = make_empty_ldi(view);
  std::size_t total = 0;
  for (const RayCaster::HitRun& run : runs)
    total += run.depth.size();
  if (total > UINT32_MAX) throw std::runtime_error("LDI has more than 2^32 samples");
  ldi.depth.reserve(total);
  ldi.normal.reserve(total);
  if (has_scalar_) ldi.scalar.reserve(total);
  std::uint32_t offset = 0;
  std::size_t pixel = 0;
  for (const RayCaster::HitRun& run : runs) {
    for (std::uint32_t c : run.counts) {
      ldi.offsets[pixel++] = offset;
      offset += c;
    }
    ldi.depth.insert(ldi.depth.end(), run.depth.begin(), run.depth.end());
    ldi.normal.insert(ldi.normal.end(), run.normal.begin(), run.normal.end());
    ldi.scalar.insert(ldi.scalar.end(), run.scalar.begin(), run.scalar.end());
  }
  ldi.offsets[view.pixel_count()] = offset;
  return ldi;
}

LdiFragment RayCaster::cast_fragment(const View& view, std::uint32_t view_index,
                                     const Subdomain& sub) const {
  const std::vector<RayCaster::HitRun> runs =
      cast_rows(view, [&](glm::dvec2 position, RaySegment& segment) {
        return subdomain_segment(sub, view.point(position.x, position.y, 0.0), view.dir, segment);
      });
  LdiFragment fragment = make_empty_fragment(view, view_index);
  // Sized once (pixels: at most all of them; untouched capacity costs no pages): growing these
  // by doubling costs more than the copy (fresh pages, each time).
  std::size_t samples = 0, pixels = 0;
  for (const RayCaster::HitRun& run : runs) {
    samples += run.depth.size();
    pixels += run.counts.size();
  }
  fragment.pixels.reserve(pixels);
  fragment.counts.reserve(pixels);
  fragment.depth.reserve(samples);
  fragment.normal.reserve(samples);
  if (has_scalar_) fragment.scalar.reserve(samples);
  std::uint32_t pixel = 0;
  for (const RayCaster::HitRun& run : runs) {
    for (std::uint32_t c : run.counts) {
      if (c > 0) {
        fragment.pixels.push_back(pixel);
        fragment.counts.push_back(c);
      }
      ++pixel;
    }
    fragment.depth.insert(fragment.depth.end(), run.depth.begin(), run.depth.end());
    fragment.normal.insert(fragment.normal.end(), run.normal.begin(), run.normal.end());
    fragment.scalar.insert(fragment.scalar.end(), run.scalar.begin(), run.scalar.end());
  }
  return fragment;
}

RayHitList RayCaster::cast_points(const View& view, std::span<const glm::dvec2> image_positions,
                                  const Subdomain* sub, std::span<const glm::dvec2> depth_ranges,
                                  bool closed_planes) const {
  const std::size_t n = image_positions.size();
  if (!depth_ranges.empty() && depth_ranges.size() != n)
    throw std::invalid_argument("cast_points: one depth range per ray, or none");
  // The segment of ray k; false if it has none.
  const auto segment_of = [&](std::size_t k, RaySegment& segment) {
    const glm::dvec2 position = image_positions[k];
    segment = {0.0, view.depth_extent, true};
    bool crosses = !sub || subdomain_segment(*sub, view.point(position.x, position.y, 0.0),
                                             view.dir, segment, closed_planes);
    if (crosses && !depth_ranges.empty()) {
      // The range is closed at both ends. Where it ends before the segment, the end is
      // closed; otherwise the segment's own rule (half-open at a shared face) stays.
      const glm::dvec2 range = depth_ranges[k];
      if (range.y < segment.t1) segment = {segment.t0, range.y, true};
      segment.t0 = std::max(segment.t0, range.x);
      crosses = segment.t0 < segment.t1 || (segment.closed_end && segment.t0 == segment.t1);
    }
    return crosses;
  };
  const bool axis = uses_axis_casters(view);
  if (n > 0) prepare(view);
  constexpr std::size_t kChunk = 256;
  std::vector<RayCaster::HitRun> chunks((n + kChunk - 1) / kChunk);
  tbb::parallel_for(std::size_t(0), chunks.size(), [&](std::size_t c) {
    std::vector<RayHit> hits;
    const std::size_t k0 = c * kChunk, k1 = std::min(n, (c + 1) * kChunk);
    if (axis) {
      AxisScratch& x = axis_scratch();
      std::vector<AxisRay>& rays = x.rays;
      std::vector<RaySegment>& segments = x.segments;
      rays.assign(k1 - k0, AxisRay{});
      segments.resize(k1 - k0);
      for (std::size_t k = k0; k < k1; ++k) {
        AxisRay& ray = rays[k - k0];
        ray.org = view.point(image_positions[k].x, image_positions[k].y, 0.0);
        if (segment_of(k, segments[k - k0])) {
          ray.t0 = segments[k - k0].t0;
          ray.t1 = segments[k - k0].t1;
        } else {
          segments[k - k0] = {0.0, -1.0, false};
        }
      }
      AxisRays query;
      query.axis = exact_axis(view.dir);
      query.dir = view.dir;
      query.rays = rays;
      cast_axis_rays(query, segments, chunks[c]);
      return;
    }
    for (std::size_t k = k0; k < k1; ++k) {
      RaySegment segment;
      if (segment_of(k, segment)) {
        trace(view, image_positions[k], segment, hits);
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

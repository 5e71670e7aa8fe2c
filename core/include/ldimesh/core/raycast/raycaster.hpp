// Multi-hit ray casting of an isosurface with Embree (paper §3: keep every hit along a ray).
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include <embree3/rtcore.h>

#include "ldimesh/core/base/view.hpp"
#include "ldimesh/core/field/field_source.hpp"
#include "ldimesh/core/raycast/fragment.hpp"
#include "ldimesh/core/raycast/ldi.hpp"

namespace ldimesh {

// Hits of a list of individual rays, in CSR form: the hits of ray k are
// [offsets[k], offsets[k + 1]) of the other arrays, sorted by depth.
struct RayHitList {
  std::vector<std::uint32_t> offsets;
  std::vector<float> depth;
  std::vector<glm::vec3> normal;
  std::vector<float> scalar;  // empty unless the source has a scalar
};

// The part of the global domain one rank ray casts. A point belongs to it iff lo ≤ p < hi on
// every axis, with ≤ hi where the box reaches the global box's upper face, so that boxes tiling
// the global box own every point exactly once.
struct Subdomain {
  Box box;
  Box global;
};

// The part [t0, t1) of a ray o + t·d of `view` that `sub` owns (t1 included when the ray leaves
// the global box there). Along the ray the rule is half-open in t: a hit exactly on a face two
// subdomains share belongs to the one the ray enters there. A ray lying in a face plane belongs
// to the subdomain on the upper side (the spatial rule above), or with `closed_planes` to those
// on both sides (extra samples: where primitives on either side both report a root on the
// face, the root keeps the one that one process would, see MpiSampleSource). Returns false if
// the ray does not cross `sub`.
struct RaySegment {
  double t0 = 0.0;
  double t1 = 0.0;
  bool closed_end = true;
};
bool subdomain_segment(const Subdomain& sub, glm::dvec3 o, glm::dvec3 d, RaySegment& segment,
                       bool closed_planes = false);

// Which caster the RayCaster uses for rays parallel to an axis.
enum class CastPath {
  automatic,  // the sources' coherent axis casters (bind_axis) when every source has one
  embree,     // Embree for every ray (the reference the coherent casters are tested against)
};

struct RayCasterOptions {
  CastPath path = CastPath::automatic;
  // Whether hits carry the sources' colour fields (FieldSource::bind_scalar) where they have
  // one.
  bool scalars = true;
};

// The roots of one isovalue of a set of field sources along rays. Two casters behind one
// interface: rays parallel to a coordinate axis (all pixel rays of axis views, and the extra
// samples along them) go to the sources' coherent axis casters when every source has one; every
// other ray goes through an Embree scene of the sources, built on the first such ray. Both give
// the same roots (docs/method.md). Casting is thread-safe and runs on all cores of the current
// TBB arena (limit them with tbb::global_control); results are identical for any number of
// threads. The sources, and the values they read, must stay unchanged while the caster lives.
class RayCaster {
 public:
  // Errors: std::runtime_error with Embree's own message (its device error callback) when Embree
  // cannot create a device or scene; where every source has an axis caster, the first cast of a
  // ray that is not along an axis throws it instead. Whatever a source's bind throws passes on.
  RayCaster(const FieldSource& source, double isovalue, RayCasterOptions options = {});
  // One caster of several sources (e.g. the blocks of one rank); a root that two sources both
  // report (on a face they share) counts once. Throws std::invalid_argument when `sources` is
  // empty; the sources are not owned.
  RayCaster(std::span<const FieldSource* const> sources, double isovalue,
            RayCasterOptions options = {});
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // The LDI of `view`: every root of the field along the ray through each pixel centre,
  // sorted by depth, with roots found twice where primitives touch merged. Throws
  // std::runtime_error when the LDI would hold more than 2³² samples (its offsets are 32-bit).
  Ldi cast(const View& view) const;

  // The part of the LDI of `view` that `sub` owns: only the pixels whose rays cross it, each ray
  // clipped to its segment (subdomain_segment), as a fragment (view index `view_index`). The
  // fragments of subdomains tiling the global box merge into the LDI of the whole box.
  LdiFragment cast_fragment(const View& view, std::uint32_t view_index, const Subdomain& sub) const;

  // All hits along the rays of `view` through the given image positions (pixel units, see
  // View::point), optionally only those `sub` owns and, where `depth_ranges` is not empty, only
  // those with depth in [depth_ranges[k].x, depth_ranges[k].y] for ray k (one range per ray).
  // Used for extra samples between pixel centres (§4) and to put merging's new vertices onto the
  // surface (§5); `closed_planes` as for subdomain_segment. Throws std::invalid_argument when
  // `depth_ranges` is neither empty nor one per ray.
  RayHitList cast_points(const View& view, std::span<const glm::dvec2> image_positions,
                         const Subdomain* sub = nullptr,
                         std::span<const glm::dvec2> depth_ranges = {},
                         bool closed_planes = false) const;

  // Whether every source has a colour field that the hits carry (RayCasterOptions::scalars).
  bool carries_scalars() const;
  // Primitives in the scene (those whose value range may contain the isovalue), all sources.
  std::size_t primitive_count() const;
  // Non-finite values (NaN, ±Inf) the sources read when the scene was built: the sum of their
  // GeometryBinding::nonfinite_values(), so a value that two sources both read (a ghost point)
  // counts once for each. The parts of the field that depend on them produce no hits. 0 for a
  // finite field.
  std::uint64_t nonfinite_values() const;
  // Seconds spent binding the sources: the axis casters, and the Embree scene once it is built.
  double build_seconds() const;
  // Whether rays along `view` go to the coherent axis casters.
  bool uses_axis_casters(const View& view) const;
  // Builds what casting along `view` needs (the axis casters' structures for its axis, or the
  // Embree scene), once; the casts do it themselves. Callers that cast several views at once
  // call it for each first, so that no thread waits on a build from inside a parallel cast.
  void prepare(const View& view) const;

 private:
  // Hits of a run of consecutive rays, appended in ray order.
  struct HitRun {
    std::vector<std::uint32_t> counts;
    std::vector<float> depth;
    std::vector<glm::vec3> normal;
    std::vector<float> scalar;
    void append(std::span<const RayHit> hits, bool with_scalar) {
      counts.push_back(std::uint32_t(hits.size()));
      for (const RayHit& h : hits) {
        depth.push_back(float(h.t));
        normal.push_back(h.normal);
        if (with_scalar) scalar.push_back(h.scalar);
      }
    }
  };

  // Every pixel's ray on the segment `segment_of(position, segment)` gives (none if it returns
  // false), in parallel over blocks of rows (or of columns); runs of consecutive rows in order.
  template <class Segment>
  std::vector<HitRun> cast_rows(const View& view, Segment segment_of) const;
  // The runs of blocks of `per_task` columns as one run per row.
  std::vector<HitRun> rows_from_column_blocks(const View& view, const std::vector<HitRun>& blocks,
                                              int per_task) const;
  // Hits along the ray through `image_position` on its segment `segment`, through Embree.
  void trace(const View& view, glm::dvec2 image_position, const RaySegment& segment,
             std::vector<RayHit>& hits) const;
  // The hits of `rays` (axis-parallel) from the axis casters, one run entry per ray, in order.
  void cast_axis_rays(const AxisRays& rays, std::span<const RaySegment> segments,
                      HitRun& run) const;
  // Sorts a ray's hits (the ray o + t·dir), merges duplicates, moves those its segment owns to
  // the front and gives them the colour field's value (when the sources have one); returns how
  // many.
  std::size_t finish_ray(const RaySegment& segment, glm::dvec3 org, glm::dvec3 dir,
                         std::span<RayHit> hits) const;
  // Builds the Embree scene on first use (thread-safe).
  void ensure_scene() const;
  // Has the axis casters build what rays along `view` need, before the parallel loops.
  void prepare_axis_casters(const View& view) const;

  std::vector<const FieldSource*> sources_;
  double isovalue_ = 0.0;
  std::vector<std::unique_ptr<AxisCaster>> axis_casters_;    // empty: Embree for every ray
  std::vector<std::unique_ptr<ScalarProbe>> scalar_probes_;  // per source, null: no colour field
  bool has_scalar_ = false;  // a source has a colour field: every hit carries its value
  double duplicate_tolerance_ = 0.0;
  double axis_seconds_ = 0.0;

  mutable std::once_flag scene_once_;
  mutable RTCDevice device_ = nullptr;
  mutable RTCScene scene_ = nullptr;
  mutable std::vector<std::unique_ptr<GeometryBinding>> bindings_;
  mutable double scene_seconds_ = 0.0;
};

}  // namespace ldimesh

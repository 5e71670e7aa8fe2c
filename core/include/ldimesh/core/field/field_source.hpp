// What the ray caster intersects: a field whose isosurface is found exactly. Each kind of source
// (analytic functions, grid blocks, high-order elements) splits its domain into primitives with
// bounds and value ranges, puts the primitives whose range may contain the isovalue into an
// Embree scene, and finds *all* roots of one ray inside one primitive in its intersect callback.
// Sources may also offer a coherent caster for rays parallel to an axis (bind_axis), which the
// ray caster prefers for such rays.
//
// Threads and determinism, for every source: a source does not change after construction, bind
// and bind_axis may run on several threads at once, and the roots a binding reports for a ray
// depend on that ray only (not on the thread, the other rays or their order). The solver's
// arrays a source reads must not change while a bind or a cast runs.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/field/axis_caster.hpp"

namespace ldimesh {

// Per-ray state handed to intersect callbacks through Embree's intersect context (the context
// is the first member, so callbacks cast RTCIntersectContext* back to RayQuery*). Callbacks
// append every root with t in [t_min, t_max] that lies in their primitive to `hits`; they never
// shorten the Embree ray, so traversal visits every primitive the ray crosses.
struct RayQuery {
  RTCIntersectContext context;
  glm::dvec3 org{0.0};
  glm::dvec3 dir{0.0};
  double t_min = 0.0;
  double t_max = 0.0;
  std::vector<RayHit>* hits = nullptr;
};

// The Embree geometry of one source bound to one isovalue. Owns the geometry handle and whatever
// per-primitive data its callbacks read; it must outlive every scene it is attached to.
class GeometryBinding {
 public:
  virtual ~GeometryBinding() = default;
  virtual RTCGeometry geometry() const = 0;
  virtual std::size_t primitive_count() const = 0;
  // How many non-finite values (NaN, +Inf, −Inf) of the source's data the bind read, each
  // counted once; what a value is depends on the source (see its bind()). The parts of the
  // field that depend on such a value (a grid cell, an element) produce no hits; the rest are
  // unaffected.
  virtual std::uint64_t nonfinite_values() const { return 0; }
};

// Helpers for intersect callbacks.

// Zero counts as positive, so that a root exactly at the end of one segment and the start of
// the next is reported once, not twice.
inline bool positive(double v) {
  return v >= 0.0;
}

// The point at parameter s ∈ [0, 1] of the stretch [a, b] (a ray's depths, a piece of one): b
// exactly at s = 1, so that a root on a stretch's end keeps the end's exact value (the half-open
// rules compare it).
inline double segment_point(double a, double b, double s) {
  return s == 1.0 ? b : a + s * (b - a);
}

// The unit normal for a gradient at a hit of a ray along `dir`; at singular points (∇f = 0) it
// faces the viewer.
inline glm::vec3 unit_normal(glm::dvec3 grad, glm::dvec3 dir) {
  const double len = glm::length(grad);
  // One division, not three: the casters' hits spend much of their time here.
  return len > 0.0 ? glm::vec3(grad * (1.0 / len)) : glm::vec3(-dir);
}

// Clips the ray o + t·d to the closed box [lo, hi], narrowing [t0, t1]; false if it misses.
inline bool clip_ray_to_box(glm::dvec3 o, glm::dvec3 d, glm::dvec3 lo, glm::dvec3 hi, double& t0,
                            double& t1) {
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    const double inv = 1.0 / d[a];
    double ta = (lo[a] - o[a]) * inv, tb = (hi[a] - o[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 < t1;
}

// Embree bounds of a box, padded so that Embree's float traversal never culls a primitive the
// double-precision ray touches (the callbacks clip exactly).
inline void write_padded_bounds(glm::dvec3 lo, glm::dvec3 hi, RTCBounds* out) {
  const glm::dvec3 pad = 1e-6 * (glm::abs(lo) + glm::abs(hi)) + 1e-12;
  out->lower_x = float(lo.x - pad.x), out->lower_y = float(lo.y - pad.y);
  out->lower_z = float(lo.z - pad.z);
  out->upper_x = float(hi.x + pad.x), out->upper_y = float(hi.y + pad.y);
  out->upper_z = float(hi.z + pad.z);
}

// An Embree user geometry with `count` primitives whose bounds and intersect callbacks receive
// `user` as geometryUserPtr, committed; released on destruction. Declare it after the members
// the callbacks read, so that they exist first. Throws std::runtime_error if Embree fails.
class UserGeometry {
 public:
  UserGeometry(RTCDevice device, std::size_t count, void* user, RTCBoundsFunction bounds,
               RTCIntersectFunctionN intersect)
      : geometry_(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER)) {
    if (!geometry_) throw std::runtime_error("Embree: cannot create user geometry");
    rtcSetGeometryUserPrimitiveCount(geometry_, unsigned(count));
    rtcSetGeometryUserData(geometry_, user);
    rtcSetGeometryBoundsFunction(geometry_, bounds, nullptr);
    rtcSetGeometryIntersectFunction(geometry_, intersect);
    rtcCommitGeometry(geometry_);
  }
  ~UserGeometry() { rtcReleaseGeometry(geometry_); }
  UserGeometry(const UserGeometry&) = delete;
  UserGeometry& operator=(const UserGeometry&) = delete;
  RTCGeometry get() const { return geometry_; }

 private:
  RTCGeometry geometry_;
};

// A new Embree device whose error function keeps Embree's own message of a failure (per thread,
// the last one), so that embree_failure can report what Embree said. Throws
// std::runtime_error when Embree cannot create a device (its message included).
RTCDevice make_embree_device();

// The device's pending error as one line — "Embree: <what> failed: <Embree's message>
// (RTCError <code>)" — and clears it; empty when there is none.
std::string embree_failure(RTCDevice device, const std::string& what);

// A second field of a source, to colour the isosurface by (the solver's other quantity:
// temperature on a density isosurface), as read when it was bound: its value at world points.
// The ray caster gives every hit the value at the hit's position (RayHit::scalar), whichever
// caster found it.
class ScalarProbe {
 public:
  virtual ~ScalarProbe() = default;
  // The field at `p` where the source's domain holds it (closed); NaN elsewhere, and where the
  // value there is not finite. Thread-safe; the same answer for the same point on any thread.
  virtual double at(glm::dvec3 p) const = 0;
  // The same, also for points a little outside the domain (rounding, an element's curved face),
  // from the nearest part of it: what a hit that no source holds exactly takes.
  virtual double near(glm::dvec3 p) const = 0;
};

class FieldSource {
 public:
  virtual ~FieldSource() = default;
  // The domain the source covers; views are laid over it.
  virtual Box bounds() const = 0;
  // A committed Embree user geometry on `device` with the primitives whose value range may
  // contain `isovalue` (possibly none). Thread-safe: a source can be bound several times.
  virtual std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const = 0;
  // The source bound to `isovalue` for rays parallel to an axis (axis_caster.hpp), with the
  // same primitives and the same roots as bind(); null if the source has no such caster (the
  // ray caster then uses bind() for every ray). Thread-safe.
  virtual std::unique_ptr<AxisCaster> bind_axis(double /*isovalue*/) const { return nullptr; }
  // A length below which two hits on one ray count as the same root (hits found twice where
  // primitives touch). Sources with a natural length scale may override.
  virtual double duplicate_tolerance() const { return 1e-9 * bounds().diagonal(); }
  // The source's field to colour by, read now (as bind reads the isovalue's field); null when
  // it has none. Thread-safe.
  virtual std::unique_ptr<ScalarProbe> bind_scalar() const { return nullptr; }
};

}  // namespace ldimesh

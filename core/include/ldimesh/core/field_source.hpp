// What the ray caster intersects: a field whose isosurface is found exactly, through Embree user
// geometry. Each kind of source (analytic functions here; grid blocks and high-order elements
// later) splits its domain into primitives with bounds and value ranges, puts the primitives
// whose range may contain the isovalue into an Embree scene, and finds *all* roots of one ray
// inside one primitive in its intersect callback.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "ldimesh/core/geometry.hpp"

namespace ldimesh {

// One root of the field along a ray.
struct RayHit {
  double t = 0.0;       // distance from the ray origin (the view's depth)
  glm::vec3 normal{};   // unit gradient direction at the hit
  float scalar = 0.0f;  // optional attribute (only meaningful when the source has one)
};

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
  // Whether hits carry a meaningful RayHit::scalar.
  virtual bool has_scalar() const { return false; }
};

class FieldSource {
 public:
  virtual ~FieldSource() = default;
  // The domain the source covers; views are laid over it.
  virtual Box bounds() const = 0;
  // A committed Embree user geometry on `device` with the primitives whose value range may
  // contain `isovalue` (possibly none). Thread-safe: a source can be bound several times.
  virtual std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const = 0;
  // A length below which two hits on one ray count as the same root (hits found twice where
  // primitives touch). Sources with a natural length scale may override.
  virtual double duplicate_tolerance() const { return 1e-9 * bounds().diagonal(); }
};

}  // namespace ldimesh

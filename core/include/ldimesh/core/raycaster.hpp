// Multi-hit ray casting of an isosurface with Embree (paper §3: keep every hit along a ray).
#pragma once

#include <memory>
#include <span>
#include <vector>

#include <embree3/rtcore.h>

#include "ldimesh/core/field_source.hpp"
#include "ldimesh/core/ldi.hpp"
#include "ldimesh/core/view.hpp"

namespace ldimesh {

// Hits of a list of individual rays, in CSR form: the hits of ray k are
// [offsets[k], offsets[k + 1]) of the other arrays, sorted by depth.
struct RayHitList {
  std::vector<std::uint32_t> offsets;
  std::vector<float> depth;
  std::vector<glm::vec3> normal;
  std::vector<float> scalar;  // empty unless the source has a scalar
};

// An Embree scene of one field source at one isovalue. Building it is the only costly part of
// construction; casting is thread-safe and runs on all cores of the current TBB arena (limit
// them with tbb::global_control). Results are identical for any number of threads.
class RayCaster {
 public:
  // Throws std::runtime_error when Embree cannot create a device or scene.
  RayCaster(const FieldSource& source, double isovalue);
  // One scene of several sources (e.g. the blocks of one rank); a root that two sources both
  // report (on a face they share) counts once. `sources` must not be empty.
  RayCaster(std::span<const FieldSource* const> sources, double isovalue);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // The LDI of `view`: every root of the field along the ray through each pixel centre,
  // sorted by depth, with roots found twice where primitives touch merged.
  Ldi cast(const View& view) const;

  // All hits along the rays of `view` through the given image positions (pixel units, see
  // View::point). Used for extra samples between pixel centres.
  RayHitList cast_points(const View& view, std::span<const glm::dvec2> image_positions) const;

  // Primitives in the scene (those whose value range may contain the isovalue), all sources.
  std::size_t primitive_count() const;
  // Seconds spent building the scene.
  double build_seconds() const { return build_seconds_; }

 private:
  void trace(const View& view, glm::dvec2 image_position, std::vector<RayHit>& hits) const;

  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
  std::vector<std::unique_ptr<GeometryBinding>> bindings_;
  bool has_scalar_ = false;
  double duplicate_tolerance_ = 0.0;
  double build_seconds_ = 0.0;
};

}  // namespace ldimesh

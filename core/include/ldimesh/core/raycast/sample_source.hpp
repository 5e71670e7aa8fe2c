// Where refinement (§4 (ii)) gets extra samples and merging (§5) moves new vertices onto the
// surface (projection.hpp): rays through arbitrary image positions of the step's views, all hits
// each within a depth range per ray. One interface, served by the local ray caster in one
// process and by an MPI round trip to the ranks that own the rays in a parallel run. One call is
// one round trip: a refinement pass (or a merging batch) asks for all its samples, of all views,
// in one call.
//
// Threads: one sample() call at a time per source (an MPI source's calls are collective round
// trips); the hits of a call depend on its points only, not on threads or earlier calls.
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {

// A ray of view `view` through image position `position` (pixel units, see View::point), of
// which only the hits with depth in [depth_min, depth_max] are wanted (the whole ray by default).
// Refinement knows where a new sample can match and asks only for that stretch: casting it costs
// a fraction of the whole ray, which crosses every layer of the surface.
struct SamplePoint {
  std::uint32_t view = 0;
  glm::dvec2 position{0.0};
  double depth_min = 0.0;
  double depth_max = INFINITY;
};

class SampleSource {
 public:
  virtual ~SampleSource() = default;
  // All hits along the rays through `points` within their depth ranges, ray k's hits sorted by
  // depth. Throws std::out_of_range for an unknown view.
  virtual RayHitList sample(std::span<const SamplePoint> points) = 0;
};

// The hits of `points` from `caster` (only the parts `sub` owns, when given; `closed_planes` as
// for subdomain_segment): the rays grouped by view, cast with RayCaster::cast_points and
// returned in the order of `points`. Throws std::out_of_range for a view index outside `views`.
RayHitList cast_sample_points(const RayCaster& caster, std::span<const View> views,
                              std::span<const SamplePoint> points, const Subdomain* sub = nullptr,
                              bool closed_planes = false);

// Samples from a ray caster in this process.
class LocalSampleSource final : public SampleSource {
 public:
  // `caster` must outlive this object.
  LocalSampleSource(const RayCaster& caster, std::vector<View> views)
      : caster_(caster), views_(std::move(views)) {}
  RayHitList sample(std::span<const SamplePoint> points) override {
    return cast_sample_points(caster_, views_, points);
  }

 private:
  const RayCaster& caster_;
  std::vector<View> views_;
};

}  // namespace ldimesh

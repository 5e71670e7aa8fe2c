// Where refinement (§4 (ii)) gets extra samples: rays through arbitrary image positions of the
// step's views, all hits each. One interface, served by the local ray caster in one process
// and by an MPI round trip to the ranks that own the rays in a parallel run.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ldimesh/core/raycaster.hpp"

namespace ldimesh {

class SampleSource {
 public:
  virtual ~SampleSource() = default;
  // All hits along the rays of view `view_index` through `image_positions` (pixel units), per
  // ray sorted by depth. Throws std::out_of_range for an unknown view.
  virtual RayHitList sample(std::uint32_t view_index,
                            std::span<const glm::dvec2> image_positions) = 0;
};

// Samples from a ray caster in this process.
class LocalSampleSource final : public SampleSource {
 public:
  // `caster` must outlive this object.
  LocalSampleSource(const RayCaster& caster, std::vector<View> views)
      : caster_(caster), views_(std::move(views)) {}
  RayHitList sample(std::uint32_t view_index,
                    std::span<const glm::dvec2> image_positions) override {
    return caster_.cast_points(views_.at(view_index), image_positions);
  }

 private:
  const RayCaster& caster_;
  std::vector<View> views_;
};

}  // namespace ldimesh

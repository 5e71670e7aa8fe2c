// Small geometric value types shared by the whole core.
#pragma once

#include <glm/glm.hpp>

namespace ldimesh {

// Axis-aligned box, closed: [lo, hi] on each axis.
struct Box {
  glm::dvec3 lo{0.0};
  glm::dvec3 hi{0.0};

  glm::dvec3 extent() const { return hi - lo; }
  glm::dvec3 center() const { return 0.5 * (lo + hi); }
  double diagonal() const { return glm::length(hi - lo); }
  bool is_valid() const { return lo.x < hi.x && lo.y < hi.y && lo.z < hi.z; }
};

}  // namespace ldimesh

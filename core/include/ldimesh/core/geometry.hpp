// Small geometric value types shared by the whole core.
#pragma once

#include <cstddef>
#include <span>

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

// Newell's normal of the polygon p[0], p[1], … (counter-clockwise seen from where it points), not
// normalised: twice its area vector when it is planar, a robust mean normal when it is not.
inline glm::dvec3 newell_normal(std::span<const glm::dvec3> p) {
  glm::dvec3 n(0.0);
  for (std::size_t i = 0; i < p.size(); ++i)
    n += glm::cross(p[i], p[(i + 1) % p.size()]);
  return n;
}

}  // namespace ldimesh

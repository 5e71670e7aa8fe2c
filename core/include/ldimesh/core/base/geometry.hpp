// Small geometric value types shared by the whole core. C++17: the adaptor's public header
// includes it, and solvers' codes (deal.II 9.4's, for one) compile as C++17.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

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

// ⌊x⌋ clamped to [lo, hi] (lo ≤ hi), converting only what an int holds: a double outside int's
// range or NaN (lo for NaN) never reaches the conversion, which would be undefined behaviour.
inline int clamped_floor(double x, int lo, int hi) {
  if (!(x >= double(lo))) return lo;
  if (x >= double(hi)) return hi;
  return int(std::floor(x));
}

// Newell's normal of the polygon p[0], …, p[count − 1] (counter-clockwise seen from where it
// points), not normalised: twice its area vector when it is planar, a robust mean normal when it
// is not.
inline glm::dvec3 newell_normal(const glm::dvec3* p, std::size_t count) {
  glm::dvec3 n(0.0);
  for (std::size_t i = 0; i < count; ++i)
    n += glm::cross(p[i], p[(i + 1) % count]);
  return n;
}

// A cell of a uniform grid (integer coordinates, 21 bits each, wrapping: far cells may share a
// key, which only costs a look) packed into one 64-bit key; the cell of size `cell` holding p.
inline std::uint64_t grid_cell_key(glm::ivec3 c) {
  return (std::uint64_t(std::uint32_t(c.x) & 0x1FFFFF) << 42) |
         (std::uint64_t(std::uint32_t(c.y) & 0x1FFFFF) << 21) |
         std::uint64_t(std::uint32_t(c.z) & 0x1FFFFF);
}
inline glm::ivec3 grid_cell(glm::dvec3 p, double cell) {
  return glm::ivec3(glm::floor(p / cell));
}

// Whether the segment p–q passes through the triangle (a, b, c) strictly inside both (by more
// than eps in the barycentric and segment parameters): touching, sharing an edge or running in
// the triangle's plane do not count. Two triangles pass through each other when an edge of one
// crosses the other.
inline bool segment_crosses_triangle(glm::dvec3 p, glm::dvec3 q, glm::dvec3 a, glm::dvec3 b,
                                     glm::dvec3 c, double eps = 1e-9) {
  const glm::dvec3 d = q - p, e1 = b - a, e2 = c - a, h = glm::cross(d, e2);
  const double det = glm::dot(e1, h);
  if (!(std::abs(det) > 1e-18)) return false;
  const glm::dvec3 s = p - a, sq = glm::cross(s, e1);
  const double u = glm::dot(s, h) / det, v = glm::dot(d, sq) / det, t = glm::dot(e2, sq) / det;
  return u > eps && v > eps && u + v < 1.0 - eps && t > eps && t < 1.0 - eps;
}

}  // namespace ldimesh

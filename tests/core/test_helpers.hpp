// Shared by the core tests: small meshes and LDIs built by hand, geometric checks.
#pragma once

#include <cmath>
#include <optional>

#include <glm/glm.hpp>

#include "ldimesh/core/mesh.hpp"

namespace ldimesh::testing {

// Möller–Trumbore: distance along the ray o + t d to the triangle (a, b, c), if it is hit.
inline std::optional<double> ray_triangle(glm::dvec3 o, glm::dvec3 d, glm::dvec3 a, glm::dvec3 b,
                                          glm::dvec3 c) {
  const glm::dvec3 e1 = b - a, e2 = c - a, p = glm::cross(d, e2);
  const double det = glm::dot(e1, p);
  if (std::abs(det) < 1e-14) return std::nullopt;
  const glm::dvec3 s = o - a;
  const double u = glm::dot(s, p) / det;
  if (u < -1e-9 || u > 1 + 1e-9) return std::nullopt;
  const glm::dvec3 q = glm::cross(s, e1);
  const double v = glm::dot(d, q) / det;
  if (v < -1e-9 || u + v > 1 + 1e-9) return std::nullopt;
  const double t = glm::dot(e2, q) / det;
  if (t < 0) return std::nullopt;
  return t;
}

// Whether the ray o + t d hits a triangle of `mesh` at some t in [t_lo, t_hi].
inline bool ray_hits_mesh(const Mesh& mesh, glm::dvec3 o, glm::dvec3 d, double t_lo, double t_hi) {
  for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
    const std::uint32_t* t = &mesh.triangles[3 * f];
    const auto hit =
        ray_triangle(o, d, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]);
    if (hit && *hit >= t_lo && *hit <= t_hi) return true;
  }
  return false;
}

}  // namespace ldimesh::testing

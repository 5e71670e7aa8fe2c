// Shared by the core tests: small meshes and LDIs built by hand, geometric checks.
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <glm/glm.hpp>

#include <gtest/gtest.h>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/base/view.hpp"
#include "ldimesh/core/raycast/ldi.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh::testing {

// a and b are the same mesh, array by array (positions and normals bit for bit).
inline void expect_identical(const Mesh& a, const Mesh& b) {
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.scalars, b.scalars);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.quads, b.quads);
  EXPECT_EQ(a.triangle_view, b.triangle_view);
  EXPECT_EQ(a.quad_view, b.quad_view);
  EXPECT_EQ(a.view_dirs, b.view_dirs);
}

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

// Where the ray through pixel (i, j) of `view` crosses the sphere of radius R around the
// origin: count 2 with the two depths, or 0; `grazing` when within `margin` of tangency (such
// rays are skipped by tests: a tangent ray may legitimately report 0, 1 or 2 hits).
struct SphereCrossing {
  int count;
  double t0, t1;
  bool grazing;
};
inline SphereCrossing sphere_crossing(const View& view, int i, int j, double R, double margin) {
  const glm::dvec3 o = view.pixel_point(i, j, 0.0);
  const double b = glm::dot(o, view.dir);
  const double dist = std::sqrt(std::max(0.0, glm::dot(o, o) - b * b));
  if (std::abs(dist - R) < margin) return {0, 0, 0, true};
  if (dist > R) return {0, 0, 0, false};
  const double s = std::sqrt(R * R - dist * dist);
  return {2, -b - s, -b + s, false};
}

// Checks that `ldi` holds the hits of the sphere of `radius` around the origin: exactly two on
// every ray through it and none outside (rays within 1e-6 of tangency are skipped), depths
// within `depth_tolerance` of the exact ones, radial unit normals. Stops at the first pixel
// with a wrong hit count. Returns the number of rays through the sphere and outside it.
struct SphereRays {
  int through = 0;
  int outside = 0;
};
inline SphereRays expect_sphere_hits(const Ldi& ldi, double radius, double depth_tolerance) {
  const View& view = ldi.view;
  SphereRays rays;
  for (int j = 0; j < view.height; ++j)
    for (int i = 0; i < view.width; ++i) {
      const std::size_t p = std::size_t(j) * view.width + i;
      const SphereCrossing c = sphere_crossing(view, i, j, radius, 1e-6);
      if (c.grazing) continue;
      if (ldi.count(p) != std::uint32_t(c.count)) {
        ADD_FAILURE() << "pixel " << i << "," << j << ": " << ldi.count(p) << " hits, expected "
                      << c.count;
        return rays;
      }
      if (c.count == 0) {
        ++rays.outside;
        continue;
      }
      ++rays.through;
      const double t[2] = {c.t0, c.t1};
      for (int h = 0; h < 2; ++h) {
        const std::uint32_t s = ldi.begin(p) + h;
        EXPECT_NEAR(ldi.depth[s], t[h], depth_tolerance);
        const glm::dvec3 q = view.pixel_point(i, j, ldi.depth[s]);
        EXPECT_NEAR(glm::length(glm::dvec3(ldi.normal[s]) - glm::normalize(q)), 0.0, 1e-4);
      }
    }
  return rays;
}

// The three axis views of `box` plus one oblique view, at `res`.
inline std::vector<View> axis_and_oblique_views(const Box& box, int res) {
  std::vector<View> views = make_axis_views(box, res, "xyz");
  views.push_back(make_view(box, {0.3, -0.5, 0.8}, res));
  return views;
}

// Casts `views` with both casters and expects the same LDIs, bit for bit: offsets, depths,
// normals and colours (NaN equal to NaN). Returns the samples compared.
inline std::size_t expect_same_casts(const RayCaster& a, const RayCaster& b,
                                     const std::vector<View>& views) {
  std::size_t samples = 0;
  for (const View& view : views) {
    const Ldi la = a.cast(view), lb = b.cast(view);
    EXPECT_EQ(la.offsets, lb.offsets);
    EXPECT_EQ(la.scalar.size(), lb.scalar.size());
    if (la.offsets != lb.offsets || la.scalar.size() != lb.scalar.size()) return samples;
    for (std::size_t s = 0; s < la.sample_count(); ++s) {
      const bool same_scalar = la.scalar.empty() || std::bit_cast<std::uint32_t>(la.scalar[s]) ==
                                                        std::bit_cast<std::uint32_t>(lb.scalar[s]);
      if (la.depth[s] != lb.depth[s] || la.normal[s] != lb.normal[s] || !same_scalar) {
        ADD_FAILURE() << "sample " << s << " differs";
        return samples;
      }
    }
    samples += la.sample_count();
  }
  return samples;
}

}  // namespace ldimesh::testing

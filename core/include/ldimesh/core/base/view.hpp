// Orthographic views over a domain box (paper §3: parallel projection).
#pragma once

#include <span>
#include <string_view>
#include <vector>

#include "ldimesh/core/base/geometry.hpp"

namespace ldimesh {

// An orthographic camera: rays travel along `dir` through the centres of a width × height pixel
// grid that covers the projection of the domain box. Image axes u, v and dir form a right-handed
// orthonormal frame (u × v = dir). Image position (x, y) is in pixel units; pixel (i, j) has its
// centre at (i + 0.5, j + 0.5). Depth is the distance along dir from the plane through `origin`,
// which touches the domain box on the side the rays come from, so every depth in the domain
// lies in [0, depth_extent].
struct View {
  glm::dvec3 dir{0.0, 0.0, 1.0};
  glm::dvec3 u{1.0, 0.0, 0.0};
  glm::dvec3 v{0.0, 1.0, 0.0};
  glm::dvec3 origin{0.0};  // world position of image position (0, 0) at depth 0
  double spacing = 1.0;    // pixel size in world units, the same along u and v
  int width = 0;
  int height = 0;
  double depth_extent = 0.0;

  std::size_t pixel_count() const { return std::size_t(width) * std::size_t(height); }

  // World position of image position (x, y) (pixel units) at `depth`.
  glm::dvec3 point(double x, double y, double depth) const {
    return origin + (x * spacing) * u + (y * spacing) * v + depth * dir;
  }
  // World position of the centre of pixel (i, j) at `depth`.
  glm::dvec3 pixel_point(int i, int j, double depth) const {
    return point(i + 0.5, j + 0.5, depth);
  }
};

// A view of `domain` along `direction` (any non-zero vector; it is normalised) whose longer image
// side has `resolution` pixels. Axis directions get the axis frames x: (u, v) = (y, z),
// y: (z, x), z: (x, y); other directions get u perpendicular to the axis least aligned with them.
// Throws std::invalid_argument for a zero direction, a resolution below 1 or an empty box.
View make_view(const Box& domain, glm::dvec3 direction, int resolution);

// Views along the axes named in `axes` (letters x, y, z, each at most once, e.g. "xyz" or "xz").
// Throws std::invalid_argument for any other letter or a repeated one.
std::vector<View> make_axis_views(const Box& domain, int resolution, std::string_view axes = "xyz");

}  // namespace ldimesh

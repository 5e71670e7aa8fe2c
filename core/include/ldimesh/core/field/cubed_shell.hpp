// A curved, unstructured hexahedral mesh to try the element sources on: the spherical shell
// r0 ≤ |x| ≤ r1 as a cubed sphere (the six faces of the cube [−1, 1]³, each split into n × n
// patches, projected onto spheres, `layers` elements through the shell's thickness). Three
// elements, not four, share the radial edges at the cube's corners and neighbouring faces meet
// at an angle, as in a solver's unstructured mesh; the mini-app ldimesh-dg (--mesh shell), the
// benchmarks and the tests use it.
#pragma once

#include <cstddef>

#include <glm/glm.hpp>

namespace ldimesh {

struct CubedShell {
  int n = 1;       // elements per cube face edge
  int layers = 1;  // elements through the thickness
  double r0 = 0.5, r1 = 1.0;

  std::size_t element_count() const { return std::size_t(6) * n * n * layers; }

  // The point at reference coordinates xi ∈ [0, 1]³ of element e. Elements are numbered face
  // after face (+x, −x, +y, −y, +z, −z), on a face row after row of patches, layer after layer
  // outwards; ξ and η run along the face (the axes after the face's normal axis, cyclically), ζ
  // outwards.
  glm::dvec3 point(std::size_t e, glm::dvec3 xi) const {
    const std::size_t per_face = std::size_t(n) * n * layers;
    const std::size_t face = e / per_face, rest = e % per_face;
    const int a = int(face / 2);
    glm::dvec3 c;
    c[a] = face % 2 ? -1.0 : 1.0;
    c[(a + 1) % 3] = -1.0 + 2.0 * (double(rest % n) + xi.x) / n;
    c[(a + 2) % 3] = -1.0 + 2.0 * (double(rest / n % n) + xi.y) / n;
    const double w = (double(rest / n / n) + xi.z) / layers;
    return (r0 + (r1 - r0) * w) * glm::normalize(c);
  }
};

}  // namespace ldimesh

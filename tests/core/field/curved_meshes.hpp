// Curved hexahedral meshes for the tests of the curved search and of the field lookup: a
// distorted box and a cubed-sphere shell, with a field sampled through each element's own
// geometry polynomial.
#pragma once

#include <cmath>
#include <cstddef>
#include <numbers>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/field/cubed_shell.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh::test {

inline constexpr double kPi = std::numbers::pi;
inline const Box kBox{{-0.5, -0.25, 0.0}, {0.5, 0.5, 0.75}};

// A smooth map of kBox onto itself that fixes its boundary (its faces stay planar): the mesh of
// distorted elements fills the box exactly.
inline glm::dvec3 distort(glm::dvec3 x, double amount) {
  const glm::dvec3 u = (x - kBox.lo) / (kBox.hi - kBox.lo);
  const double bump = std::sin(kPi * u.x) * std::sin(kPi * u.y) * std::sin(kPi * u.z);
  const glm::dvec3 wave(std::sin(2.0 * kPi * u.y + 0.3), std::cos(2.0 * kPi * u.z),
                        std::sin(2.0 * kPi * u.x + 1.1));
  return x + amount * bump * wave * (kBox.hi - kBox.lo);
}

// An n³ mesh of kBox, distorted, with geometry nodes of order q (node set `nodes`) and the
// field `field(x)` at the field's nodes of order p, their world positions taken through the
// element's own geometry polynomial (the source's to_world), so that a field the element
// represents exactly stays exact.
struct CurvedMesh {
  std::vector<double> geometry, values;
  HexBlock block;
};

// Elements whose geometry node (i, j, k) is point(e, ξ) at the node set's positions ξ, with the
// field `field(x)` at the field's nodes of order p taken through the element's own geometry
// polynomial (the source's to_world), so that a field the element represents exactly stays
// exact.
template <class Point, class Field>
CurvedMesh mesh_of(std::size_t elements, int p, int q, NodeSet nodes, Point point, Field field) {
  CurvedMesh m;
  const std::vector<double> xq = node_positions(q, nodes);
  for (std::size_t e = 0; e < elements; ++e)
    for (int k = 0; k <= q; ++k)
      for (int j = 0; j <= q; ++j)
        for (int i = 0; i <= q; ++i) {
          const glm::dvec3 x = point(e, glm::dvec3(xq[i], xq[j], xq[k]));
          m.geometry.insert(m.geometry.end(), {x.x, x.y, x.z});
        }
  m.block.order = p;
  m.block.nodes = nodes;
  m.block.element_count = elements;
  m.block.geometry_order = q;
  m.block.geometry = m.geometry.data();
  m.values.assign(m.block.element_count * (p + 1) * (p + 1) * (p + 1), 0.0);
  m.block.values = m.values.data();
  const HexElementSource geometry(m.block);
  const std::vector<double> xp = node_positions(p, nodes);
  std::size_t v = 0;
  for (std::size_t e = 0; e < m.block.element_count; ++e)
    for (int k = 0; k <= p; ++k)
      for (int j = 0; j <= p; ++j)
        for (int i = 0; i <= p; ++i)
          m.values[v++] = field(geometry.to_world(e, {xp[i], xp[j], xp[k]}));
  return m;
}

template <class Field>
CurvedMesh curved_mesh(int n, int p, int q, NodeSet nodes, double amount, Field field) {
  const glm::dvec3 size = (kBox.hi - kBox.lo) / double(n);
  return mesh_of(
      std::size_t(n) * n * n, p, q, nodes,
      [&](std::size_t e, glm::dvec3 xi) {
        const glm::dvec3 cell(double(e % n), double(e / n % n), double(e / n / n));
        return distort(kBox.lo + size * (cell + xi), amount);
      },
      field);
}

// A spherical shell r0 ≤ |x| ≤ r1 as a cubed sphere: 6 patches of n × n elements across and
// `layers` elements along the radius, each geometry node on the sphere of its radius (a curved,
// unstructured mesh: the patches meet at an angle, eight elements share each cube corner).
template <class Field>
CurvedMesh shell_mesh(int n, int layers, int p, int q, NodeSet nodes, double r0, double r1,
                      Field field) {
  return mesh_of(
      std::size_t(6) * n * n * layers, p, q, nodes,
      [shell = CubedShell{n, layers, r0, r1}](std::size_t e, glm::dvec3 xi) {
        return shell.point(e, xi);
      },
      field);
}

}  // namespace ldimesh::test

// The reference cells of CellElementSource (cell_source.hpp): each type's nodes in VTK's order,
// its nodal basis, and the split of its reference domain into sub-hexahedra. Internal.
#pragma once

#include <cstddef>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/field/cell_source.hpp"

namespace ldimesh::cells {

struct ReferenceCell {
  CellType type = CellType::tetrahedron;
  int order = 1;
  int degree = 1;         // of the cell's polynomials per axis on each sub-hexahedron
  int sub_hexahedra = 1;  // per cell
  bool top_collapsed = false;
  std::vector<glm::dvec3> nodes;  // reference coordinates, node order
  // The nodal basis: φ_i(r) = Σ_j g_j(r) · inverse[j·N + i], g the space's own basis (Bernstein
  // polynomials, or the nodal functions themselves where inverse is empty).
  std::vector<double> inverse;
  // Tetrahedra: N × N, the field's Bernstein–Bézier coefficients on the tetrahedron from its
  // nodal values (c_j = Σ_i to_bernstein[j·N + i] · f_i), which bound it (convex hull).
  std::vector<double> to_bernstein;
  // Per sub-hexahedron: (degree + 1)³ rows (ξ fastest) × N: the nodal basis at its equispaced
  // lattice.
  std::vector<double> sampling;
};

// The reference cell of (type, order), built once (thread-safe). Throws std::invalid_argument
// for an unknown type or an order the type does not have.
const ReferenceCell& reference_cell(CellType type, int order);

// The nodal basis at reference point r (N values).
void shape_functions(const ReferenceCell& cell, glm::dvec3 r, double* out);

// The reference point of sub-hexahedron k's point u ∈ [0, 1]³ (its trilinear map).
glm::dvec3 sub_hexahedron_point(const ReferenceCell& cell, int k, glm::dvec3 u);

}  // namespace ldimesh::cells

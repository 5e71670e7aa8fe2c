// Finite elements of every shape a DG/FEM solver writes — hexahedra, tetrahedra, wedges
// (triangular prisms) and pyramids, of order 1–8 — as ray-caster sources.
//
// Each cell is split in its reference domain into sub-hexahedra (a tetrahedron into 4, one per
// vertex; a wedge into 3, one per vertex of its triangle, times its height; a hexahedron and a
// pyramid are their own — a pyramid's reference cube has its top face collapsed to the apex), and
// the field and the geometry are sampled on each sub-hexahedron's equispaced lattice. A cell's
// polynomial composed with the trilinear map of a sub-hexahedron is a tensor-product polynomial of
// the cell's degree per axis, so the sub-hexahedra carry exactly the cell's polynomial and
// geometry: HexElementSource intersects them (Bernstein bounds, root isolation, the curved search:
// hex_source.hpp), and every hit lies on the cell's own isosurface. docs/method.md ("Cells of
// every shape").
//
// The reference domains and node orders are VTK's (its parametric coordinates, vtkCell::
// GetParametricCoords): the hexahedron [0, 1]³; the tetrahedron r, s, t ≥ 0, r + s + t ≤ 1; the
// wedge r, s ≥ 0, r + s ≤ 1 times t ∈ [0, 1]; the pyramid (r, s, t) ∈ [0, 1]³, base r, s at t = 0,
// its apex t = 1.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/scalar_type.hpp"
#include "ldimesh/core/field/field_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {

// A cell's shape, polynomial space and node order (VTK's numbering in each case).
enum class CellType : std::uint8_t {
  // Q_p (p + 1)³ nodes in VTK_LAGRANGE_HEXAHEDRON's order (vtk_lagrange_index): VTK_HEXAHEDRON
  // is p = 1, VTK_TRIQUADRATIC_HEXAHEDRON p = 2.
  hexahedron,
  // The 20-node serendipity hexahedron, VTK_QUADRATIC_HEXAHEDRON (p = 2; its space lies in Q₂):
  // corners, then edge midpoints.
  serendipity_hexahedron,
  // P_p, (p + 1)(p + 2)(p + 3)/6 nodes in VTK_LAGRANGE_TETRAHEDRON's order: VTK_TETRA is p = 1,
  // VTK_QUADRATIC_TETRA p = 2.
  tetrahedron,
  // P_p(triangle) ⊗ P_p(height), (p + 1)²(p + 2)/2 nodes in VTK_LAGRANGE_WEDGE's order:
  // VTK_WEDGE is p = 1, VTK_BIQUADRATIC_QUADRATIC_WEDGE p = 2.
  wedge,
  // The 15-node wedge, VTK_QUADRATIC_WEDGE (p = 2): vertices, then edge midpoints.
  serendipity_wedge,
  // VTK_PYRAMID (p = 1, 5 nodes) and VTK_QUADRATIC_PYRAMID (p = 2, 13 nodes: vertices, then edge
  // midpoints), with VTK's own shape functions (polynomials in r, s, t of degree p per variable).
  pyramid,
};

// Nodes per cell of `type` and order `order`, or 0 where the type has no such order (no
// exception: for readers that check what they are given).
inline std::size_t cell_nodes(CellType type, int order) {
  const std::size_t p = std::size_t(order);
  const bool lagrange = order >= 1 && order <= 8;
  switch (type) {
    case CellType::hexahedron:
      return lagrange ? (p + 1) * (p + 1) * (p + 1) : 0;
    case CellType::tetrahedron:
      return lagrange ? (p + 1) * (p + 2) * (p + 3) / 6 : 0;
    case CellType::wedge:
      return lagrange ? (p + 1) * (p + 1) * (p + 2) / 2 : 0;
    case CellType::serendipity_hexahedron:
      return order == 2 ? 20 : 0;
    case CellType::serendipity_wedge:
      return order == 2 ? 15 : 0;
    case CellType::pyramid:
      return order == 1 ? 5 : order == 2 ? 13 : 0;
  }
  return 0;
}

// A name for messages ("tetrahedron").
const char* cell_type_name(CellType type);
// The highest order a type has (8 for the Lagrange families, 2 for the serendipity ones and the
// pyramid).
int max_cell_order(CellType type);
// Nodes per cell of `type` and order `order`; throws std::invalid_argument for an order the type
// does not have (1..max_cell_order; the serendipity types only 2).
std::size_t cell_node_count(CellType type, int order);
// The nodes' reference (VTK parametric) coordinates, in the type's node order; throws as
// cell_node_count.
std::vector<glm::dvec3> cell_reference_nodes(CellType type, int order);
// The values at `reference` of the cell's nodal basis (Lagrange) functions, one per node in the
// node order: the cell's field there is Σ values[i] · nodal[i]. Throws as cell_node_count.
std::vector<double> cell_shape_functions(CellType type, int order, glm::dvec3 reference);

// One block of cells of one type and order, described by pointers into the caller's arrays.
// Geometry and field have the same nodes (isoparametric, as files and most solvers give them):
// cell e's node i sits at points[3·(e·node_count + i) + (0, 1, 2)] and has value
// values[e·element_stride + i].
struct CellBlock {
  CellType type = CellType::tetrahedron;
  int order = 1;
  std::size_t element_count = 0;
  const double* points = nullptr;  // node_count × (x, y, z) per cell
  const void* values = nullptr;    // node_count values per cell (element_stride apart)
  ScalarType value_type = ScalarType::float64;
  std::size_t element_stride = 0;  // in values; 0 means the node count
  // Optional: a second field in the layout of `values` to colour the isosurface by.
  const void* colour = nullptr;
  ScalarType colour_type = ScalarType::float64;
};

// A block of cells as a ray-caster source: the cells' sub-hexahedra (see the top of this file)
// through HexElementSource. Hits are exact roots of each cell's polynomial on its isosurface; a
// root on a face two sub-hexahedra or two cells share is found by both and merged by the caster.
class CellElementSource final : public FieldSource {
 public:
  // Checks the block and prepares the sub-hexahedra's geometry. Throws std::invalid_argument for
  // an unknown type or scalar type, an order the type does not have, no cells, a null array, an
  // element stride below the node count, and for the first cell (named by its index in the
  // block) with a non-finite point or that is inverted or degenerate (the Jacobian determinant
  // of its map vanishes or changes sign inside it; a pyramid's vanishes at its apex only).
  // The points are read here only; the value arrays must outlive the source and may change:
  // every bind() reads them.
  explicit CellElementSource(const CellBlock& block);

  Box bounds() const override;
  std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const override;
  std::unique_ptr<AxisBinding> bind_axis(double isovalue) const override;
  std::unique_ptr<ScalarProbe> bind_scalar() const override;

  const CellBlock& block() const { return block_; }
  // Sub-hexahedra per cell (4, 3 or 1) and their degree per axis.
  int sub_hexahedra_per_cell() const { return sub_per_cell_; }

  // The sub-hexahedra with the field as it is now (read and converted by this call), for point
  // lookups (HexFieldLookup): sub-hexahedron k·sub_hexahedra_per_cell() + j belongs to cell k.
  struct Snapshot {
    std::vector<double> values, colour;
    std::unique_ptr<HexElementSource> source;
  };
  std::shared_ptr<const Snapshot> snapshot() const;

 private:
  // A snapshot (the colour field too when `colour`) and the non-finite nodal values it read.
  struct Counted;
  Counted convert(bool colour) const;

  CellBlock block_;
  std::size_t nodes_ = 0;
  int sub_per_cell_ = 1;
  int degree_ = 1;  // per axis on a sub-hexahedron
  // Per sub-hexahedron: (degree + 1)³ rows × nodes: the sub-hexahedron's equispaced lattice
  // values from the cell's nodal values.
  std::shared_ptr<const std::vector<double>> sampling_;
  std::vector<double> geometry_;  // the sub-hexahedra's lattice points (constructor only)
  std::unique_ptr<HexElementSource> prepared_;  // the geometry, prepared once
};

}  // namespace ldimesh

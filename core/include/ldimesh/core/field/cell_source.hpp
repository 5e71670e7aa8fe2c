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
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/scalar_type.hpp"
#include "ldimesh/core/field/field_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {
namespace cells {
struct LinearTet;     // linear_tets.hpp (internal)
struct StraightTets;  // straight_tets.hpp (internal)
}  // namespace cells

// The highest order a type has (8 for the Lagrange families, 2 for the serendipity ones and the
// pyramid).
int max_cell_order(CellType type);
// Nodes per cell of `type` and order `order`; throws std::invalid_argument for an order the type
// does not have (1..max_cell_order; the serendipity types only 2).
std::size_t cell_node_count(CellType type, int order);
// gmsh's numbering of the cells of `type` and `order` (CellNodeOrder::gmsh): VTK's node i is
// gmsh's node permutation[i]. Empty where gmsh's order is not taken for that type and order.
std::vector<int> cell_gmsh_permutation(CellType type, int order);

// The values at `reference` of the cell's nodal basis (Lagrange) functions, one per node in the
// node order: the cell's field there is Σ values[i] · nodal[i]. Throws as cell_node_count.
std::vector<double> cell_shape_functions(CellType type, int order, glm::dvec3 reference);

// A block of cells as a ray-caster source: the cells' sub-hexahedra (see the top of this file)
// through HexElementSource. Hits are exact roots of each cell's polynomial on its isosurface; a
// root on a face two sub-hexahedra or two cells share is found by both and merged by the caster.
class CellElementSource final : public FieldSource {
 public:
  // Checks the block and prepares the sub-hexahedra's geometry. Throws std::invalid_argument for
  // an unknown type or scalar type, an order (or geometry order) the type does not have, no
  // cells, a null array, an element stride below the node count, and for the first cell (named
  // by its index in the block) with a non-finite point or that is inverted or degenerate (the
  // Jacobian determinant of its map vanishes or changes sign inside it; a pyramid's vanishes at its
  // apex only). The points are read here only; the value arrays must outlive the source and may
  // change: every bind() reads them.
  explicit CellElementSource(const CellBlock& block);
  // A source over `block`, whose geometry is that of `prepared`'s block, with its own values (the
  // adaptor's snapshot of a block at each due step): the prepared sub-hexahedra are shared, not
  // built again; `block`'s points are not read (they may be null), only its layout. Throws
  // std::invalid_argument where the type, order, geometry order, node order or cell count differ,
  // for a null value array, an unknown scalar type or an element stride below the node count.
  CellElementSource(const CellElementSource& prepared, const CellBlock& block);

  Box bounds() const override;
  // Whether the cells are tetrahedra of order ≥ 2 with straight sides (geometry order 1, or
  // every node where the affine map of the vertices puts it, to float32 rounding), cast
  // directly (the field along a ray a polynomial of degree p on the ray's exact segment in the
  // tetrahedron) instead of as 4 curved sub-hexahedra each.
  bool straight_tetrahedra() const { return geometry_->straight; }
  std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const override;
  std::unique_ptr<AxisCaster> bind_axis(double isovalue) const override;
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
  void check_values(const std::string& what);
  // A snapshot (the colour field too when `colour`) and the non-finite nodal values it read.
  struct Counted;
  Counted convert(bool colour) const;

  CellBlock block_;
  std::size_t nodes_ = 0;
  int sub_per_cell_ = 1;
  int degree_ = 1;         // per axis on a sub-hexahedron
  std::vector<int> from_;  // VTK's node i is the block's node from_[i] within a cell
  // The geometry's cell (the field's unless block.geometry_order says otherwise): its type and
  // order, node count, degree per axis on a sub-hexahedron, and node order as from_.
  CellType geometry_type_ = CellType::tetrahedron;
  int geometry_order_ = 1;
  std::size_t geometry_nodes_ = 0;
  int geometry_degree_ = 1;
  std::vector<int> geometry_from_;
  // Per sub-hexahedron: (degree + 1)³ rows × nodes: the sub-hexahedron's equispaced lattice
  // values from the cell's nodal values.
  // The geometry as prepared, shared by the sources made from one another: the sub-hexahedra
  // (for linear tetrahedra only when first needed: a lookup, a colour field), the linear
  // tetrahedra's vertices (12 per cell, VTK's order; empty for other cells), the bounds.
  struct Geometry {
    std::once_flag once;
    std::shared_ptr<const HexElementSource> sub_hexahedra;
    std::string failure;  // a lazy build's refusal, given again without building again
    std::vector<double> tets;
    bool straight = false;  // tetrahedra of order ≥ 2 with straight sides: `tets` their vertices
    Box bounds;
  };
  std::shared_ptr<Geometry> geometry_;
  std::shared_ptr<const HexElementSource> build_sub_hexahedra(const double* points,
                                                              const std::vector<int>& from) const;
  const HexElementSource& sub_hexahedra() const;
  std::vector<cells::LinearTet> active_tets(double isovalue, std::uint64_t& nonfinite) const;
  cells::StraightTets active_straight_tets(double isovalue) const;
  // Whether every cell's geometry nodes (`points`, the geometry's order) lie where the affine
  // map of its 4 vertices puts them; if so, the vertices into geometry_->tets.
  bool take_straight_tetrahedra(const double* points);
};

}  // namespace ldimesh

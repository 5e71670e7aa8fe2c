// The solver-side descriptions of rank-local data blocks: pointers into the solver's own arrays
// and their layout. What the adaptor's API takes; GridSource, HexElementSource and
// CellElementSource (grid_source.hpp, hex_source.hpp, cell_source.hpp) cast them. Needs neither
// Embree nor TBB.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/scalar_type.hpp"

namespace ldimesh {

// One rank-local block of point data. Nothing is copied: `values` (and `coords` for a
// rectilinear grid) must stay valid, and unchanged during a cast, while a source built on
// them is used.
//
// Ghost layers: the first ghost_lo[a] and last ghost_hi[a] point layers along axis a belong to
// neighbouring blocks. A cell produces hits only if this block owns its lowest corner point,
// so ghost points are read for interpolation of the cells between the last owned point and
// the first ghost point, and blocks whose owned points tile a grid produce every cell exactly
// once: no duplicate and no missing surface where blocks meet. Blocks that instead share
// their interface points (no ghosts) tile it as well. The hits' normals (central differences
// at the cells' corners) read one point beyond them: a block with a ghost layer below and a
// second one above where a neighbour is (ghost_lo ≥ 1, ghost_hi ≥ 2) gets the normals one whole
// block would; with fewer, they are one-sided on those faces.
struct GridBlock {
  std::array<std::int64_t, 3> dims{{0, 0, 0}};  // points per axis, ghost layers included
  const void* values = nullptr;
  ScalarType type = ScalarType::float32;
  // Distance in values between neighbouring points along x, y, z; {0, 0, 0} means contiguous
  // with x fastest: {1, nx, nx·ny}.
  std::array<std::int64_t, 3> strides{{0, 0, 0}};
  // Uniform geometry: point (i, j, k) at origin + (i, j, k)·spacing (ghost points included).
  glm::dvec3 origin{0.0};
  glm::dvec3 spacing{1.0};
  // Rectilinear geometry, used instead when all three are set: dims[a] strictly increasing
  // coordinates per axis.
  std::array<const double*, 3> coords{{nullptr, nullptr, nullptr}};
  std::array<int, 3> ghost_lo{{0, 0, 0}};
  std::array<int, 3> ghost_hi{{0, 0, 0}};
  // Optional: a second point field in the layout of `values` (the same dims and strides, ghosts
  // included) to colour the isosurface by; hits carry its trilinear interpolant at the hit
  // (FieldSource::bind_scalar). Null: none. Read in place like `values`.
  const void* colour = nullptr;
  ScalarType colour_type = ScalarType::float32;
};

// Where an element's p + 1 nodes per axis lie.
enum class NodeSet {
  gauss_lobatto_legendre,  // both ends and the roots of P'_p (spectral elements, Nek5000)
  gauss_legendre,          // the roots of P_{p+1}, no ends (DG codes such as FLEXI)
  equispaced,              // evenly spaced, both ends (Lagrange finite elements)
};

inline constexpr int kMaxHexOrder = 8;

// Where an element's nodes lie in the solver's arrays.
enum class NodeOrdering {
  lexicographic,  // node (i, j, k) is the i + (n + 1)·(j + (n + 1)·k)-th: ξ fastest
  vtk_lagrange,   // VTK_LAGRANGE_HEXAHEDRON's: corners, edges, faces, interior (vtk_lagrange_index)
};

// One block of hexahedral elements of one polynomial order and node set, described by pointers
// into the solver's own arrays (nothing is copied).
struct HexBlock {
  int order = 0;  // polynomial degree p per axis, 1..kMaxHexOrder
  NodeSet nodes = NodeSet::gauss_lobatto_legendre;
  std::size_t element_count = 0;
  // 8 corners × (x, y, z) per element, element after element. Corner c sits at reference
  // coordinates (c & 1, (c >> 1) & 1, (c >> 2) & 1) along ξ, η, ζ. The element is the
  // trilinear map of its corners (affine where they form a parallelepiped). Not read when
  // geometry_order > 0.
  const double* corners = nullptr;
  // (p + 1)³ nodal values per element; node (i, j, k) (along ξ, η, ζ) is value
  // i + (p + 1)·(j + (p + 1)·k) of its element, and element e starts at value e·element_stride.
  const void* values = nullptr;
  ScalarType type = ScalarType::float64;
  std::size_t element_stride = 0;  // in values, not bytes; 0 means (p + 1)³
  // Curved elements: geometry of its own order q = geometry_order (1..kMaxHexOrder, independent
  // of the field's order), given by (q + 1)³ nodes × (x, y, z) per element at the nodes of
  // `nodes` for order q, node (i, j, k) the i + (q + 1)·(j + (q + 1)·k)-th of its element,
  // element after element. 0: the corners describe the elements.
  int geometry_order = 0;
  const double* geometry = nullptr;
  // The order of the nodal values and of the geometry nodes within an element (not of the
  // corners, whose order is the one above).
  NodeOrdering ordering = NodeOrdering::lexicographic;
  // Optional: a second field's nodal values in the layout of `values` (the same nodes, order
  // and element_stride) to colour the isosurface by; hits carry its polynomial's value at the
  // hit (FieldSource::bind_scalar). Null: none. Read in place like `values`.
  const void* colour = nullptr;
  ScalarType colour_type = ScalarType::float64;
};

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
  // gmsh's 14-node pyramid (MSH_PYR_14, p = 2): VTK_QUADRATIC_PYRAMID's 13 nodes, then the base's
  // centre (VTK has no such cell), with gmsh's complete quadratic pyramid space (Bergot's: P₂
  // and xy/(1 − z)·{1, x, y}, (xy/(1 − z))², in gmsh's coordinates).
  pyramid14,
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
    case CellType::pyramid14:
      return order == 2 ? 14 : 0;
  }
  return 0;
}

// The shape of the geometry's cell for cells of `type` and order `order` whose points are of
// geometry order `geometry_order` (CellBlock::geometry_order; 0: the field's): the same shape,
// except that the 20-node hexahedron, the 15-node wedge and the 14-node pyramid at another
// order are the Lagrange hexahedron and wedge and VTK's pyramid of that order.
inline CellType cell_geometry_type(CellType type, int order, int geometry_order) {
  if (geometry_order == 0 || geometry_order == order) return type;
  if (type == CellType::serendipity_hexahedron) return CellType::hexahedron;
  if (type == CellType::serendipity_wedge) return CellType::wedge;
  if (type == CellType::pyramid14) return CellType::pyramid;
  return type;
}

// Points per cell of such cells, or 0 where the geometry order is not one the shape has.
inline std::size_t cell_geometry_nodes(CellType type, int order, int geometry_order) {
  if (geometry_order < 0) return 0;
  return cell_nodes(cell_geometry_type(type, order, geometry_order),
                    geometry_order == 0 ? order : geometry_order);
}

// A name for messages ("tetrahedron"; defined in the core library, as cell_source.hpp's
// functions).
const char* cell_type_name(CellType type);
// The nodes' reference (VTK parametric) coordinates, in the type's node order: where a solver
// evaluates its cell's geometry and field to fill a CellBlock. Throws std::invalid_argument for
// an order the type does not have.
std::vector<glm::dvec3> cell_reference_nodes(CellType type, int order);

// Where a cell's nodes lie in the caller's arrays: VTK's numbering (every type and order), or
// gmsh's (its tetrahedra and hexahedra of order 1–8, 20-node hexahedra, prisms of 6, 15 and 18
// nodes, pyramids of 5, 13 and 14 nodes; a 13-node pyramid has VTK's shape functions either
// way).
enum class CellNodeOrder : std::uint8_t { vtk, gmsh };

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
  // The order of the nodes within a cell, for the points and the values alike.
  CellNodeOrder node_order = CellNodeOrder::vtk;
  // The points' own order q: 0 (default) means the field's (isoparametric: a point per value);
  // otherwise the cells' geometry is the cell of the same shape and order q (1: straight sides),
  // `points` holding its nodes (cell_geometry_nodes(type, order, q) per cell; for the 20-node
  // hexahedron, the 15-node wedge and the 14-node pyramid, q = 1 is the linear hexahedron's,
  // wedge's or pyramid's 8, 6 or 5 corners).
  int geometry_order = 0;
};

}  // namespace ldimesh

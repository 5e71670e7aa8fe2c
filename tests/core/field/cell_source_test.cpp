// Cells of every shape (tetrahedra, wedges, pyramids, serendipity and Lagrange hexahedra) as
// ray-caster sources: exact isosurfaces, all hits, errors.
#include <cmath>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ldimesh/core/base/view.hpp"
#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

#include "../test_helpers.hpp"
#include "field/cells/reference_cells.hpp"  // the nodal bases without a lookup per call (internal)

namespace ldimesh {
namespace {

using Field = std::function<double(glm::dvec3)>;

// Cells of one type and order with their points and values.
struct Cells {
  CellType type = CellType::tetrahedron;
  int order = 1;
  int geometry_order = 0;
  std::vector<double> points, values;
  std::size_t count = 0;
  CellBlock block() const {
    CellBlock b;
    b.type = type;
    b.order = order;
    b.geometry_order = geometry_order;
    b.element_count = count;
    b.points = points.data();
    b.values = values.data();
    return b;
  }
};

// The corners of a straight cell of `type` in VTK's vertex order: a tetrahedron's 4, a wedge's 6
// (the triangle at t = 0, then at t = 1), a pyramid's 5 (base, apex), a hexahedron's 8.
using Corners = std::vector<glm::dvec3>;

// The world point of reference point r of the straight cell with `corners` (the linear cell's
// own map; affine for tetrahedra and extruded wedges).
glm::dvec3 linear_map(CellType type, const Corners& c, glm::dvec3 r) {
  const CellType linear = type == CellType::serendipity_hexahedron ? CellType::hexahedron
                          : type == CellType::serendipity_wedge    ? CellType::wedge
                          : type == CellType::pyramid14            ? CellType::pyramid
                                                                   : type;
  const std::vector<double> w = cell_shape_functions(linear, 1, r);
  // The linear hexahedron's nodes are VTK's corner order; `corners` follow it.
  glm::dvec3 x(0.0);
  for (std::size_t i = 0; i < w.size(); ++i)
    x += w[i] * c[i];
  return x;
}

// Appends one cell: its nodes at the linear map of its reference nodes, optionally bent by
// `bend` (curved cells), values of `field` at the nodes.
void add_cell(Cells& cells, const Corners& corners, const Field& field,
              const std::function<glm::dvec3(glm::dvec3)>& bend = {}) {
  for (const glm::dvec3& r : cell_reference_nodes(cells.type, cells.order)) {
    glm::dvec3 x = linear_map(cells.type, corners, r);
    if (bend) x = bend(x);
    cells.points.insert(cells.points.end(), {x.x, x.y, x.z});
    cells.values.push_back(field(x));
  }
  ++cells.count;
}

// The 8 corners of cube (i, j, k) of an n³ grid over [lo, hi]³, VTK's hexahedron order.
Corners cube_corners(int i, int j, int k, int n, double lo, double hi) {
  const double h = (hi - lo) / n;
  Corners c;
  for (const glm::ivec3 o :
       {glm::ivec3(0, 0, 0), glm::ivec3(1, 0, 0), glm::ivec3(1, 1, 0), glm::ivec3(0, 1, 0),
        glm::ivec3(0, 0, 1), glm::ivec3(1, 0, 1), glm::ivec3(1, 1, 1), glm::ivec3(0, 1, 1)})
    c.push_back(glm::dvec3(lo) + h * glm::dvec3(i + o.x, j + o.y, k + o.z));
  return c;
}

// A cube (VTK corner order c) split into cells of `type`, each as its corners: 6 tetrahedra
// around the diagonal 0–6 (Kuhn), 2 wedges (the square 0123 cut along 0–2, extruded), 6
// pyramids (a face each, apex at the centre), or the hexahedron itself.
std::vector<Corners> split_cube(CellType type, const Corners& c) {
  switch (type) {
    case CellType::tetrahedron:
      return {{c[0], c[1], c[2], c[6]}, {c[0], c[2], c[3], c[6]}, {c[0], c[3], c[7], c[6]},
              {c[0], c[7], c[4], c[6]}, {c[0], c[4], c[5], c[6]}, {c[0], c[5], c[1], c[6]}};
    case CellType::wedge:
    case CellType::serendipity_wedge:
      return {{c[0], c[1], c[2], c[4], c[5], c[6]}, {c[0], c[2], c[3], c[4], c[6], c[7]}};
    case CellType::pyramid:
    case CellType::pyramid14: {
      glm::dvec3 m(0.0);
      for (const glm::dvec3& v : c)
        m += v / 8.0;
      // Each face's corners in a cycle, the apex at the centre.
      return {{c[0], c[3], c[2], c[1], m}, {c[4], c[5], c[6], c[7], m},
              {c[0], c[1], c[5], c[4], m}, {c[1], c[2], c[6], c[5], m},
              {c[2], c[3], c[7], c[6], m}, {c[3], c[0], c[4], c[7], m}};
    }
    default:
      return {c};
  }
}

// An n³ grid of cubes over [lo, hi]³, each split into cells of `type` and order `order`.
Cells grid_cells(CellType type, int order, int n, double lo, double hi, const Field& field,
                 const std::function<glm::dvec3(glm::dvec3)>& bend = {}) {
  Cells cells;
  cells.type = type;
  cells.order = order;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const Corners& corners : split_cube(type, cube_corners(i, j, k, n, lo, hi)))
          add_cell(cells, corners, field, bend);
  return cells;
}

double r2(glm::dvec3 x) {
  return glm::dot(x, x);
}

std::string describe(CellType type, int order) {
  return std::string(cell_type_name(type)) + " of order " + std::to_string(order);
}

TEST(CellSource, ReferenceNodesAreDistinctAndTheBasisIsNodal) {
  for (CellType type :
       {CellType::hexahedron, CellType::serendipity_hexahedron, CellType::tetrahedron,
        CellType::wedge, CellType::serendipity_wedge, CellType::pyramid, CellType::pyramid14})
    for (int order = 1; order <= max_cell_order(type); ++order) {
      if ((type == CellType::serendipity_hexahedron || type == CellType::serendipity_wedge ||
           type == CellType::pyramid14) &&
          order != 2)
        continue;
      SCOPED_TRACE(describe(type, order));
      const std::vector<glm::dvec3> nodes = cell_reference_nodes(type, order);
      ASSERT_EQ(nodes.size(), cell_node_count(type, order));
      for (std::size_t i = 0; i < nodes.size(); ++i) {
        const std::vector<double> phi = cell_shape_functions(type, order, nodes[i]);
        for (std::size_t j = 0; j < nodes.size(); ++j)
          ASSERT_NEAR(phi[j], i == j ? 1.0 : 0.0, 1e-10) << "node " << i << ", function " << j;
      }
    }
  EXPECT_EQ(cell_node_count(CellType::tetrahedron, 8), 165u);
  EXPECT_EQ(cell_node_count(CellType::wedge, 8), 405u);
  EXPECT_EQ(cell_node_count(CellType::pyramid, 2), 13u);
  EXPECT_EQ(cell_node_count(CellType::pyramid14, 2), 14u);
  EXPECT_THROW(cell_node_count(CellType::pyramid14, 1), std::invalid_argument);
  EXPECT_EQ(cell_node_count(CellType::serendipity_hexahedron, 2), 20u);
  EXPECT_EQ(cell_node_count(CellType::serendipity_wedge, 2), 15u);
}

TEST(CellSource, SphereFromQuadraticFieldsOnStraightCellsIsExact) {
  // |x|² lies in every space of order ≥ 2 on straight tetrahedra, extruded wedges, the
  // serendipity cells and pyramids on a parallelogram (affine maps; the 14-node pyramid's space
  // holds P₂, VTK's 13-node one does not), so the isosurface at 1 is the unit sphere up to
  // rounding.
  struct Case {
    CellType type;
    int order;
  };
  for (const Case c :
       {Case{CellType::tetrahedron, 2}, Case{CellType::tetrahedron, 3},
        Case{CellType::tetrahedron, 5}, Case{CellType::tetrahedron, 8}, Case{CellType::wedge, 2},
        Case{CellType::wedge, 4}, Case{CellType::serendipity_wedge, 2},
        Case{CellType::serendipity_hexahedron, 2}, Case{CellType::hexahedron, 2},
        Case{CellType::pyramid14, 2}}) {
    SCOPED_TRACE(describe(c.type, c.order));
    const int n = c.order >= 5 ? 2 : 3;
    const Cells cells = grid_cells(c.type, c.order, n, -1.25, 1.25, r2);
    const CellElementSource source(cells.block());
    const RayCaster caster(source, 1.0);
    for (const View& view : testing::axis_and_oblique_views(source.bounds(), 24)) {
      const testing::SphereRays rays = testing::expect_sphere_hits(caster.cast(view), 1.0, 1e-6);
      EXPECT_GT(rays.through, 60);
      EXPECT_GT(rays.outside, 50);
    }
  }
}

// Hits of the plane x = c (the field x, exact in every cell: isoparametric): every hit on the
// plane, and exactly one on each ray that crosses it inside the box away from its faces.
void expect_plane_hits(const CellElementSource& source, double c, double lo, double hi) {
  const RayCaster caster(source, c);
  for (const glm::dvec3 dir : {glm::dvec3(1, 0, 0), glm::dvec3(0, 0, -1),
                               glm::dvec3(0.3, -0.5, 0.8), glm::dvec3(-0.6, 0.2, -0.5)}) {
    const View view = make_view(source.bounds(), dir, 40);
    const Ldi ldi = caster.cast(view);
    int through = 0;
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i) {
        const std::size_t pixel = std::size_t(j) * view.width + i;
        const glm::dvec3 o = view.pixel_point(i, j, 0.0);
        if (view.dir.x == 0.0) {
          EXPECT_EQ(ldi.count(pixel), 0u);
          continue;
        }
        const double t = (c - o.x) / view.dir.x;
        const glm::dvec3 x = o + t * view.dir;
        bool inside = true, near = false;
        for (int a = 0; a < 3; ++a) {
          inside = inside && x[a] >= lo && x[a] <= hi;
          near = near || std::abs(x[a] - lo) < 1e-6 || std::abs(x[a] - hi) < 1e-6;
        }
        if (near) continue;
        ASSERT_EQ(ldi.count(pixel), inside ? 1u : 0u) << "pixel " << i << "," << j;
        if (!inside) continue;
        ++through;
        EXPECT_NEAR(ldi.depth[ldi.begin(pixel)], t, 1e-6);
      }
    if (view.dir.x != 0.0) {
      EXPECT_GT(through, 100);
    }
  }
}

TEST(CellSource, TheFieldXOnCurvedCellsCutsThePlaneExactly) {
  // Isoparametric cells bent inside the box (the box's faces stay flat): the field x is exact in
  // every cell, so its isosurface is the plane, whatever the bending and the shape.
  const double lo = -1.0, hi = 1.0;
  const auto bend = [](glm::dvec3 x) {
    const glm::dvec3 w = (1.0 - x * x);  // zero on the box's faces
    return x + 0.08 * glm::dvec3(w.x * std::sin(2.0 * x.y) * w.y * w.z,
                                 w.y * std::sin(1.5 * x.z + 0.3) * w.x * w.z,
                                 w.z * std::cos(1.7 * x.x) * w.x * w.y);
  };
  struct Case {
    CellType type;
    int order;
  };
  for (const Case c : {Case{CellType::tetrahedron, 1}, Case{CellType::tetrahedron, 2},
                       Case{CellType::tetrahedron, 4}, Case{CellType::wedge, 1},
                       Case{CellType::wedge, 3}, Case{CellType::serendipity_wedge, 2},
                       Case{CellType::pyramid, 1}, Case{CellType::pyramid, 2},
                       Case{CellType::pyramid14, 2}, Case{CellType::serendipity_hexahedron, 2}}) {
    SCOPED_TRACE(describe(c.type, c.order));
    const Cells cells = grid_cells(
        c.type, c.order, 2, lo, hi, [](glm::dvec3 x) { return x.x; },
        c.order > 1 ? bend : std::function<glm::dvec3(glm::dvec3)>());
    const CellElementSource source(cells.block());
    // x = ±0.5 holds the pyramids' apexes (each sub-cube's centre): hits next to the collapsed
    // top face.
    for (double plane : {-0.31, 0.0, 0.47, -0.5, 0.5}) {
      SCOPED_TRACE("x = " + std::to_string(plane));
      expect_plane_hits(source, plane, lo, hi);
    }
  }
}

// The same cells with their points and values in gmsh's node order (the block's node_order
// still says VTK's: the caller sets it).
Cells to_gmsh_order(const Cells& vtk) {
  const std::vector<int> from = cell_gmsh_permutation(vtk.type, vtk.order);
  Cells gmsh = vtk;
  const std::size_t n = from.size();
  for (std::size_t e = 0; e < vtk.count; ++e)
    for (std::size_t i = 0; i < n; ++i) {
      gmsh.values[e * n + std::size_t(from[i])] = vtk.values[e * n + i];
      for (int a = 0; a < 3; ++a)
        gmsh.points[3 * (e * n + std::size_t(from[i])) + a] = vtk.points[3 * (e * n + i) + a];
    }
  return gmsh;
}

// Cells of `type` and field order `order` whose points are the nodes of the same shape at
// geometry order q (CellBlock::geometry_order): the n³ cubes of grid_cells, the geometry nodes
// bent by `bend`, the field at the field nodes' images under the geometry's own map.
Cells cells_with_geometry_order(CellType type, int order, int q, int n, double lo, double hi,
                                const Field& field,
                                const std::function<glm::dvec3(glm::dvec3)>& bend = {}) {
  const CellType geometry_type = cell_geometry_type(type, order, q);
  Cells cells;
  cells.type = type;
  cells.order = order;
  cells.geometry_order = q;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const Corners& corners : split_cube(type, cube_corners(i, j, k, n, lo, hi))) {
          std::vector<glm::dvec3> nodes;
          for (const glm::dvec3& r : cell_reference_nodes(geometry_type, q)) {
            glm::dvec3 x = linear_map(type, corners, r);
            if (bend) x = bend(x);
            nodes.push_back(x);
            cells.points.insert(cells.points.end(), {x.x, x.y, x.z});
          }
          for (const glm::dvec3& r : cell_reference_nodes(type, order)) {
            const std::vector<double> phi = cell_shape_functions(geometry_type, q, r);
            glm::dvec3 x(0.0);
            for (std::size_t m = 0; m < nodes.size(); ++m)
              x += phi[m] * nodes[m];
            cells.values.push_back(field(x));
          }
          ++cells.count;
        }
  return cells;
}

TEST(CellSource, PointsOfTheirOwnOrderGiveTheIsoparametricSurface) {
  // CellBlock::geometry_order: straight cells given by their corners (q = 1) carry |x|² at order
  // 2 and 3 — the unit sphere, within 10⁻⁶, and the same samples as the isoparametric block of
  // the same cells; curved cells of geometry order 2 carry the field x at order 4 (x has degree
  // 2 ≤ 4 on them): the plane, hit once per ray. Bad geometry orders are refused. Tetrahedra of
  // either kind would take the straight caster, so there the isoparametric cells are bent by
  // 10⁻⁹ (past its tolerance): the straight caster's hits are compared with the curved search's.
  struct Case {
    CellType type;
    int order;
  };
  for (const Case c : {Case{CellType::tetrahedron, 2}, Case{CellType::tetrahedron, 3},
                       Case{CellType::wedge, 2}, Case{CellType::serendipity_hexahedron, 2},
                       Case{CellType::serendipity_wedge, 2}, Case{CellType::pyramid14, 2}}) {
    SCOPED_TRACE(describe(c.type, c.order));
    const bool tetrahedra = c.type == CellType::tetrahedron;
    const auto nudge = [](glm::dvec3 x) {
      return x + 1e-9 * glm::dvec3(std::sin(3.0 * x.y), std::sin(2.0 * x.z), std::cos(x.x));
    };
    const Cells straight = cells_with_geometry_order(c.type, c.order, 1, 3, -1.25, 1.25, r2);
    const Cells iso = tetrahedra ? grid_cells(c.type, c.order, 3, -1.25, 1.25, r2, nudge)
                                 : grid_cells(c.type, c.order, 3, -1.25, 1.25, r2);
    ASSERT_EQ(straight.values.size(), iso.values.size());
    for (std::size_t k = 0; k < iso.values.size(); ++k)
      ASSERT_NEAR(straight.values[k], iso.values[k], tetrahedra ? 1e-8 : 0.0);
    ASSERT_LT(straight.points.size(), iso.points.size());
    const CellElementSource a(straight.block()), b(iso.block());
    if (tetrahedra) {
      EXPECT_TRUE(a.straight_tetrahedra());
      EXPECT_FALSE(b.straight_tetrahedra());
    }
    const RayCaster ca(a, 1.0), cb(b, 1.0);
    for (const View& view : testing::axis_and_oblique_views(a.bounds(), 24)) {
      const Ldi la = ca.cast(view), lb = cb.cast(view);
      const testing::SphereRays rays = testing::expect_sphere_hits(la, 1.0, 1e-6);
      EXPECT_GT(rays.through, 60);
      ASSERT_EQ(la.offsets, lb.offsets);
      for (std::size_t k = 0; k < la.sample_count(); ++k)
        EXPECT_NEAR(la.depth[k], lb.depth[k], 1e-7);
    }
  }
  const auto bend = [](glm::dvec3 x) {
    const glm::dvec3 w = (1.0 - x * x);
    return x + 0.08 * glm::dvec3(w.x * std::sin(2.0 * x.y) * w.y * w.z,
                                 w.y * std::sin(1.5 * x.z + 0.3) * w.x * w.z,
                                 w.z * std::cos(1.7 * x.x) * w.x * w.y);
  };
  for (const CellType type : {CellType::tetrahedron, CellType::wedge, CellType::hexahedron}) {
    SCOPED_TRACE(describe(type, 4));
    const Cells curved = cells_with_geometry_order(
        type, 4, 2, 2, -1.0, 1.0, [](glm::dvec3 x) { return x.x; }, bend);
    const CellElementSource source(curved.block());
    for (double plane : {-0.31, 0.0, 0.47})
      expect_plane_hits(source, plane, -1.0, 1.0);
  }
  Cells cells = cells_with_geometry_order(CellType::tetrahedron, 3, 1, 1, 0.0, 1.0, r2);
  for (const int q : {9, -1}) {
    CellBlock b = cells.block();
    b.geometry_order = q;
    try {
      const CellElementSource source(b);
      ADD_FAILURE() << "geometry order " << q << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("geometry order " + std::to_string(q)),
                std::string::npos)
          << e.what();
    }
  }
  // A block sharing the prepared geometry must say the same geometry order.
  const CellElementSource prepared(cells.block());
  CellBlock other = cells.block();
  other.geometry_order = 3;
  EXPECT_THROW(CellElementSource(prepared, other), std::invalid_argument);
}

TEST(CellSource, MixedCellsGiveTheSurfaceOfOneHexahedralMesh) {
  // One box meshed by cubes of four kinds (hexahedra, Kuhn tetrahedra, wedges, 15-node wedges),
  // the same quadratic field |x|² on each: one sphere, two hits per ray through it, none twice at
  // a boundary between kinds. (Pyramids: the 13-node space does not hold |x|²; they meet the
  // other kinds in the VTU test's mixed file, and their apexes in the plane test.)
  const int n = 4;
  const double lo = -1.25, hi = 1.25;
  std::vector<Cells> kinds;
  for (CellType type :
       {CellType::hexahedron, CellType::tetrahedron, CellType::wedge, CellType::serendipity_wedge})
    kinds.push_back(Cells{type, 2, 0, {}, {}, 0});
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        Cells& cells = kinds[(i + 2 * j + 3 * k) % 4];
        for (const Corners& corners : split_cube(cells.type, cube_corners(i, j, k, n, lo, hi)))
          add_cell(cells, corners, r2);
      }
  std::vector<std::unique_ptr<CellElementSource>> sources;
  std::vector<const FieldSource*> list;
  for (const Cells& cells : kinds) {
    ASSERT_GT(cells.count, 0u);
    sources.push_back(std::make_unique<CellElementSource>(cells.block()));
    list.push_back(sources.back().get());
  }
  const RayCaster caster(list, 1.0);
  for (const View& view :
       testing::axis_and_oblique_views(Box{glm::dvec3(lo), glm::dvec3(hi)}, 32)) {
    const testing::SphereRays rays = testing::expect_sphere_hits(caster.cast(view), 1.0, 1e-6);
    EXPECT_GT(rays.through, 100);
  }
}

TEST(CellSource, AxisAndEmbreeCastersGiveTheSameHits) {
  const auto bend = [](glm::dvec3 x) {
    return x + 0.05 * glm::dvec3(std::sin(2.0 * x.y), std::cos(1.3 * x.z), std::sin(x.x + 0.4)) *
                   (1.0 - x.x * x.x) * (1.0 - x.y * x.y) * (1.0 - x.z * x.z);
  };
  for (CellType type :
       {CellType::tetrahedron, CellType::wedge, CellType::pyramid, CellType::pyramid14}) {
    SCOPED_TRACE(cell_type_name(type));
    const Cells cells = grid_cells(
        type, 2, 2, -1.0, 1.0, [](glm::dvec3 x) { return r2(x) + 0.3 * x.x * x.y; }, bend);
    const CellElementSource source(cells.block());
    // The curved search by pieces of a cell (axis) and whole (Embree): the same roots up to
    // rounding (curved_element.hpp).
    const RayCaster axis(source, 0.6), reference(source, 0.6, RayCasterOptions{CastPath::embree});
    for (const View& view : make_axis_views(source.bounds(), 32)) {
      ASSERT_TRUE(axis.uses_axis_casters(view));
      const Ldi a = axis.cast(view), b = reference.cast(view);
      EXPECT_EQ(a.offsets, b.offsets);
      ASSERT_EQ(a.depth.size(), b.depth.size());
      EXPECT_GT(a.sample_count(), 300u);
      for (std::size_t k = 0; k < a.depth.size(); ++k) {
        EXPECT_NEAR(a.depth[k], b.depth[k], 1e-6);
        EXPECT_NEAR(glm::length(a.normal[k] - b.normal[k]), 0.0, 1e-5);
      }
    }
  }
}

// The dense reference: the field of one cell (its nodes `points`, values `values`) at world point
// x, by Newton's method on the cell's own map Σ φ_i(r) x_i (central differences), continued from
// `r`; NaN outside the cell's reference domain (grown by `pad`) or where Newton fails.
double cell_field_at(CellType type, int order, const double* points, const double* values,
                     glm::dvec3 x, glm::dvec3& r, double pad) {
  const cells::ReferenceCell& cell = cells::reference_cell(type, order);
  const std::size_t n = cell.nodes.size();
  const auto map = [&](glm::dvec3 q, double* f) {
    double phi[405];
    cells::shape_functions(cell, q, phi);
    glm::dvec3 y(0.0);
    double v = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      y += phi[i] * glm::dvec3(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
      v += phi[i] * values[i];
    }
    if (f) *f = v;
    return y;
  };
  bool converged = false;
  for (int iter = 0; iter < 25 && !converged; ++iter) {
    const glm::dvec3 y = map(r, nullptr);
    glm::dmat3 jac;
    for (int a = 0; a < 3; ++a) {
      glm::dvec3 e(0.0);
      e[a] = 1e-6;
      jac[a] = (map(r + e, nullptr) - map(r - e, nullptr)) / 2e-6;
    }
    const glm::dvec3 step = glm::inverse(jac) * (y - x);
    r -= step;
    converged = glm::length(step) < 1e-12;
    if (!(glm::length(r) < 10.0)) return std::nan("");
  }
  bool inside = r.x >= -pad && r.y >= -pad && r.z >= -pad && r.z <= 1.0 + pad;
  if (type == CellType::tetrahedron) inside = inside && r.x + r.y + r.z <= 1.0 + pad;
  if (type == CellType::wedge || type == CellType::serendipity_wedge)
    inside = inside && r.x + r.y <= 1.0 + pad;
  if (type == CellType::hexahedron || type == CellType::serendipity_hexahedron ||
      type == CellType::pyramid || type == CellType::pyramid14)
    inside = inside && r.x <= 1.0 + pad && r.y <= 1.0 + pad;
  if (!inside) return std::nan("");
  double f = 0.0;
  map(r, &f);
  return f;
}

// The roots of the cell's field minus `iso` along o + t·d for t in [t0, t1]: sign changes on a
// dense scan, refined by bisection; nullopt where the scan cannot be trusted (a root near the
// cell's boundary or two within a few steps, a near-tangency).
std::optional<std::vector<double>> dense_roots(CellType type, int order, const double* points,
                                               const double* values, double iso, glm::dvec3 o,
                                               glm::dvec3 d, double t0, double t1) {
  constexpr int kSteps = 500;
  std::vector<double> g(kSteps + 1), ts(kSteps + 1);
  std::vector<glm::dvec3> rs(kSteps + 1);
  glm::dvec3 r(0.25);
  double scale = 0.0;
  for (int k = 0; k <= kSteps; ++k) {
    ts[k] = t0 + (t1 - t0) * k / kSteps;
    glm::dvec3 start = k > 0 && !std::isnan(g[k - 1]) ? rs[k - 1] : glm::dvec3(0.25);
    g[k] = cell_field_at(type, order, points, values, o + ts[k] * d, start, 1e-9) - iso;
    rs[k] = start;
    if (!std::isnan(g[k])) scale = std::max(scale, std::abs(g[k]));
  }
  std::vector<double> roots;
  int last = -100;
  for (int k = 0; k < kSteps; ++k) {
    const bool a = std::isnan(g[k]), b = std::isnan(g[k + 1]);
    if (a != b) {  // the boundary: a root close to it is not trusted
      const double v = a ? g[k + 1] : g[k];
      if (std::abs(v) < 0.02 * scale) return std::nullopt;
      continue;
    }
    if (a) continue;
    if (std::abs(g[k]) < 1e-9 * scale) return std::nullopt;
    if ((g[k] < 0) == (g[k + 1] < 0)) {
      // A near-tangency (a small extremum between samples) could hide two roots.
      if (k > 0 && !std::isnan(g[k - 1]) && std::abs(g[k]) < 0.01 * scale &&
          (g[k] - g[k - 1]) * (g[k + 1] - g[k]) < 0)
        return std::nullopt;
      continue;
    }
    if (k - last < 4) return std::nullopt;
    last = k;
    double lo = ts[k], hi = ts[k + 1], glo = g[k];
    glm::dvec3 rr = rs[k];
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi);
      const double gm = cell_field_at(type, order, points, values, o + mid * d, rr, 1e-6) - iso;
      if ((gm < 0) == (glo < 0))
        lo = mid, glo = gm;
      else
        hi = mid;
    }
    roots.push_back(0.5 * (lo + hi));
  }
  return roots;
}

TEST(CellSource, RootsOfRandomCurvedCellsMatchADenseScan) {
  // One curved cell of each family at a time (nodes bent at random, a random polynomial field at
  // them), oblique rays through it: every root the dense scan finds, within 10⁻⁶, and no other.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  struct Case {
    CellType type;
    int order;
  };
  for (const Case c : {Case{CellType::tetrahedron, 2}, Case{CellType::tetrahedron, 3},
                       Case{CellType::wedge, 2}, Case{CellType::serendipity_wedge, 2},
                       Case{CellType::pyramid, 2}, Case{CellType::pyramid, 1},
                       Case{CellType::pyramid14, 2}, Case{CellType::serendipity_hexahedron, 2}}) {
    SCOPED_TRACE(describe(c.type, c.order));
    const glm::dvec3 w(u(rng), u(rng), u(rng));
    const auto bend = [&](glm::dvec3 x) {
      return x + 0.07 * glm::dvec3(std::sin(2.0 * x.y + w.x), std::cos(1.7 * x.z + w.y),
                                   std::sin(1.3 * x.x + w.z));
    };
    const glm::dvec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const Field field = [&](glm::dvec3 x) {
      return glm::dot(a, x) + 0.8 * (x.x * x.y * b.z + x.z * x.z * b.x) + 0.5 * x.y * x.y * b.y;
    };
    Cells cells;
    cells.type = c.type;
    cells.order = c.order;
    const Corners corners = split_cube(c.type, cube_corners(0, 0, 0, 1, -1.0, 1.0))[0];
    add_cell(cells, corners, field, c.order > 1 ? bend : std::function<glm::dvec3(glm::dvec3)>());
    const CellElementSource source(cells.block());
    // The isovalue: the field at the cell's centre (the surface crosses it).
    const double iso = field(linear_map(c.type, corners, glm::dvec3(0.25)));
    const RayCaster caster(source, iso, RayCasterOptions{CastPath::embree});
    int compared = 0, roots = 0;
    for (const glm::dvec3 dir : {glm::dvec3(0.3, -0.5, 0.8), glm::dvec3(-0.7, 0.2, 0.4)}) {
      const View view = make_view(source.bounds(), dir, 12);
      const Ldi ldi = caster.cast(view);
      const double t_max = 2.0 * source.bounds().diagonal();
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          const std::size_t pixel = std::size_t(j) * view.width + i;
          const glm::dvec3 o = view.pixel_point(i, j, 0.0);
          double t0 = 0.0, t1 = t_max;  // the scan over the cell's box only
          if (!clip_ray_to_box(o, view.dir, source.bounds().lo, source.bounds().hi, t0, t1)) {
            EXPECT_EQ(ldi.count(pixel), 0u);
            continue;
          }
          const auto expected = dense_roots(c.type, c.order, cells.points.data(),
                                            cells.values.data(), iso, o, view.dir, t0, t1);
          if (!expected) continue;
          ++compared;
          ASSERT_EQ(ldi.count(pixel), expected->size()) << "pixel " << i << "," << j;
          for (std::size_t h = 0; h < expected->size(); ++h)
            EXPECT_NEAR(ldi.depth[ldi.begin(pixel) + h], (*expected)[h], 1e-6);
          roots += int(expected->size());
        }
    }
    EXPECT_GT(compared, 120);
    EXPECT_GT(roots, 20);
  }
}

TEST(CellSource, StraightTetrahedraOfHigherOrderAreCastDirectly) {
  // Straight tetrahedra of order 2, 3, 5 (isoparametric nodes on straight sides, and the same
  // cells by their corners) take the direct caster; a quadric field, exact in them: at every
  // pixel of axis and oblique views the samples are the quadric's roots along the ray within the
  // box, to 10⁻⁶; axis and Embree casters the same bits. Bent by 10⁻⁴, the cells take the curved
  // search of their sub-hexahedra.
  const double iso = 0.8;
  const auto quadric = [](glm::dvec3 x) { return r2(x) + 0.3 * x.x * x.y - 0.2 * x.z * x.x; };
  const auto bend = [](glm::dvec3 x) {
    return x + 1e-4 * glm::dvec3(std::sin(3.0 * x.y), std::cos(2.0 * x.z), std::sin(x.x)) *
                   (1.5625 - x.x * x.x) * (1.5625 - x.y * x.y) * (1.5625 - x.z * x.z);
  };
  const Box box{glm::dvec3(-1.25), glm::dvec3(1.25)};
  for (const int p : {2, 3, 5}) {
    SCOPED_TRACE("order " + std::to_string(p));
    const Cells straight = grid_cells(CellType::tetrahedron, p, 3, -1.25, 1.25, quadric);
    const Cells corners =
        cells_with_geometry_order(CellType::tetrahedron, p, 1, 3, -1.25, 1.25, quadric);
    const Cells bent = grid_cells(CellType::tetrahedron, p, 3, -1.25, 1.25, quadric, bend);
    EXPECT_FALSE(CellElementSource(bent.block()).straight_tetrahedra());
    const CellElementSource s(straight.block()), c(corners.block());
    ASSERT_TRUE(s.straight_tetrahedra());
    ASSERT_TRUE(c.straight_tetrahedra());
    const RayCaster cs(s, iso), cc(c, iso), embree(s, iso, RayCasterOptions{CastPath::embree});
    std::size_t compared = 0, roots = 0;
    for (const View& view : testing::axis_and_oblique_views(s.bounds(), 40)) {
      const Ldi ls = cs.cast(view), lc = cc.cast(view);
      ASSERT_EQ(ls.offsets, lc.offsets);
      if (exact_axis(view.dir) >= 0) {
        const Ldi le = embree.cast(view);
        EXPECT_EQ(ls.offsets, le.offsets);
        EXPECT_EQ(ls.depth, le.depth);
      }
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          // The quadric along the ray: A t² + B t + C = iso, its roots inside the box.
          const glm::dvec3 o = view.pixel_point(i, j, 0.0), d = view.dir;
          double t0 = 0.0, t1 = 1e9;
          if (!clip_ray_to_box(o, d, box.lo, box.hi, t0, t1)) continue;
          const double a2 = glm::dot(d, d) + 0.3 * d.x * d.y - 0.2 * d.z * d.x;
          const double b1 =
              2.0 * glm::dot(o, d) + 0.3 * (o.x * d.y + o.y * d.x) - 0.2 * (o.z * d.x + o.x * d.z);
          const double c0 = quadric(o) - iso, disc = b1 * b1 - 4.0 * a2 * c0;
          if (disc < 0.0) continue;
          if (disc < 1e-6) continue;  // near-tangent: two roots too close to tell
          std::vector<double> expected;
          bool near_boundary = false;
          for (const double t :
               {(-b1 - std::sqrt(disc)) / (2.0 * a2), (-b1 + std::sqrt(disc)) / (2.0 * a2)}) {
            near_boundary = near_boundary || std::abs(t - t0) < 1e-6 || std::abs(t - t1) < 1e-6;
            if (t >= t0 && t <= t1) expected.push_back(t);
          }
          if (near_boundary) continue;
          const std::size_t pixel = std::size_t(j) * view.width + i;
          ++compared;
          ASSERT_EQ(ls.count(pixel), expected.size()) << "pixel " << i << "," << j;
          for (std::size_t h = 0; h < expected.size(); ++h) {
            EXPECT_NEAR(ls.depth[ls.begin(pixel) + h], expected[h], 1e-6);
            EXPECT_NEAR(lc.depth[lc.begin(pixel) + h], expected[h], 1e-6);
          }
          roots += expected.size();
        }
    }
    EXPECT_GT(compared, 2000u);
    EXPECT_GT(roots, 4000u);
  }
  {
    // Straightness as the file's precision allows: nodes rounded to float (VTK's default
    // points) are straight; small cells far from the origin bent by 3·10⁻⁶ of their size are not
    // (a tolerance of float rounding for double coordinates would flatten them).
    Cells rounded = grid_cells(CellType::tetrahedron, 2, 3, -1.25, 1.25, quadric);
    for (double& x : rounded.points)
      x = double(float(x));
    const CellElementSource r(rounded.block());
    EXPECT_TRUE(r.straight_tetrahedra());
    const Cells far = grid_cells(
        CellType::tetrahedron, 2, 2, 1000.0, 1000.002, [](glm::dvec3 x) { return x.x; },
        [](glm::dvec3 x) {
          return x + 3e-9 * glm::dvec3(std::sin(3e3 * x.y), std::cos(2e3 * x.z), 1.0);
        });
    EXPECT_FALSE(CellElementSource(far.block()).straight_tetrahedra());
    // gmsh's node order, and a source sharing a prepared one's geometry with values of its own
    // (the adaptor's per-step copies): the same straight caster, the same samples.
    const Cells vtk = grid_cells(CellType::tetrahedron, 3, 2, -1.25, 1.25, quadric);
    const Cells gmsh = to_gmsh_order(vtk);
    CellBlock gb = gmsh.block();
    gb.node_order = CellNodeOrder::gmsh;
    const CellElementSource v(vtk.block()), g(gb);
    ASSERT_TRUE(g.straight_tetrahedra());
    Cells shifted = vtk;  // the field + 0.1: another surface, the same cells
    for (double& value : shifted.values)
      value += 0.1;
    CellBlock copy_block = shifted.block();
    copy_block.points = nullptr;  // a copy reads no points
    const CellElementSource copy(v, copy_block), fresh(shifted.block());
    EXPECT_TRUE(copy.straight_tetrahedra());
    const RayCaster cv(v, iso), cg(g, iso), ccopy(copy, iso), cfresh(fresh, iso);
    for (const View& view : testing::axis_and_oblique_views(v.bounds(), 24)) {
      const Ldi lv = cv.cast(view), lg = cg.cast(view), lcopy = ccopy.cast(view),
                lfresh = cfresh.cast(view);
      EXPECT_GT(lv.sample_count(), 100u);
      EXPECT_EQ(lv.offsets, lg.offsets);
      EXPECT_EQ(lv.depth, lg.depth);
      EXPECT_EQ(lcopy.offsets, lfresh.offsets);
      EXPECT_EQ(lcopy.depth, lfresh.depth);
      EXPECT_NE(lcopy.depth, lv.depth);
    }
  }
  // One straight cubic tetrahedron with random nodal values (several roots per ray): every root
  // a dense scan finds, within 10⁻⁶, and no other.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 3; ++trial) {
    Cells cells;
    cells.type = CellType::tetrahedron;
    cells.order = 3;
    const Corners corners =
        split_cube(CellType::tetrahedron, cube_corners(0, 0, 0, 1, -1.0, 1.0))[0];
    add_cell(cells, corners, [](glm::dvec3) { return 0.0; }, {});
    for (double& v : cells.values)
      v = u(rng);
    const CellElementSource source(cells.block());
    ASSERT_TRUE(source.straight_tetrahedra());
    const double iso = 0.1 * u(rng);
    const RayCaster caster(source, iso, RayCasterOptions{CastPath::embree});
    int compared = 0, roots = 0;
    for (const glm::dvec3 dir : {glm::dvec3(0.3, -0.5, 0.8), glm::dvec3(-0.7, 0.2, 0.4)}) {
      const View view = make_view(source.bounds(), dir, 16);
      const Ldi ldi = caster.cast(view);
      const double t_max = 2.0 * source.bounds().diagonal();
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          const std::size_t pixel = std::size_t(j) * view.width + i;
          const glm::dvec3 o = view.pixel_point(i, j, 0.0);
          double t0 = 0.0, t1 = t_max;
          if (!clip_ray_to_box(o, view.dir, source.bounds().lo, source.bounds().hi, t0, t1))
            continue;
          const auto expected = dense_roots(CellType::tetrahedron, 3, cells.points.data(),
                                            cells.values.data(), iso, o, view.dir, t0, t1);
          if (!expected) continue;
          ++compared;
          ASSERT_EQ(ldi.count(pixel), expected->size()) << "pixel " << i << "," << j;
          for (std::size_t h = 0; h < expected->size(); ++h)
            EXPECT_NEAR(ldi.depth[ldi.begin(pixel) + h], (*expected)[h], 1e-6);
          roots += int(expected->size());
        }
    }
    EXPECT_GT(compared, 150);
    EXPECT_GT(roots, 40);
  }
}

TEST(CellSource, GmshOrderedCellsGiveTheSameHitsAsVtkOrderedOnes) {
  // The same curved cells with their points and values in gmsh's order: the same LDI.
  const auto bend = [](glm::dvec3 x) {
    return x + 0.06 * glm::dvec3(std::sin(2.0 * x.y), std::cos(1.3 * x.z), std::sin(x.x + 0.4)) *
                   (1.0 - x.x * x.x) * (1.0 - x.y * x.y) * (1.0 - x.z * x.z);
  };
  struct Case {
    CellType type;
    int order;
  };
  for (const Case c : {Case{CellType::tetrahedron, 2}, Case{CellType::tetrahedron, 3},
                       Case{CellType::wedge, 2}, Case{CellType::serendipity_wedge, 2},
                       Case{CellType::pyramid, 2}, Case{CellType::serendipity_hexahedron, 2},
                       Case{CellType::hexahedron, 2}, Case{CellType::tetrahedron, 5},
                       Case{CellType::hexahedron, 4}, Case{CellType::pyramid14, 2}}) {
    SCOPED_TRACE(describe(c.type, c.order));
    const Cells vtk = grid_cells(c.type, c.order, 2, -1.0, 1.0, r2, bend);
    ASSERT_EQ(cell_gmsh_permutation(c.type, c.order).size(), cell_node_count(c.type, c.order));
    const Cells gmsh = to_gmsh_order(vtk);
    ASSERT_NE(gmsh.values, vtk.values);
    CellBlock b = gmsh.block();
    b.node_order = CellNodeOrder::gmsh;
    const CellElementSource a(vtk.block()), g(b);
    const RayCaster ca(a, 0.6), cg(g, 0.6);
    EXPECT_GT(testing::expect_same_casts(ca, cg, testing::axis_and_oblique_views(a.bounds(), 24)),
              200u);
  }
  // gmsh describes no prism above order 2: refused.
  Cells cells = grid_cells(CellType::wedge, 3, 1, 0.0, 1.0, r2);
  CellBlock b = cells.block();
  b.node_order = CellNodeOrder::gmsh;
  EXPECT_THROW(CellElementSource{b}, std::invalid_argument);
}

TEST(CellSource, LinearTetrahedraAreCastDirectlyWithTheSameHitsEverywhere) {
  // VTK_TETRA cells take their own caster (the plane of the linear field in each tetrahedron):
  // its axis and Embree paths give the same bits; the hits of a linear field are those of the
  // same field on quadratic tetrahedra (the sub-hexahedra's curved search), to rounding.
  const Field field = [](glm::dvec3 x) { return 0.9 * x.x + 0.35 * x.y - 0.2 * x.z; };
  const Cells linear = grid_cells(CellType::tetrahedron, 1, 3, -1.0, 1.0, field);
  const Cells quadratic = grid_cells(CellType::tetrahedron, 2, 3, -1.0, 1.0, field);
  const CellElementSource a(linear.block()), b(quadratic.block());
  const RayCaster axis(a, 0.1), embree(a, 0.1, RayCasterOptions{CastPath::embree}), other(b, 0.1);
  const std::vector<View> views = testing::axis_and_oblique_views(a.bounds(), 32);
  EXPECT_GT(testing::expect_same_casts(axis, embree, make_axis_views(a.bounds(), 32)), 1000u);
  for (const View& view : views) {
    const Ldi la = axis.cast(view), lb = other.cast(view);
    ASSERT_EQ(la.offsets, lb.offsets);
    for (std::size_t k = 0; k < la.sample_count(); ++k) {
      EXPECT_NEAR(la.depth[k], lb.depth[k], 1e-6);
      EXPECT_NEAR(glm::length(la.normal[k] - lb.normal[k]), 0.0, 1e-5);
    }
  }
  // |x|² at the vertices (piecewise linear): the two casters still agree bit for bit, and the
  // colour field (x, read through the sub-hexahedra built on demand) is x at every hit.
  Cells sphere = grid_cells(CellType::tetrahedron, 1, 4, -1.25, 1.25, r2);
  std::vector<double> colour;
  for (std::size_t i = 0; i < sphere.points.size(); i += 3)
    colour.push_back(sphere.points[i]);
  CellBlock coloured = sphere.block();
  coloured.colour = colour.data();
  const CellElementSource s(coloured);
  RayCasterOptions with_scalars;
  with_scalars.scalars = true;
  const RayCaster sa(s, 1.0, with_scalars);
  RayCasterOptions embree_scalars = with_scalars;
  embree_scalars.path = CastPath::embree;
  const RayCaster se(s, 1.0, embree_scalars);
  EXPECT_GT(testing::expect_same_casts(sa, se, make_axis_views(s.bounds(), 32)), 1000u);
  const Ldi ldi = sa.cast(make_axis_views(s.bounds(), 32, "z")[0]);
  ASSERT_EQ(ldi.scalar.size(), ldi.sample_count());
  for (std::size_t p = 0; p < ldi.pixel_count(); ++p)
    for (std::uint32_t k = ldi.begin(p); k < ldi.end(p); ++k) {
      const int i = int(p % std::size_t(ldi.view.width)), j = int(p / std::size_t(ldi.view.width));
      EXPECT_NEAR(ldi.scalar[k], ldi.view.pixel_point(i, j, ldi.depth[k]).x, 1e-5);
    }
}

TEST(CellSource, GradedLinearTetrahedraKeepTheirBinsBounded) {
  // 8³ cubes of Kuhn tetrahedra in one corner and a few tetrahedra as wide as the box: the bins
  // (sized by the median tetrahedron) are coarsened rather than each wide one listed in
  // thousands; the axis caster still gives the Embree caster's bits.
  const Field field = [](glm::dvec3 x) { return x.x + 0.4 * x.y + 0.3 * x.z; };
  Cells cells = grid_cells(CellType::tetrahedron, 1, 8, 0.0, 0.05, field);
  for (int k = 0; k < 6; ++k)
    add_cell(cells,
             {glm::dvec3(0.0, 0.0, 0.1 * k), glm::dvec3(1.0, 0.0, 0.1 * k),
              glm::dvec3(0.0, 1.0, 0.1 * k), glm::dvec3(0.2, 0.3, 0.1 * k + 0.5)},
             field);
  const CellElementSource source(cells.block());
  for (const double iso : {0.03, 0.5}) {
    const RayCaster axis(source, iso), embree(source, iso, RayCasterOptions{CastPath::embree});
    EXPECT_GT(testing::expect_same_casts(axis, embree, make_axis_views(source.bounds(), 256)),
              iso < 0.1 ? 100u : 1000u);
  }
}

TEST(CellSource, LinearTetrahedraFindEveryCrossingOfABruteForceSolver) {
  // The axis caster tests only the pixels of each tetrahedron's crossing polygon grown by a
  // margin (linear_tets.cpp, set_crossing). Against a brute-force solver over every tetrahedron
  // and ray (long double), on Kuhn tetrahedra and fields that make that margin matter: values
  // exactly at the isovalue (planes through vertices, edges and faces), a plane within 10⁻¹⁵ of
  // the mesh's boundary face z = −1, tilted differently in each tetrahedron there (its crossing
  // polygons are slivers, the rest of the face crossed 10⁻¹⁵ outside, which the caster accepts
  // and no neighbour covers), and a field within 10⁻¹³ of
  // the isovalue everywhere (every tetrahedron active, its plane anywhere in it). Every crossing
  // inside a tetrahedron or on its boundary (to 10⁻¹³ in barycentric coordinates, the caster
  // accepting 10⁻¹²) is found, and every hit is a crossing of some tetrahedron (inside it to
  // 10⁻⁷); depths to 10⁻⁶, as the LDI keeps them in single precision.
  const auto jitter = [](glm::dvec3 x) {
    const auto h = [&](double a) { return std::sin(a * 12.9898 + x.y * 78.233 + x.z * 37.719); };
    return x + 0.04 * glm::dvec3(h(x.x), h(x.x + 1.0), h(x.x + 2.0));
  };
  const auto sign = [](glm::dvec3 x) {  // −1, 0 or 1 by vertex
    return double(int(std::floor(std::abs(std::sin(x.x * 91.7 + x.y * 13.1)) * 3.0)) - 1);
  };
  struct Case {
    std::string name;
    Field field;
    double iso;
    bool jittered;
  };
  const std::vector<Case> cases = {
      {"quantized", [](glm::dvec3 x) { return std::round(4.0 * (x.x + 0.3 * x.y)) / 4.0; }, 0.5,
       true},
      {"grazing", [&](glm::dvec3 x) { return x.z + 1e-15 * sign(x); }, -1.0, false},
      {"flat",
       [](glm::dvec3 x) { return 0.5 + 1e-13 * std::sin(9.0 * x.x - 5.0 * x.y + 3.0 * x.z); }, 0.5,
       true},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const Cells cells = c.jittered ? grid_cells(
                                         CellType::tetrahedron, 1, 5, -1.0, 1.0,
                                         [&](glm::dvec3 x) { return c.field(jitter(x)); }, jitter)
                                   : grid_cells(CellType::tetrahedron, 1, 5, -1.0, 1.0, c.field);
    const CellElementSource source(cells.block());
    const RayCaster caster(source, c.iso);
    std::size_t found = 0;
    // Views of a larger box: the boundary's crossings lie inside the rays' depth range.
    const Box box{source.bounds().lo - 0.1, source.bounds().hi + 0.1};
    for (const View& view : make_axis_views(box, 40)) {
      const Ldi ldi = caster.cast(view);
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          const glm::dvec3 o = view.pixel_point(i, j, 0.0);
          // Each tetrahedron's crossing of the ray: depth, smallest barycentric coordinate.
          std::vector<std::pair<long double, long double>> crossings;
          for (std::size_t e = 0; e < cells.count; ++e) {
            using V = glm::vec<3, long double>;
            V p[4];
            long double f[4];
            for (int k = 0; k < 4; ++k) {
              p[k] = V(cells.points[12 * e + 3 * k], cells.points[12 * e + 3 * k + 1],
                       cells.points[12 * e + 3 * k + 2]);
              f[k] = (long double)cells.values[4 * e + k] - c.iso;
            }
            if (std::min({f[0], f[1], f[2], f[3]}) > 0 || std::max({f[0], f[1], f[2], f[3]}) < 0)
              continue;
            glm::mat<3, 3, long double> edges;
            for (int k = 0; k < 3; ++k)
              edges[k] = p[k + 1] - p[0];
            const auto to_bary = glm::inverse(edges);
            const V g = glm::transpose(to_bary) * V(f[1] - f[0], f[2] - f[0], f[3] - f[0]);
            const V d(view.dir), org(o);
            const long double gd = glm::dot(g, d);
            if (std::abs(gd) <= 1e-6L * glm::length(g)) continue;  // nearly in the plane
            const long double t = -(f[0] + glm::dot(g, org - p[0])) / gd;
            const V l = to_bary * (org + t * d - p[0]);
            crossings.push_back({t, std::min({l.x, l.y, l.z, 1.0L - l.x - l.y - l.z})});
          }
          const std::size_t pixel = std::size_t(j) * std::size_t(view.width) + std::size_t(i);
          for (const auto& [t, inside] : crossings) {
            if (inside < -1e-13L) continue;
            bool hit = false;
            for (std::uint32_t k = ldi.begin(pixel); k < ldi.end(pixel); ++k)
              hit = hit || std::abs(ldi.depth[k] - double(t)) < 1e-6;
            EXPECT_TRUE(hit) << "missed crossing at depth " << double(t) << ", pixel " << i << ", "
                             << j << ", view " << view.dir.x << view.dir.y << view.dir.z;
            found += hit;
          }
          for (std::uint32_t k = ldi.begin(pixel); k < ldi.end(pixel); ++k) {
            bool known = false;
            for (const auto& [t, inside] : crossings)
              known = known || (inside > -1e-7L && std::abs(ldi.depth[k] - double(t)) < 1e-6);
            EXPECT_TRUE(known) << "hit at depth " << ldi.depth[k] << " is no crossing";
          }
        }
    }
    EXPECT_GT(found, 1000u);
  }
}

TEST(CellSource, RaysAlongSharedEdgesAndThroughVerticesOfTetrahedraHitOnce) {
  // Kuhn tetrahedra of unit cubes over [0, 4]³; axis views whose pixel rays run along the cubes'
  // edges and through their vertices (the tetrahedra's shared edges and vertices); a linear field
  // whose plane crosses every such ray once inside the box: one hit per ray, at the plane.
  const Field field = [](glm::dvec3 x) { return x.x + 0.37 * x.y + 0.21 * x.z; };
  for (const int order : {1, 2}) {
    SCOPED_TRACE("order " + std::to_string(order));
    const Cells cells = grid_cells(CellType::tetrahedron, order, 4, 0.0, 4.0, field);
    const CellElementSource source(cells.block());
    const double iso = 2.3;
    const RayCaster caster(source, iso);
    const Box box{glm::dvec3(-0.5), glm::dvec3(4.5)};  // pixel centres at 0, 1, …, 4
    int rays = 0;
    for (const View& view : make_axis_views(box, 5)) {
      const Ldi ldi = caster.cast(view);
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          const glm::dvec3 o = view.pixel_point(i, j, 0.0);
          const int axis = exact_axis(view.dir);
          glm::dvec3 g(1.0, 0.37, 0.21);
          const double t = (iso - glm::dot(g, o)) / glm::dot(g, view.dir);
          const glm::dvec3 x = o + t * view.dir;
          const bool inside = x[axis] > 1e-9 && x[axis] < 4.0 - 1e-9;
          const std::size_t p = std::size_t(j) * view.width + i;
          ASSERT_EQ(ldi.count(p), inside ? 1u : 0u) << "pixel " << i << "," << j;
          if (inside) {
            EXPECT_NEAR(ldi.depth[ldi.begin(p)], t, 1e-6);  // float depths
          }
          rays += inside;
        }
    }
    EXPECT_GT(rays, 30);
  }
}

TEST(CellSource, InvalidBlocksAreRejected) {
  Cells cells = grid_cells(CellType::tetrahedron, 2, 1, 0.0, 1.0, r2);
  const auto throws = [](const CellBlock& b, const std::string& text) {
    try {
      const CellElementSource source(b);
      ADD_FAILURE() << "accepted; expected: " << text;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
    }
  };
  CellBlock b = cells.block();
  b.order = 9;
  throws(b, "tetrahedron of order 9 does not exist");
  b = cells.block();
  b.type = CellType::pyramid;
  b.order = 3;
  throws(b, "pyramid of order 3 does not exist");
  b = cells.block();
  b.type = CellType::serendipity_wedge;
  b.order = 1;
  throws(b, "does not exist");
  b = cells.block();
  b.element_count = 0;
  throws(b, "no cells");
  b = cells.block();
  b.points = nullptr;
  throws(b, "null point array");
  b = cells.block();
  b.values = nullptr;
  throws(b, "null value array");
  b = cells.block();
  b.element_stride = 9;
  throws(b, "element stride 9 below the 10 nodes");
  b = cells.block();
  b.type = CellType(42);
  throws(b, "unknown cell type");
  // Cell 3: a point not finite; cell 4: flattened (its apex on its base's plane).
  Cells bad = cells;
  bad.points[3 * (10 * 3 + 5) + 1] = std::nan("");
  throws(bad.block(), "cell 3 has a non-finite point");
  bad = cells;
  for (int i = 0; i < 10; ++i)
    bad.points[3 * (10 * 4 + i) + 2] = 0.5;  // every node of cell 4 on one plane
  throws(bad.block(), "cell 4 is inverted or degenerate");
}

TEST(CellSource, CellsWithNonFiniteValuesProduceNoHitsAndAreCounted) {
  Cells cells = grid_cells(CellType::tetrahedron, 2, 2, -1.25, 1.25, r2);
  const CellElementSource clean(cells.block());
  const RayCaster all(clean, 1.0);
  cells.values[7] = std::nan("");       // cell 0
  cells.values[10 * 5 + 2] = INFINITY;  // cell 5
  const CellElementSource source(cells.block());
  const RayCaster caster(source, 1.0);
  EXPECT_EQ(caster.nonfinite_values(), 2u);
  // Cells 0 and 5 (straight: one primitive each, and both hold the sphere) are left out; the
  // others are kept.
  ASSERT_TRUE(source.straight_tetrahedra());
  EXPECT_EQ(all.primitive_count() - caster.primitive_count(), 2u);
}

}  // namespace
}  // namespace ldimesh

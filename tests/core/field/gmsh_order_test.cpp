// gmsh's node orders (CellNodeOrder::gmsh) against gmsh's own reference elements: gmsh's library
// (libgmsh, beside deal.II) gives each element type's node coordinates; VTK's node i of ours must
// sit where gmsh's node permutation[i] sits, mapped to VTK's parametric coordinates.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <gmsh.h>
#include <gtest/gtest.h>

#include "ldimesh/core/field/cell_source.hpp"

namespace ldimesh {
namespace {

// gmsh's reference coordinates in VTK's parametric ones: tetrahedra the same; prisms (u, v) on
// the triangle and w ∈ [−1, 1]; pyramids a base [−1, 1]² at z = 0 and the apex (0, 0, 1)
// (VTK's r, s run over the base at every height: x = (2r − 1)(1 − t)); hexahedra [−1, 1]³.
glm::dvec3 to_vtk(CellType type, glm::dvec3 g) {
  switch (type) {
    case CellType::tetrahedron:
      return g;
    case CellType::wedge:
    case CellType::serendipity_wedge:
      return {g.x, g.y, 0.5 * (g.z + 1.0)};
    case CellType::pyramid:
    case CellType::pyramid14:
      if (g.z == 1.0) return {0.0, 0.0, 1.0};  // the apex: VTK's (0, 0, 1)
      return {0.5 * (g.x / (1.0 - g.z) + 1.0), 0.5 * (g.y / (1.0 - g.z) + 1.0), g.z};
    default:
      return 0.5 * (g + 1.0);
  }
}

// VTK's node i of ours sits where gmsh's node permutation[i] of element type `gmsh_type` sits.
void expect_gmsh_positions(int gmsh_type, CellType type, int order) {
  SCOPED_TRACE("gmsh type " + std::to_string(gmsh_type) + ", order " + std::to_string(order));
  std::string name;
  int dim = 0, gmsh_order = 0, nodes = 0, primary = 0;
  std::vector<double> local;
  gmsh::model::mesh::getElementProperties(gmsh_type, name, dim, gmsh_order, nodes, local, primary);
  ASSERT_EQ(gmsh_order, order) << name;
  const std::vector<glm::dvec3> ours = cell_reference_nodes(type, order);
  const std::vector<int> permutation = cell_gmsh_permutation(type, order);
  ASSERT_EQ(int(ours.size()), nodes) << name;
  ASSERT_EQ(permutation.size(), ours.size()) << name;
  std::vector<int> seen(ours.size(), 0);
  for (std::size_t i = 0; i < ours.size(); ++i) {
    const int g = permutation[i];
    ASSERT_TRUE(g >= 0 && g < nodes) << name;
    ++seen[std::size_t(g)];
    const glm::dvec3 at = to_vtk(type, {local[3 * g], local[3 * g + 1], local[3 * g + 2]});
    EXPECT_NEAR(glm::length(ours[i] - at), 0.0, 1e-12)
        << name << ": VTK node " << i << " is gmsh node " << g;
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), nodes) << name << ": not a permutation";
}

TEST(GmshOrder, EveryTakenTypeSitsWhereGmshPutsItsNodes) {
  gmsh::initialize();
  // Tetrahedra and hexahedra of every order we take (gmsh's types found by gmsh itself); prisms
  // of order 1 and 2 (gmsh 4.8 describes none above: "FaceClosureFull not implemented for prisms
  // of order 3"), the serendipity and pyramid types by number.
  struct Family {
    const char* gmsh_family;
    CellType type;
  };
  for (const Family f :
       {Family{"Tetrahedron", CellType::tetrahedron}, Family{"Hexahedron", CellType::hexahedron}})
    for (int order = 1; order <= max_cell_order(f.type); ++order)
      expect_gmsh_positions(gmsh::model::mesh::getElementType(f.gmsh_family, order), f.type, order);
  struct Case {
    int gmsh_type;
    CellType type;
    int order;
  };
  // The types by number too, as gmsh's documentation lists them (MSH 4: 4, 11, 29 tetrahedra;
  // 6, 13, 18 prisms; 7, 19, 14 pyramids; 5, 12, 17 hexahedra).
  const Case cases[] = {{4, CellType::tetrahedron, 1},  {11, CellType::tetrahedron, 2},
                        {29, CellType::tetrahedron, 3}, {6, CellType::wedge, 1},
                        {13, CellType::wedge, 2},       {18, CellType::serendipity_wedge, 2},
                        {7, CellType::pyramid, 1},      {19, CellType::pyramid, 2},
                        {14, CellType::pyramid14, 2},   {5, CellType::hexahedron, 1},
                        {12, CellType::hexahedron, 2},  {17, CellType::serendipity_hexahedron, 2}};
  for (const Case& c : cases)
    expect_gmsh_positions(c.gmsh_type, c.type, c.order);
  gmsh::finalize();
  // Orders no cell of ours has.
  EXPECT_TRUE(cell_gmsh_permutation(CellType::pyramid14, 1).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::tetrahedron, 9).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::pyramid, 3).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::serendipity_wedge, 3).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::wedge, 3).empty());
}

TEST(GmshOrder, ShapeFunctionsAreGmshsWhereTheSpacesAreTheSame) {
  // Our nodal basis at random points of the reference cell equals gmsh's Lagrange basis
  // (getBasisFunctions) there, node for node through the permutation: the Lagrange tetrahedra,
  // prisms and hexahedra, the 20-node hexahedron, and the 14-node pyramid (gmsh's own space).
  // Not VTK's 13-node pyramid and 15-node wedge, whose spaces are VTK's, not gmsh's.
  gmsh::initialize();
  struct Case {
    int gmsh_type;
    CellType type;
    int order;
  };
  const Case cases[] = {{11, CellType::tetrahedron, 2},
                        {29, CellType::tetrahedron, 3},
                        {31, CellType::tetrahedron, 5},
                        {13, CellType::wedge, 2},
                        {12, CellType::hexahedron, 2},
                        {93, CellType::hexahedron, 4},
                        {17, CellType::serendipity_hexahedron, 2},
                        {14, CellType::pyramid14, 2}};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (const Case& c : cases) {
    SCOPED_TRACE("gmsh type " + std::to_string(c.gmsh_type));
    // Random points in gmsh's reference cell.
    std::vector<double> points;
    for (int k = 0; k < 30; ++k) {
      double a = u(rng), b = u(rng), z = u(rng);
      switch (c.type) {
        case CellType::tetrahedron:
          while (a + b + z > 1.0)
            a = u(rng), b = u(rng), z = u(rng);
          break;
        case CellType::wedge:
          while (a + b > 1.0)
            a = u(rng), b = u(rng);
          z = 2.0 * z - 1.0;
          break;
        case CellType::pyramid14:
          z = k < 6 ? 0.0 : 0.95 * z;  // the base too
          a = (2.0 * a - 1.0) * (1.0 - z), b = (2.0 * b - 1.0) * (1.0 - z);
          break;
        default:
          a = 2.0 * a - 1.0, b = 2.0 * b - 1.0, z = 2.0 * z - 1.0;
      }
      points.insert(points.end(), {a, b, z});
    }
    int components = 0, orientations = 0;
    std::vector<double> theirs;
    gmsh::model::mesh::getBasisFunctions(c.gmsh_type, points, "Lagrange", components, theirs,
                                         orientations);
    const std::vector<int> permutation = cell_gmsh_permutation(c.type, c.order);
    const std::size_t n = permutation.size();
    ASSERT_EQ(theirs.size(), 30 * n);
    double worst = 0.0;
    for (int k = 0; k < 30; ++k) {
      const glm::dvec3 g(points[3 * k], points[3 * k + 1], points[3 * k + 2]);
      const std::vector<double> ours = cell_shape_functions(c.type, c.order, to_vtk(c.type, g));
      for (std::size_t i = 0; i < n; ++i)
        worst = std::max(worst, std::abs(ours[i] - theirs[k * n + std::size_t(permutation[i])]));
    }
    EXPECT_LT(worst, 1e-9);
  }
  gmsh::finalize();
}

}  // namespace
}  // namespace ldimesh

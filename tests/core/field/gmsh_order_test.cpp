// gmsh's node orders (CellNodeOrder::gmsh) against gmsh's own reference elements: gmsh's library
// (libgmsh, beside deal.II) gives each element type's node coordinates; VTK's node i of ours must
// sit where gmsh's node permutation[i] sits, mapped to VTK's parametric coordinates.
#include <algorithm>
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
  // 6, 13, 18 prisms; 7, 19 pyramids; 5, 12, 17 hexahedra).
  const Case cases[] = {{4, CellType::tetrahedron, 1},
                        {11, CellType::tetrahedron, 2},
                        {29, CellType::tetrahedron, 3},
                        {6, CellType::wedge, 1},
                        {13, CellType::wedge, 2},
                        {18, CellType::serendipity_wedge, 2},
                        {7, CellType::pyramid, 1},
                        {19, CellType::pyramid, 2},
                        {5, CellType::hexahedron, 1},
                        {12, CellType::hexahedron, 2},
                        {17, CellType::serendipity_hexahedron, 2}};
  for (const Case& c : cases)
    expect_gmsh_positions(c.gmsh_type, c.type, c.order);
  gmsh::finalize();
  // Orders no cell of ours has.
  EXPECT_TRUE(cell_gmsh_permutation(CellType::tetrahedron, 9).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::pyramid, 3).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::serendipity_wedge, 3).empty());
  EXPECT_TRUE(cell_gmsh_permutation(CellType::wedge, 3).empty());
}

}  // namespace
}  // namespace ldimesh

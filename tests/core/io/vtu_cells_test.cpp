// Cells of every type `ldimesh mesh --vtu` reads, written by VTK's own writer with their nodes at
// VTK's own parametric coordinates: our node orders are VTK's, and the field we mesh is the one
// VTK's own evaluation of the file gives, at random points of curved cells.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <unistd.h>
#include <vtkCell.h>
#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkDoubleArray.h>
#include <vtkGenericCell.h>
#include <vtkIdList.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLUnstructuredGridWriter.h>

#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/io/vtu.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

#include "../test_helpers.hpp"

namespace ldimesh {
namespace {

struct VtkType {
  int vtk;     // VTK's cell type
  int points;  // its point count
  CellType type;
  int order;
};

// Every type and order the reader takes (the Lagrange families at a few orders).
std::vector<VtkType> vtk_types() {
  std::vector<VtkType> t = {
      {VTK_HEXAHEDRON, 8, CellType::hexahedron, 1},
      {VTK_TRIQUADRATIC_HEXAHEDRON, 27, CellType::hexahedron, 2},
      {VTK_QUADRATIC_HEXAHEDRON, 20, CellType::serendipity_hexahedron, 2},
      {VTK_TETRA, 4, CellType::tetrahedron, 1},
      {VTK_QUADRATIC_TETRA, 10, CellType::tetrahedron, 2},
      {VTK_WEDGE, 6, CellType::wedge, 1},
      {VTK_QUADRATIC_WEDGE, 15, CellType::serendipity_wedge, 2},
      {VTK_BIQUADRATIC_QUADRATIC_WEDGE, 18, CellType::wedge, 2},
      {VTK_PYRAMID, 5, CellType::pyramid, 1},
      {VTK_QUADRATIC_PYRAMID, 13, CellType::pyramid, 2},
  };
  for (int p = 1; p <= kMaxHexOrder; ++p) {
    t.push_back({VTK_LAGRANGE_TETRAHEDRON, int(cell_nodes(CellType::tetrahedron, p)),
                 CellType::tetrahedron, p});
    t.push_back({VTK_LAGRANGE_WEDGE, int(cell_nodes(CellType::wedge, p)), CellType::wedge, p});
    t.push_back({VTK_LAGRANGE_HEXAHEDRON, int(cell_nodes(CellType::hexahedron, p)),
                 CellType::hexahedron, p});
  }
  return t;
}

std::string describe(const VtkType& t) {
  return "VTK type " + std::to_string(t.vtk) + " with " + std::to_string(t.points) + " points";
}

// A cell of `t` as VTK makes it (its parametric coordinates, its order set).
vtkSmartPointer<vtkCell> vtk_cell(vtkUnstructuredGrid* grid, vtkIdType id) {
  vtkNew<vtkGenericCell> generic;
  grid->GetCell(id, generic);
  return vtkSmartPointer<vtkCell>(generic->GetRepresentativeCell());
}

// The world point of reference point r: a cell-dependent affine map, bent (curved cells).
glm::dvec3 place(glm::dvec3 r, int cell, bool bent) {
  const glm::dvec3 origin(3.0 * cell, -0.2 * cell, 0.1 * cell);  // apart: no overlap
  const glm::dmat3 a(glm::dvec3(1.0, 0.2, -0.1), glm::dvec3(0.1, 0.9, 0.3),
                     glm::dvec3(-0.2, 0.1, 1.1));
  glm::dvec3 x = origin + a * r;
  if (bent) x += 0.06 * glm::dvec3(std::sin(2.0 * r.y + cell), std::cos(1.5 * r.z), r.x * r.y);
  return x;
}

double field(glm::dvec3 x) {
  return std::sin(1.3 * x.x) + x.y * x.z - 0.4 * x.z * x.z + 0.2 * x.x * x.y;
}

// Writes `cells` cells of `t` (each placed by `place`, the field at the nodes) to `path` with
// VTK's writer; returns the grid.
vtkSmartPointer<vtkUnstructuredGrid> write_cells(const VtkType& t, int cells, bool bent,
                                                 const std::string& path,
                                                 const std::vector<bool>& ghost = {}) {
  auto grid = vtkSmartPointer<vtkUnstructuredGrid>::New();
  vtkNew<vtkPoints> points;
  vtkNew<vtkDoubleArray> u;
  u->SetName("u");
  grid->SetPoints(points);
  std::vector<vtkIdType> ids(t.points);
  for (int c = 0; c < cells; ++c) {
    for (int i = 0; i < t.points; ++i)
      ids[i] = points->InsertNextPoint(0.0, 0.0, 0.0);
    grid->InsertNextCell(t.vtk, t.points, ids.data());
  }
  if (t.vtk == VTK_LAGRANGE_WEDGE || t.vtk == VTK_LAGRANGE_HEXAHEDRON) {
    vtkNew<vtkDoubleArray> degrees;
    degrees->SetName("HigherOrderDegrees");
    degrees->SetNumberOfComponents(3);
    for (int c = 0; c < cells; ++c)
      degrees->InsertNextTuple3(t.order, t.order, t.order);
    grid->GetCellData()->AddArray(degrees);
  }
  for (int c = 0; c < cells; ++c) {
    vtkSmartPointer<vtkCell> cell = vtk_cell(grid, c);
    const double* pc = cell->GetParametricCoords();
    EXPECT_NE(pc, nullptr);
    for (int i = 0; i < t.points; ++i) {
      const glm::dvec3 x = place(glm::dvec3(pc[3 * i], pc[3 * i + 1], pc[3 * i + 2]), c, bent);
      vtkNew<vtkIdList> cell_ids;
      grid->GetCellPoints(c, cell_ids);
      points->SetPoint(cell_ids->GetId(i), x.x, x.y, x.z);
    }
  }
  for (vtkIdType k = 0; k < points->GetNumberOfPoints(); ++k) {
    double x[3];
    points->GetPoint(k, x);
    u->InsertNextValue(field({x[0], x[1], x[2]}));
  }
  grid->GetPointData()->AddArray(u);
  if (!ghost.empty()) {
    vtkNew<vtkUnsignedCharArray> flags;
    flags->SetName("vtkGhostType");
    for (int c = 0; c < cells; ++c)
      flags->InsertNextValue(ghost[c] ? 1 : 0);
    grid->GetCellData()->AddArray(flags);
  }
  vtkNew<vtkXMLUnstructuredGridWriter> writer;
  writer->SetFileName(path.c_str());
  writer->SetInputData(grid);
  EXPECT_EQ(writer->Write(), 1);
  return grid;
}

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("ldimesh_vtu_cells_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

TEST(VtuCells, NodeOrdersAreVtks) {
  for (const VtkType& t : vtk_types()) {
    SCOPED_TRACE(describe(t));
    const std::string path = temp_path("order.vtu");
    const auto grid = write_cells(t, 1, false, path);
    std::filesystem::remove(path);
    vtkSmartPointer<vtkCell> cell = vtk_cell(grid, 0);
    const double* pc = cell->GetParametricCoords();
    const std::vector<glm::dvec3> ours = cell_reference_nodes(t.type, t.order);
    ASSERT_EQ(int(ours.size()), t.points);
    for (int i = 0; i < t.points; ++i)
      EXPECT_NEAR(glm::length(ours[i] - glm::dvec3(pc[3 * i], pc[3 * i + 1], pc[3 * i + 2])), 0.0,
                  1e-12)
          << "node " << i;
  }
}

TEST(VtuCells, TheFieldIsVtksOwnEvaluationOfTheFile) {
  // Curved cells (orders ≥ 2) of every type; at random parametric points VTK maps to the world
  // and interpolates the file's values, and our reader's cells give the same value there.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (const VtkType& t : vtk_types()) {
    SCOPED_TRACE(describe(t));
    const int cells = 3;
    const std::string path = temp_path("field.vtu");
    const auto grid = write_cells(t, cells, t.order >= 2, path);
    VtuField data;
    const Status st = read_vtu_field(path, "u", data);
    std::filesystem::remove(path);
    ASSERT_TRUE(st) << st.message();
    ASSERT_EQ(data.elements.cells, std::size_t(cells));
    ASSERT_EQ(data.elements.groups.size(), 1u);
    EXPECT_EQ(data.elements.groups[0].type, t.type);
    EXPECT_EQ(data.elements.groups[0].order, t.order);
    vtkDataArray* u = grid->GetPointData()->GetArray("u");
    int checked = 0;
    for (int c = 0; c < cells; ++c) {
      vtkSmartPointer<vtkCell> cell = vtk_cell(grid, c);
      std::vector<double> weights(t.points);
      for (int k = 0; k < 20; ++k) {
        // A point inside the reference domain (away from its faces by a little).
        glm::dvec3 r(0.05 + 0.9 * unit(rng), 0.05 + 0.9 * unit(rng), 0.05 + 0.9 * unit(rng));
        if (t.type == CellType::tetrahedron) r *= 0.9 / std::max(1.0, r.x + r.y + r.z) * 0.95;
        if (t.type == CellType::wedge || t.type == CellType::serendipity_wedge)
          if (r.x + r.y > 0.95) r.x *= 0.45, r.y *= 0.45;
        if (t.type == CellType::pyramid) r.z *= 0.9;
        double pc[3] = {r.x, r.y, r.z}, x[3];
        int sub = 0;
        cell->EvaluateLocation(sub, pc, x, weights.data());
        double expected = 0.0;
        for (int i = 0; i < t.points; ++i)
          expected += weights[i] * u->GetTuple1(cell->GetPointId(i));
        PolynomialSample got;
        ASSERT_TRUE(data.lookup->sample(glm::dvec3(x[0], x[1], x[2]), got))
            << "cell " << c << " at " << r.x << ", " << r.y << ", " << r.z;
        EXPECT_NEAR(got.value, expected, 1e-9) << "cell " << c;
        ++checked;
      }
    }
    EXPECT_EQ(checked, 60);
  }
}

TEST(VtuCells, GhostCellsAreSkipped) {
  const VtkType t{VTK_QUADRATIC_TETRA, 10, CellType::tetrahedron, 2};
  const std::string path = temp_path("ghosts.vtu");
  write_cells(t, 4, true, path, {false, true, false, true});
  // Through the child process (the counts cross its pipe); the cells kept are 0 and 2, whose
  // points lie below x = 2 and from x = 6 on (place() puts cell c at x ≈ 3c).
  VtuElements elements;
  const Status st = read_vtu_isolated(path, "u", elements);
  std::filesystem::remove(path);
  ASSERT_TRUE(st) << st.message();
  EXPECT_EQ(elements.cells, 2u);
  EXPECT_EQ(elements.ghost_cells, 2u);
  ASSERT_EQ(elements.groups.size(), 1u);
  const std::vector<double>& g = elements.groups[0].geometry;
  ASSERT_EQ(g.size(), 2u * 10 * 3);
  for (int i = 0; i < 10; ++i) {
    EXPECT_LT(g[3 * i], 2.0);
    EXPECT_GT(g[3 * (10 + i)], 5.0);
  }
}

TEST(VtuCells, MixedTypesInOneFileMeshTheSphere) {
  // A cube of side 2.5 as 4³ sub-cubes, each a hexahedron, 6 tetrahedra, 2 wedges or 6 pyramids
  // in turn (quadratic cells, nodes from VTK's parametric coordinates), r² at the nodes: one
  // sphere, two hits per ray through it; the pyramids' cubes lie outside the sphere (their
  // quadratic space does not hold r²).
  auto grid = vtkSmartPointer<vtkUnstructuredGrid>::New();
  vtkNew<vtkPoints> points;
  vtkNew<vtkDoubleArray> u;
  u->SetName("r");
  grid->SetPoints(points);
  const int n = 4;
  const double lo = -1.25, h = 2.5 / n;
  int pyramids = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const glm::dvec3 o = glm::dvec3(lo) + h * glm::dvec3(i, j, k);
        const glm::dvec3 c[8] = {o,
                                 o + h * glm::dvec3(1, 0, 0),
                                 o + h * glm::dvec3(1, 1, 0),
                                 o + h * glm::dvec3(0, 1, 0),
                                 o + h * glm::dvec3(0, 0, 1),
                                 o + h * glm::dvec3(1, 0, 1),
                                 o + h * glm::dvec3(1, 1, 1),
                                 o + h * glm::dvec3(0, 1, 1)};
        const bool outer = i == 0 || j == 0 || k == 0 || i == n - 1 || j == n - 1 || k == n - 1;
        const glm::dvec3 centre = o + 0.5 * h;
        const bool far = glm::length(centre) > 1.0 + 0.9 * h;  // the cube misses the sphere
        const int kind = far && outer ? 3 : (i + 2 * j + 3 * k) % 3;
        std::vector<std::pair<int, std::vector<glm::dvec3>>> parts;  // (VTK type, corners)
        if (kind == 0) parts.push_back({VTK_TRIQUADRATIC_HEXAHEDRON, {c, c + 8}});
        if (kind == 1)
          for (const auto& tet : {std::vector<int>{0, 1, 2, 6},
                                  {0, 2, 3, 6},
                                  {0, 3, 7, 6},
                                  {0, 7, 4, 6},
                                  {0, 4, 5, 6},
                                  {0, 5, 1, 6}})
            parts.push_back({VTK_QUADRATIC_TETRA, {c[tet[0]], c[tet[1]], c[tet[2]], c[tet[3]]}});
        if (kind == 2) {
          parts.push_back({VTK_QUADRATIC_WEDGE, {c[0], c[1], c[2], c[4], c[5], c[6]}});
          parts.push_back({VTK_BIQUADRATIC_QUADRATIC_WEDGE, {c[0], c[2], c[3], c[4], c[6], c[7]}});
        }
        if (kind == 3) {
          for (const auto& f : {std::vector<int>{0, 3, 2, 1},
                                {4, 5, 6, 7},
                                {0, 1, 5, 4},
                                {1, 2, 6, 5},
                                {2, 3, 7, 6},
                                {3, 0, 4, 7}})
            parts.push_back({VTK_QUADRATIC_PYRAMID, {c[f[0]], c[f[1]], c[f[2]], c[f[3]], centre}});
          ++pyramids;
        }
        for (const auto& [type, corners] : parts) {
          const int count = type == VTK_TRIQUADRATIC_HEXAHEDRON       ? 27
                            : type == VTK_QUADRATIC_TETRA             ? 10
                            : type == VTK_QUADRATIC_WEDGE             ? 15
                            : type == VTK_BIQUADRATIC_QUADRATIC_WEDGE ? 18
                                                                      : 13;
          std::vector<vtkIdType> ids(count);
          for (int m = 0; m < count; ++m)
            ids[m] = points->InsertNextPoint(0.0, 0.0, 0.0);
          const vtkIdType id = grid->InsertNextCell(type, count, ids.data());
          vtkSmartPointer<vtkCell> cell = vtk_cell(grid, id);
          const double* pc = cell->GetParametricCoords();
          // The linear cell's map of the corners (VTK's vertex order for each shape).
          const CellType shape = type == VTK_TRIQUADRATIC_HEXAHEDRON ? CellType::hexahedron
                                 : type == VTK_QUADRATIC_TETRA       ? CellType::tetrahedron
                                 : type == VTK_QUADRATIC_PYRAMID     ? CellType::pyramid
                                                                     : CellType::wedge;
          for (int m = 0; m < count; ++m) {
            const std::vector<double> w =
                cell_shape_functions(shape, 1, glm::dvec3(pc[3 * m], pc[3 * m + 1], pc[3 * m + 2]));
            glm::dvec3 x(0.0);
            for (std::size_t v = 0; v < w.size(); ++v)
              x += w[v] * corners[v];
            points->SetPoint(ids[m], x.x, x.y, x.z);
          }
        }
      }
  ASSERT_GT(pyramids, 0);
  for (vtkIdType k = 0; k < points->GetNumberOfPoints(); ++k) {
    double x[3];
    points->GetPoint(k, x);
    u->InsertNextValue(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
  }
  grid->GetPointData()->AddArray(u);
  const std::string path = temp_path("mixed.vtu");
  vtkNew<vtkXMLUnstructuredGridWriter> writer;
  writer->SetFileName(path.c_str());
  writer->SetInputData(grid);
  ASSERT_EQ(writer->Write(), 1);
  VtuField data;
  const Status st = read_vtu_field(path, "r", data);
  std::filesystem::remove(path);
  ASSERT_TRUE(st) << st.message();
  // Hexahedra, tetrahedra, wedges, 15-node wedges, pyramids.
  EXPECT_EQ(data.elements.groups.size(), 5u);
  std::vector<const FieldSource*> list;
  for (const auto& s : data.sources)
    list.push_back(s.get());
  const RayCaster caster(list, 1.0);
  for (const View& view : testing::axis_and_oblique_views(data.elements.bounds, 32)) {
    const testing::SphereRays rays = testing::expect_sphere_hits(caster.cast(view), 1.0, 1e-6);
    EXPECT_GT(rays.through, 100);
  }
}

}  // namespace
}  // namespace ldimesh

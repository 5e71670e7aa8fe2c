// The Fortran module's elements (adaptor/fortran/ldimesh_mod.f90, ldimesh_add_hex_elements)
// under mpiexec: fortran_hex_elements.f90 builds a solver's arrays in Fortran and hands them
// over through the module; this side creates the adaptor through the C API, runs the step and
// reads the published surface back. Collective tests (tests/mpi/mpi_gtest.hpp).
#include "ldimesh.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "../mpi/mpi_gtest.hpp"
#include "published_step.hpp"

extern "C" int fortran_add_hex_elements(ldimesh_adaptor* a, int rank, int ranks, int curved);
extern "C" int fortran_refused_shapes(ldimesh_adaptor* a);
extern "C" int fortran_add_grid_field(ldimesh_adaptor* a, int rank);
extern "C" int fortran_add_cells(ldimesh_adaptor* a, int rank, int ranks);
extern "C" int fortran_add_tets_by_corners(ldimesh_adaptor* a, int rank, int ranks);

namespace ldimesh {
namespace {

using testing::rank_of;
using testing::ranks;

ldimesh_adaptor* create(const std::string& dir) {
  const std::string options =
      R"({"server": {"enabled": false}, "log": false, "resolution": 48, "isovalues": [0.3],
          "colour_by": "y", "output_dir": ")" +
      dir + R"("})";
  ldimesh_adaptor* a = nullptr;
  EXPECT_EQ(ldimesh_create(MPI_COMM_WORLD, options.c_str(), &a), LDIMESH_OK)
      << ldimesh_last_error(nullptr);
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  EXPECT_EQ(ldimesh_set_domain(a, lo, hi), a ? LDIMESH_OK : LDIMESH_ERROR_ARGUMENT);
  return a;
}

// The published step 1 in `dir` is the whole plane x = 0.3 across the unit cube, its vertices
// on it (within Draco's quantization), each coloured by its y.
void expect_plane_coloured_by_y(const std::string& dir, const std::string& what) {
  const Mesh mesh = testing::published_mesh(dir, 1);
  EXPECT_GT(mesh.vertex_count(), 500u) << what;
  double far = 0.0;
  glm::dvec3 lo(1.0), hi(0.0);
  for (const glm::vec3& v : mesh.positions) {
    far = std::max(far, std::abs(double(v.x) - 0.3));
    lo = glm::min(lo, glm::dvec3(v));
    hi = glm::max(hi, glm::dvec3(v));
  }
  EXPECT_LT(far, 1e-4) << what;
  // The whole plane across the cube, not a piece of it.
  EXPECT_LT(std::max(lo.y, lo.z), 0.05) << what;
  EXPECT_GT(std::min(hi.y, hi.z), 0.95) << what;
  testing::expect_coloured_by(
      mesh, testing::published_step(dir, 1), "y", [](glm::dvec3 p) { return p.y; }, 1.0, 1.0 / 48);
}

// The field x on 2³ elements of order 2, curved (interiors bent along x) or straight with float
// values: the isosurface x = 0.3 is a plane, whatever the geometry, and the published vertices
// lie on it (within Draco's quantization); coloured by the field y (ldimesh_add_field), which
// the elements represent exactly: each vertex's colour is its y.
TEST(FortranApi, HexElementsArePublishedOnTheirIsosurface) {
  for (const int curved : {1, 0}) {
    const std::string what = curved ? "curved geometry" : "corners, float values";
    const std::string dir =
        testing::fresh_temp_dir("ldimesh_fortran_api", curved ? "curved" : "corners");
    ldimesh_adaptor* a = create(dir);
    if (!a) return;
    EXPECT_EQ(fortran_add_hex_elements(a, rank_of(), ranks(), curved), LDIMESH_OK)
        << what << ": " << ldimesh_last_error(a);
    EXPECT_EQ(ldimesh_execute(a, 1, 0.0), LDIMESH_OK) << ldimesh_last_error(a);
    EXPECT_EQ(ldimesh_finalize(a), LDIMESH_OK) << ldimesh_last_error(a);
    if (rank_of() == 0) expect_plane_coloured_by_y(dir, what);
    ldimesh_destroy(a);
  }
}

// A grid block from a 3D Fortran array with its field y (ldimesh_add_field's grid form): the
// plane x = 0.3, each vertex coloured by its y.
TEST(FortranApi, AGridBlocksFieldColoursItsSurface) {
  const std::string dir = testing::fresh_temp_dir("ldimesh_fortran_api", "grid_field");
  ldimesh_adaptor* a = create(dir);
  if (!a) return;
  EXPECT_EQ(fortran_add_grid_field(a, rank_of()), LDIMESH_OK) << ldimesh_last_error(a);
  EXPECT_EQ(ldimesh_execute(a, 1, 0.0), LDIMESH_OK) << ldimesh_last_error(a);
  EXPECT_EQ(ldimesh_finalize(a), LDIMESH_OK) << ldimesh_last_error(a);
  if (rank_of() == 0) expect_plane_coloured_by_y(dir, "grid");
  ldimesh_destroy(a);
}

// Cells through ldimesh_add_cells with their field y: linear wedges, and quadratic tetrahedra
// given by their corners (geometry_order = 1): the plane x = 0.3, coloured by y; calls whose
// shapes do not fit the cell type (or the geometry order) refused with a message.
TEST(FortranApi, CellsArePublishedOnTheirIsosurface) {
  struct Case {
    const char* what;
    int (*add)(ldimesh_adaptor*, int, int);
  };
  for (const Case& c : {Case{"wedges", fortran_add_cells},
                        Case{"tetrahedra by their corners", fortran_add_tets_by_corners}}) {
    SCOPED_TRACE(c.what);
    const std::string dir = testing::fresh_temp_dir("ldimesh_fortran_api", "cells");
    ldimesh_adaptor* a = create(dir);
    if (!a) return;
    EXPECT_EQ(c.add(a, rank_of(), ranks()), LDIMESH_OK) << ldimesh_last_error(a);
    EXPECT_EQ(ldimesh_execute(a, 1, 0.0), LDIMESH_OK) << ldimesh_last_error(a);
    EXPECT_EQ(ldimesh_finalize(a), LDIMESH_OK) << ldimesh_last_error(a);
    if (rank_of() == 0) expect_plane_coloured_by_y(dir, c.what);
    ldimesh_destroy(a);
  }
}

TEST(FortranApi, WrongShapesAreRefusedWithAMessage) {
  const std::string dir = testing::fresh_temp_dir("ldimesh_fortran_api", "refused");
  ldimesh_adaptor* a = create(dir);
  if (!a) return;
  EXPECT_EQ(fortran_refused_shapes(a), 0);
  // Nothing was added by the refused calls: the good elements alone give the plane.
  EXPECT_EQ(fortran_add_hex_elements(a, rank_of(), ranks(), 1), LDIMESH_OK)
      << ldimesh_last_error(a);
  EXPECT_EQ(ldimesh_execute(a, 1, 0.0), LDIMESH_OK) << ldimesh_last_error(a);
  EXPECT_EQ(ldimesh_finalize(a), LDIMESH_OK);
  if (rank_of() == 0) {
    EXPECT_GT(testing::published_mesh(dir, 1).vertex_count(), 500u);
  }
  ldimesh_destroy(a);
}

}  // namespace
}  // namespace ldimesh

int main(int argc, char** argv) {
  return ldimesh::testing::run_mpi_tests(argc, argv);
}

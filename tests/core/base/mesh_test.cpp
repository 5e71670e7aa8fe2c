// check_mesh: the one check of the meshes merging, the quad conversion and the GLB encoder are
// given — each defect found with its message, the optional checks only when asked for.
#include "ldimesh/core/base/mesh.hpp"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

namespace ldimesh {
namespace {

// Two triangles and a quad over five vertices, with views.
Mesh small_mesh() {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {2, 0, 0}};
  m.normals.assign(5, {0, 0, 1});
  m.quads = {0, 1, 2, 3};
  m.triangles = {1, 4, 2, 0, 2, 3};
  m.quad_view = {0};
  m.triangle_view = {1, 2};
  return m;
}

void expect_error(const Mesh& m, const MeshChecks& checks, const std::string& words) {
  const Status s = check_mesh(m, checks);
  EXPECT_EQ(s.code(), StatusCode::invalid_argument) << words;
  EXPECT_NE(s.message().find(words), std::string::npos) << s.message();
}

TEST(CheckMesh, AWellFormedMeshPassesEveryCheck) {
  const Mesh m = small_mesh();
  EXPECT_TRUE(check_mesh(m).is_ok());
  EXPECT_TRUE(check_mesh(m, {.views_per_face = true, .distinct_corners = true, .finite = true}));
  Mesh no_views = m;
  no_views.quad_view.clear();
  no_views.triangle_view.clear();
  EXPECT_TRUE(check_mesh(no_views).is_ok());  // views are optional unless asked for
  expect_error(no_views, {.views_per_face = true}, "quad_view or triangle_view");
}

TEST(CheckMesh, EachStructuralDefectIsNamed) {
  Mesh m = small_mesh();
  m.normals.pop_back();
  expect_error(m, {}, "normals and positions differ");
  m = small_mesh();
  m.scalars = {1.0f, 2.0f};
  expect_error(m, {}, "scalars and positions differ");
  m = small_mesh();
  m.triangles.pop_back();
  expect_error(m, {}, "a partial face");
  m = small_mesh();
  m.triangle_view.push_back(0);
  expect_error(m, {}, "quad_view or triangle_view");
  m = small_mesh();
  m.quads[2] = 5;
  expect_error(m, {}, "out of range");
}

TEST(CheckMesh, RepeatedCornersAndNonFiniteValuesOnlyWhenAsked) {
  Mesh m = small_mesh();
  m.triangles[2] = 1;  // triangle 1, 4, 1
  EXPECT_TRUE(check_mesh(m).is_ok());
  expect_error(m, {.distinct_corners = true}, "repeated vertex");
  m = small_mesh();
  m.positions[4].y = std::nanf("");
  EXPECT_TRUE(check_mesh(m).is_ok());
  expect_error(m, {.finite = true}, "position or normal is not finite");
  m = small_mesh();
  m.scalars.assign(5, 0.0f);
  m.scalars[3] = INFINITY;
  expect_error(m, {.finite = true}, "scalar is not finite");
}

}  // namespace
}  // namespace ldimesh

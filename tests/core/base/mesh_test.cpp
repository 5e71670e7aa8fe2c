// check_mesh: the one check of the meshes merging, the quad conversion and the GLB encoder are
// given — each defect found with its message, the optional checks only when asked for; and the
// helpers that join a step's surfaces (append_mesh, replace_nonfinite_scalars).
#include "ldimesh/core/base/mesh.hpp"

#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

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

// append_mesh: b's vertices after a's, its faces renumbered by a's vertex count with their views,
// scalars appended, a's view directions kept (b's taken where a has none).
TEST(AppendMesh, RenumbersTheFacesAndKeepsEveryArrayPerElement) {
  Mesh a = small_mesh();
  a.scalars = {1, 2, 3, 4, 5};
  Mesh b;
  b.positions = {{5, 5, 5}, {6, 5, 5}, {6, 6, 5}, {5, 6, 5}};
  b.normals.assign(4, {1, 0, 0});
  b.scalars = {-1, -2, -3, -4};
  b.triangles = {0, 1, 2};
  b.quads = {3, 2, 1, 0};
  b.triangle_view = {7};
  b.quad_view = {6};
  b.view_dirs = {{1, 0, 0}};
  append_mesh(a, b);
  ASSERT_EQ(a.vertex_count(), 9u);
  EXPECT_EQ(a.positions[5], glm::vec3(5, 5, 5));
  EXPECT_EQ(a.normals[8], glm::vec3(1, 0, 0));
  EXPECT_EQ(a.scalars, (std::vector<float>{1, 2, 3, 4, 5, -1, -2, -3, -4}));
  EXPECT_EQ(a.triangles, (std::vector<std::uint32_t>{1, 4, 2, 0, 2, 3, 5, 6, 7}));
  EXPECT_EQ(a.quads, (std::vector<std::uint32_t>{0, 1, 2, 3, 8, 7, 6, 5}));
  EXPECT_EQ(a.triangle_view, (std::vector<std::uint8_t>{1, 2, 7}));
  EXPECT_EQ(a.quad_view, (std::vector<std::uint8_t>{0, 6}));
  EXPECT_EQ(a.view_dirs, b.view_dirs);  // a had none
  EXPECT_TRUE(check_mesh(a, {.views_per_face = true, .distinct_corners = true}));

  Mesh c = b;
  c.view_dirs = {{0, 0, 1}};
  append_mesh(c, a);  // c keeps its own view directions
  EXPECT_EQ(c.view_dirs, (std::vector<glm::dvec3>{{0, 0, 1}}));
  EXPECT_EQ(c.vertex_count(), 13u);
  EXPECT_EQ(c.triangles[3], 4u + 1u);  // a's first triangle after c's 4 vertices

  Mesh empty;
  append_mesh(empty, b);  // into an empty mesh: b itself
  EXPECT_EQ(empty.triangles, b.triangles);
  EXPECT_EQ(empty.quads, b.quads);
}

// replace_nonfinite_scalars: NaN and ±Inf take the smallest finite value (over all parts
// together), 0 where there is none; the count replaced; finite values untouched.
TEST(ReplaceNonfiniteScalars, TakeTheSmallestFiniteValueOfAllParts) {
  Mesh m;
  m.scalars = {3.0f, NAN, -2.5f, INFINITY, -INFINITY, 7.0f};
  EXPECT_EQ(replace_nonfinite_scalars(m), 3u);
  EXPECT_EQ(m.scalars, (std::vector<float>{3.0f, -2.5f, -2.5f, -2.5f, -2.5f, 7.0f}));
  EXPECT_EQ(replace_nonfinite_scalars(m), 0u);  // nothing left to replace

  std::vector<float> first = {NAN, 4.0f}, second = {1.5f, INFINITY};
  const std::span<float> parts[] = {first, second};
  EXPECT_EQ(replace_nonfinite_scalars(parts), 2u);
  EXPECT_EQ(first, (std::vector<float>{1.5f, 4.0f}));  // the other part's 1.5 is the smallest
  EXPECT_EQ(second, (std::vector<float>{1.5f, 1.5f}));

  Mesh none;
  none.scalars = {NAN, -INFINITY};
  EXPECT_EQ(replace_nonfinite_scalars(none), 2u);
  EXPECT_EQ(none.scalars, (std::vector<float>{0.0f, 0.0f}));
  Mesh empty;
  EXPECT_EQ(replace_nonfinite_scalars(empty), 0u);
}

}  // namespace
}  // namespace ldimesh

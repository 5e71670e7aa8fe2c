#include "ldimesh/core/merge/crossings.hpp"

#include <limits>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace ldimesh {
namespace {

// Sheet A: a fan of four triangles around vertex 0 in the plane z = 0; sheet B: one triangle
// at z = 0.5 over the fan's centre, sharing no vertex with it. Vertex 0 was moved from the
// origin to `centre`.
Mesh two_sheets(glm::vec3 centre) {
  Mesh m;
  m.positions = {centre,
                 {1.0f, 0.0f, 0.0f},
                 {0.0f, 1.0f, 0.0f},
                 {-1.0f, 0.0f, 0.0f},
                 {0.0f, -1.0f, 0.0f},
                 {-2.0f, -2.0f, 0.5f},
                 {2.0f, -2.0f, 0.5f},
                 {0.0f, 2.0f, 0.5f}};
  m.normals.assign(m.positions.size(), {0.0f, 0.0f, 1.0f});
  m.normals[0] = {0.6f, 0.0f, 0.8f};
  m.triangles = {0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1, 5, 6, 7};
  return m;
}

const std::vector<VertexMove> kMoved = {{0, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 1.0f}}};

TEST(Crossings, MoveThroughAnotherSheetIsPutBack) {
  Mesh m = two_sheets({0.0f, 0.0f, 1.0f});  // the fan now pokes through sheet B
  EXPECT_EQ(undo_crossing_moves(m, kMoved, 1.0), 1u);
  EXPECT_EQ(m.positions[0], glm::vec3(0.0f));
  EXPECT_EQ(m.normals[0], glm::vec3(0.0f, 0.0f, 1.0f));
  // Nothing else moved.
  EXPECT_EQ(m.positions[5], glm::vec3(-2.0f, -2.0f, 0.5f));
}

// A vertex listed twice (a projected path vertex that was smoothed too) goes back to its first
// entry; renumber_moves keeps the moves of kept vertices under their new indices.
TEST(Crossings, FirstEntryWinsAndMovesFollowTheRenumbering) {
  Mesh m = two_sheets({0.0f, 0.0f, 1.0f});
  std::vector<VertexMove> moved = kMoved;
  moved.push_back({0, {0.0f, 0.0f, 0.9f}, {0.0f, 0.0f, 1.0f}});
  EXPECT_EQ(undo_crossing_moves(m, moved, 1.0), 1u);
  EXPECT_EQ(m.positions[0], glm::vec3(0.0f));
  const std::vector<std::uint32_t> index = {UINT32_MAX, 0, 1};
  std::vector<VertexMove> moves = {{0, {1.0f, 0.0f, 0.0f}, {}},
                                   {2, {2.0f, 0.0f, 0.0f}, {}},
                                   {7, {3.0f, 0.0f, 0.0f}, {}},
                                   {1, {4.0f, 0.0f, 0.0f}, {}}};
  renumber_moves(moves, index);  // 0 dropped, 2 → 1, 7 out of range, 1 → 0
  ASSERT_EQ(moves.size(), 2u);
  EXPECT_EQ(moves[0].vertex, 1u);
  EXPECT_EQ(moves[0].position, glm::vec3(2.0f, 0.0f, 0.0f));
  EXPECT_EQ(moves[1].vertex, 0u);
  EXPECT_EQ(moves[1].position, glm::vec3(4.0f, 0.0f, 0.0f));
}

TEST(Crossings, MoveThatCrossesNothingStays) {
  Mesh m = two_sheets({0.0f, 0.0f, 0.2f});  // still below sheet B
  EXPECT_EQ(undo_crossing_moves(m, kMoved, 1.0), 0u);
  EXPECT_EQ(m.positions[0], glm::vec3(0.0f, 0.0f, 0.2f));
}

TEST(Crossings, AnyCellSizeFindsTheCrossing) {
  // 1e-7 and 1e-12: far more cells than the grids hold, so they take coarser ones.
  for (double cell : {1e-12, 1e-7, 0.05, 0.3, 1.0, 10.0}) {
    Mesh m = two_sheets({0.0f, 0.0f, 1.0f});
    EXPECT_EQ(undo_crossing_moves(m, kMoved, cell), 1u) << cell;
  }
}

TEST(Crossings, MovesShorterThanTheMinimumAreNotChecked) {
  Mesh m = two_sheets({0.0f, 0.0f, 1.0f});
  EXPECT_EQ(undo_crossing_moves(m, kMoved, 1.0, 1.5), 0u);  // moved by 1
  EXPECT_EQ(m.positions[0], glm::vec3(0.0f, 0.0f, 1.0f));
}

TEST(Crossings, QuadsCountBothDiagonals) {
  // A non-planar quad: split (0, 1, 2) + (0, 2, 3) it is z = 0.2x − 0.2y on the needle's side,
  // split (1, 2, 3) + (1, 3, 0) it is z = 0.4 − 0.2x − 0.2y: at (0.5, 0.3) 0.04 and 0.24. The
  // needle's foot (vertex 4) moved from z = 0.5 down to 0.1, between the two.
  Mesh m;
  m.positions = {{-1.0f, -1.0f, 0.0f}, {1.0f, -1.0f, 0.4f}, {1.0f, 1.0f, 0.0f}, {-1.0f, 1.0f, 0.4f},
                 {0.5f, 0.3f, 0.1f},   {0.5f, 0.3f, 1.0f},  {0.6f, 0.3f, 1.0f}};
  m.normals.assign(m.positions.size(), {0.0f, 0.0f, 1.0f});
  m.triangles = {4, 5, 6};
  const std::vector<VertexMove> moved = {{4, {0.5f, 0.3f, 0.5f}, {0.0f, 0.0f, 1.0f}}};
  Mesh split = m;  // the quad as the (0, 2) split only: the needle passes above it
  split.triangles.insert(split.triangles.end(), {0, 1, 2, 0, 2, 3});
  EXPECT_EQ(undo_crossing_moves(split, moved, 0.5), 0u);
  m.quads = {0, 1, 2, 3};
  EXPECT_EQ(undo_crossing_moves(m, moved, 0.5), 1u);
  EXPECT_EQ(m.positions[4], glm::vec3(0.5f, 0.3f, 0.5f));
  // Faces that share a vertex never count as crossing.
  CrossingPolygon quad, needle;
  quad.n = 4, needle.n = 3;
  for (std::uint32_t k = 0; k < 4; ++k)
    quad.v[k] = k, quad.p[k] = glm::dvec3(m.positions[k]);
  needle.p = {glm::dvec3(0.5, 0.3, 0.1), glm::dvec3(0.5, 0.3, 1.0), glm::dvec3(0.6, 0.3, 1.0)};
  needle.v = {4, 5, 6};
  EXPECT_TRUE(polygons_cross(quad, needle));
  EXPECT_TRUE(polygons_cross(needle, quad));
  // Triangles that share a vertex never count; a neighbour's other triangles do (a face folded
  // over its neighbour). Given the quad's vertex 0, the needle still passes through (1, 2, 3);
  // given vertex 2 it could only meet (1, 3, 0), which it misses.
  needle.v[0] = 0;
  EXPECT_TRUE(polygons_cross(quad, needle));
  EXPECT_TRUE(polygons_cross(needle, quad));
  needle.v[0] = 2;
  EXPECT_FALSE(polygons_cross(quad, needle));
  EXPECT_FALSE(polygons_cross(needle, quad));
  CrossingPolygon triangle;  // (1, 2, 3) alone
  triangle.n = 3;
  for (std::uint32_t k = 0; k < 3; ++k)
    triangle.v[k] = k + 1, triangle.p[k] = quad.p[k + 1];
  needle.v[0] = 0;
  EXPECT_TRUE(polygons_cross(triangle, needle));
  needle.v[0] = 3;
  EXPECT_FALSE(polygons_cross(triangle, needle));
  // The same face never crosses itself.
  EXPECT_FALSE(polygons_cross(quad, quad));
}

TEST(Crossings, InvalidInputIsRefused) {
  Mesh m = two_sheets({0.0f, 0.0f, 1.0f});
  EXPECT_THROW(undo_crossing_moves(m, kMoved, 0.0), std::invalid_argument);
  EXPECT_THROW(undo_crossing_moves(m, kMoved, std::numeric_limits<double>::infinity()),
               std::invalid_argument);
  const std::vector<VertexMove> outside = {{99, {}, {}}};
  EXPECT_THROW(undo_crossing_moves(m, outside, 1.0), std::invalid_argument);
  Mesh bad = m;
  bad.triangles.push_back(99);
  bad.triangles.push_back(0);
  bad.triangles.push_back(1);
  EXPECT_THROW(undo_crossing_moves(bad, kMoved, 1.0), std::invalid_argument);
  bad = m;
  bad.triangles.pop_back();
  EXPECT_THROW(undo_crossing_moves(bad, kMoved, 1.0), std::invalid_argument);
  bad = m;
  bad.positions[6].y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(undo_crossing_moves(bad, kMoved, 1.0), std::invalid_argument);
  bad = m;
  bad.normals.pop_back();
  EXPECT_THROW(undo_crossing_moves(bad, kMoved, 1.0), std::invalid_argument);
  EXPECT_EQ(m.positions[0], glm::vec3(0.0f, 0.0f, 1.0f));  // the throws changed nothing
}

}  // namespace
}  // namespace ldimesh

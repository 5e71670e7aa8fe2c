#include "ldimesh/core/merge/quadrangulate.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../mesh_topology.hpp"
#include "../test_helpers.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/merge/merge.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

using testing::Topology;
using testing::topology;

// Hand-made meshes: vertices by their coordinates, normals pointing away from `centre`.
struct Builder {
  Mesh mesh;
  glm::dvec3 centre{0.0};
  std::map<std::array<double, 3>, std::uint32_t> index;
  std::uint32_t vertex(double x, double y, double z) {
    const auto [it, added] = index.try_emplace({x, y, z}, std::uint32_t(index.size()));
    if (added) {
      mesh.positions.emplace_back(x, y, z);
      mesh.normals.emplace_back(glm::normalize(glm::dvec3(x, y, z) - centre));
    }
    return it->second;
  }
  void quad(std::array<std::uint32_t, 4> v) {
    mesh.quads.insert(mesh.quads.end(), v.begin(), v.end());
    mesh.quad_view.push_back(0);
  }
  void triangle(std::array<std::uint32_t, 3> v) {
    mesh.triangles.insert(mesh.triangles.end(), v.begin(), v.end());
    mesh.triangle_view.push_back(0);
  }
};

// The surface of the cube [0, n]³ in n × n quads per side, wound outward; cells for which
// skip(axis, side, i, j) holds are left out.
Builder cube(int n, const std::function<bool(int, int, int, int)>& skip) {
  Builder b;
  b.centre = glm::dvec3(0.5 * n);
  b.mesh.view_dirs = {{0.0, 0.0, 1.0}};
  for (int a = 0; a < 3; ++a)
    for (int side : {0, n})
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          if (skip(a, side, i, j)) continue;
          // (a, b, c) cyclic, so e_b × e_c = e_a: (i, j) → (i + 1, j) → … turns about +e_a.
          auto at = [&](int u, int v) {
            std::array<double, 3> p{};
            p[a] = side, p[(a + 1) % 3] = u, p[(a + 2) % 3] = v;
            return b.vertex(p[0], p[1], p[2]);
          };
          std::array<std::uint32_t, 4> q{at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)};
          if (side == 0) std::reverse(q.begin(), q.end());
          b.quad(q);
        }
  return b;
}

QuadOptions exact_options() {
  QuadOptions o;
  o.flip_passes = 0;
  o.smoothing_iterations = 0;
  return o;
}

// A closed quad mesh of one piece with the given Euler characteristic, nothing left over.
void expect_closed_quad_mesh(const Mesh& out, const QuadStats& stats, long euler) {
  const Topology t = topology(out);
  SCOPED_TRACE(t.describe() + "; paired " + std::to_string(stats.paired) + ", paths " +
               std::to_string(stats.paths) + ", rounds " + std::to_string(stats.path_rounds) +
               ", turns " + std::to_string(stats.turns) + ", merges " +
               std::to_string(stats.quad_merges) + ", flips " + std::to_string(stats.flips));
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.euler(), euler);
  EXPECT_EQ(t.pieces, 1u);
  EXPECT_EQ(out.triangle_count(), 0u);
  EXPECT_EQ(stats.leftover_triangles, 0u);
  EXPECT_EQ(out.quad_count(), stats.output_quads);
  ASSERT_EQ(out.quad_view.size(), out.quad_count());
  for (std::uint8_t view : out.quad_view)
    EXPECT_LT(view, out.view_dirs.size());
  EXPECT_EQ(out.normals.size(), out.positions.size());
}

// A triangular prism, its sides k quads long, closed by a triangle at either end; the scalar is
// z.
Builder prism(int k) {
  Builder b;
  b.centre = {0.0, 0.0, 0.5 * k};
  b.mesh.view_dirs = {{0.0, 0.0, 1.0}};
  auto ring = [&](int i, int level) {
    const double angle = 2.0 * M_PI * (i % 3) / 3.0;
    return b.vertex(std::cos(angle), std::sin(angle), level);
  };
  for (int level = 0; level < k; ++level)
    for (int i = 0; i < 3; ++i)
      b.quad({ring(i, level), ring(i + 1, level), ring(i + 1, level + 1), ring(i, level + 1)});
  b.triangle({ring(0, k), ring(1, k), ring(2, k)});
  b.triangle({ring(0, 0), ring(2, 0), ring(1, 0)});
  for (const glm::vec3& p : b.mesh.positions)
    b.mesh.scalars.push_back(p.z);
  return b;
}

// The path from one end triangle of a prism to the other crosses k quads straight, each splits
// in two.
TEST(QuadHandMade, StraightPathSplitsEachQuadInTwo) {
  constexpr int k = 3;
  const Builder b = prism(k);
  QuadStats stats;
  const Mesh out = quadrangulate(b.mesh, exact_options(), stats);
  expect_closed_quad_mesh(out, stats, 2);
  EXPECT_EQ(out.quad_count(), 3u * k + k + 2u);
  EXPECT_EQ(stats.paired, 0u);
  EXPECT_EQ(stats.paths, 1u);
  EXPECT_EQ(stats.turns, 0u);
  EXPECT_EQ(stats.path_splits, std::size_t(k + 1));
  // New vertices are interpolated: the scalar (z) stays equal to z.
  ASSERT_EQ(out.scalars.size(), out.positions.size());
  for (std::size_t v = 0; v < out.positions.size(); ++v)
    EXPECT_NEAR(out.scalars[v], out.positions[v].z, 1e-6);
}

// Two quads of the cube's top side share an edge with a vertex m in its middle; each becomes a
// quad and a triangle, the triangles on opposite ends of m. Their path crosses one quad through
// two edges meeting at a corner: the Fig. 3(d) template makes three quads of it.
Builder cube_with_two_triangles() {
  constexpr int n = 4;
  Builder b = cube(n, [](int a, int side, int i, int j) {
    return a == 2 && side == n && j == 1 && (i == 1 || i == 2);
  });
  auto top = [&](double x, double y) { return b.vertex(x, y, n); };
  const std::uint32_t m = top(2, 1.5);
  b.triangle({top(2, 1), m, top(1, 1)});
  b.quad({top(1, 1), m, top(2, 2), top(1, 2)});
  b.triangle({top(2, 2), m, top(3, 2)});
  b.quad({top(2, 1), top(3, 1), top(3, 2), m});
  return b;
}

TEST(QuadHandMade, TurningPathMakesThreeQuads) {
  const Builder b = cube_with_two_triangles();
  ASSERT_TRUE(topology(b.mesh).closed_manifold());
  QuadStats stats;
  const Mesh out = quadrangulate(b.mesh, exact_options(), stats);
  expect_closed_quad_mesh(out, stats, 2);
  EXPECT_EQ(stats.paired, 0u);
  EXPECT_EQ(stats.paths, 1u);
  EXPECT_EQ(stats.turns, 1u);
  EXPECT_EQ(stats.path_splits, 2u);
  EXPECT_EQ(out.quad_count(), b.mesh.quad_count() + 2u + 2u);  // +2 from the turn, +2 ends
  // Everything stays in the plane of the top side or on the cube.
  for (const glm::vec3& p : out.positions)
    EXPECT_TRUE(p.x == 0 || p.x == 4 || p.y == 0 || p.y == 4 || p.z == 0 || p.z == 4);
}

// With open edges a lone triangle splits one of them; the grid around keeps its open boundary.
TEST(QuadHandMade, TrianglesNextToOpenEdgesEndTheirPathsThere) {
  Builder lone;
  lone.mesh.view_dirs = {{0.0, 0.0, 1.0}};
  lone.centre = {0.0, 0.0, -1.0};
  lone.triangle({lone.vertex(0, 0, 0), lone.vertex(1, 0, 0), lone.vertex(0, 1, 0)});
  QuadStats stats;
  Mesh out = quadrangulate(lone.mesh, exact_options(), stats);
  EXPECT_EQ(out.quad_count(), 1u);
  EXPECT_EQ(out.triangle_count(), 0u);
  EXPECT_EQ(stats.boundary_splits, 1u);
  EXPECT_EQ(topology(out).open_edges, 4u);

  // The top side of cube_with_two_triangles alone: an open 4 × 4 grid.
  Builder grid = cube_with_two_triangles();
  Mesh open = grid.mesh;
  open.quads.clear();
  open.quad_view.clear();
  for (std::size_t q = 0; q < grid.mesh.quads.size(); q += 4) {
    bool on_top = true;
    for (int k = 0; k < 4; ++k)
      on_top = on_top && grid.mesh.positions[grid.mesh.quads[q + k]].z == 4.0f;
    if (!on_top) continue;
    open.quads.insert(open.quads.end(), &grid.mesh.quads[q], &grid.mesh.quads[q] + 4);
    open.quad_view.push_back(0);
  }
  out = quadrangulate(open, exact_options(), stats);
  const Topology t = topology(out);
  SCOPED_TRACE(t.describe());
  EXPECT_EQ(out.triangle_count(), 0u);
  EXPECT_EQ(stats.leftover_triangles, 0u);
  EXPECT_EQ(t.nonmanifold_edges + t.misoriented_edges + t.nonmanifold_vertices, 0u);
  EXPECT_EQ(t.euler(), 1);  // a disc
  EXPECT_GE(t.open_edges, 16u);
}

TEST(QuadInput, InvalidInputThrows) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  QuadStats stats;
  m.triangles = {0, 1, 3};
  EXPECT_THROW(quadrangulate(m, {}, stats), std::invalid_argument);
  m.triangles = {0, 1, 1};
  EXPECT_THROW(quadrangulate(m, {}, stats), std::invalid_argument);
  m.triangles = {0, 1, 2, 0, 1, 2};  // the same edges twice in one direction
  EXPECT_THROW(quadrangulate(m, {}, stats), std::invalid_argument);
  m.triangles = {0, 1};
  EXPECT_THROW(quadrangulate(m, {}, stats), std::invalid_argument);
  m.triangles = {0, 1, 2};
  m.normals.pop_back();
  EXPECT_THROW(quadrangulate(m, {}, stats), std::invalid_argument);
  m.normals.push_back({0, 0, 1});
  m.triangle_view = {0, 0};
  EXPECT_THROW(quadrangulate(m, {}, stats), std::invalid_argument);
  m.triangle_view = {0};
  EXPECT_NO_THROW(quadrangulate(m, {}, stats));
  const Mesh empty = quadrangulate(Mesh{}, {}, stats);
  EXPECT_EQ(empty.vertex_count() + empty.face_count(), 0u);
}

// Merged meshes of the built-in surfaces: triangles only (merging with triangle output) or
// quads with the triangles of the sewing region (merge_views with quad output), cached.
const Mesh& merged(const std::string& surface, int res, bool mixed) {
  static std::map<std::tuple<std::string, int, bool>, Mesh> cache;
  const auto key = std::make_tuple(surface, res, mixed);
  if (const auto it = cache.find(key); it != cache.end()) return it->second;
  const auto source = make_surface_source(surface);
  const SurfaceInfo* info = find_surface(surface);
  const RayCaster caster(*source, info->isovalue);
  std::vector<Ldi> ldis;
  for (const View& view : make_axis_views(source->bounds(), res))
    ldis.push_back(caster.cast(view));
  MeshingOptions options;
  Mesh mesh;
  if (mixed) {
    options.r = 1.0;
    options.faces = FaceType::quads;
    const MeshingResult per_view = mesh_ldis(ldis, options);
    MergeOptions merging;
    merging.enabled = true;
    merging.all_quads = false;  // the quads and the sewing region's triangles, unconverted
    MergeStats stats;
    mesh = merge_views(per_view.mesh, FaceType::quads, merging, stats);
  } else {
    options.merging.enabled = true;
    options.faces = FaceType::triangles;
    mesh = mesh_ldis(ldis, options).mesh;
  }
  return cache.emplace(key, std::move(mesh)).first->second;
}

// Analytic projections onto the unit sphere and the torus R = 1, a = 0.4 (surfaces.cpp).
std::size_t onto_sphere(std::vector<glm::dvec3>& points, std::vector<glm::dvec3>& normals, double) {
  for (std::size_t i = 0; i < points.size(); ++i)
    points[i] = normals[i] = glm::normalize(points[i]);
  return points.size();
}

glm::dvec3 torus_normal(const glm::dvec3& p) {
  const glm::dvec3 ring = glm::normalize(glm::dvec3(p.x, p.y, 0.0));
  return glm::normalize(p - ring);
}

std::size_t onto_torus(std::vector<glm::dvec3>& points, std::vector<glm::dvec3>& normals, double) {
  for (std::size_t i = 0; i < points.size(); ++i) {
    const glm::dvec3 ring = glm::normalize(glm::dvec3(points[i].x, points[i].y, 0.0));
    normals[i] = glm::normalize(points[i] - ring);
    points[i] = ring + 0.4 * normals[i];
  }
  return points.size();
}

double off_surface(const std::string& surface, const glm::dvec3& p) {
  if (surface == "sphere") return std::abs(glm::length(p) - 1.0);
  const glm::dvec3 ring = glm::normalize(glm::dvec3(p.x, p.y, 0.0));
  return std::abs(glm::distance(p, ring) - 0.4);
}

TEST(QuadMerged, SurfacesBecomeClosedQuadMeshes) {
  for (const auto& [surface, euler] : {std::pair<std::string, long>{"sphere", 2}, {"torus", 0}})
    for (int res : {64, 128})
      for (bool mixed : {false, true}) {
        const Mesh& in = merged(surface, res, mixed);
        SCOPED_TRACE(surface + " " + std::to_string(res) + (mixed ? " mixed" : " triangles"));
        ASSERT_TRUE(topology(in).closed_manifold());
        ASSERT_GT(in.triangle_count(), 0u);
        QuadStats stats;
        const Mesh out = quadrangulate(in, {}, stats);
        expect_closed_quad_mesh(out, stats, euler);
        EXPECT_EQ(stats.input_triangles, in.triangle_count());
        if (!mixed) {
          EXPECT_GT(stats.paired, in.triangle_count() / 4);
        }
      }
}

TEST(QuadSmoothing, ProjectionKeepsVerticesOnTheSurface) {
  for (const std::string surface : {"sphere", "torus"}) {
    SCOPED_TRACE(surface);
    const Mesh& in = merged(surface, 64, true);
    QuadStats stats;
    const Mesh out = quadrangulate(in, {}, stats, surface == "sphere" ? onto_sphere : onto_torus);
    expect_closed_quad_mesh(out, stats, surface == "sphere" ? 2 : 0);
    EXPECT_GT(stats.projected, 0u);
    double worst = 0.0, worst_normal = 0.0;
    for (std::size_t v = 0; v < out.positions.size(); ++v) {
      const glm::dvec3 p(out.positions[v]);
      worst = std::max(worst, off_surface(surface, p));
      const glm::dvec3 n = surface == "sphere" ? glm::normalize(p) : torus_normal(p);
      worst_normal = std::max(worst_normal, 1.0 - glm::dot(n, glm::dvec3(out.normals[v])));
    }
    EXPECT_LT(worst, 1e-4);  // the ray caster's input vertices included
    EXPECT_LT(worst_normal, 1e-3);
  }
}

TEST(QuadSmoothing, WithoutProjectionVerticesMoveAtMostTheLimit) {
  const Mesh& in = merged("sphere", 64, true);
  QuadOptions still;
  still.smoothing_iterations = 0;
  QuadStats stats;
  const Mesh before = quadrangulate(in, still, stats);
  QuadOptions options;
  options.smoothing_iterations = 8;
  const Mesh after = quadrangulate(in, options, stats);
  ASSERT_EQ(after.positions.size(), before.positions.size());
  EXPECT_EQ(after.quads, before.quads);
  const double limit = options.max_unprojected_move * stats.median_edge;
  double moved = 0.0;
  for (std::size_t v = 0; v < after.positions.size(); ++v)
    moved = std::max(moved, double(glm::distance(after.positions[v], before.positions[v])));
  EXPECT_GT(moved, 0.1 * limit);
  EXPECT_LE(moved, limit * (1.0 + 1e-4) + 1e-6);
}

// Two rings around each end triangle of a long prism are two separate regions with one triangle
// each and no open edge: the conversion runs again on the whole mesh, as without regions.
TEST(QuadRegion, TrianglesARegionCannotPairAreConvertedOverTheWholeMesh) {
  const Builder b = prism(12);
  QuadOptions whole = exact_options(), rings = exact_options();
  whole.region_rings = -1;
  rings.region_rings = 2;
  QuadStats whole_stats, stats;
  const Mesh expected = quadrangulate(b.mesh, whole, whole_stats);
  const Mesh out = quadrangulate(b.mesh, rings, stats);
  expect_closed_quad_mesh(out, stats, 2);
  EXPECT_EQ(stats.region_faces, b.mesh.face_count());  // fell back to the whole mesh
  EXPECT_EQ(stats.paths, 1u);
  EXPECT_EQ(out.positions, expected.positions);
  EXPECT_EQ(out.quads, expected.quads);
}

// Without triangles the region is empty: every quad and vertex comes out as it went in.
TEST(QuadRegion, QuadsOnlyInputPassesThrough) {
  const Builder b = cube(3, [](int, int, int, int) { return false; });
  QuadStats stats;
  const Mesh out = quadrangulate(b.mesh, {}, stats);
  EXPECT_EQ(stats.region_faces, 0u);
  EXPECT_EQ(out.positions, b.mesh.positions);
  EXPECT_EQ(out.normals, b.mesh.normals);
  EXPECT_EQ(out.quads, b.mesh.quads);
  EXPECT_EQ(out.quad_view, b.mesh.quad_view);
  EXPECT_EQ(out.triangle_count(), 0u);
}

// On a merged sphere the region is the sewing region and a few rings: the quads beyond come
// out as they went in (same corners, same places: the region's edge does not move either).
TEST(QuadRegion, QuadsAwayFromTrianglesPassThroughUnchanged) {
  const Mesh& in = merged("sphere", 128, true);
  QuadStats stats;
  const Mesh out = quadrangulate(in, {}, stats, onto_sphere);
  expect_closed_quad_mesh(out, stats, 2);
  EXPECT_GT(stats.region_faces, in.triangle_count());
  EXPECT_LT(stats.region_faces, in.face_count() / 2);
  using Corners = std::array<float, 12>;
  auto corners = [](const Mesh& m, std::size_t q) {
    Corners c;
    for (int k = 0; k < 4; ++k)
      for (int d = 0; d < 3; ++d)
        c[3 * k + d] = m.positions[m.quads[4 * q + k]][d];
    return c;
  };
  std::set<Corners> output;
  for (std::size_t q = 0; q < out.quad_count(); ++q)
    output.insert(corners(out, q));
  std::size_t kept = 0;
  for (std::size_t q = 0; q < in.quad_count(); ++q)
    kept += output.count(corners(in, q));
  EXPECT_GE(kept, in.face_count() - stats.region_faces);
}

TEST(QuadDeterminism, TwoRunsGiveTheSameMesh) {
  const Mesh& in = merged("torus", 64, true);
  QuadStats a_stats, b_stats;
  const Mesh a = quadrangulate(in, {}, a_stats, onto_torus);
  const Mesh b = quadrangulate(in, {}, b_stats, onto_torus);
  testing::expect_identical(a, b);
}

}  // namespace
}  // namespace ldimesh

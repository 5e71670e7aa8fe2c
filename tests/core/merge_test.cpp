#include "ldimesh/core/merge.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ldimesh/core/distance.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycaster.hpp"
#include "ldimesh/core/sample_source.hpp"
#include "ldimesh/core/surfaces.hpp"
#include "mesh_topology.hpp"

namespace ldimesh {
namespace {

using testing::Topology;
using testing::topology;

std::string describe(const Topology& t, const MergeStats& s) {
  return t.describe() + "; patches " + std::to_string(s.patches) + ", bridges " +
         std::to_string(s.bridges) + ", holes " + std::to_string(s.holes) + ", unfilled " +
         std::to_string(s.unfilled_holes);
}

// The §3 meshes of `surface` at `res`, merged (with the sewing region's new vertices projected
// through a local sample source), or, with merge = false, trimmed with r = 1 and not merged.
MeshingResult merged(const std::string& surface, int res, bool merge = true,
                     FaceType faces = FaceType::triangles) {
  const auto source = make_surface_source(surface);
  const SurfaceInfo* info = find_surface(surface);
  const RayCaster caster(*source, info->isovalue);
  const std::vector<View> views = make_axis_views(source->bounds(), res);
  std::vector<Ldi> ldis;
  for (const View& view : views)
    ldis.push_back(caster.cast(view));
  MeshingOptions options;
  options.r = 1.0;
  options.faces = faces;
  options.merging.enabled = merge;
  LocalSampleSource samples(caster, views);
  return mesh_ldis(ldis, options, &samples);
}

// Pairs of triangles that share no vertex and cross each other (an edge of one passes through
// the other), found through a uniform grid over their bounding boxes.
std::size_t crossing_pairs(const Mesh& m, std::string* where = nullptr) {
  const std::size_t n = m.triangles.size() / 3;
  auto corner = [&](std::size_t t, int k) {
    return glm::dvec3(m.positions[m.triangles[3 * t + k]]);
  };
  double edge = 0.0;
  for (std::size_t t = 0; t < n; ++t)
    edge += glm::distance(corner(t, 0), corner(t, 1));
  const double cell = 2.0 * edge / double(n);
  std::map<std::array<long, 3>, std::vector<std::uint32_t>> grid;
  for (std::uint32_t t = 0; t < n; ++t) {
    glm::dvec3 lo = corner(t, 0), hi = lo;
    for (int k = 1; k < 3; ++k)
      lo = glm::min(lo, corner(t, k)), hi = glm::max(hi, corner(t, k));
    const glm::ivec3 a(glm::floor(lo / cell)), b(glm::floor(hi / cell));
    for (int z = a.z; z <= b.z; ++z)
      for (int y = a.y; y <= b.y; ++y)
        for (int x = a.x; x <= b.x; ++x)
          grid[{x, y, z}].push_back(t);
  }
  // Segment p–q against triangle (a, b, c), strictly inside both.
  auto crosses = [](glm::dvec3 p, glm::dvec3 q, glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
    const glm::dvec3 d = q - p, e1 = b - a, e2 = c - a, h = glm::cross(d, e2);
    const double det = glm::dot(e1, h);
    if (std::abs(det) < 1e-18) return false;
    const glm::dvec3 s = p - a;
    const double u = glm::dot(s, h) / det;
    const glm::dvec3 qv = glm::cross(s, e1);
    const double v = glm::dot(d, qv) / det, t = glm::dot(e2, qv) / det;
    constexpr double eps = 1e-9;
    return u > eps && v > eps && u + v < 1.0 - eps && t > eps && t < 1.0 - eps;
  };
  std::set<std::pair<std::uint32_t, std::uint32_t>> found;
  for (const auto& [key, ts] : grid)
    for (std::size_t i = 0; i < ts.size(); ++i)
      for (std::size_t j = i + 1; j < ts.size(); ++j) {
        const std::uint32_t s = ts[i], t = ts[j];
        bool shared = false;
        for (int k = 0; k < 3; ++k)
          for (int l = 0; l < 3; ++l)
            shared = shared || m.triangles[3 * s + k] == m.triangles[3 * t + l];
        if (shared) continue;
        bool hit = false;
        for (int k = 0; k < 3 && !hit; ++k) {
          hit = crosses(corner(s, k), corner(s, (k + 1) % 3), corner(t, 0), corner(t, 1),
                        corner(t, 2)) ||
                crosses(corner(t, k), corner(t, (k + 1) % 3), corner(s, 0), corner(s, 1),
                        corner(s, 2));
        }
        if (hit && found.insert({s, t}).second && where && found.size() <= 5) {
          const glm::dvec3 c = (corner(s, 0) + corner(s, 1) + corner(s, 2)) / 3.0;
          *where += " (" + std::to_string(c.x) + ", " + std::to_string(c.y) + ", " +
                    std::to_string(c.z) + ")";
        }
      }
  return found.size();
}

// The checker itself: a closed tetrahedron, the same with one face turned, and a bowtie (two
// triangles sharing only a vertex).
TEST(Merge, TopologyCheckerSeesDefects) {
  Mesh tet;
  tet.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tet.triangles = {0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2};
  Topology t = topology(tet);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.euler(), 2);
  EXPECT_EQ(t.pieces, 1u);
  std::swap(tet.triangles[10], tet.triangles[11]);
  EXPECT_EQ(topology(tet).misoriented_edges, 3u);
  Mesh bowtie;
  bowtie.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
  bowtie.triangles = {0, 1, 2, 0, 3, 4};
  t = topology(bowtie);
  EXPECT_EQ(t.nonmanifold_vertices, 1u);
  EXPECT_EQ(t.open_edges, 6u);
  EXPECT_FALSE(t.closed_manifold());
}

TEST(Merge, ClosedSurfacesBecomeOneClosedManifold) {
  for (const auto& [surface, euler] : {std::pair<std::string, long>{"sphere", 2}, {"torus", 0}})
    for (int res : {64, 128}) {
      const MeshingResult r = merged(surface, res);
      const Topology t = topology(r.mesh);
      SCOPED_TRACE(surface + " " + std::to_string(res) + ": " + describe(t, r.merging));
      EXPECT_TRUE(t.closed_manifold());
      EXPECT_EQ(t.euler(), euler);
      EXPECT_EQ(t.pieces, 1u);
      EXPECT_EQ(r.merging.unfilled_holes, 0u);
      EXPECT_EQ(r.mesh.quad_count(), 0u);
    }
}

// Klein bottle (an immersed surface: it crosses itself) and Barth's sextic (clipped, many
// pieces): no edge is shared by more than two faces or run the same way by two, and every hole
// left open is counted: the output has open edges exactly when holes are reported.
TEST(Merge, HardSurfacesStayManifoldAndReportTheirHoles) {
  for (const char* surface : {"klein", "barth"})
    for (int res : {64, 128}) {
      const MeshingResult r = merged(surface, res);
      const Topology t = topology(r.mesh);
      SCOPED_TRACE(std::string(surface) + " " + std::to_string(res) + ": " +
                   describe(t, r.merging));
      EXPECT_EQ(t.nonmanifold_edges, 0u);
      EXPECT_EQ(t.misoriented_edges, 0u);
      EXPECT_GT(r.merging.bridges, 0u);
      EXPECT_EQ(r.merging.unfilled_holes == 0, t.open_edges == 0);
      EXPECT_LE(r.merging.unfilled_holes, t.open_edges);
      EXPECT_EQ(r.merging.components, t.pieces);
    }
}

// The crossing check itself: two triangles through each other, then apart.
TEST(Merge, CrossingCheckSeesCrossingTriangles) {
  Mesh m;
  m.positions = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0.5, 0.5, -1}, {0.5, 0.5, 1}, {1.5, 1.5, 0}};
  m.triangles = {0, 1, 2, 3, 4, 5};
  EXPECT_EQ(crossing_pairs(m), 1u);
  m.positions[3].z = m.positions[4].z = 0.5f;
  m.positions[5].z = 0.5f;
  EXPECT_EQ(crossing_pairs(m), 0u);
}

// Bridges and fill triangles never pass through other faces: the merged meshes of the sphere and
// the torus have no crossing triangles. (The Klein bottle crosses itself; Barth's sextic has
// conical double points where its sheets meet, and its merged meshes do have crossing pairs —
// docs/method.md, §5.)
TEST(Merge, BridgesAndFillsDoNotOverlap) {
  for (const char* surface : {"sphere", "torus"})
    for (int res : {64, 128}) {
      SCOPED_TRACE(std::string(surface) + " " + std::to_string(res));
      const MeshingResult r = merged(surface, res);
      EXPECT_GT(r.merging.bridges, 0u);
      std::string where;
      EXPECT_EQ(crossing_pairs(r.mesh, &where), 0u) << "first at" << where;
    }
}

// Merging keeps the surface's accuracy: the forward mean distance to the true surface grows by
// at most 10 % over the r = 1 per-view meshes (flat bridges and fills across gaps of a few
// cells would add more; their long edges are split and the new vertices projected).
TEST(Merge, KeepsTheForwardMeanDistance) {
  for (const char* surface : {"sphere", "torus"})
    for (int res : {64, 128}) {
      const SurfaceInfo* info = find_surface(surface);
      const MeshingResult per_view = merged(surface, res, false), one = merged(surface, res);
      const double before = surface_distance(per_view.mesh, *info, info->isovalue).forward.mean;
      const double after = surface_distance(one.mesh, *info, info->isovalue).forward.mean;
      SCOPED_TRACE(std::string(surface) + " " + std::to_string(res) + ": per view " +
                   std::to_string(before) + ", merged " + std::to_string(after));
      EXPECT_GT(one.merging.split_edges, 0u);
      EXPECT_GT(one.merging.projected, one.merging.split_edges / 2);
      EXPECT_LE(after, 1.1 * before);
    }
}

// §5 (iv) through the pipeline: merged with quad output, the sphere and the torus are closed
// manifolds of quads only, with the right Euler characteristic, in one piece.
TEST(Merge, AllQuadOutputIsClosedQuads) {
  for (const auto& [surface, euler] : {std::pair<std::string, long>{"sphere", 2}, {"torus", 0}})
    for (int res : {64, 128}) {
      const MeshingResult r = merged(surface, res, true, FaceType::quads);
      const Topology t = topology(r.mesh);
      SCOPED_TRACE(surface + " " + std::to_string(res) + ": " + describe(t, r.merging));
      EXPECT_EQ(r.mesh.triangle_count(), 0u);
      EXPECT_EQ(r.merging.quads.leftover_triangles, 0u);
      EXPECT_EQ(r.mesh.quad_count(), r.merging.quads.output_quads);
      EXPECT_GT(r.merging.quads.input_triangles, 0u);
      EXPECT_TRUE(t.closed_manifold());
      EXPECT_EQ(t.euler(), euler);
      EXPECT_EQ(t.pieces, 1u);
      EXPECT_EQ(r.mesh.quad_view.size(), r.mesh.quad_count());
    }
}

}  // namespace
}  // namespace ldimesh

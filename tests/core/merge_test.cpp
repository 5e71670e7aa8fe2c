#include "ldimesh/core/merge.hpp"

#include <algorithm>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycaster.hpp"
#include "ldimesh/core/surfaces.hpp"

namespace ldimesh {
namespace {

// Topology of a polygon mesh: edges by the number of faces on them, vertices whose faces do not
// form one fan (disk or half-disk), pieces, and V − E + F.
struct Topology {
  std::size_t vertices = 0, edges = 0, faces = 0;
  std::size_t open_edges = 0;            // one face
  std::size_t nonmanifold_edges = 0;     // three or more faces
  std::size_t misoriented_edges = 0;     // two faces running the same way along the edge
  std::size_t nonmanifold_vertices = 0;  // more than one fan
  std::size_t pieces = 0;
  long euler() const { return long(vertices) - long(edges) + long(faces); }
  bool closed_manifold() const {
    return open_edges == 0 && nonmanifold_edges == 0 && misoriented_edges == 0 &&
           nonmanifold_vertices == 0;
  }
};

std::vector<std::vector<std::uint32_t>> faces_of(const Mesh& m) {
  std::vector<std::vector<std::uint32_t>> faces;
  for (std::size_t q = 0; q < m.quads.size(); q += 4)
    faces.push_back({m.quads[q], m.quads[q + 1], m.quads[q + 2], m.quads[q + 3]});
  for (std::size_t t = 0; t < m.triangles.size(); t += 3)
    faces.push_back({m.triangles[t], m.triangles[t + 1], m.triangles[t + 2]});
  return faces;
}

std::uint32_t find(std::vector<std::uint32_t>& parent, std::uint32_t a) {
  while (parent[a] != a)
    a = parent[a] = parent[parent[a]];
  return a;
}

Topology topology(const Mesh& m) {
  Topology t;
  const auto faces = faces_of(m);
  t.faces = faces.size();
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  std::set<std::uint32_t> used;
  std::vector<std::uint32_t> parent(m.positions.size());
  for (std::uint32_t v = 0; v < parent.size(); ++v)
    parent[v] = v;
  // Per vertex: its faces' corner edges (prev, next), to count fans.
  std::map<std::uint32_t, std::vector<std::pair<std::uint32_t, std::uint32_t>>> corners;
  for (const auto& f : faces)
    for (std::size_t i = 0; i < f.size(); ++i) {
      const std::uint32_t a = f[i], b = f[(i + 1) % f.size()];
      ++directed[{a, b}];
      used.insert(a);
      parent[find(parent, a)] = find(parent, b);
      corners[a].push_back({f[(i + f.size() - 1) % f.size()], b});
    }
  t.vertices = used.size();
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> undirected;
  for (const auto& [e, n] : directed) {
    undirected[{std::min(e.first, e.second), std::max(e.first, e.second)}] += n;
    if (n > 1) ++t.misoriented_edges;
  }
  t.edges = undirected.size();
  for (const auto& [e, n] : undirected) {
    if (n == 1) ++t.open_edges;
    if (n > 2) ++t.nonmanifold_edges;
  }
  // Fans: corners (prev, v, next) chained where one corner's next is another's prev.
  for (const auto& [v, cs] : corners) {
    std::vector<std::uint32_t> p(cs.size());
    for (std::uint32_t k = 0; k < cs.size(); ++k)
      p[k] = k;
    std::map<std::uint32_t, std::vector<std::uint32_t>> at;
    for (std::uint32_t k = 0; k < cs.size(); ++k) {
      at[cs[k].first].push_back(k);
      at[cs[k].second].push_back(k);
    }
    for (const auto& [n, ks] : at)
      for (std::uint32_t k : ks)
        p[find(p, k)] = find(p, ks[0]);
    std::size_t fans = 0;
    for (std::uint32_t k = 0; k < cs.size(); ++k)
      if (find(p, k) == k) ++fans;
    if (fans > 1) ++t.nonmanifold_vertices;
  }
  for (std::uint32_t v : used)
    if (find(parent, v) == v) ++t.pieces;
  return t;
}

std::string describe(const Topology& t, const MergeStats& s) {
  return "V " + std::to_string(t.vertices) + ", E " + std::to_string(t.edges) + ", F " +
         std::to_string(t.faces) + ", open edges " + std::to_string(t.open_edges) +
         ", non-manifold edges " + std::to_string(t.nonmanifold_edges) + ", misoriented " +
         std::to_string(t.misoriented_edges) + ", non-manifold vertices " +
         std::to_string(t.nonmanifold_vertices) + ", pieces " + std::to_string(t.pieces) +
         "; patches " + std::to_string(s.patches) + ", bridges " + std::to_string(s.bridges) +
         ", holes " + std::to_string(s.holes) + ", unfilled " + std::to_string(s.unfilled_holes);
}

MeshingResult merged(const std::string& surface, int res, MergeOptions merging = {}) {
  const auto source = make_surface_source(surface);
  const SurfaceInfo* info = find_surface(surface);
  const RayCaster caster(*source, info->isovalue);
  std::vector<Ldi> ldis;
  for (const View& view : make_axis_views(source->bounds(), res))
    ldis.push_back(caster.cast(view));
  MeshingOptions options;
  options.merging = merging;
  options.merging.enabled = true;
  return mesh_ldis(ldis, options);
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

TEST(Merge, RefusesQuadOutputForNow) {
  const auto source = make_surface_source("sphere");
  const RayCaster caster(*source, 1.0);
  std::vector<Ldi> ldis;
  for (const View& view : make_axis_views(source->bounds(), 16))
    ldis.push_back(caster.cast(view));
  MeshingOptions options;
  options.merging.enabled = true;
  options.faces = FaceType::quads;
  EXPECT_THROW(mesh_ldis(ldis, options), std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

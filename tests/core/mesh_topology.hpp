// Topology checks for the merging tests (merge_test.cpp, quadrangulate_test.cpp): is a mesh a
// closed, consistently oriented 2-manifold, of which Euler characteristic, in how many pieces.
#pragma once

#include <algorithm>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "ldimesh/core/base/mesh.hpp"

namespace ldimesh::testing {

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
  std::string describe() const {
    return "V " + std::to_string(vertices) + ", E " + std::to_string(edges) + ", F " +
           std::to_string(faces) + ", open " + std::to_string(open_edges) + ", non-manifold " +
           std::to_string(nonmanifold_edges) + ", misoriented " +
           std::to_string(misoriented_edges) + ", non-manifold vertices " +
           std::to_string(nonmanifold_vertices) + ", pieces " + std::to_string(pieces);
  }
};

inline std::vector<std::vector<std::uint32_t>> faces_of(const Mesh& m) {
  std::vector<std::vector<std::uint32_t>> faces;
  for (std::size_t q = 0; q < m.quads.size(); q += 4)
    faces.push_back({m.quads[q], m.quads[q + 1], m.quads[q + 2], m.quads[q + 3]});
  for (std::size_t t = 0; t < m.triangles.size(); t += 3)
    faces.push_back({m.triangles[t], m.triangles[t + 1], m.triangles[t + 2]});
  return faces;
}

inline std::uint32_t find(std::vector<std::uint32_t>& parent, std::uint32_t a) {
  while (parent[a] != a)
    a = parent[a] = parent[parent[a]];
  return a;
}

inline Topology topology(const Mesh& m) {
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

}  // namespace ldimesh::testing

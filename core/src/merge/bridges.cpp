// §5 (i) bridges between close patches (merge_state.hpp).
#include <algorithm>
#include <cmath>
#include <queue>
#include <unordered_map>
#include <vector>

#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "merge_state.hpp"

namespace ldimesh::merge_detail {

void bridge(MergeState& ms) {
  // Patches: connected pieces of the whole mesh, through shared vertices (input numbers: a
  // piece is named by its smallest vertex, as when the whole mesh is built).
  UnionFind pieces(ms.in_.positions.size());
  for (const auto& f : ms.mesh_.faces()) {
    const std::uint32_t first = ms.global(f.halfedge().from());
    for (const auto& v : f.vertices())
      pieces.join(first, ms.global(v));
  }
  for (std::size_t f = 0; f < ms.region_.inside.size(); ++f)
    if (!ms.region_.inside[f]) {
      const auto c = face_corners(ms.in_, f);
      for (std::uint32_t v : c)
        pieces.join(c[0], v);
    }
  std::vector<HH> open;
  double longest = 0.0;
  for (const auto& h : ms.mesh_.halfedges())
    if (ms.is_open(h)) {
      open.push_back(h);
      longest = std::max(longest, ms.length(h));
    }
  for (std::uint32_t g = 0; g < ms.in_.positions.size(); ++g) {
    const std::uint32_t l = ms.region_.local[g];
    const bool used = l == kNone ? bool(ms.region_.used[g]) : ms.alive(VH(int(l)));
    if (used && pieces.find(g) == g) ++ms.stats_.patches;
  }
  if (open.empty() || ms.scale_ <= 0.0) return;
  // Open half-edges by their start vertex in a uniform grid whose cells are as wide as the
  // longest connecting edge a bridge may have, so each half-edge looks at 27 cells.
  const double reach = ms.options_.bridge_limit * std::min(2.0 * longest, 8.0 * ms.scale_);
  const double cell = std::max(2.0 * ms.scale_, reach);
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid;
  for (std::uint32_t k = 0; k < open.size(); ++k)
    grid[grid_cell_key(grid_cell(ms.point(ms.mesh_.from_vertex_handle(open[k])), cell))].push_back(
        k);

  struct Candidate {
    double cost;
    HH a, b;
  };
  struct PairBest {
    std::vector<Candidate> best;  // up to kKeep, cheapest first
    bool done = false;            // the paper's early stop: cost < l / 2 found
  };
  constexpr std::size_t kKeep = 4;
  std::unordered_map<std::uint64_t, PairBest> pairs;
  const int span = int(std::ceil(reach / cell));
  for (const HH ha : open) {
    const VH p = ms.mesh_.from_vertex_handle(ha), q = ms.mesh_.to_vertex_handle(ha);
    const std::uint32_t pa = pieces.find(ms.global(p));
    const glm::dvec3 P = ms.point(p), Q = ms.point(q);
    const double la = glm::distance(P, Q);
    const glm::ivec3 c0 = grid_cell(Q, cell);
    for (int dz = -span; dz <= span; ++dz)
      for (int dy = -span; dy <= span; ++dy)
        for (int dx = -span; dx <= span; ++dx) {
          const auto it = grid.find(grid_cell_key(c0 + glm::ivec3(dx, dy, dz)));
          if (it == grid.end()) continue;
          for (std::uint32_t k : it->second) {
            const HH hb = open[k];
            const VH s = ms.mesh_.from_vertex_handle(hb), t = ms.mesh_.to_vertex_handle(hb);
            const std::uint32_t pb = pieces.find(ms.global(s));
            if (pb == pa) continue;
            const std::uint64_t pair = std::uint64_t(std::min(pa, pb)) << 32 | std::max(pa, pb);
            const glm::dvec3 S = ms.point(s), T = ms.point(t);
            const double lb = glm::distance(S, T);
            const double l = ms.options_.bridge_limit * (la + lb);
            const double qs = glm::distance(Q, S), tp = glm::distance(T, P);
            if (qs > l || tp > l) continue;
            if (glm::dot(Q - P, T - S) >= 0.0) continue;  // the open edges must run opposite
            PairBest& best = pairs[pair];
            if (best.done || !ms.faces_its_normals({p, q, s, t})) continue;
            if (!ms.spans_surface(q, s) || !ms.spans_surface(t, p)) continue;
            const Candidate c{qs + tp, ha, hb};
            auto at = std::find_if(best.best.begin(), best.best.end(), [&](const Candidate& o) {
              return std::tie(c.cost, c.a, c.b) < std::tie(o.cost, o.a, o.b);
            });
            best.best.insert(at, c);
            if (best.best.size() > kKeep) best.best.pop_back();
            if (qs + tp < 0.5 * (la + lb)) best.done = true;
          }
        }
  }
  // Cheapest pairs first, so that where two pairs want the same open edge the better wins.
  std::vector<std::pair<double, std::uint64_t>> order;
  for (const auto& [pair, best] : pairs)
    if (!best.best.empty()) order.emplace_back(best.best.front().cost, pair);
  std::sort(order.begin(), order.end());
  ms.stats_.bridge_pairs = order.size();
  for (const auto& [cost, pair] : order)
    for (const Candidate& c : pairs[pair].best) {
      if (!ms.mesh_.is_boundary(c.a) || !ms.mesh_.is_boundary(c.b)) continue;
      const VH p = ms.mesh_.from_vertex_handle(c.a), q = ms.mesh_.to_vertex_handle(c.a);
      const VH s = ms.mesh_.from_vertex_handle(c.b), t = ms.mesh_.to_vertex_handle(c.b);
      if (ms.add({p, q, s, t}, Kind::kBridge)) {
        ++ms.stats_.bridges;
        break;
      }
    }
}

}  // namespace ldimesh::merge_detail

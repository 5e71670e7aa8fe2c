// §5 (ii) hole filling by ear cutting (merge_state.hpp).
#include <algorithm>
#include <cmath>
#include <queue>
#include <unordered_map>
#include <vector>

#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "merge_state.hpp"

namespace ldimesh::merge_detail {

void fill_holes(MergeState& ms) {
  ms.stats_.holes = ms.count_loops();
  struct Ear {
    double length;
    int u, v, w;
    bool operator>(const Ear& o) const {
      return std::tie(length, u, v, w) > std::tie(o.length, o.u, o.v, o.w);
    }
  };
  for (int round = 0; round < 2; ++round) {
    const bool strict = round == 0;
    std::priority_queue<Ear, std::vector<Ear>, std::greater<Ear>> ears;
    auto consider = [&](HH in) {
      if (!in.is_valid() || !ms.is_open(in)) return;
      const HH out = ms.mesh_.next_halfedge_handle(in);
      const VH u = ms.mesh_.from_vertex_handle(in), v = ms.mesh_.to_vertex_handle(in);
      const VH w = ms.mesh_.to_vertex_handle(out);
      if (u == w) return;
      ears.push({glm::distance(ms.point(u), ms.point(w)), u.idx(), v.idx(), w.idx()});
    };
    for (const auto& h : ms.mesh_.halfedges())
      if (ms.is_open(h)) consider(h);
    while (!ears.empty()) {
      const Ear e = ears.top();
      ears.pop();
      const VH u(e.u), v(e.v), w(e.w);
      const HH in = ms.mesh_.find_halfedge(u, v);
      if (!in.is_valid() || !ms.mesh_.is_boundary(in)) continue;
      const HH out = ms.mesh_.next_halfedge_handle(in);
      if (ms.mesh_.to_vertex_handle(out) != w) continue;
      const bool closes = ms.mesh_.to_vertex_handle(ms.mesh_.next_halfedge_handle(out)) == u;
      if (!closes) {
        if (ms.mesh_.find_halfedge(u, w).is_valid()) continue;  // u–w exists elsewhere
        if (e.length > ms.options_.max_fill_edge * ms.scale_) continue;
        if (!ms.ear_is_convex(u, v, w, strict) || !ms.spans_surface(u, w)) continue;
      }
      if (!ms.add({u, v, w}, Kind::kFill)) continue;
      ++ms.stats_.fill_triangles;
      if (closes) continue;
      const HH uw = ms.mesh_.find_halfedge(u, w);
      consider(ms.mesh_.prev_halfedge_handle(uw));
      consider(uw);
    }
  }
  ms.stats_.unfilled_holes = ms.count_loops();
}

}  // namespace ldimesh::merge_detail

// §5 (iii) triangle enhancement: length flips, splits projected onto the surface, merges
// (merge_state.hpp).
#include <algorithm>
#include <cmath>
#include <queue>
#include <unordered_map>
#include <vector>

#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "merge_state.hpp"

namespace ldimesh::merge_detail {

void enhance(MergeState& ms, const SurfaceProjection& project) {
  const bool refine = bool(project);
  std::vector<FH> quads;
  for (const auto& f : ms.mesh_.faces()) {
    if (refine && ms.mesh_.property(ms.kind_, f) == Kind::kBridge) quads.push_back(f);
    if (ms.mesh_.property(ms.kind_, f) != Kind::kFill) continue;
    for (const auto& g : f.faces())
      if (g.valence() == 4) quads.push_back(g);
  }
  std::sort(quads.begin(), quads.end());
  quads.erase(std::unique(quads.begin(), quads.end()), quads.end());
  for (FH f : quads) {
    std::vector<VH> c;
    for (const auto& v : ms.mesh_.fv_range(f))
      c.push_back(v);
    // Bridges stay bridges (they are the sewing region already); input quads become kSplit.
    const Kind kind =
        ms.mesh_.property(ms.kind_, f) == Kind::kBridge ? Kind::kBridge : Kind::kSplit;
    ms.erase(f, false);
    const bool along_02 = glm::distance(ms.point(c[0]), ms.point(c[2])) <=
                          glm::distance(ms.point(c[1]), ms.point(c[3]));
    const bool ok = along_02 ? ms.add({c[0], c[1], c[2]}, kind) && ms.add({c[0], c[2], c[3]}, kind)
                             : ms.add({c[0], c[1], c[3]}, kind) && ms.add({c[1], c[2], c[3]}, kind);
    if (ok) {
      ++ms.stats_.split_quads;
    } else {
      ++ms.stats_.lost_faces;
    }
  }
  flip_all(ms);
  if (refine) {
    refine_region(ms, project);
    flip_all(ms);
  }
  // Each corner of the region's faces once (its valence walks its fan), in index order.
  std::vector<std::uint8_t> seen(ms.mesh_.n_vertices(), 0);
  for (FH f : ms.region_faces_)
    if (!ms.mesh_.status(f).deleted())
      for (const auto& v : ms.mesh_.fv_range(f))
        seen[v.idx()] = 1;
  std::vector<VH> centres;
  for (std::size_t i = 0; i < seen.size(); ++i) {
    const VH v{int(i)};
    if (seen[i] && !ms.mesh_.is_boundary(v) && ms.mesh_.valence(v) == 3) centres.push_back(v);
  }
  for (VH v : centres)
    if (!ms.mesh_.status(v).deleted() && ms.try_merge(v)) ++ms.stats_.merges;
}

void flip_all(MergeState& ms) {
  std::vector<HH> edges = ms.region_edges();
  for (int pass = 0; pass < 8 && !edges.empty(); ++pass) {
    std::vector<HH> next;
    for (HH h : edges) {
      if (ms.mesh_.status(ms.mesh_.edge_handle(h)).deleted()) continue;
      const HH flipped = ms.try_flip(h);
      if (!flipped.is_valid()) continue;
      ++ms.stats_.flips;
      for (HH side : {flipped, ms.mesh_.opposite_halfedge_handle(flipped)})
        for (const auto& g : ms.mesh_.fh_range(ms.mesh_.face_handle(side)))
          next.push_back(ms.mesh_.halfedge_handle(ms.mesh_.edge_handle(g), 0));
    }
    std::sort(next.begin(), next.end());
    next.erase(std::unique(next.begin(), next.end()), next.end());
    edges = std::move(next);
  }
}

void refine_region(MergeState& ms, const SurfaceProjection& project) {
  const double limit = ms.options_.split_length * ms.scale_;
  if (!(limit > 0.0)) return;
  // The first pass looks at every edge of the region; a later one at the long edges the
  // previous pass left and the edges of the faces it made (no other edge's length or faces
  // changed).
  std::vector<HH> candidates = ms.region_edges();
  for (int pass = 0; pass < ms.options_.split_passes; ++pass) {
    std::vector<std::pair<double, HH>> long_edges;
    for (const HH h : candidates) {
      const HH o = ms.mesh_.opposite_halfedge_handle(h);
      const FH f = ms.mesh_.face_handle(h), g = ms.mesh_.face_handle(o);
      if (!f.is_valid() || !g.is_valid() || !ms.is_triangle(f) || !ms.is_triangle(g)) continue;
      if (!ms.in_region(f) && !ms.in_region(g)) continue;
      const double l = ms.length(h);
      if (l > limit) long_edges.emplace_back(l, h);
    }
    if (long_edges.empty()) break;
    std::sort(long_edges.begin(), long_edges.end(), [](const auto& x, const auto& y) {
      return x.first != y.first ? x.first > y.first : x.second < y.second;
    });
    std::vector<std::uint8_t> touched(ms.mesh_.n_faces(), 0);
    const std::size_t first_new_face = ms.region_faces_.size();
    std::vector<VH> fresh;
    std::vector<glm::dvec3> points, normals;
    for (const auto& [l, h] : long_edges) {
      const FH f = ms.mesh_.face_handle(h),
               g = ms.mesh_.face_handle(ms.mesh_.opposite_halfedge_handle(h));
      // Faces made in this pass (indices past `touched`) took over edges of split triangles.
      auto done = [&](FH x) { return std::size_t(x.idx()) >= touched.size() || touched[x.idx()]; };
      if (done(f) || done(g)) continue;
      const VH m = ms.split(h);
      if (!m.is_valid()) continue;
      touched[f.idx()] = touched[g.idx()] = 1;
      fresh.push_back(m);
      points.push_back(ms.point(m));
      normals.push_back(to_glm(ms.mesh_.normal(m)));
    }
    if (fresh.empty()) break;
    ms.stats_.split_edges += fresh.size();
    ++ms.stats_.split_passes;
    ms.edge_mark_.assign(ms.mesh_.n_edges(), 0);
    for (const auto& [l, h] : long_edges)
      if (!ms.mesh_.status(ms.mesh_.edge_handle(h)).deleted())
        ms.edge_mark_[ms.mesh_.edge_handle(h).idx()] = 1;
    for (std::size_t i = first_new_face; i < ms.region_faces_.size(); ++i)
      if (!ms.mesh_.status(ms.region_faces_[i]).deleted()) ms.mark_edges(ms.region_faces_[i]);
    candidates = ms.marked_edges();
    const std::vector<glm::dvec3> mid = points, mid_normals = normals;
    project(points, normals, ms.options_.project_reach * ms.scale_);
    for (std::size_t k = 0; k < fresh.size(); ++k) {
      if (points[k] == mid[k]) continue;
      // The move must not turn any face of the new vertex over.
      std::vector<glm::dvec3> before;
      for (const auto& f : ms.mesh_.vf_range(fresh[k]))
        before.push_back(ms.face_normal(f));
      ms.set_point(fresh[k], points[k], normals[k]);
      std::size_t i = 0;
      bool turned = false;
      for (const auto& f : ms.mesh_.vf_range(fresh[k]))
        turned = turned || !(glm::dot(ms.face_normal(f), before[i++]) > 0.0);
      if (turned) {
        ms.set_point(fresh[k], mid[k], mid_normals[k]);
      } else {
        ++ms.stats_.projected;
        ms.moves_.push_back(
            {std::uint32_t(fresh[k].idx()), glm::vec3(mid[k]), glm::vec3(mid_normals[k])});
      }
    }
  }
}

}  // namespace ldimesh::merge_detail

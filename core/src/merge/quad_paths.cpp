// §5 (iv) the remaining triangles paired along shortest paths over the faces, Fig. 3(d)
// (quad_state.hpp).
#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <queue>
#include <vector>

#include "quad_state.hpp"

namespace ldimesh::quad_detail {
namespace {

void apply_path(QuadState& qs, const std::vector<std::uint32_t>& faces,
                const std::vector<std::uint32_t>& crossings) {
  const bool to_boundary = crossings.size() == faces.size();
  ++(to_boundary ? qs.stats_.boundary_splits : qs.stats_.paths);
  // entry[i]/exit[i]: the half-edge of faces[i] that ends at the midpoint of its entry/exit.
  std::vector<std::uint32_t> entry(faces.size(), kNone), exit(faces.size(), kNone);
  for (std::size_t i = 0; i < crossings.size(); ++i) {
    const std::uint32_t h = crossings[i], o = qs.opp_[h];
    qs.split_edge(h, qs.add_vertex({qs.from_[h], qs.to_[h]}));
    exit[i] = h;
    if (o != kNone) entry[i + 1] = o;
    ++qs.stats_.path_splits;
  }
  for (std::size_t i = 0; i < faces.size(); ++i) {
    const std::uint32_t f = faces[i];
    qs.face_new_[f] = 1;
    if (qs.face_size(f) != 6) continue;  // an end triangle, now a quad
    std::array<std::uint32_t, 6> hs;
    std::uint32_t h = qs.face_he_[f];
    int first = -1, second = -1;
    for (int k = 0; k < 6; ++k, h = qs.next_[h]) {
      hs[k] = h;
      if (h == entry[i] || h == exit[i]) (first < 0 ? first : second) = k;
    }
    const int d = (second - first + 6) % 6;
    if (d == 3) {  // straight: two quads
      qs.split_face(hs[first], hs[second]);
      continue;
    }
    // A turn (Fig. 3(d)): loop a, m1, b, m2, c, d with the midpoints m1, m2 either side of
    // corner b; edge m1–d with a centre vertex x on it, then x–m2: quads (a, m1, x, d),
    // (m1, b, m2, x), (x, m2, c, d).
    if (d == 4) std::swap(first, second);
    auto at = [&](int k) { return hs[(first + k) % 6]; };
    const std::uint32_t x =
        qs.add_vertex({qs.to_[at(5)], qs.to_[at(1)], qs.to_[at(3)], qs.to_[at(4)]});  // a, b, c, d
    const std::uint32_t to_m2 = at(2);
    const std::uint32_t back = qs.split_face(at(0), at(4));  // d→m1
    qs.split_edge(qs.opp_[back], x);                         // m1→x→d and d→x→m1
    qs.split_face(back, to_m2);
    ++qs.stats_.turns;
  }
}

// One Dijkstra round; returns the number of paths applied.
std::size_t run_paths(QuadState& qs, const std::vector<std::uint32_t>& sources) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const std::size_t nf = qs.face_he_.size();
  qs.search_.resize(nf);
  qs.touched_.clear();
  struct Item {
    double d;
    std::uint32_t f;
    bool operator>(const Item& o) const { return d != o.d ? d > o.d : f > o.f; }
  };
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (std::uint32_t s : sources) {
    qs.search_[s].dist = 0.0;
    qs.search_[s].source = s;
    qs.touched_.push_back(s);
    queue.push({0.0, s});
  }
  // A candidate path: the faces either side of the edge h where two regions meet (g = kNone:
  // h is open, the path ends there).
  struct Candidate {
    double cost;
    std::uint32_t h, f, g;
  };
  std::vector<Candidate> candidates;
  std::size_t without = sources.size();  // sources with no candidate yet
  double stop = kInf;                    // once every source has one: the dearest of their cheapest
  auto note = [&](std::uint32_t s, double cost) {
    if (qs.search_[s].best == kInf) --without;
    qs.search_[s].best = std::min(qs.search_[s].best, cost);
  };
  while (!queue.empty()) {
    const Item item = queue.top();
    queue.pop();
    const std::uint32_t x = item.f;
    if (qs.search_[x].settled || item.d > qs.search_[x].dist) continue;
    if (item.d > stop) break;
    qs.search_[x].settled = 1;
    // A region grows no further than its source's cheapest candidate: beyond, it could only
    // find dearer ones for it (its neighbours still meet it here).
    const bool grow = item.d <= qs.search_[qs.search_[x].source].best;
    const glm::vec3 cx = qs.centroid_[x];
    std::uint32_t hx = qs.face_he_[x];
    do {
      const std::uint32_t o = qs.opp_[hx];
      if (o == kNone) {
        if (!qs.is_cut(hx)) {  // an open edge of the mesh, not the region's edge
          const double cost = item.d + glm::distance(glm::dvec3(cx), qs.midpoint(hx));
          candidates.push_back({cost, hx, x, kNone});
          note(qs.search_[x].source, cost);
        }
      } else if (const std::uint32_t y = qs.face_[o]; y != x) {
        const double w = glm::distance(cx, qs.centroid_[y]);
        if (qs.search_[y].settled) {
          if (qs.search_[y].source != qs.search_[x].source) {
            const double cost = item.d + w + qs.search_[y].dist;
            candidates.push_back({cost, hx, x, y});
            note(qs.search_[x].source, cost);
            note(qs.search_[y].source, cost);
          }
        } else if (grow &&
                   item.d + w < qs.search_[y].dist) {  // never a triangle: those are sources
          if (qs.search_[y].dist == kInf) qs.touched_.push_back(y);
          qs.search_[y].dist = item.d + w;
          qs.search_[y].source = qs.search_[x].source;
          qs.search_[y].parent = x;
          qs.search_[y].cross = hx;
          queue.push({qs.search_[y].dist, y});
        }
      }
      hx = qs.next_[hx];
    } while (hx != qs.face_he_[x]);
    if (without == 0 && stop == kInf) {
      stop = 0.0;
      for (std::uint32_t s : sources)
        stop = std::max(stop, qs.search_[s].best);
    }
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return a.cost != b.cost ? a.cost < b.cost : a.h < b.h;
  });
  std::size_t applied = 0;
  std::vector<std::uint32_t> left, right, faces, crossings;
  // The faces from x back to its source, or false if one is on a path already (faces of an
  // applied path have changed; the walk stops at the first).
  auto chain = [&](std::uint32_t x, std::vector<std::uint32_t>& out) {
    out.clear();
    for (;; x = qs.search_[x].parent) {
      if (qs.search_[x].used) return false;
      out.push_back(x);
      if (x == qs.search_[x].source) return true;
    }
  };
  for (const Candidate& c : candidates) {
    if (qs.search_[qs.search_[c.f].source].used ||
        (c.g != kNone && qs.search_[qs.search_[c.g].source].used))
      continue;
    if (!chain(c.f, left)) continue;
    if (c.g != kNone && !chain(c.g, right)) continue;
    if (c.g == kNone) right.clear();
    // faces from one source to the other; crossings[i] lies in faces[i] with its opposite in
    // faces[i + 1] (the last one open for a path to the boundary).
    faces.assign(left.rbegin(), left.rend());
    crossings.clear();
    for (std::size_t i = 1; i < faces.size(); ++i)
      crossings.push_back(qs.search_[faces[i]].cross);
    crossings.push_back(c.h);
    for (std::uint32_t x : right) {
      faces.push_back(x);
      if (x != qs.search_[x].source) crossings.push_back(qs.opp_[qs.search_[x].cross]);
    }
    for (std::uint32_t x : faces)
      qs.search_[x].used = 1;
    const std::uint32_t first_face = std::uint32_t(qs.face_he_.size());
    apply_path(qs, faces, crossings);
    qs.centroid_.resize(qs.face_he_.size());
    for (std::uint32_t x : faces)
      qs.centroid_[x] = qs.centroid(x);
    for (std::uint32_t x = first_face; x < qs.face_he_.size(); ++x)
      qs.centroid_[x] = qs.centroid(x);
    ++applied;
  }
  for (std::uint32_t x : qs.touched_)
    qs.search_[x] = {};
  return applied;
}

void project_new(QuadState& qs, std::uint32_t first, const SurfaceProjection& project) {
  if (!project || first == qs.pos_.size()) return;
  for (std::uint32_t v = first; v < qs.pos_.size(); ++v)
    qs.remember(v);
  std::vector<glm::dvec3> points(qs.pos_.begin() + first, qs.pos_.end());
  std::vector<glm::dvec3> normals(qs.nrm_.begin() + first, qs.nrm_.end());
  qs.stats_.projected += project(points, normals, qs.reach());
  std::copy(points.begin(), points.end(), qs.pos_.begin() + first);
  std::copy(normals.begin(), normals.end(), qs.nrm_.begin() + first);
}
}  // namespace

void connect_triangles(QuadState& qs, const SurfaceProjection& project) {
  std::vector<std::uint32_t> triangles;
  for (std::uint32_t f = 0; f < qs.face_he_.size(); ++f)
    if (qs.face_he_[f] != kNone && qs.face_size(f) == 3) triangles.push_back(f);
  const std::uint32_t first_new = std::uint32_t(qs.pos_.size());
  qs.centroid_.resize(qs.face_he_.size());
  for (std::uint32_t f = 0; f < qs.face_he_.size(); ++f)
    if (qs.face_he_[f] != kNone) qs.centroid_[f] = qs.centroid(f);
  for (int round = 0; round < qs.options_.max_path_rounds && !triangles.empty(); ++round) {
    ++qs.stats_.path_rounds;
    if (run_paths(qs, triangles) == 0) break;
    std::erase_if(triangles, [&](std::uint32_t f) { return qs.face_size(f) != 3; });
  }
  qs.stats_.leftover_triangles = triangles.size();
  project_new(qs, first_new, project);
}

}  // namespace ldimesh::quad_detail

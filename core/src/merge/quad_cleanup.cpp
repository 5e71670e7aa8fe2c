// §5 (iv) clean-up: quads sharing two edges merged, quad edge flips toward valence 4
// (quad_state.hpp).
#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "quad_state.hpp"

namespace ldimesh::quad_detail {

void merge_quad_pairs(QuadState& qs) {
  qs.build_vertex_rings();
  std::vector<std::uint32_t> work;
  for (std::uint32_t v = 0; v < qs.pos_.size(); ++v)
    if (qs.valence_[v] == 2 && !qs.boundary_[v] && !qs.is_pinned(v)) work.push_back(v);
  std::reverse(work.begin(), work.end());  // a stack, lowest index first
  while (!work.empty()) {
    const std::uint32_t v = work.back();
    work.pop_back();
    if (qs.valence_[v] != 2 || qs.boundary_[v] || qs.out_he_[v] == kNone) continue;
    const std::uint32_t h1 = qs.out_he_[v];
    const std::uint32_t f1 = qs.face_[h1];
    const std::uint32_t p1 = qs.prev(h1);  // b→v
    const std::uint32_t h2 = qs.opp_[p1];  // v→b
    if (h2 == kNone) continue;
    const std::uint32_t f2 = qs.face_[h2];
    const std::uint32_t p2 = qs.prev(h2);  // a→v
    if (f1 == f2 || qs.opp_[p2] != h1 || qs.face_size(f1) != 4 || qs.face_size(f2) != 4) continue;
    // f1: v→a (h1), a→p (x1), p→b (x2), b→v; f2: v→b (h2), b→q (y1), q→a (y2), a→v.
    const std::uint32_t x1 = qs.next_[h1], x2 = qs.next_[x1], y1 = qs.next_[h2], y2 = qs.next_[y1];
    const std::uint32_t a = qs.to_[h1], b = qs.to_[h2];
    if (qs.to_[x1] == qs.to_[y1]) continue;
    // One of the two has a reflex corner at v already (their angles there sum to 360°), so
    // the merged quad need not be convex; it must face the way of its normals.
    if (!qs.faces_its_normals({a, qs.to_[x1], b, qs.to_[y1]})) continue;
    qs.next_[x2] = y1;
    qs.next_[y2] = x1;
    qs.face_[y1] = qs.face_[y2] = f1;
    for (std::uint32_t h : {h1, p1, h2, p2})
      qs.face_[h] = kNone;
    qs.face_he_[f1] = x1;
    qs.face_he_[f2] = kNone;
    qs.face_new_[f1] = 1;
    qs.out_he_[v] = kNone;
    qs.valence_[v] = 0;
    qs.out_he_[a] = x1;
    qs.out_he_[b] = y1;
    for (std::uint32_t u : {a, b})
      if (--qs.valence_[u] == 2 && !qs.boundary_[u] && !qs.is_pinned(u)) work.push_back(u);
    ++qs.stats_.quad_merges;
  }
}

namespace {

bool try_flip(QuadState& qs, std::uint32_t h) {
  const std::uint32_t o = qs.opp_[h];
  const std::uint32_t f = qs.face_[h], g = qs.face_[o];
  // Removing the edge must help u or v, and leave both with three edges at least.
  const std::uint32_t u = qs.from_[h], v = qs.to_[h];
  if (qs.valence_[u] <= 3 || qs.valence_[v] <= 3) return false;
  if (int(qs.valence_[u]) <= qs.ideal(u) && int(qs.valence_[v]) <= qs.ideal(v)) return false;
  if (qs.face_size(f) != 4 || qs.face_size(g) != 4) return false;
  // f: h (u→v), fa1 (v→a1), fa2 (a1→a2), fa3 (a2→u); g: o (v→u), gb1 (u→b1), gb2, gb3 (b2→v).
  const std::uint32_t fa1 = qs.next_[h], fa2 = qs.next_[fa1], fa3 = qs.next_[fa2];
  const std::uint32_t gb1 = qs.next_[o], gb2 = qs.next_[gb1], gb3 = qs.next_[gb2];
  const std::uint32_t a1 = qs.to_[fa1], a2 = qs.to_[fa2], b1 = qs.to_[gb1], b2 = qs.to_[gb2];
  // Valences at the region's edge count only its own faces.
  for (std::uint32_t x : {u, v, a1, a2, b1, b2})
    if (qs.is_pinned(x)) return false;
  const int before = qs.energy(u, 0) + qs.energy(v, 0);
  const int gain_a = before - qs.energy(u, -1) - qs.energy(v, -1) + qs.energy(a1, 0) +
                     qs.energy(b1, 0) - qs.energy(a1, 1) - qs.energy(b1, 1);
  const int gain_b = before - qs.energy(u, -1) - qs.energy(v, -1) + qs.energy(a2, 0) +
                     qs.energy(b2, 0) - qs.energy(a2, 1) - qs.energy(b2, 1);
  if (gain_a <= 0 && gain_b <= 0) return false;
  const double old_quality = std::min(qs.quality({u, v, a1, a2}), qs.quality({v, u, b1, b2}));
  auto acceptable = [&](std::uint32_t p, std::uint32_t q, const std::array<std::uint32_t, 4>& x,
                        const std::array<std::uint32_t, 4>& y) {
    if (p == q || qs.adjacent(p, q)) return false;
    const double qx = qs.quality(x), qy = qs.quality(y);
    return qx > 0.0 && qy > 0.0 && std::min(qx, qy) >= 0.5 * old_quality;
  };
  const bool try_a_first = gain_a >= gain_b;
  for (int k = 0; k < 2; ++k) {
    const bool a_side = (k == 0) == try_a_first;
    if ((a_side ? gain_a : gain_b) <= 0) continue;
    if (a_side && acceptable(a1, b1, {a1, a2, u, b1}, {b1, b2, v, a1})) {
      // (a1, a2, u, b1): fa2, fa3, gb1, h (b1→a1); (b1, b2, v, a1): gb2, gb3, fa1, o (a1→b1).
      qs.from_[h] = b1, qs.to_[h] = a1, qs.from_[o] = a1, qs.to_[o] = b1;
      qs.next_[fa2] = fa3, qs.next_[fa3] = gb1, qs.next_[gb1] = h, qs.next_[h] = fa2;
      qs.next_[gb2] = gb3, qs.next_[gb3] = fa1, qs.next_[fa1] = o, qs.next_[o] = gb2;
      qs.face_[gb1] = f, qs.face_[fa1] = g;
      qs.face_he_[f] = fa2, qs.face_he_[g] = gb2;
      ++qs.valence_[a1], ++qs.valence_[b1];
    } else if (!a_side && acceptable(a2, b2, {a2, u, b1, b2}, {b2, v, a1, a2})) {
      // (a2, u, b1, b2): fa3, gb1, gb2, h (b2→a2); (b2, v, a1, a2): gb3, fa1, fa2, o (a2→b2).
      qs.from_[h] = b2, qs.to_[h] = a2, qs.from_[o] = a2, qs.to_[o] = b2;
      qs.next_[fa3] = gb1, qs.next_[gb1] = gb2, qs.next_[gb2] = h, qs.next_[h] = fa3;
      qs.next_[gb3] = fa1, qs.next_[fa1] = fa2, qs.next_[fa2] = o, qs.next_[o] = gb3;
      qs.face_[gb1] = qs.face_[gb2] = f, qs.face_[fa1] = qs.face_[fa2] = g;
      qs.face_he_[f] = fa3, qs.face_he_[g] = gb3;
      ++qs.valence_[a2], ++qs.valence_[b2];
    } else {
      continue;
    }
    --qs.valence_[u], --qs.valence_[v];
    qs.out_he_[u] = gb1, qs.out_he_[v] = fa1;
    qs.face_new_[f] = qs.face_new_[g] = 1;
    return true;
  }
  return false;
}
}  // namespace

void flip_edges(QuadState& qs) {
  qs.build_vertex_rings();
  const std::size_t nf = qs.face_he_.size();
  std::vector<std::uint8_t> dirty(nf, 1), dirty_next(nf, 0);  // per face
  for (int pass = 0; pass < qs.options_.flip_passes; ++pass) {
    std::size_t flipped = 0;
    for (std::uint32_t h = 0; h < qs.to_.size(); ++h) {
      const std::uint32_t o = qs.opp_[h];
      if (o == kNone || o < h || qs.face_[h] == kNone || qs.face_[h] == qs.face_[o]) continue;
      if (!dirty[qs.face_[h]] && !dirty[qs.face_[o]]) continue;
      if (!qs.face_new_[qs.face_[h]] && !qs.face_new_[qs.face_[o]])
        continue;  // the input's own quads
      if (!try_flip(qs, h)) continue;
      ++flipped;
      // The flipped pair holds the six corners whose valences or fans changed: their faces
      // are looked at again, later in this pass as in the next.
      for (std::uint32_t face : {qs.face_[h], qs.face_[o]}) {
        std::uint32_t c = qs.face_he_[face];
        do {
          const std::uint32_t v = qs.from_[c];
          const std::size_t seen =
              qs.for_each_face_around(v, [&](std::uint32_t g) { dirty[g] = dirty_next[g] = 1; });
          // A vertex with more than one fan (not a manifold there): all faces, to be safe.
          if (seen != qs.valence_[v] - qs.boundary_[v]) {
            std::fill(dirty.begin(), dirty.end(), 1);
            std::fill(dirty_next.begin(), dirty_next.end(), 1);
          }
          c = qs.next_[c];
        } while (c != qs.face_he_[face]);
      }
    }
    qs.stats_.flips += flipped;
    if (flipped == 0) break;
    dirty.swap(dirty_next);
    std::fill(dirty_next.begin(), dirty_next.end(), 0);
  }
}

}  // namespace ldimesh::quad_detail

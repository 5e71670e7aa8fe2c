// §5 (iv) greedy pairing of triangles into quads (quad_state.hpp).
#include <algorithm>
#include <cstdint>
#include <vector>

#include "quad_state.hpp"

namespace ldimesh::quad_detail {

void pair_triangles(QuadState& qs) {
  struct Pair {
    double quality;
    std::uint32_t h;
  };
  std::vector<Pair> pairs;
  for (std::uint32_t h = 0; h < qs.to_.size(); ++h) {
    const std::uint32_t o = qs.opp_[h];
    if (o == kNone || o < h || qs.face_[h] == qs.face_[o]) continue;
    if (qs.face_size(qs.face_[h]) != 3 || qs.face_size(qs.face_[o]) != 3) continue;
    const std::uint32_t c = qs.to_[qs.next_[h]], d = qs.to_[qs.next_[o]];
    if (c == d) continue;
    const double q = qs.quality({qs.from_[h], d, qs.to_[h], c});
    if (q > 0.0 && q >= qs.options_.min_pair_quality) pairs.push_back({q, h});
  }
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) {
    return a.quality != b.quality ? a.quality > b.quality : a.h < b.h;
  });
  std::vector<std::uint8_t> paired(qs.face_he_.size(), 0);
  for (const Pair& p : pairs) {
    const std::uint32_t h = p.h, o = qs.opp_[h];
    const std::uint32_t f = qs.face_[h], g = qs.face_[o];
    if (paired[f] || paired[g]) continue;
    paired[f] = paired[g] = 1;
    // f: h (a→b), h1 (b→c), h2 (c→a); g: o (b→a), o1 (a→d), o2 (d→b) → a→d→b→c.
    const std::uint32_t h1 = qs.next_[h], h2 = qs.next_[h1], o1 = qs.next_[o], o2 = qs.next_[o1];
    qs.next_[h2] = o1;
    qs.next_[o2] = h1;
    qs.face_[o1] = qs.face_[o2] = f;
    qs.face_[h] = qs.face_[o] = kNone;
    qs.face_he_[f] = h1;
    qs.face_he_[g] = kNone;
    qs.face_new_[f] = 1;
    ++qs.stats_.paired;
  }
}

}  // namespace ldimesh::quad_detail

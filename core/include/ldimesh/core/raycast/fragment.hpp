// LDI fragments: the sparse part of an LDI that one rank produced (its pixels with at least one
// sample), and how fragments of one view become a full LDI again.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/raycast/ldi.hpp"

namespace ldimesh {

// Normals in a total order, component by component: ties between hits of the same depth.
inline bool normal_less(const glm::vec3& a, const glm::vec3& b) {
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}

// Of hits of one ray closer than a duplicate tolerance (a root that primitives, blocks or ranks on
// either side of a face all found), whether the one with normal `a` is kept before the one with
// `b`: the normal facing the viewer of a ray along `dir` most (smaller a · dir), then the
// smaller normal. Every collapse of duplicates keeps hits by it (collapse_duplicate_hits) — one
// caster's, the blocks' of a rank, the ranks' in the reduction and in sample requests — so
// that one process and several ranks keep the same hit; where a gradient jumps at a cell face
// the duplicates' normals differ along the ray, so the choice does not hang on rounding or on
// the order in which they were found.
inline bool kept_before(const glm::vec3& a, const glm::vec3& b, const glm::vec3& dir) {
  const float da = glm::dot(a, dir), db = glm::dot(b, dir);
  return da != db ? da < db : normal_less(a, b);
}

// The duplicate rule: sorts one ray's hits by `less` (depth first) and collapses each run of hits
// whose depth lies within `tolerance` of the run's first into the one kept_before chooses (the
// first such in `less` order). Returns how many are kept, at the front of `hits`. `depth(h)` and
// `normal(h)` read a hit.
template <class Hit, class Less, class Depth, class Normal>
std::size_t collapse_duplicate_hits(std::span<Hit> hits, double tolerance, const glm::vec3& dir,
                                    Less less, Depth depth, Normal normal) {
  if (hits.size() <= 16) {  // a ray's few hits, often in order already
    for (std::size_t k = 1; k < hits.size(); ++k)
      for (std::size_t m = k; m > 0 && less(hits[m], hits[m - 1]); --m)
        std::swap(hits[m], hits[m - 1]);
  } else {
    std::sort(hits.begin(), hits.end(), less);
  }
  std::size_t kept = 0;
  for (std::size_t k = 0; k < hits.size();) {
    const double first = double(depth(hits[k]));
    std::size_t end = k + 1;
    while (end < hits.size() && double(depth(hits[end])) - first <= tolerance)
      ++end;
    hits[kept++] = *std::min_element(
        hits.begin() + k, hits.begin() + end,
        [&](const Hit& a, const Hit& b) { return kept_before(normal(a), normal(b), dir); });
    k = end;
  }
  return kept;
}

// Samples of the listed pixels of one view, in CSR form over the listed pixels: pixel
// pixels[k] holds counts[k] ≥ 1 samples, sorted by depth, stored consecutively. Pixel ids are
// strictly increasing and below pixel_count. Depths lie in [depth_lo, depth_hi], the interval
// a codec quantizes against (the view's [0, depth_extent]).
struct LdiFragment {
  std::uint32_t view = 0;         // index of the view in the step's list of views
  std::uint64_t pixel_count = 0;  // width × height of that view
  double depth_lo = 0.0;
  double depth_hi = 0.0;
  std::vector<std::uint32_t> pixels;
  std::vector<std::uint32_t> counts;
  std::vector<float> depth;
  std::vector<glm::vec3> normal;
  std::vector<float> scalar;  // empty, or one value per sample
  // The range the lossy wire format quantizes the scalars over (transport/fragment_codec.hpp),
  // widened to hold every finite scalar; NaN: the scalars' own range. The ranks of a step agree
  // on one per view (the reduction sets it), so that a sample's value does not depend on the
  // rank that cast it, nor on the number of ranks.
  float scalar_lo = NAN;
  float scalar_hi = NAN;

  std::size_t sample_count() const { return depth.size(); }
};

// The union of the scalar ranges [lo, hi] and [a, b], NaN ends unset (the other's, or NaN).
void widen_scalar_range(float& lo, float& hi, float a, float b);

// The fragment's scalar range (scalar_lo, scalar_hi) widened to hold its finite scalars; NaN
// ends where it has neither: what the ranks agree on and the codec quantizes over.
void fragment_scalar_range(const LdiFragment& f, float& lo, float& hi);

// An empty fragment of `view` (what a rank with nothing to cast sends).
LdiFragment make_empty_fragment(const View& view, std::uint32_t view_index);

// The non-empty pixels of `ldi` as a fragment.
LdiFragment fragment_from_ldi(const Ldi& ldi, std::uint32_t view_index);

// Checks every invariant above (sizes agree, counts ≥ 1 and sum to the samples, pixel ids
// strictly increasing and in range, depths finite and sorted per pixel, a scalar range either
// unset (both NaN) or finite with lo ≤ hi); a Status naming the first violation.
Status validate_fragment(const LdiFragment& fragment);

// Fragments of one view combined: per pixel the samples of all fragments are concatenated,
// sorted by depth (ties by normal, then scalar) and collapsed by the duplicate rule
// (collapse_duplicate_hits) with `tolerance` and the view's direction `dir` (one root found by two
// blocks or ranks on their shared face: the one a single caster would keep). The result does not
// depend on the order of the fragments. All fragments must be of the same view (same view
// index, pixel_count and depth interval) and carry a scalar alike; throws
// std::invalid_argument otherwise. The scalar range is the union of the fragments' (NaN where
// none has one). An empty list gives an empty fragment.
LdiFragment combine_fragments(std::span<const LdiFragment> fragments, double tolerance,
                              const glm::vec3& dir);

// The full LDI of `view` with the fragment's samples; throws std::invalid_argument if the
// fragment's pixel_count differs from the view's.
Ldi ldi_from_fragment(const LdiFragment& fragment, const View& view);

}  // namespace ldimesh

// LDI fragments: the sparse part of an LDI that one rank produced (its pixels with at least one
// sample), and how fragments of one view become a full LDI again.
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/raycast/ldi.hpp"

namespace ldimesh {

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

// Fragments of one view merged: per pixel the samples of all fragments are concatenated,
// sorted by depth (ties by normal) and samples closer than `tolerance` in depth merged into
// the first of them (one root found by two ranks on their shared face). The result does not
// depend on the order of the fragments. All fragments must be of the same view (same view
// index, pixel_count and depth interval) and carry a scalar alike; throws
// std::invalid_argument otherwise. The scalar range is the union of the fragments' (NaN where
// none has one). An empty list gives an empty fragment.
LdiFragment merge_fragments(std::span<const LdiFragment> fragments, double tolerance);

// The full LDI of `view` with the fragment's samples; throws std::invalid_argument if the
// fragment's pixel_count differs from the view's.
Ldi ldi_from_fragment(const LdiFragment& fragment, const View& view);

}  // namespace ldimesh

// Quads from one Layered Depth Image (paper §3).
#pragma once

#include <cstdint>
#include <vector>

#include "ldimesh/core/raycast/ldi.hpp"

namespace ldimesh {

struct MatchOptions {
  // A candidate whose §3 matching cost exceeds this many pixel spacings is no match. Samples of
  // one smooth layer cost a small fraction of a pixel; samples of separate layers cost about
  // their depth gap, so a layer gap wider than this is never bridged.
  double max_cost = 2.0;
  // Depth predictions use max(|n·d|, min_facing) in place of |n·d|: near silhouettes a normal
  // is almost perpendicular to the view and the predicted slope would blow up.
  double min_facing = 0.05;
};

// §3: every sample s0 at pixel (x, y) picks its best match in each of the pixels (x+1, y),
// (x, y+1) and (x+1, y+1): the candidate s minimising |e(s,x,y) − d(s0)| + |e(s0,x+a,y+b) − d(s)|,
// where e(s, ·) predicts depth from s's normal. No two samples of a pixel keep the same match
// (the cheaper one wins), so every quad edge is shared by at most two quads. A quad
// (s0, right, top-right, top) is made where all three matches exist and agree (the right
// match's top match and the top match's right match are s0's top-right match).
//
// Returns sample indices, four per quad, ordered so that the quad is counter-clockwise seen
// from the side its sample normals point to. Quads come in pixel order; the result does not
// depend on the thread count.
std::vector<std::uint32_t> build_quads(const Ldi& ldi, const MatchOptions& options = {});

}  // namespace ldimesh

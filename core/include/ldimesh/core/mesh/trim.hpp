// Trimming the overlap between views (paper §3). Pure functions: reentrant, no errors (bad
// indices are the caller's; the mesher only passes its own quads).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

namespace ldimesh {

// The §3 validity of a corner whose normal (unnormalised) is `nv`, in a face of view `dq`:
// |nv·dq| / max_{d∈dirs} |nv·d| > r, without dividing. A degenerate corner (nv·d = 0 for all d)
// is invalid; a corner whose own view is the best stays valid even at r = 1, as §5 needs.
inline bool view_quality_ok(glm::vec3 nv, glm::vec3 dq, std::span<const glm::vec3> dirs, float r) {
  float best = 0.0f;
  for (const glm::vec3& d : dirs)
    best = std::max(best, std::abs(glm::dot(nv, d)));
  const float own = std::abs(glm::dot(nv, dq));
  return best > 0.0f && (own > r * best || own >= best);
}

// §3: for every corner v of a quad of view d_q, n_v = (v − v_prev) × (v − v_next); v is valid
// iff |n_v·d_q| / max_{d∈D} |n_v·d| > r. Keeps (in order) the quads whose four corners are
// valid. `quads` holds four indices into `positions` per quad; `all_dirs` is D (it contains
// view_dir). r = 0 keeps every non-degenerate quad; a corner whose own view is the best in D
// is always valid, so r = 1 keeps exactly the quads whose corners all see d_q as their best
// view (what §5 trims with). Returns the number of quads kept.
std::size_t trim_by_view_quality(std::vector<std::uint32_t>& quads,
                                 std::span<const glm::vec3> positions, glm::dvec3 view_dir,
                                 std::span<const glm::dvec3> all_dirs, double r);

}  // namespace ldimesh

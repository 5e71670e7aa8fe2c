// §4 the hits of one pass's rays matched to its new vertices (refine_state.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "refine_state.hpp"

namespace ldimesh::refine_detail {

void resolve(RefineState& rs, const RayHitList& hits, std::size_t first) {
  // Hits this view's vertices took, from this view's first hit on.
  const std::uint32_t base = hits.offsets[first];
  rs.claimed_.assign(hits.offsets[first + rs.stretch_ranges_.size()] - base, 0);
  for (const Pending& p : rs.pending_) {
    Vertex& v = rs.vertices_[p.vertex];
    const std::array<std::uint32_t, 4>& use = p.match.use;
    const std::uint32_t n = p.match.n;
    const std::uint32_t b = hits.offsets[first + rs.first_stretch_[p.ray]],
                        e = hits.offsets[first + rs.first_stretch_[p.ray + 1]];
    std::uint32_t best = kNone;
    double best_cost = p.match.threshold;
    for (std::uint32_t s = b; s < e; ++s) {
      if (rs.claimed_[s - base]) continue;
      const double ds = hits.depth[s];
      const glm::dvec2 slope = rs.slope_of(glm::dvec3(hits.normal[s]));
      double cost = 0.0;
      for (std::uint32_t k = 0; k < n; ++k) {
        const Vertex& r = rs.vertices_[use[k]];
        const glm::dvec2 step = v.image - r.image;
        cost += std::abs(ds - glm::dot(slope, step) - r.depth) +
                std::abs(r.depth + glm::dot(r.slope, step) - ds);
      }
      cost /= n;
      if (cost < best_cost) {
        best = s;
        best_cost = cost;
      }
    }
    if (best != kNone) {
      rs.claimed_[best - base] = 1;
      v.depth = hits.depth[best];
      v.normal = glm::dvec3(hits.normal[best]);
      v.scalar = hits.scalar.empty() ? 0.0f : hits.scalar[best];
      v.valid = true;
    } else {
      double scalar = 0.0;
      glm::dvec3 normal(0.0);
      for (std::uint32_t k = 0; k < n; ++k) {
        normal += rs.vertices_[use[k]].normal;
        scalar += rs.vertices_[use[k]].scalar;
      }
      v.depth = p.match.predicted;
      const double length = glm::length(normal);
      v.normal = length > 0.0 ? normal / length : rs.vertices_[use[0]].normal;
      v.scalar = float(scalar / n);
      v.valid = false;
      ++rs.invalid_;
    }
    v.slope = rs.slope_of(v.normal);
  }
}

}  // namespace ldimesh::refine_detail

// §5 (iv) Laplacian smoothing of the converted faces (quad_state.hpp).
#include <cstdint>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "quad_state.hpp"

namespace ldimesh::quad_detail {

void smooth(QuadState& qs, const SurfaceProjection& project) {
  if (qs.options_.smoothing_iterations <= 0) return;
  const std::size_t nv = qs.pos_.size();
  std::vector<std::uint8_t> moves(nv, 0), boundary(nv, 0);
  std::vector<std::uint32_t> count(nv + 1, 0);
  for (std::uint32_t h = 0; h < qs.to_.size(); ++h) {
    if (qs.face_[h] == kNone) continue;
    if (qs.opp_[h] == kNone) boundary[qs.from_[h]] = boundary[qs.to_[h]] = 1;
    if (qs.options_.smooth_all || qs.face_new_[qs.face_[h]]) moves[qs.from_[h]] = 1;
    if (qs.opp_[h] == kNone || h < qs.opp_[h]) ++count[qs.from_[h] + 1], ++count[qs.to_[h] + 1];
  }
  for (std::size_t v = 0; v < nv; ++v)
    count[v + 1] += count[v];
  std::vector<std::uint32_t> neighbours(count[nv]), fill(count.begin(), count.end() - 1);
  for (std::uint32_t h = 0; h < qs.to_.size(); ++h) {
    if (qs.face_[h] == kNone || (qs.opp_[h] != kNone && h > qs.opp_[h])) continue;
    neighbours[fill[qs.from_[h]]++] = qs.to_[h];
    neighbours[fill[qs.to_[h]]++] = qs.from_[h];
  }
  std::vector<std::uint32_t> region;
  for (std::uint32_t v = 0; v < nv; ++v)
    if (moves[v] && !boundary[v] && !qs.is_pinned(v) && count[v + 1] > count[v])
      region.push_back(v);
  std::vector<glm::dvec3> start(region.size()), points(region.size()), normals(region.size());
  for (std::size_t i = 0; i < region.size(); ++i) {
    start[i] = qs.pos_[region[i]];
    qs.remember(region[i]);
  }
  const double limit = qs.options_.max_unprojected_move * qs.median_edge_;
  // Each step reads the old positions only (Jacobi), so the vertices go in parallel with the
  // same result for any number of threads.
  for (int it = 0; it < qs.options_.smoothing_iterations; ++it) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, region.size(), 2048), [&](const auto& r) {
      for (std::size_t i = r.begin(); i < r.end(); ++i) {
        const std::uint32_t v = region[i];
        glm::dvec3 mean(0.0);
        for (std::uint32_t k = count[v]; k < count[v + 1]; ++k)
          mean += qs.pos_[neighbours[k]];
        mean /= double(count[v + 1] - count[v]);
        glm::dvec3 step = qs.options_.smoothing_step * (mean - qs.pos_[v]);
        step -= glm::dot(step, qs.nrm_[v]) * qs.nrm_[v];
        points[i] = qs.pos_[v] + step;
        if (!project) {
          const glm::dvec3 moved = points[i] - start[i];
          const double d = glm::length(moved);
          if (d > limit) points[i] = start[i] + moved * (limit / d);
        }
      }
    });
    for (std::size_t i = 0; i < region.size(); ++i)
      qs.pos_[region[i]] = points[i];
  }
  if (!project) return;
  for (std::size_t i = 0; i < region.size(); ++i)
    normals[i] = qs.nrm_[region[i]];
  qs.stats_.projected += project(points, normals, qs.reach());
  for (std::size_t i = 0; i < region.size(); ++i) {
    qs.pos_[region[i]] = points[i];
    qs.nrm_[region[i]] = normals[i];
  }
}

}  // namespace ldimesh::quad_detail

#include "ldimesh/core/merge/projection.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ldimesh {

SurfaceProjection sample_projection(SampleSource& samples, std::span<const View> views) {
  if (views.empty()) throw std::invalid_argument("surface projection needs at least one view");
  return [&samples, views](std::vector<glm::dvec3>& points, std::vector<glm::dvec3>& normals,
                           double reach) -> std::size_t {
    if (points.size() != normals.size())
      throw std::invalid_argument("surface projection: points and normals differ in number");
    // One ray per point, along the view closest to its normal: that ray meets the surface near
    // the point at the steepest angle, and the stretch ± reach keeps other sheets out.
    std::vector<SamplePoint> rays(points.size());
    std::vector<double> depth(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      std::uint32_t best = 0;
      for (std::uint32_t k = 1; k < views.size(); ++k)
        if (std::abs(glm::dot(normals[i], views[k].dir)) >
            std::abs(glm::dot(normals[i], views[best].dir)))
          best = k;
      const View& view = views[best];
      const glm::dvec3 d = points[i] - view.origin;
      depth[i] = glm::dot(d, view.dir);
      rays[i] = {best, glm::dvec2(glm::dot(d, view.u), glm::dot(d, view.v)) / view.spacing,
                 std::max(0.0, depth[i] - reach), depth[i] + reach};
    }
    const RayHitList hits = samples.sample(rays);
    std::size_t moved = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      // The hit nearest in depth whose normal faces the way the estimate does.
      std::uint32_t best = UINT32_MAX;
      for (std::uint32_t h = hits.offsets[i]; h < hits.offsets[i + 1]; ++h) {
        if (glm::dot(glm::dvec3(hits.normal[h]), normals[i]) <= 0.0) continue;
        if (best == UINT32_MAX ||
            std::abs(hits.depth[h] - depth[i]) < std::abs(hits.depth[best] - depth[i]))
          best = h;
      }
      if (best == UINT32_MAX) continue;
      const View& view = views[rays[i].view];
      points[i] = view.point(rays[i].position.x, rays[i].position.y, hits.depth[best]);
      normals[i] = glm::dvec3(hits.normal[best]);
      ++moved;
    }
    return moved;
  };
}

}  // namespace ldimesh

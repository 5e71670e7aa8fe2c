#include "ldimesh/core/raycast/sample_source.hpp"

#include <stdexcept>

namespace ldimesh {

RayHitList cast_sample_points(const RayCaster& caster, std::span<const View> views,
                              std::span<const SamplePoint> points, const Subdomain* sub,
                              bool closed_planes) {
  // Rays of each view in request order, cast together.
  std::vector<std::vector<glm::dvec2>> positions(views.size()), ranges(views.size());
  std::vector<std::uint32_t> slot(points.size());  // index of point k among its view's rays
  for (std::size_t k = 0; k < points.size(); ++k) {
    const std::uint32_t v = points[k].view;
    if (v >= views.size()) throw std::out_of_range("sample request for an unknown view");
    slot[k] = std::uint32_t(positions[v].size());
    positions[v].push_back(points[k].position);
    ranges[v].push_back({points[k].depth_min, points[k].depth_max});
  }
  std::vector<RayHitList> hits(views.size());
  for (std::size_t v = 0; v < views.size(); ++v)
    if (!positions[v].empty())
      hits[v] = caster.cast_points(views[v], positions[v], sub, ranges[v], closed_planes);

  RayHitList out;
  out.offsets.reserve(points.size() + 1);
  out.offsets.push_back(0);
  const bool with_scalar = [&] {
    for (const RayHitList& h : hits)
      if (!h.scalar.empty()) return true;
    return false;
  }();
  for (std::size_t k = 0; k < points.size(); ++k) {
    const RayHitList& h = hits[points[k].view];
    const std::uint32_t b = h.offsets[slot[k]], e = h.offsets[slot[k] + 1];
    // Hit by hit: for the few hits of a ray this is cheaper than a range insert (a memmove call
    // each).
    for (std::uint32_t i = b; i < e; ++i) {
      out.depth.push_back(h.depth[i]);
      out.normal.push_back(h.normal[i]);
      if (with_scalar) out.scalar.push_back(h.scalar.empty() ? 0.0f : h.scalar[i]);
    }
    out.offsets.push_back(std::uint32_t(out.depth.size()));
  }
  return out;
}

}  // namespace ldimesh

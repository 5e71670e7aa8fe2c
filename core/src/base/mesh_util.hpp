// Internal to the core: the small helpers the mesh stages share (§3 meshing, §4 refinement, §5
// merging and quad conversion) — the "no index" value, edge keys, a mesh's faces by one number,
// the median of a set of lengths.
#pragma once

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "ldimesh/core/base/mesh.hpp"

namespace ldimesh {

// No vertex, face or half-edge (indices are below it).
inline constexpr std::uint32_t kNone = UINT32_MAX;

// The key of the directed edge from → to.
inline std::uint64_t directed_edge_key(std::uint32_t from, std::uint32_t to) {
  return std::uint64_t(from) << 32 | to;
}

// The key of the undirected edge {a, b}: the same both ways.
inline std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return a < b ? directed_edge_key(a, b) : directed_edge_key(b, a);
}

// The corners of face `face` of `m`, numbered quads first, then triangles.
inline std::span<const std::uint32_t> face_corners(const Mesh& m, std::size_t face) {
  const std::size_t nq = m.quad_count();
  return face < nq ? std::span<const std::uint32_t>(&m.quads[4 * face], 4)
                   : std::span<const std::uint32_t>(&m.triangles[3 * (face - nq)], 3);
}

// The median of `values` (the upper one of an even count; reorders them), or `none` if empty.
inline double median_of(std::vector<double>& values, double none) {
  if (values.empty()) return none;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

}  // namespace ldimesh

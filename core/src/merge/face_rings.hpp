// Internal to §5: the rings of faces around a set of vertices — how merging and the quad
// conversion each pick the part of a mesh they rewrite (MergeOptions::region_rings,
// QuadOptions::region_rings), the rest passing through as it is.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ldimesh/core/base/mesh.hpp"

namespace ldimesh {

// Per vertex of a mesh, its corners: corner k of face f is 4 f + k for a quad and
// 4 nq + 3 (f − nq) + k for a triangle (faces numbered quads first, then triangles), in
// increasing order.
struct VertexCorners {
  explicit VertexCorners(const Mesh& m);
  std::span<const std::uint32_t> at(std::uint32_t v) const {
    return {corners.data() + start[v], start[v + 1] - start[v]};
  }
  std::uint32_t face_of(std::uint32_t c) const {
    return c < quad_corners ? c / 4 : quads + (c - quad_corners) / 3;
  }
  std::vector<std::uint32_t> start;  // vertex count + 1
  std::vector<std::uint32_t> corners;
  std::uint32_t quads = 0, quad_corners = 0;
};

// Grows a region by `rings` rings of faces (none for rings ≤ 0): each ring adds every face not
// yet `inside` with a corner among `frontier` (the seed vertices for the first ring, then the
// vertices the previous ring added) and marks its corners in `in_vertex`. `inside` has one flag
// per face, `in_vertex` one per vertex (the seeds set). Returns the count of faces added.
std::size_t grow_face_rings(const Mesh& m, const VertexCorners& at, int rings,
                            std::vector<std::uint32_t> frontier,
                            std::vector<std::uint8_t>& in_vertex,
                            std::vector<std::uint8_t>& inside);

}  // namespace ldimesh

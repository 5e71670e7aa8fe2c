#include "face_rings.hpp"

#include "../base/mesh_util.hpp"

namespace ldimesh {

VertexCorners::VertexCorners(const Mesh& m)
    : start(m.positions.size() + 1, 0),
      quads(std::uint32_t(m.quad_count())),
      quad_corners(std::uint32_t(m.quads.size())) {
  const std::size_t nv = m.positions.size();
  for (std::uint32_t v : m.quads)
    ++start[v + 1];
  for (std::uint32_t v : m.triangles)
    ++start[v + 1];
  for (std::size_t v = 0; v < nv; ++v)
    start[v + 1] += start[v];
  corners.resize(start[nv]);
  std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
  for (std::uint32_t c = 0; c < m.quads.size(); ++c)
    corners[fill[m.quads[c]]++] = c;
  for (std::uint32_t c = 0; c < m.triangles.size(); ++c)
    corners[fill[m.triangles[c]]++] = quad_corners + c;
}

std::size_t grow_face_rings(const Mesh& m, const VertexCorners& at, int rings,
                            std::vector<std::uint32_t> frontier,
                            std::vector<std::uint8_t>& in_vertex,
                            std::vector<std::uint8_t>& inside) {
  std::size_t added = 0;
  std::vector<std::uint32_t> next;
  for (int ring = 0; ring < rings && !frontier.empty(); ++ring) {
    next.clear();
    for (std::uint32_t v : frontier)
      for (std::uint32_t c : at.at(v)) {
        const std::uint32_t f = at.face_of(c);
        if (inside[f]) continue;
        inside[f] = 1;
        ++added;
        for (std::uint32_t u : face_corners(m, f))
          if (!in_vertex[u]) in_vertex[u] = 1, next.push_back(u);
      }
    frontier.swap(next);
  }
  return added;
}

}  // namespace ldimesh

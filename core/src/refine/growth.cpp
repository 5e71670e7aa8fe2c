// §4 (iii) growing the view across open edges (refine_state.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "refine_state.hpp"

namespace ldimesh::refine_detail {
namespace {

// The corner of a grown cell at pixel p, next to the existing corner `near`: the sample of
// pixel p that best matches `near` (§3 cost), else an invalid vertex on near's tangent plane
// (shared with other grown cells of the same sheet there).
std::uint32_t far_vertex(RefineState& rs, glm::ivec2 p, std::uint32_t near) {
  const Vertex n = rs.vertices_[near];
  const glm::dvec2 image = glm::dvec2(p) + 0.5, step = image - n.image;
  // A top-level edge already joins `near` to a vertex there: the same sheet, so the same
  // vertex (two cells of one sheet meeting along one lattice edge share it).
  if (const std::uint32_t* w = rs.top_neighbours_.find_if(
          near, [&](std::uint32_t w) { return rs.vertices_[w].image == image; }))
    return *w;
  const double predicted = n.depth + glm::dot(n.slope, step);
  if (p.x >= 0 && p.y >= 0 && p.x < rs.view_.width && p.y < rs.view_.height) {
    const std::size_t pixel = std::size_t(p.y) * rs.view_.width + p.x;
    std::uint32_t best = kNone;
    double best_cost = rs.tolerance_;
    for (std::uint32_t s = rs.ldi_.begin(pixel); s < rs.ldi_.end(pixel); ++s) {
      const double ds = rs.ldi_.depth[s];
      const glm::dvec2 slope = rs.slope_of(glm::dvec3(rs.ldi_.normal[s]));
      const double cost = std::abs(ds - glm::dot(slope, step) - n.depth) + std::abs(predicted - ds);
      if (cost <= best_cost) {
        best = s;
        best_cost = cost;
      }
    }
    if (best != kNone) return rs.sample_vertex(best);
  }
  if (const std::uint32_t* v = rs.invalid_at_.find_if(rs.lattice_index(p), [&](std::uint32_t v) {
        return std::abs(rs.vertices_[v].depth - predicted) <= rs.tolerance_;
      }))
    return *v;
  Vertex v = n;
  v.image = image;
  v.depth = predicted;
  v.valid = false;
  v.edge_node = rs.edge_node_at(p);
  const std::uint32_t index = std::uint32_t(rs.vertices_.size());
  rs.invalid_at_.append(rs.lattice_index(p), index);
  rs.vertices_.push_back(v);
  ++rs.invalid_;
  return index;
}

}  // namespace

void grow(RefineState& rs) {
  // A FIFO queue of (cell, edge): the front is queue[next].
  std::vector<std::pair<std::uint32_t, int>> queue;
  queue.reserve(4 * rs.cells_.size());
  for (std::uint32_t t = 0; t < rs.cells_.size(); ++t)
    for (int k = 0; k < 4; ++k)
      queue.emplace_back(t, k);
  for (std::size_t next = 0; next < queue.size(); ++next) {
    const auto [t, k] = queue[next];
    const Cell from = rs.cells_[t];
    const std::uint32_t a = from.c[k], b = from.c[(k + 1) & 3];
    const EdgeUse e = rs.edges_[rs.top_cell_edges_[t][k]];
    if (e.top != 1) continue;
    if (e.untrimmed != (from.grown ? 0 : 1)) continue;
    if (!rs.vertices_[a].valid && !rs.vertices_[b].valid) continue;

    const glm::ivec2 at = rs.pixel_of(from.c[0]), target = at + kAcross[k];
    if (target.x < -1 || target.y < -1 || target.x >= rs.view_.width || target.y >= rs.view_.height)
      continue;
    Cell cell;
    cell.flip = from.flip;
    cell.grown = true;
    for (int q = 0; q < 4; ++q) {
      const glm::ivec2 p = target + kCorner[q];
      std::uint32_t shared = kNone, near = kNone;
      for (int m = 0; m < 4; ++m) {
        if (at + kCorner[m] == p) shared = from.c[m];
        if (at + kCorner[m] == p - kAcross[k]) near = from.c[m];
      }
      cell.c[q] = shared != kNone ? shared : far_vertex(rs, p, near);
    }
    if (rs.occupied(target, cell.c)) continue;
    bool manifold = true;
    for (int q = 0; q < 4; ++q) {
      const std::uint32_t e = rs.edge_of_.find(edge_key(cell.c[q], cell.c[(q + 1) & 3]));
      if (e != kNone && rs.edges_[e].top >= 2) manifold = false;
    }
    if (!manifold || rs.crosses_sheet_edge(cell)) continue;
    const std::uint32_t index = rs.add_top_cell(cell);
    rs.occupy(target, cell.c);
    ++rs.grown_;
    for (int q = 0; q < 4; ++q)
      queue.emplace_back(index, q);
  }
}

}  // namespace ldimesh::refine_detail

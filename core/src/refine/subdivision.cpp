// §4 marking and subdivision: one pass's topology and the rays its new vertices need
// (refine_state.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "refine_state.hpp"

namespace ldimesh::refine_detail {
namespace {

// §4 marking: an invalid corner, or two corner normals further apart than the threshold.
bool needs_refinement(const RefineState& rs, const Cell& cell) {
  for (std::uint32_t v : cell.c)
    if (!rs.vertices_[v].valid) return true;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b)
      if (glm::dot(rs.vertices_[cell.c[a]].normal, rs.vertices_[cell.c[b]].normal) <
          rs.options_.min_normal_dot)
        return true;
  return false;
}

// Triangles: the marked cells split, then the 1-level difference rule: a leaf splits while
// a neighbour across one of its edges is two levels finer (the edge's midpoint has one
// itself).
void split_quadtree(RefineState& rs) {
  const std::size_t before = rs.cells_.size();
  for (std::uint32_t i : rs.marked_)
    rs.subdivide(i);
  for (bool changed = true; changed;) {
    changed = false;
    for (std::uint32_t i = 0; i < rs.cells_.size(); ++i) {
      if (!rs.cells_[i].leaf) continue;
      const Cell& cell = rs.cells_[i];
      // A leaf from before this pass kept the rule when the last pass ended (its last sweep
      // split nothing; before the first pass there are no midpoints). Only a midpoint made in
      // this pass can break it, on the leaf's edge or one of its halves: an edge that ends at
      // a corner of the leaf. So a leaf with no such corner is skipped, as it would not split.
      if (i < before && std::none_of(cell.c.begin(), cell.c.end(), [&](std::uint32_t v) {
            return rs.split_edge_pass(v) == rs.pass_;
          }))
        continue;
      bool split = false;
      for (int k = 0; k < 4 && !split; ++k) {
        const std::uint32_t a = cell.c[k], b = cell.c[(k + 1) & 3], m = rs.find_midpoint(a, b);
        split = m != kNone && (rs.find_midpoint(a, m) != kNone || rs.find_midpoint(m, b) != kNone);
      }
      if (split) {
        rs.subdivide(i);
        changed = true;
      }
    }
  }
}

// Quads: 2-refinement. The edge nodes of the marked cells become active; every leaf with an
// active corner is a transition cell: two active corners (a marked cell) split it into four,
// one gives the corner template (three quads around the active corner). Every edge at an
// active node is split once and shared, so no hanging node remains. The active nodes stop
// being edge nodes; the new midpoints become edge nodes.
void split_two_refinement(RefineState& rs) {
  std::vector<std::uint32_t> active;
  std::vector<std::uint8_t> is_active(rs.vertices_.size(), 0);
  for (std::uint32_t i : rs.marked_)
    for (std::uint32_t v : rs.cells_[i].c)
      if (rs.vertices_[v].edge_node && !is_active[v]) {
        is_active[v] = 1;
        active.push_back(v);
      }
  const std::uint32_t count = std::uint32_t(rs.cells_.size());
  for (std::uint32_t i = 0; i < count; ++i) {
    if (!rs.cells_[i].leaf) continue;
    const Cell cell = rs.cells_[i];
    int corners = 0, first = -1;
    for (int k = 0; k < 4; ++k)
      if (is_active[cell.c[k]]) {
        ++corners;
        if (first < 0) first = k;
      }
    if (corners == 0) continue;
    if (corners >= 2) {
      rs.subdivide(i);
      continue;
    }
    // Corner template at c[k]: its two edges split, the cell's centre joins them.
    rs.cells_[i].leaf = false;
    ++rs.subdivided_;
    const int k = first;
    const std::uint32_t ck = cell.c[k], c1 = cell.c[(k + 1) & 3], c2 = cell.c[(k + 2) & 3],
                        c3 = cell.c[(k + 3) & 3];
    const std::uint32_t ma = rs.midpoint(ck, c1), mb = rs.midpoint(c3, ck);
    const std::uint32_t x = rs.new_vertex({cell.c[0], cell.c[1], cell.c[2], cell.c[3]}, false);
    rs.add_child(cell, {ck, ma, x, mb});
    rs.add_child(cell, {ma, c1, c2, x});
    rs.add_child(cell, {mb, x, c2, c3});
  }
  for (std::uint32_t v : active)
    rs.vertices_[v].edge_node = false;
}

}  // namespace

bool split(RefineState& rs) {
  ++rs.pass_;
  rs.pending_.clear();
  rs.ray_of_.clear();
  rs.rays_.clear();
  rs.marked_.clear();
  for (std::uint32_t i = 0; i < rs.cells_.size(); ++i)
    if (rs.cells_[i].leaf && rs.cells_[i].level < rs.options_.levels &&
        needs_refinement(rs, rs.cells_[i]))
      rs.marked_.push_back(i);
  if (rs.marked_.empty()) return false;
  const std::size_t first_new = rs.vertices_.size();
  if (rs.faces_ == FaceType::triangles)
    split_quadtree(rs);
  else
    split_two_refinement(rs);
  // The depths at which each ray's new vertices can match (see resolve): a matching hit lies
  // within the threshold of the mean prediction of its references. Each position's intervals
  // (one per vertex there, one per layer) are merged where they overlap and cast as separate
  // stretches of its ray, in depth order, so the position's hits stay one sorted run that
  // holds every hit the whole ray would give its vertices. The references are corners of cells
  // that existed before the pass (a cell split in a pass never needs splitting again in it), so
  // their depths are known here. The intervals are grouped by ray with a counting sort (one
  // pass, no comparison sort over all of them): counted at rs.first_wanted_[ray + 2], summed into
  // the starts at rs.first_wanted_[ray + 1], and placed by advancing those to the ends, which
  // leaves ray k's at rs.wanted_[rs.first_wanted_[k], rs.first_wanted_[k + 1]); each ray's few are
  // then sorted by start and merged (their order before does not change the union).
  rs.first_wanted_.assign(rs.rays_.size() + 2, 0);
  for (const Pending& p : rs.pending_)
    ++rs.first_wanted_[p.ray + 2];
  for (std::size_t k = 2; k < rs.first_wanted_.size(); ++k)
    rs.first_wanted_[k] += rs.first_wanted_[k - 1];
  rs.wanted_.resize(rs.pending_.size());
  const double pad = 1e-6 * (1.0 + rs.view_.depth_extent);  // the hits' depths are floats
  for (Pending& p : rs.pending_) {
    p.match = rs.match_references(p, first_new);
    double& predicted = p.match.predicted;
    for (std::uint32_t k = 0; k < p.match.n; ++k) {
      const Vertex& r = rs.vertices_[p.match.use[k]];
      predicted += r.depth + glm::dot(r.slope, rs.vertices_[p.vertex].image - r.image);
    }
    predicted /= p.match.n;
    rs.wanted_[rs.first_wanted_[p.ray + 1]++] = {std::max(0.0, predicted - p.match.threshold - pad),
                                                 predicted + p.match.threshold + pad};
  }
  rs.stretch_positions_.clear();
  rs.stretch_ranges_.clear();
  rs.first_stretch_.assign(1, 0);
  for (std::size_t ray = 0; ray < rs.rays_.size(); ++ray) {
    const std::span<glm::dvec2> ranges(rs.wanted_.begin() + rs.first_wanted_[ray],
                                       rs.wanted_.begin() + rs.first_wanted_[ray + 1]);
    std::sort(ranges.begin(), ranges.end(), [](glm::dvec2 a, glm::dvec2 b) { return a.x < b.x; });
    for (const glm::dvec2& range : ranges) {
      if (rs.stretch_ranges_.size() > rs.first_stretch_.back() &&
          range.x <= rs.stretch_ranges_.back().y) {
        rs.stretch_ranges_.back().y = std::max(rs.stretch_ranges_.back().y, range.y);
      } else {
        rs.stretch_positions_.push_back(rs.rays_[ray]);
        rs.stretch_ranges_.push_back(range);
      }
    }
    rs.first_stretch_.push_back(std::uint32_t(rs.stretch_ranges_.size()));
  }
  return true;
}

}  // namespace ldimesh::refine_detail

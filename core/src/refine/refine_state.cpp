// The state of one view's §4 refinement and its edits (refine_state.hpp).
#include "refine_state.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "ldimesh/core/mesh/trim.hpp"

namespace ldimesh::refine_detail {

RefineState::RefineState(const Ldi& ldi, const ViewQuads& quads, FaceType faces,
                         const RefinementOptions& options, const MatchOptions& matching,
                         std::span<const glm::dvec3> all_dirs, double r)
    : ldi_(ldi),
      view_(ldi.view),
      faces_(faces),
      options_(options),
      min_facing_(matching.min_facing),
      tolerance_(matching.max_cost * ldi.view.spacing),
      dirs_(all_dirs.begin(), all_dirs.end()),
      r_(r),
      vertex_of_sample_(ldi.sample_count(), kNone) {
  pixel_of_sample_ = sample_pixels(ldi);
  const std::size_t pixels = std::size_t(view_.width + 2) * (view_.height + 2);  // lattice_index
  occupants_.reserve_lists(pixels);
  invalid_at_.reserve_lists(pixels);
  lattice_edges_.reserve_lists(2 * pixels);
  edge_of_.reserve(quads.untrimmed.size() / 2);  // two edges per quad and some boundary
  // §3 quads come as (s0, right, top-right, top), or reversed where their normals face −dir.
  auto lattice = [&](const std::uint32_t* q, bool& flip) {
    flip = pixel_of_sample_[q[1]] != pixel_of_sample_[q[0]] + 1;
    return flip ? std::array<std::uint32_t, 4>{sample_vertex(q[0]), sample_vertex(q[3]),
                                               sample_vertex(q[2]), sample_vertex(q[1])}
                : std::array<std::uint32_t, 4>{sample_vertex(q[0]), sample_vertex(q[1]),
                                               sample_vertex(q[2]), sample_vertex(q[3])};
  };
  for (std::size_t q = 0; q < quads.untrimmed.size(); q += 4) {
    bool flip = false;
    const std::array<std::uint32_t, 4> c = lattice(&quads.untrimmed[q], flip);
    for (int k = 0; k < 4; ++k)
      ++edges_[edge(c[k], c[(k + 1) & 3])].untrimmed;
    occupy(pixel_of(c[0]), c);
  }
  for (std::size_t q = 0; q < quads.kept.size(); q += 4) {
    Cell cell;
    cell.c = lattice(&quads.kept[q], cell.flip);
    add_top_cell(cell);  // its lattice cell is occupied already, as an untrimmed quad
  }
}

References RefineState::match_references(const Pending& p, std::size_t first_new) const {
  References refs;
  for (std::uint32_t k = 0; k < p.ref_count; ++k) {
    if (p.refs[k] >= first_new)
      throw std::logic_error("refinement: a new vertex refers to a vertex of the same pass");
    if (vertices_[p.refs[k]].valid) refs.use[refs.n++] = p.refs[k];
  }
  if (refs.n == 0) {
    refs.use = p.refs;
    refs.n = p.ref_count;
  }
  double reach = 0.0;
  for (std::uint32_t k = 0; k < refs.n; ++k)
    reach += glm::length(vertices_[p.vertex].image - vertices_[refs.use[k]].image);
  refs.threshold = tolerance_ * std::min(1.0, reach / refs.n);
  return refs;
}

glm::dvec2 RefineState::slope_of(glm::dvec3 n) const {
  double nd = glm::dot(n, view_.dir);
  if (std::abs(nd) < min_facing_) nd = std::copysign(min_facing_, nd);
  // Tangent plane n·Δp = 0 with Δp = h(a u + b v) + Δdepth dir.
  return -view_.spacing / nd * glm::dvec2(glm::dot(n, view_.u), glm::dot(n, view_.v));
}

std::uint32_t RefineState::sample_vertex(std::uint32_t s) {
  if (vertex_of_sample_[s] != kNone) return vertex_of_sample_[s];
  const std::uint32_t p = pixel_of_sample_[s];
  const glm::ivec2 pixel(int(p % std::uint32_t(view_.width)), int(p / std::uint32_t(view_.width)));
  Vertex v;
  v.image = glm::dvec2(pixel) + 0.5;
  v.depth = ldi_.depth[s];
  v.normal = glm::dvec3(ldi_.normal[s]);
  v.scalar = ldi_.scalar.empty() ? 0.0f : ldi_.scalar[s];
  v.slope = slope_of(v.normal);
  v.edge_node = edge_node_at(pixel);
  vertex_of_sample_[s] = std::uint32_t(vertices_.size());
  vertices_.push_back(v);
  return vertex_of_sample_[s];
}

std::uint32_t RefineState::add_top_cell(const Cell& cell) {
  const std::uint32_t index = std::uint32_t(cells_.size());
  cells_.push_back(cell);
  std::array<std::uint32_t, 4>& ids = top_cell_edges_.emplace_back();
  for (int k = 0; k < 4; ++k) {
    const std::uint32_t a = cell.c[k], b = cell.c[(k + 1) & 3];
    ids[k] = edge(a, b);
    if (edges_[ids[k]].top++ == 0) {
      top_neighbours_.append(a, b);
      top_neighbours_.append(b, a);
      lattice_edges_.append(lattice_edge(a, b), edge_key(a, b));
    }
  }
  return index;
}

std::uint32_t RefineState::edge(std::uint32_t a, std::uint32_t b) {
  const auto [e, added] = edge_of_.try_emplace(edge_key(a, b), std::uint32_t(edges_.size()));
  if (added) edges_.emplace_back();
  return e;
}

std::size_t RefineState::lattice_edge(std::uint32_t a, std::uint32_t b) const {
  const glm::ivec2 pa = pixel_of(a), pb = pixel_of(b);
  return 2 * lattice_index(glm::min(pa, pb)) + (pa.x == pb.x ? 1 : 0);
}

bool RefineState::crosses_sheet_edge(const Cell& cell) const {
  for (int k = 0; k < 4; ++k) {
    const std::uint32_t a = cell.c[k], b = cell.c[(k + 1) & 3];
    const double depth = vertices_[a].depth + vertices_[b].depth;
    const auto same_sheet = [&](std::uint64_t other) {
      if (other == edge_key(a, b)) return false;
      const std::uint32_t oa = std::uint32_t(other >> 32), ob = std::uint32_t(other);
      return oa == a || oa == b || ob == a || ob == b ||
             std::abs(vertices_[oa].depth + vertices_[ob].depth - depth) <= 2.0 * tolerance_;
    };
    if (lattice_edges_.find_if(lattice_edge(a, b), same_sheet)) return true;
  }
  return false;
}

double RefineState::mean_depth(const std::array<std::uint32_t, 4>& c) const {
  return 0.25 * (vertices_[c[0]].depth + vertices_[c[1]].depth + vertices_[c[2]].depth +
                 vertices_[c[3]].depth);
}

bool RefineState::occupied(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) const {
  const double depth = mean_depth(c);
  return occupants_.find_if(lattice_index(pixel), [&](const std::array<std::uint32_t, 4>& other) {
    if (std::abs(mean_depth(other) - depth) <= tolerance_) return true;
    for (std::uint32_t a : c)
      if (std::find(other.begin(), other.end(), a) != other.end()) return true;
    return false;
  });
}

std::uint32_t RefineState::new_vertex(std::initializer_list<std::uint32_t> refs, bool edge_node) {
  const std::uint32_t index = std::uint32_t(vertices_.size());
  Pending& p = pending_.emplace_back();
  p.vertex = index;
  glm::dvec2 image(0.0);
  for (std::uint32_t r : refs) {
    p.refs[p.ref_count++] = r;
    image += vertices_[r].image;
  }
  image /= double(p.ref_count);
  const auto [ray, added] = ray_of_.try_emplace(image, std::uint32_t(rays_.size()));
  if (added) rays_.push_back(image);
  p.ray = ray;
  Vertex& v = vertices_.emplace_back();
  v.image = image;
  v.edge_node = edge_node;
  return index;
}

std::uint32_t RefineState::midpoint(std::uint32_t a, std::uint32_t b) {
  // The vertex new_vertex makes next, unless the edge has one.
  const auto [m, added] = midpoints_.try_emplace(edge_key(a, b), std::uint32_t(vertices_.size()));
  if (added) {
    new_vertex({a, b}, true);
    split_edge_pass_.resize(vertices_.size(), 0);
    split_edge_pass_[a] = split_edge_pass_[b] = pass_;
  }
  return m;
}

std::uint32_t RefineState::find_midpoint(std::uint32_t a, std::uint32_t b) const {
  if (split_edge_pass(a) == 0 || split_edge_pass(b) == 0) return kNone;
  return midpoints_.find(edge_key(a, b));
}

void RefineState::add_child(const Cell& parent, std::array<std::uint32_t, 4> c) {
  Cell& child = cells_.emplace_back(parent);
  child.c = c;
  child.level = parent.level + 1;
  child.leaf = true;
}

void RefineState::subdivide(std::uint32_t index) {
  const Cell cell = cells_[index];
  cells_[index].leaf = false;
  ++subdivided_;
  std::array<std::uint32_t, 4> m;
  for (int k = 0; k < 4; ++k)
    m[k] = midpoint(cell.c[k], cell.c[(k + 1) & 3]);
  const std::uint32_t x = new_vertex({cell.c[0], cell.c[1], cell.c[2], cell.c[3]}, false);
  add_child(cell, {cell.c[0], m[0], x, m[3]});
  add_child(cell, {m[0], cell.c[1], m[1], x});
  add_child(cell, {x, m[1], cell.c[2], m[2]});
  add_child(cell, {m[3], x, m[2], cell.c[3]});
}

}  // namespace ldimesh::refine_detail

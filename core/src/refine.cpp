#include "ldimesh/core/refine.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <memory>
#include <stdexcept>
#include <unordered_map>

#include <tbb/parallel_for.h>

#include "ldimesh/core/mesh.hpp"
#include "ldimesh/core/timing.hpp"
#include "ldimesh/core/trim.hpp"

namespace ldimesh {
namespace {

constexpr std::uint32_t kNone = UINT32_MAX;

std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return a < b ? (std::uint64_t(a) << 32 | b) : (std::uint64_t(b) << 32 | a);
}

// Lattice cells (i, j) with i, j ≥ -1.
std::uint64_t cell_key(glm::ivec2 p) {
  return std::uint64_t(std::uint32_t(p.x + 1)) << 32 | std::uint32_t(p.y + 1);
}

struct PositionHash {
  std::size_t operator()(const glm::dvec2& p) const {
    std::uint64_t a = 0, b = 0;
    std::memcpy(&a, &p.x, 8);
    std::memcpy(&b, &p.y, 8);
    return std::hash<std::uint64_t>()(a * 0x9E3779B97F4A7C15ull ^ b);
  }
};

// A vertex of a view's refined mesh. Top-level vertices are LDI samples at pixel centres;
// refinement adds vertices between them, at dyadic image positions.
struct Vertex {
  glm::dvec2 image;    // pixel units (View::point)
  double depth = 0.0;  // along the view direction
  glm::dvec3 normal{0.0};
  float scalar = 0.0f;
  glm::dvec2 slope{0.0};   // depth change per pixel along u and v, from the normal
  bool valid = true;       // false: no matching sample; depth and normal interpolated
  bool edge_node = false;  // quads: a 2-refinement edge node
};

// A quad cell, corners counter-clockwise in the image plane (u, v); lattice cells start at the
// lower left. `flip`: the output runs the other way round (its normals face −dir).
struct Cell {
  std::array<std::uint32_t, 4> c;
  std::int32_t level = 0;
  bool leaf = true;
  bool flip = false;
  bool grown = false;
};

// What a new vertex is matched against (see ViewRefiner::match_references): reference
// vertices and the cost threshold.
struct References {
  std::array<std::uint32_t, 4> use{};
  std::uint32_t n = 0;
  double threshold = 0.0;
};

// A vertex made in the current pass, waiting for its ray.
struct Pending {
  std::uint32_t vertex;
  std::array<std::uint32_t, 4> refs;
  std::uint32_t ref_count;
  std::uint32_t ray;
  References match;  // set once the pass's templates are applied
};

// Corner offsets of a lattice cell and the neighbour across each edge (edge k joins corners k
// and k + 1).
constexpr glm::ivec2 kCorner[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
constexpr glm::ivec2 kAcross[4] = {{0, -1}, {1, 0}, {0, 1}, {-1, 0}};

class ViewRefiner {
 public:
  ViewRefiner(const Ldi& ldi, const ViewQuads& quads, FaceType faces,
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
        ++untrimmed_edges_[edge_key(c[k], c[(k + 1) & 3])];
      occupy(pixel_of(c[0]), c);
    }
    for (std::size_t q = 0; q < quads.kept.size(); q += 4) {
      Cell cell;
      cell.c = lattice(&quads.kept[q], cell.flip);
      add_top_cell(cell);  // its lattice cell is occupied already, as an untrimmed quad
    }
  }

  // §4 (iii): new top-level cells across open edges that hold a valid vertex, until none is
  // left. Their far corners are LDI samples that match (§3 cost) or invalid vertices.
  void grow() {
    std::deque<std::pair<std::uint32_t, int>> queue;
    for (std::uint32_t t = 0; t < cells_.size(); ++t)
      for (int k = 0; k < 4; ++k)
        queue.emplace_back(t, k);
    while (!queue.empty()) {
      const auto [t, k] = queue.front();
      queue.pop_front();
      const Cell from = cells_[t];
      const std::uint32_t a = from.c[k], b = from.c[(k + 1) & 3];
      const std::uint64_t e = edge_key(a, b);
      if (top_edges_[e] != 1) continue;
      const auto u = untrimmed_edges_.find(e);
      if ((u == untrimmed_edges_.end() ? 0 : u->second) != (from.grown ? 0 : 1)) continue;
      if (!vertices_[a].valid && !vertices_[b].valid) continue;

      const glm::ivec2 at = pixel_of(from.c[0]), target = at + kAcross[k];
      if (target.x < -1 || target.y < -1 || target.x >= view_.width || target.y >= view_.height)
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
        cell.c[q] = shared != kNone ? shared : far_vertex(p, near);
      }
      if (occupied(target, cell.c)) continue;
      bool manifold = true;
      for (int q = 0; q < 4; ++q) {
        const auto it = top_edges_.find(edge_key(cell.c[q], cell.c[(q + 1) & 3]));
        if (it != top_edges_.end() && it->second >= 2) manifold = false;
      }
      if (!manifold || crosses_sheet_edge(cell)) continue;
      const std::uint32_t index = add_top_cell(cell);
      occupy(target, cell.c);
      ++grown_;
      for (int q = 0; q < 4; ++q)
        queue.emplace_back(index, q);
    }
  }

  // One pass's topology: marks cells, applies the templates, and lists the rays the new
  // vertices need. Returns false when nothing was marked.
  bool split() {
    pending_.clear();
    ray_of_.clear();
    rays_.clear();
    std::vector<std::uint32_t> marked;
    for (std::uint32_t i = 0; i < cells_.size(); ++i)
      if (cells_[i].leaf && cells_[i].level < options_.levels && needs_refinement(cells_[i]))
        marked.push_back(i);
    if (marked.empty()) return false;
    const std::size_t first_new = vertices_.size();
    if (faces_ == FaceType::triangles)
      split_quadtree(marked);
    else
      split_two_refinement(marked);
    // The depths at which each ray's new vertices can match (see resolve): a matching hit lies
    // within the threshold of the mean prediction of its references. Each position's intervals
    // (one per vertex there, one per layer) are merged where they overlap and cast as separate
    // stretches of its ray, in depth order, so the position's hits stay one sorted run that
    // holds every hit the whole ray would give its vertices. The references are corners of cells
    // that existed before the pass (a cell split in a pass never needs splitting again in it), so
    // their depths are known here.
    std::vector<std::vector<glm::dvec2>> wanted(rays_.size());
    const double pad = 1e-6 * (1.0 + view_.depth_extent);  // the hits' depths are floats
    for (Pending& p : pending_) {
      p.match = match_references(p, first_new);
      double predicted = 0.0;
      for (std::uint32_t k = 0; k < p.match.n; ++k) {
        const Vertex& r = vertices_[p.match.use[k]];
        predicted += r.depth + glm::dot(r.slope, vertices_[p.vertex].image - r.image);
      }
      predicted /= p.match.n;
      wanted[p.ray].push_back({std::max(0.0, predicted - p.match.threshold - pad),
                               predicted + p.match.threshold + pad});
    }
    stretch_positions_.clear();
    stretch_ranges_.clear();
    first_stretch_.assign(1, 0);
    for (std::size_t ray = 0; ray < rays_.size(); ++ray) {
      std::vector<glm::dvec2>& ranges = wanted[ray];
      std::sort(ranges.begin(), ranges.end(), [](glm::dvec2 a, glm::dvec2 b) { return a.x < b.x; });
      for (const glm::dvec2& range : ranges) {
        if (stretch_ranges_.size() > first_stretch_.back() && range.x <= stretch_ranges_.back().y) {
          stretch_ranges_.back().y = std::max(stretch_ranges_.back().y, range.y);
        } else {
          stretch_positions_.push_back(rays_[ray]);
          stretch_ranges_.push_back(range);
        }
      }
      first_stretch_.push_back(std::uint32_t(stretch_ranges_.size()));
    }
    return true;
  }

  // The ray stretches this pass asks for: image positions and depth ranges.
  std::span<const glm::dvec2> stretch_positions() const { return stretch_positions_; }
  std::span<const glm::dvec2> stretch_ranges() const { return stretch_ranges_; }

  // The answers to the stretches: stretch k's hits are [offsets[first + k],
  // offsets[first + k + 1]) of `hits`.
  void resolve(const RayHitList& hits, std::size_t first) {
    std::vector<std::uint8_t> claimed(hits.depth.size(), 0);
    for (const Pending& p : pending_) {
      Vertex& v = vertices_[p.vertex];
      const std::array<std::uint32_t, 4>& use = p.match.use;
      const std::uint32_t n = p.match.n;
      const std::uint32_t b = hits.offsets[first + first_stretch_[p.ray]],
                          e = hits.offsets[first + first_stretch_[p.ray + 1]];
      std::uint32_t best = kNone;
      double best_cost = p.match.threshold;
      for (std::uint32_t s = b; s < e; ++s) {
        if (claimed[s]) continue;
        const double ds = hits.depth[s];
        const glm::dvec2 slope = slope_of(glm::dvec3(hits.normal[s]));
        double cost = 0.0;
        for (std::uint32_t k = 0; k < n; ++k) {
          const Vertex& r = vertices_[use[k]];
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
        claimed[best] = 1;
        v.depth = hits.depth[best];
        v.normal = glm::dvec3(hits.normal[best]);
        v.scalar = hits.scalar.empty() ? 0.0f : hits.scalar[best];
        v.valid = true;
      } else {
        double depth = 0.0, scalar = 0.0;
        glm::dvec3 normal(0.0);
        for (std::uint32_t k = 0; k < n; ++k) {
          const Vertex& r = vertices_[use[k]];
          depth += r.depth + glm::dot(r.slope, v.image - r.image);
          normal += r.normal;
          scalar += r.scalar;
        }
        v.depth = depth / n;
        const double length = glm::length(normal);
        v.normal = length > 0.0 ? normal / length : vertices_[use[0]].normal;
        v.scalar = float(scalar / n);
        v.valid = false;
        ++invalid_;
      }
      v.slope = slope_of(v.normal);
    }
  }

  // The references a pending vertex is matched against: its valid ones, or all when none is
  // valid, and the cost threshold. §3's cost against every reference is the mean of
  // |e(s, ref) − d(ref)| + |e(ref, p) − d(s)|, accepted below the §3 threshold scaled by the mean
  // step (in pixels) to the references: predictions over shorter steps are better, and a layer
  // as close as the threshold would otherwise be taken for this one. Throws std::logic_error if
  // a reference is a vertex of this pass (index ≥ first_new), whose depth is not known yet.
  References match_references(const Pending& p, std::size_t first_new) const {
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

  // The leaves as faces: quads as they are, triangles through the six templates. Faces with an
  // invalid vertex are dropped; faces of grown cells are trimmed like §3.
  RefinedView output(RefinementStats& stats) const {
    std::vector<std::uint32_t> faces;
    std::vector<std::uint8_t> from_grown;
    const int arity = faces_ == FaceType::quads ? 4 : 3;
    std::vector<std::uint32_t> tris;
    std::vector<glm::vec3> world(vertices_.size());
    for (std::size_t v = 0; v < vertices_.size(); ++v)
      world[v] = position(vertices_[v]);
    for (const Cell& cell : cells_) {
      if (!cell.leaf) continue;
      std::size_t before = faces.size();
      if (faces_ == FaceType::quads) {
        faces.insert(faces.end(), cell.c.begin(), cell.c.end());
      } else {
        tris.clear();
        triangle_templates(cell, world, tris);
        faces.insert(faces.end(), tris.begin(), tris.end());
      }
      if (cell.flip)
        for (std::size_t f = before; f < faces.size(); f += arity)
          std::reverse(faces.begin() + f, faces.begin() + f + arity);
      from_grown.insert(from_grown.end(), (faces.size() - before) / arity, cell.grown);
    }

    RefinedView out;
    std::vector<std::uint32_t> index(vertices_.size(), kNone);
    const glm::vec3 dq(view_.dir);
    const float rf = float(r_);
    std::vector<std::uint32_t> kept;
    for (std::size_t f = 0; f < faces.size(); f += arity) {
      const std::uint32_t* c = &faces[f];
      bool valid = true;
      for (int k = 0; k < arity; ++k)
        valid = valid && vertices_[c[k]].valid;
      if (!valid) {
        ++stats.removed_faces;
        continue;
      }
      if (from_grown[f / arity]) {
        for (int k = 0; k < arity && valid; ++k) {
          const glm::vec3 v = world[c[k]], prev = world[c[(k + arity - 1) % arity]],
                          next = world[c[(k + 1) % arity]];
          valid = view_quality_ok(glm::cross(v - prev, v - next), dq, dirs_, rf);
        }
        if (!valid) {
          ++stats.trimmed_faces;
          continue;
        }
      }
      kept.insert(kept.end(), c, c + arity);
    }
    // Vertices used by a kept face, in the order they were made.
    for (std::uint32_t v : kept)
      index[v] = 0;
    for (std::size_t v = 0; v < vertices_.size(); ++v) {
      if (index[v] == kNone) continue;
      index[v] = std::uint32_t(out.positions.size());
      out.positions.push_back(world[v]);
      out.normals.push_back(glm::vec3(vertices_[v].normal));
      if (!ldi_.scalar.empty()) out.scalars.push_back(vertices_[v].scalar);
    }
    out.faces.reserve(kept.size());
    for (std::uint32_t v : kept)
      out.faces.push_back(index[v]);
    stats.grown_cells += grown_;
    stats.subdivided_cells += subdivided_;
    stats.invalid_vertices += invalid_;
    return out;
  }

 private:
  glm::dvec2 slope_of(glm::dvec3 n) const {
    double nd = glm::dot(n, view_.dir);
    if (std::abs(nd) < min_facing_) nd = std::copysign(min_facing_, nd);
    // Tangent plane n·Δp = 0 with Δp = h(a u + b v) + Δdepth dir.
    return -view_.spacing / nd * glm::dvec2(glm::dot(n, view_.u), glm::dot(n, view_.v));
  }

  glm::vec3 position(const Vertex& v) const {
    return glm::vec3(view_.point(v.image.x, v.image.y, v.depth));
  }

  glm::ivec2 pixel_of(std::uint32_t vertex) const {
    return glm::ivec2(glm::floor(vertices_[vertex].image));
  }

  static bool edge_node_at(glm::ivec2 p) { return ((p.x + p.y) % 2 + 2) % 2 == 0; }

  std::uint32_t sample_vertex(std::uint32_t s) {
    if (vertex_of_sample_[s] != kNone) return vertex_of_sample_[s];
    const std::uint32_t p = pixel_of_sample_[s];
    const glm::ivec2 pixel(int(p % std::uint32_t(view_.width)),
                           int(p / std::uint32_t(view_.width)));
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

  // A top-level cell (corner 0 at its lattice position) and its edges.
  std::uint32_t add_top_cell(const Cell& cell) {
    const std::uint32_t index = std::uint32_t(cells_.size());
    cells_.push_back(cell);
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t a = cell.c[k], b = cell.c[(k + 1) & 3];
      if (top_edges_[edge_key(a, b)]++ == 0) {
        top_neighbours_[a].push_back(b);
        top_neighbours_[b].push_back(a);
        lattice_edges_[lattice_edge_key(a, b)].push_back(edge_key(a, b));
      }
    }
    return index;
  }

  // The lattice edge between the pixel centres of two top-level vertices.
  std::pair<std::uint64_t, std::uint64_t> lattice_edge_key(std::uint32_t a, std::uint32_t b) const {
    const std::uint64_t ka = cell_key(pixel_of(a)), kb = cell_key(pixel_of(b));
    return {std::min(ka, kb), std::max(ka, kb)};
  }

  // Whether an edge of `cell` runs along a top-level edge of the same sheet between other
  // vertices (one end in common, or a mean depth within the match tolerance): the two cells
  // would meet without sharing their vertices, and refinement would leave hanging vertices.
  bool crosses_sheet_edge(const Cell& cell) const {
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t a = cell.c[k], b = cell.c[(k + 1) & 3];
      const auto it = lattice_edges_.find(lattice_edge_key(a, b));
      if (it == lattice_edges_.end()) continue;
      const double depth = vertices_[a].depth + vertices_[b].depth;
      for (std::uint64_t other : it->second) {
        if (other == edge_key(a, b)) continue;
        const std::uint32_t oa = std::uint32_t(other >> 32), ob = std::uint32_t(other);
        if (oa == a || oa == b || ob == a || ob == b) return true;
        if (std::abs(vertices_[oa].depth + vertices_[ob].depth - depth) <= 2.0 * tolerance_)
          return true;
      }
    }
    return false;
  }

  double mean_depth(const std::array<std::uint32_t, 4>& c) const {
    return 0.25 * (vertices_[c[0]].depth + vertices_[c[1]].depth + vertices_[c[2]].depth +
                   vertices_[c[3]].depth);
  }

  void occupy(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) {
    occupants_[cell_key(pixel)].push_back(c);
  }

  // Whether a cell of the same sheet (a shared corner, or a mean depth within the match
  // tolerance) already sits at lattice cell `pixel`.
  bool occupied(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) const {
    const auto it = occupants_.find(cell_key(pixel));
    if (it == occupants_.end()) return false;
    const double depth = mean_depth(c);
    for (const auto& other : it->second) {
      if (std::abs(mean_depth(other) - depth) <= tolerance_) return true;
      for (std::uint32_t a : c)
        if (std::find(other.begin(), other.end(), a) != other.end()) return true;
    }
    return false;
  }

  // The corner of a grown cell at pixel p, next to the existing corner `near`: the sample of
  // pixel p that best matches `near` (§3 cost), else an invalid vertex on near's tangent plane
  // (shared with other grown cells of the same sheet there).
  std::uint32_t far_vertex(glm::ivec2 p, std::uint32_t near) {
    const Vertex n = vertices_[near];
    const glm::dvec2 image = glm::dvec2(p) + 0.5, step = image - n.image;
    // A top-level edge already joins `near` to a vertex there: the same sheet, so the same
    // vertex (two cells of one sheet meeting along one lattice edge share it).
    if (const auto it = top_neighbours_.find(near); it != top_neighbours_.end())
      for (std::uint32_t w : it->second)
        if (vertices_[w].image == image) return w;
    const double predicted = n.depth + glm::dot(n.slope, step);
    if (p.x >= 0 && p.y >= 0 && p.x < view_.width && p.y < view_.height) {
      const std::size_t pixel = std::size_t(p.y) * view_.width + p.x;
      std::uint32_t best = kNone;
      double best_cost = tolerance_;
      for (std::uint32_t s = ldi_.begin(pixel); s < ldi_.end(pixel); ++s) {
        const double ds = ldi_.depth[s];
        const glm::dvec2 slope = slope_of(glm::dvec3(ldi_.normal[s]));
        const double cost =
            std::abs(ds - glm::dot(slope, step) - n.depth) + std::abs(predicted - ds);
        if (cost <= best_cost) {
          best = s;
          best_cost = cost;
        }
      }
      if (best != kNone) return sample_vertex(best);
    }
    std::vector<std::uint32_t>& here = invalid_at_[cell_key(p)];
    for (std::uint32_t v : here)
      if (std::abs(vertices_[v].depth - predicted) <= tolerance_) return v;
    Vertex v = n;
    v.image = image;
    v.depth = predicted;
    v.valid = false;
    v.edge_node = edge_node_at(p);
    here.push_back(std::uint32_t(vertices_.size()));
    vertices_.push_back(v);
    ++invalid_;
    return here.back();
  }

  // §4 marking: an invalid corner, or two corner normals further apart than the threshold.
  bool needs_refinement(const Cell& cell) const {
    for (std::uint32_t v : cell.c)
      if (!vertices_[v].valid) return true;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        if (glm::dot(vertices_[cell.c[a]].normal, vertices_[cell.c[b]].normal) <
            options_.min_normal_dot)
          return true;
    return false;
  }

  // A vertex of this pass between `refs` (their mean image position), waiting for its ray.
  std::uint32_t new_vertex(std::initializer_list<std::uint32_t> refs, bool edge_node) {
    Pending p{};
    p.vertex = std::uint32_t(vertices_.size());
    p.ref_count = 0;
    glm::dvec2 image(0.0);
    for (std::uint32_t r : refs) {
      p.refs[p.ref_count++] = r;
      image += vertices_[r].image;
    }
    image /= double(p.ref_count);
    const auto [it, added] = ray_of_.try_emplace(image, std::uint32_t(rays_.size()));
    if (added) rays_.push_back(image);
    p.ray = it->second;
    Vertex v;
    v.image = image;
    v.edge_node = edge_node;
    vertices_.push_back(v);
    pending_.push_back(p);
    return p.vertex;
  }

  std::uint32_t midpoint(std::uint32_t a, std::uint32_t b) {
    const auto [it, added] = midpoints_.try_emplace(edge_key(a, b), kNone);
    if (added) it->second = new_vertex({a, b}, true);
    return it->second;
  }

  std::uint32_t find_midpoint(std::uint32_t a, std::uint32_t b) const {
    const auto it = midpoints_.find(edge_key(a, b));
    return it == midpoints_.end() ? kNone : it->second;
  }

  void add_child(const Cell& parent, std::array<std::uint32_t, 4> c) {
    Cell child = parent;
    child.c = c;
    child.level = parent.level + 1;
    child.leaf = true;
    cells_.push_back(child);
  }

  // Quadtree subdivision into four: midpoints of the edges (shared with the neighbours) and
  // the centre.
  void subdivide(std::uint32_t index) {
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

  // Triangles: the marked cells split, then the 1-level difference rule: a leaf splits while
  // a neighbour across one of its edges is two levels finer (the edge's midpoint has one
  // itself).
  void split_quadtree(const std::vector<std::uint32_t>& marked) {
    for (std::uint32_t i : marked)
      subdivide(i);
    for (bool changed = true; changed;) {
      changed = false;
      for (std::uint32_t i = 0; i < cells_.size(); ++i) {
        if (!cells_[i].leaf) continue;
        const Cell& cell = cells_[i];
        bool split = false;
        for (int k = 0; k < 4 && !split; ++k) {
          const std::uint32_t a = cell.c[k], b = cell.c[(k + 1) & 3], m = find_midpoint(a, b);
          split = m != kNone && (find_midpoint(a, m) != kNone || find_midpoint(m, b) != kNone);
        }
        if (split) {
          subdivide(i);
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
  void split_two_refinement(const std::vector<std::uint32_t>& marked) {
    std::vector<std::uint32_t> active;
    std::vector<std::uint8_t> is_active(vertices_.size(), 0);
    for (std::uint32_t i : marked)
      for (std::uint32_t v : cells_[i].c)
        if (vertices_[v].edge_node && !is_active[v]) {
          is_active[v] = 1;
          active.push_back(v);
        }
    const std::uint32_t count = std::uint32_t(cells_.size());
    for (std::uint32_t i = 0; i < count; ++i) {
      if (!cells_[i].leaf) continue;
      const Cell cell = cells_[i];
      int corners = 0, first = -1;
      for (int k = 0; k < 4; ++k)
        if (is_active[cell.c[k]]) {
          ++corners;
          if (first < 0) first = k;
        }
      if (corners == 0) continue;
      if (corners >= 2) {
        subdivide(i);
        continue;
      }
      // Corner template at c[k]: its two edges split, the cell's centre joins them.
      cells_[i].leaf = false;
      ++subdivided_;
      const int k = first;
      const std::uint32_t ck = cell.c[k], c1 = cell.c[(k + 1) & 3], c2 = cell.c[(k + 2) & 3],
                          c3 = cell.c[(k + 3) & 3];
      const std::uint32_t ma = midpoint(ck, c1), mb = midpoint(c3, ck);
      const std::uint32_t x = new_vertex({cell.c[0], cell.c[1], cell.c[2], cell.c[3]}, false);
      add_child(cell, {ck, ma, x, mb});
      add_child(cell, {ma, c1, c2, x});
      add_child(cell, {mb, x, c2, c3});
    }
    for (std::uint32_t v : active)
      vertices_[v].edge_node = false;
  }

  // The six templates (up to rotation and inversion) for a leaf with hanging midpoints m[k] on
  // its edges: none (two triangles), one, two adjacent, two opposite, three, four.
  void triangle_templates(const Cell& cell, const std::vector<glm::vec3>& world,
                          std::vector<std::uint32_t>& out) const {
    std::array<std::uint32_t, 4> m;
    int hanging = 0;
    for (int k = 0; k < 4; ++k) {
      m[k] = find_midpoint(cell.c[k], cell.c[(k + 1) & 3]);
      hanging += m[k] != kNone;
    }
    const auto c = [&](int k) { return cell.c[k & 3]; };
    const auto h = [&](int k) { return m[k & 3] != kNone; };
    const auto mid = [&](int k) { return m[k & 3]; };
    const auto quad = [&](std::uint32_t a, std::uint32_t b, std::uint32_t e, std::uint32_t d) {
      const std::uint32_t v[4] = {a, b, e, d};
      append_quad_triangles(world, v, out);
    };
    if (hanging == 0) {
      quad(c(0), c(1), c(2), c(3));
      return;
    }
    // Rotate: edge s is hanging, and so is s + 1 for two adjacent, s + 2 for two opposite, s + 1
    // and s + 2 for three.
    const auto fits = [&](int k) {
      if (!h(k)) return false;
      if (hanging == 2) return h(k + 1) || h(k + 2);
      if (hanging == 3) return h(k + 1) && h(k + 2);
      return true;
    };
    int s = 0;
    while (!fits(s))
      ++s;
    if (hanging == 1) {
      out.insert(out.end(),
                 {mid(s), c(s + 1), c(s + 2), mid(s), c(s + 2), c(s + 3), mid(s), c(s + 3), c(s)});
    } else if (hanging == 2 && h(s + 2)) {
      quad(c(s), mid(s), mid(s + 2), c(s + 3));
      quad(mid(s), c(s + 1), c(s + 2), mid(s + 2));
    } else if (hanging == 2) {  // edges s and s + 1
      out.insert(out.end(), {mid(s), c(s + 1), mid(s + 1), mid(s), mid(s + 1), c(s + 2), mid(s),
                             c(s + 2), c(s + 3), mid(s), c(s + 3), c(s)});
    } else if (hanging == 3) {  // edges s, s + 1, s + 2
      out.insert(out.end(),
                 {mid(s), c(s + 1), mid(s + 1), mid(s + 1), c(s + 2), mid(s + 2), mid(s),
                  mid(s + 1), mid(s + 2), mid(s), mid(s + 2), c(s + 3), mid(s), c(s + 3), c(s)});
    } else {
      for (int k = 0; k < 4; ++k)
        out.insert(out.end(), {mid(k - 1), c(k), mid(k)});
      quad(mid(0), mid(1), mid(2), mid(3));
    }
  }

  const Ldi& ldi_;
  const View& view_;
  FaceType faces_;
  RefinementOptions options_;
  double min_facing_;
  double tolerance_;  // world units: the §3 match rejection threshold
  std::vector<glm::vec3> dirs_;
  double r_;

  std::vector<std::uint32_t> pixel_of_sample_;
  std::vector<std::uint32_t> vertex_of_sample_;
  std::vector<Vertex> vertices_;
  std::vector<Cell> cells_;  // top-level cells first
  std::unordered_map<std::uint64_t, int> untrimmed_edges_;
  std::unordered_map<std::uint64_t, int> top_edges_;
  std::unordered_map<std::uint32_t, std::vector<std::uint32_t>> top_neighbours_;
  struct PairHash {
    std::size_t operator()(const std::pair<std::uint64_t, std::uint64_t>& p) const {
      return std::hash<std::uint64_t>()(p.first * 0x9E3779B97F4A7C15ull ^ p.second);
    }
  };
  std::unordered_map<std::pair<std::uint64_t, std::uint64_t>, std::vector<std::uint64_t>, PairHash>
      lattice_edges_;
  std::unordered_map<std::uint64_t, std::vector<std::array<std::uint32_t, 4>>> occupants_;
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> invalid_at_;
  std::unordered_map<std::uint64_t, std::uint32_t> midpoints_;

  std::vector<Pending> pending_;
  std::vector<glm::dvec2> rays_;  // image positions of this pass's new vertices
  std::vector<glm::dvec2> stretch_positions_, stretch_ranges_;
  std::vector<std::uint32_t> first_stretch_;  // stretches of rays_[k]: [first[k], first[k + 1])
  std::unordered_map<glm::dvec2, std::uint32_t, PositionHash> ray_of_;

  std::size_t grown_ = 0, subdivided_ = 0, invalid_ = 0;
};

}  // namespace

std::vector<RefinedView> refine_views(std::span<const Ldi> ldis, std::span<const ViewQuads> quads,
                                      FaceType faces, const RefinementOptions& options,
                                      const MatchOptions& matching,
                                      std::span<const glm::dvec3> all_dirs, double r,
                                      SampleSource& samples, RefinementStats& stats) {
  if (options.levels < 0 || options.levels > 16)
    throw std::invalid_argument("refinement levels must lie in [0, 16]");
  if (quads.size() != ldis.size())
    throw std::invalid_argument("refine_views: one set of quads per LDI");
  stats = {};
  const auto start = std::chrono::steady_clock::now();
  const std::size_t n = ldis.size();
  std::vector<std::unique_ptr<ViewRefiner>> views(n);
  tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) {
    views[k] =
        std::make_unique<ViewRefiner>(ldis[k], quads[k], faces, options, matching, all_dirs, r);
    if (options.grow && options.levels > 0) views[k]->grow();
  });

  for (int pass = 0; pass < options.levels; ++pass) {
    const auto pass_start = std::chrono::steady_clock::now();
    std::vector<std::uint8_t> split(n, 0);
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) { split[k] = views[k]->split(); });
    if (std::none_of(split.begin(), split.end(), [](std::uint8_t s) { return s != 0; })) break;
    // One round trip for the new vertices of all views.
    std::vector<SamplePoint> points;
    std::vector<std::size_t> first(n);
    for (std::size_t k = 0; k < n; ++k) {
      first[k] = points.size();
      const std::span<const glm::dvec2> positions = views[k]->stretch_positions(),
                                        ranges = views[k]->stretch_ranges();
      for (std::size_t i = 0; i < positions.size(); ++i)
        points.push_back({std::uint32_t(k), positions[i], ranges[i].x, ranges[i].y});
    }
    const auto sample_start = std::chrono::steady_clock::now();
    const RayHitList hits = samples.sample(points);
    stats.sample_seconds += seconds_since(sample_start);
    ++stats.round_trips;
    if (hits.offsets.size() != points.size() + 1)
      throw std::runtime_error("sample source answered " + std::to_string(hits.offsets.size() - 1) +
                               " rays for " + std::to_string(points.size()));
    tbb::parallel_for(std::size_t(0), n, [&](std::size_t k) { views[k]->resolve(hits, first[k]); });
    ++stats.passes;
    stats.rays_per_pass.push_back(points.size());
    stats.seconds_per_pass.push_back(seconds_since(pass_start));
  }

  std::vector<RefinedView> out(n);
  std::vector<RefinementStats> per_view(n);
  tbb::parallel_for(std::size_t(0), n,
                    [&](std::size_t k) { out[k] = views[k]->output(per_view[k]); });
  for (const RefinementStats& s : per_view) {
    stats.grown_cells += s.grown_cells;
    stats.subdivided_cells += s.subdivided_cells;
    stats.invalid_vertices += s.invalid_vertices;
    stats.removed_faces += s.removed_faces;
    stats.trimmed_faces += s.trimmed_faces;
  }
  stats.seconds = seconds_since(start);
  return out;
}

}  // namespace ldimesh

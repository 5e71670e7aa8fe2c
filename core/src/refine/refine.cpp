#include "ldimesh/core/refine/refine.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <stdexcept>

#include <tbb/parallel_for.h>

#include "../base/index_map.hpp"
#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/mesh/trim.hpp"

namespace ldimesh {
namespace {

struct PositionHash {
  std::uint64_t operator()(const glm::dvec2& p) const {
    std::uint64_t a = 0, b = 0;
    std::memcpy(&a, &p.x, 8);
    std::memcpy(&b, &p.y, 8);
    return mix(a ^ mix(b));
  }
};

// Lists of values under dense list numbers (lattice positions, vertices), all in one pool:
// appending allocates nothing per list, and a list keeps the order its values came in.
template <class T>
class ListPool {
 public:
  // Lists [0, lists) exist (empty) from now on; append makes more as needed.
  void reserve_lists(std::size_t lists) {
    if (lists > head_.size()) {
      head_.resize(lists, kNone);
      tail_.resize(lists, kNone);
    }
  }

  void append(std::size_t list, const T& value) {
    reserve_lists(list + 1);
    const std::uint32_t node = std::uint32_t(nodes_.size());
    nodes_.push_back({value, kNone});
    if (head_[list] == kNone)
      head_[list] = node;
    else
      nodes_[tail_[list]].next = node;
    tail_[list] = node;
  }

  // The first value of `list`, in order, for which `pred` holds, or nullptr.
  template <class Pred>
  const T* find_if(std::size_t list, Pred pred) const {
    if (list >= head_.size()) return nullptr;
    for (std::uint32_t n = head_[list]; n != kNone; n = nodes_[n].next)
      if (pred(nodes_[n].value)) return &nodes_[n].value;
    return nullptr;
  }

 private:
  struct Node {
    T value;
    std::uint32_t next;
  };
  std::vector<std::uint32_t> head_, tail_;
  std::vector<Node> nodes_;
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

// How many untrimmed §3 quads and top-level cells have an edge.
struct EdgeUse {
  int untrimmed = 0;
  int top = 0;
};

// What a new vertex is matched against (see ViewRefiner::match_references): reference
// vertices and the cost threshold.
struct References {
  std::array<std::uint32_t, 4> use{};
  std::uint32_t n = 0;
  double threshold = 0.0;
  double predicted = 0.0;  // the mean of their depth predictions at the vertex
};

// A vertex made in the current pass, waiting for its ray.
struct Pending {
  std::uint32_t vertex = 0;
  std::array<std::uint32_t, 4> refs{};
  std::uint32_t ref_count = 0;
  std::uint32_t ray = 0;
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

  // §4 (iii): new top-level cells across open edges that hold a valid vertex, until none is
  // left. Their far corners are LDI samples that match (§3 cost) or invalid vertices.
  void grow() {
    // A FIFO queue of (cell, edge): the front is queue[next].
    std::vector<std::pair<std::uint32_t, int>> queue;
    queue.reserve(4 * cells_.size());
    for (std::uint32_t t = 0; t < cells_.size(); ++t)
      for (int k = 0; k < 4; ++k)
        queue.emplace_back(t, k);
    for (std::size_t next = 0; next < queue.size(); ++next) {
      const auto [t, k] = queue[next];
      const Cell from = cells_[t];
      const std::uint32_t a = from.c[k], b = from.c[(k + 1) & 3];
      const EdgeUse e = edges_[top_cell_edges_[t][k]];
      if (e.top != 1) continue;
      if (e.untrimmed != (from.grown ? 0 : 1)) continue;
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
        const std::uint32_t e = edge_of_.find(edge_key(cell.c[q], cell.c[(q + 1) & 3]));
        if (e != kNone && edges_[e].top >= 2) manifold = false;
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
    ++pass_;
    pending_.clear();
    ray_of_.clear();
    rays_.clear();
    marked_.clear();
    for (std::uint32_t i = 0; i < cells_.size(); ++i)
      if (cells_[i].leaf && cells_[i].level < options_.levels && needs_refinement(cells_[i]))
        marked_.push_back(i);
    if (marked_.empty()) return false;
    const std::size_t first_new = vertices_.size();
    if (faces_ == FaceType::triangles)
      split_quadtree();
    else
      split_two_refinement();
    // The depths at which each ray's new vertices can match (see resolve): a matching hit lies
    // within the threshold of the mean prediction of its references. Each position's intervals
    // (one per vertex there, one per layer) are merged where they overlap and cast as separate
    // stretches of its ray, in depth order, so the position's hits stay one sorted run that
    // holds every hit the whole ray would give its vertices. The references are corners of cells
    // that existed before the pass (a cell split in a pass never needs splitting again in it), so
    // their depths are known here. The intervals are grouped by ray with a counting sort (one
    // pass, no comparison sort over all of them): counted at first_wanted_[ray + 2], summed into
    // the starts at first_wanted_[ray + 1], and placed by advancing those to the ends, which
    // leaves ray k's at wanted_[first_wanted_[k], first_wanted_[k + 1]); each ray's few are then
    // sorted by start and merged (their order before does not change the union).
    first_wanted_.assign(rays_.size() + 2, 0);
    for (const Pending& p : pending_)
      ++first_wanted_[p.ray + 2];
    for (std::size_t k = 2; k < first_wanted_.size(); ++k)
      first_wanted_[k] += first_wanted_[k - 1];
    wanted_.resize(pending_.size());
    const double pad = 1e-6 * (1.0 + view_.depth_extent);  // the hits' depths are floats
    for (Pending& p : pending_) {
      p.match = match_references(p, first_new);
      double& predicted = p.match.predicted;
      for (std::uint32_t k = 0; k < p.match.n; ++k) {
        const Vertex& r = vertices_[p.match.use[k]];
        predicted += r.depth + glm::dot(r.slope, vertices_[p.vertex].image - r.image);
      }
      predicted /= p.match.n;
      wanted_[first_wanted_[p.ray + 1]++] = {std::max(0.0, predicted - p.match.threshold - pad),
                                             predicted + p.match.threshold + pad};
    }
    stretch_positions_.clear();
    stretch_ranges_.clear();
    first_stretch_.assign(1, 0);
    for (std::size_t ray = 0; ray < rays_.size(); ++ray) {
      const std::span<glm::dvec2> ranges(wanted_.begin() + first_wanted_[ray],
                                         wanted_.begin() + first_wanted_[ray + 1]);
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
    // Hits this view's vertices took, from this view's first hit on.
    const std::uint32_t base = hits.offsets[first];
    claimed_.assign(hits.offsets[first + stretch_ranges_.size()] - base, 0);
    for (const Pending& p : pending_) {
      Vertex& v = vertices_[p.vertex];
      const std::array<std::uint32_t, 4>& use = p.match.use;
      const std::uint32_t n = p.match.n;
      const std::uint32_t b = hits.offsets[first + first_stretch_[p.ray]],
                          e = hits.offsets[first + first_stretch_[p.ray + 1]];
      std::uint32_t best = kNone;
      double best_cost = p.match.threshold;
      for (std::uint32_t s = b; s < e; ++s) {
        if (claimed_[s - base]) continue;
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
        claimed_[best - base] = 1;
        v.depth = hits.depth[best];
        v.normal = glm::dvec3(hits.normal[best]);
        v.scalar = hits.scalar.empty() ? 0.0f : hits.scalar[best];
        v.valid = true;
      } else {
        double scalar = 0.0;
        glm::dvec3 normal(0.0);
        for (std::uint32_t k = 0; k < n; ++k) {
          normal += vertices_[use[k]].normal;
          scalar += vertices_[use[k]].scalar;
        }
        v.depth = p.match.predicted;
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
    const int arity = faces_ == FaceType::quads ? 4 : 3;
    std::vector<glm::vec3> world(vertices_.size());
    for (std::size_t v = 0; v < vertices_.size(); ++v)
      world[v] = position(vertices_[v]);
    const glm::vec3 dq(view_.dir);
    const float rf = float(r_);
    RefinedView out;
    // The kept faces, in vertex numbers until the end: each leaf's faces are appended, then the
    // ones it keeps are moved down over those it drops.
    std::vector<std::uint32_t>& faces = out.faces;
    for (const Cell& cell : cells_) {
      if (!cell.leaf) continue;
      std::size_t kept = faces.size();
      if (faces_ == FaceType::quads)
        faces.insert(faces.end(), cell.c.begin(), cell.c.end());
      else
        triangle_templates(cell, world, faces);
      for (std::size_t f = kept; f < faces.size(); f += arity) {
        std::uint32_t* c = &faces[f];
        if (cell.flip) std::reverse(c, c + arity);
        bool valid = true;
        for (int k = 0; k < arity; ++k)
          valid = valid && vertices_[c[k]].valid;
        if (!valid) {
          ++stats.removed_faces;
          continue;
        }
        if (cell.grown) {
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
        for (int k = 0; k < arity; ++k)  // kept ≤ f: no overlap ahead of the copy
          faces[kept + k] = c[k];
        kept += arity;
      }
      faces.resize(kept);
    }
    // Vertices used by a kept face, in the order they were made.
    std::vector<std::uint32_t> index(vertices_.size(), kNone);
    std::uint32_t used = 0;
    for (std::uint32_t v : faces)
      if (index[v] == kNone) {
        index[v] = 0;
        ++used;
      }
    out.positions.reserve(used);
    out.normals.reserve(used);
    if (!ldi_.scalar.empty()) out.scalars.reserve(used);
    for (std::size_t v = 0; v < vertices_.size(); ++v) {
      if (index[v] == kNone) continue;
      index[v] = std::uint32_t(out.positions.size());
      out.positions.push_back(world[v]);
      out.normals.push_back(glm::vec3(vertices_[v].normal));
      if (!ldi_.scalar.empty()) out.scalars.push_back(vertices_[v].scalar);
    }
    for (std::uint32_t& v : faces)
      v = index[v];
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

  // The number in edges_ of the top-level edge a–b, added unused if new.
  std::uint32_t edge(std::uint32_t a, std::uint32_t b) {
    const auto [e, added] = edge_of_.try_emplace(edge_key(a, b), std::uint32_t(edges_.size()));
    if (added) edges_.emplace_back();
    return e;
  }

  // Pixels p ∈ [−1, width] × [−1, height] (of top-level vertices; lattice cells are numbered by
  // their lower left corner's pixel) in the arrays over the lattice.
  std::size_t lattice_index(glm::ivec2 p) const {
    return std::size_t(p.y + 1) * std::size_t(view_.width + 2) + std::size_t(p.x + 1);
  }

  // The lattice edge between the pixel centres of two top-level vertices (4-neighbours): twice
  // the lower or left one's index, plus one when it runs along v.
  std::size_t lattice_edge(std::uint32_t a, std::uint32_t b) const {
    const glm::ivec2 pa = pixel_of(a), pb = pixel_of(b);
    return 2 * lattice_index(glm::min(pa, pb)) + (pa.x == pb.x ? 1 : 0);
  }

  // Whether an edge of `cell` runs along a top-level edge of the same sheet between other
  // vertices (one end in common, or a mean depth within the match tolerance): the two cells
  // would meet without sharing their vertices, and refinement would leave hanging vertices.
  bool crosses_sheet_edge(const Cell& cell) const {
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

  double mean_depth(const std::array<std::uint32_t, 4>& c) const {
    return 0.25 * (vertices_[c[0]].depth + vertices_[c[1]].depth + vertices_[c[2]].depth +
                   vertices_[c[3]].depth);
  }

  void occupy(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) {
    occupants_.append(lattice_index(pixel), c);
  }

  // Whether a cell of the same sheet (a shared corner, or a mean depth within the match
  // tolerance) already sits at lattice cell `pixel`.
  bool occupied(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) const {
    const double depth = mean_depth(c);
    return occupants_.find_if(lattice_index(pixel), [&](const std::array<std::uint32_t, 4>& other) {
      if (std::abs(mean_depth(other) - depth) <= tolerance_) return true;
      for (std::uint32_t a : c)
        if (std::find(other.begin(), other.end(), a) != other.end()) return true;
      return false;
    });
  }

  // The corner of a grown cell at pixel p, next to the existing corner `near`: the sample of
  // pixel p that best matches `near` (§3 cost), else an invalid vertex on near's tangent plane
  // (shared with other grown cells of the same sheet there).
  std::uint32_t far_vertex(glm::ivec2 p, std::uint32_t near) {
    const Vertex n = vertices_[near];
    const glm::dvec2 image = glm::dvec2(p) + 0.5, step = image - n.image;
    // A top-level edge already joins `near` to a vertex there: the same sheet, so the same
    // vertex (two cells of one sheet meeting along one lattice edge share it).
    if (const std::uint32_t* w = top_neighbours_.find_if(
            near, [&](std::uint32_t w) { return vertices_[w].image == image; }))
      return *w;
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
    if (const std::uint32_t* v = invalid_at_.find_if(lattice_index(p), [&](std::uint32_t v) {
          return std::abs(vertices_[v].depth - predicted) <= tolerance_;
        }))
      return *v;
    Vertex v = n;
    v.image = image;
    v.depth = predicted;
    v.valid = false;
    v.edge_node = edge_node_at(p);
    const std::uint32_t index = std::uint32_t(vertices_.size());
    invalid_at_.append(lattice_index(p), index);
    vertices_.push_back(v);
    ++invalid_;
    return index;
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

  std::uint32_t midpoint(std::uint32_t a, std::uint32_t b) {
    // The vertex new_vertex makes next, unless the edge has one.
    const auto [m, added] = midpoints_.try_emplace(edge_key(a, b), std::uint32_t(vertices_.size()));
    if (added) {
      new_vertex({a, b}, true);
      split_edge_pass_.resize(vertices_.size(), 0);
      split_edge_pass_[a] = split_edge_pass_[b] = pass_;
    }
    return m;
  }

  // The midpoint of edge a–b, or kNone. Most edges asked about (every leaf's, in each sweep of
  // the 1-level rule and in the output) have none; split_edge_pass_ answers those without a hash
  // lookup.
  std::uint32_t find_midpoint(std::uint32_t a, std::uint32_t b) const {
    if (split_edge_pass(a) == 0 || split_edge_pass(b) == 0) return kNone;
    return midpoints_.find(edge_key(a, b));
  }

  // The last pass (counted from 1) that put a midpoint on an edge ending at v; 0: none did.
  std::uint32_t split_edge_pass(std::uint32_t v) const {
    return v < split_edge_pass_.size() ? split_edge_pass_[v] : 0;
  }

  // `parent` must not live in cells_, which may move.
  void add_child(const Cell& parent, std::array<std::uint32_t, 4> c) {
    Cell& child = cells_.emplace_back(parent);
    child.c = c;
    child.level = parent.level + 1;
    child.leaf = true;
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
  void split_quadtree() {
    const std::size_t before = cells_.size();
    for (std::uint32_t i : marked_)
      subdivide(i);
    for (bool changed = true; changed;) {
      changed = false;
      for (std::uint32_t i = 0; i < cells_.size(); ++i) {
        if (!cells_[i].leaf) continue;
        const Cell& cell = cells_[i];
        // A leaf from before this pass kept the rule when the last pass ended (its last sweep
        // split nothing; before the first pass there are no midpoints). Only a midpoint made in
        // this pass can break it, on the leaf's edge or one of its halves: an edge that ends at
        // a corner of the leaf. So a leaf with no such corner is skipped, as it would not split.
        if (i < before && std::none_of(cell.c.begin(), cell.c.end(), [&](std::uint32_t v) {
              return split_edge_pass(v) == pass_;
            }))
          continue;
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
  void split_two_refinement() {
    std::vector<std::uint32_t> active;
    std::vector<std::uint8_t> is_active(vertices_.size(), 0);
    for (std::uint32_t i : marked_)
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
  // Top-level edges (see edge()), numbered by edge_of_, and those of each top-level cell (the
  // first cells_), so that growth, which visits every one, needs no lookup.
  IndexMap<std::uint64_t, MixHash> edge_of_;
  std::vector<EdgeUse> edges_;
  std::vector<std::array<std::uint32_t, 4>> top_cell_edges_;
  ListPool<std::uint32_t> top_neighbours_;            // per vertex, over top-level edges
  ListPool<std::uint64_t> lattice_edges_;             // top-level edges per lattice_edge()
  ListPool<std::array<std::uint32_t, 4>> occupants_;  // top-level cells per lattice cell
  ListPool<std::uint32_t> invalid_at_;  // invalid top-level vertices per pixel (lattice_index)
  IndexMap<std::uint64_t, MixHash> midpoints_;  // per edge_key: the vertex splitting the edge
  // Per vertex: the last pass that split an edge ending there (see split_edge_pass()).
  std::vector<std::uint32_t> split_edge_pass_;
  std::uint32_t pass_ = 0;  // passes begun, the current one included

  // One pass's state, kept to reuse its memory.
  std::vector<std::uint32_t> marked_;
  std::vector<Pending> pending_;
  std::vector<glm::dvec2> rays_;  // image positions of this pass's new vertices
  IndexMap<glm::dvec2, PositionHash> ray_of_;
  std::vector<glm::dvec2> wanted_;           // depth intervals of rays_[k]: wanted_[first[k],
  std::vector<std::uint32_t> first_wanted_;  // first[k + 1]) (see split())
  std::vector<glm::dvec2> stretch_positions_, stretch_ranges_;
  std::vector<std::uint32_t> first_stretch_;  // stretches of rays_[k]: [first[k], first[k + 1])
  std::vector<std::uint8_t> claimed_;         // see resolve()

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
    std::size_t total = 0;
    for (std::size_t k = 0; k < n; ++k)
      total += views[k]->stretch_positions().size();
    points.reserve(total);
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

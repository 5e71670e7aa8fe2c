// Internal to §4 refinement (refine.hpp): the state one view's refinement keeps across its
// passes — its vertices (LDI samples at pixel centres and the ones refinement adds), the cells
// of its quadtree (top-level cells first), the top-level edges and the lattice lookups growth
// and the 1-level rule use, the midpoints, and one pass's pending vertices and their ray
// stretches — with the edits the steps are built from (a vertex for a sample, a top-level cell,
// a pending vertex, a midpoint, a quadtree subdivision). The steps are free functions over it,
// one file each: growth.cpp (§4 (iii) growing across open edges), subdivision.cpp (marking and
// the two subdivision schemes, one pass's rays), matching.cpp (the rays' hits matched to the
// pending vertices); refine.cpp runs the passes over all views and writes each view's faces.
//
// Threads: one RefineState per view, used by one thread at a time (refine_views runs the views
// in parallel); every step is in a fixed order (deterministic).
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <span>
#include <vector>

#include "../base/index_map.hpp"
#include "../base/mesh_util.hpp"
#include "ldimesh/core/refine/refine.hpp"

namespace ldimesh::refine_detail {

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

// What a new vertex is matched against (see RefineState::match_references): reference
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

struct RefineState {
  RefineState(const Ldi& ldi, const ViewQuads& quads, FaceType faces,
              const RefinementOptions& options, const MatchOptions& matching,
              std::span<const glm::dvec3> all_dirs, double r);

  // The ray stretches this pass asks for: image positions and depth ranges.
  std::span<const glm::dvec2> stretch_positions() const { return stretch_positions_; }
  std::span<const glm::dvec2> stretch_ranges() const { return stretch_ranges_; }

  // The references a pending vertex is matched against: its valid ones, or all when none is
  // valid, and the cost threshold. §3's cost against every reference is the mean of
  // |e(s, ref) − d(ref)| + |e(ref, p) − d(s)|, accepted below the §3 threshold scaled by the mean
  // step (in pixels) to the references: predictions over shorter steps are better, and a layer
  // as close as the threshold would otherwise be taken for this one. Throws std::logic_error if
  // a reference is a vertex of this pass (index ≥ first_new), whose depth is not known yet.
  References match_references(const Pending& p, std::size_t first_new) const;

  // The depth change per pixel along u and v of the tangent plane with normal n (its facing
  // |n·dir| clamped below at the §3 min_facing).
  glm::dvec2 slope_of(glm::dvec3 n) const;
  glm::vec3 position(const Vertex& v) const {
    return glm::vec3(view_.point(v.image.x, v.image.y, v.depth));
  }
  glm::ivec2 pixel_of(std::uint32_t vertex) const {
    return glm::ivec2(glm::floor(vertices_[vertex].image));
  }
  // Quads: the top-level vertices that start as 2-refinement edge nodes (a checkerboard).
  static bool edge_node_at(glm::ivec2 p) { return ((p.x + p.y) % 2 + 2) % 2 == 0; }
  // The vertex of LDI sample s, made on first use.
  std::uint32_t sample_vertex(std::uint32_t s);

  // A top-level cell (corner 0 at its lattice position) and its edges.
  std::uint32_t add_top_cell(const Cell& cell);

  // The number in edges_ of the top-level edge a–b, added unused if new.
  std::uint32_t edge(std::uint32_t a, std::uint32_t b);

  // Pixels p ∈ [−1, width] × [−1, height] (of top-level vertices; lattice cells are numbered by
  // their lower left corner's pixel) in the arrays over the lattice.
  std::size_t lattice_index(glm::ivec2 p) const {
    return std::size_t(p.y + 1) * std::size_t(view_.width + 2) + std::size_t(p.x + 1);
  }

  // The lattice edge between the pixel centres of two top-level vertices (4-neighbours): twice
  // the lower or left one's index, plus one when it runs along v.
  std::size_t lattice_edge(std::uint32_t a, std::uint32_t b) const;

  // Whether an edge of `cell` runs along a top-level edge of the same sheet between other
  // vertices (one end in common, or a mean depth within the match tolerance): the two cells
  // would meet without sharing their vertices, and refinement would leave hanging vertices.
  bool crosses_sheet_edge(const Cell& cell) const;
  double mean_depth(const std::array<std::uint32_t, 4>& c) const;
  void occupy(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) {
    occupants_.append(lattice_index(pixel), c);
  }

  // Whether a cell of the same sheet (a shared corner, or a mean depth within the match
  // tolerance) already sits at lattice cell `pixel`.
  bool occupied(glm::ivec2 pixel, const std::array<std::uint32_t, 4>& c) const;

  // A vertex of this pass between `refs` (their mean image position), waiting for its ray.
  std::uint32_t new_vertex(std::initializer_list<std::uint32_t> refs, bool edge_node);
  // The vertex splitting edge a–b: a new pending one (an edge node) unless the edge has one.
  std::uint32_t midpoint(std::uint32_t a, std::uint32_t b);

  // The midpoint of edge a–b, or kNone. Most edges asked about (every leaf's, in each sweep of
  // the 1-level rule and in the output) have none; split_edge_pass_ answers those without a hash
  // lookup.
  std::uint32_t find_midpoint(std::uint32_t a, std::uint32_t b) const;

  // The last pass (counted from 1) that put a midpoint on an edge ending at v; 0: none did.
  std::uint32_t split_edge_pass(std::uint32_t v) const {
    return v < split_edge_pass_.size() ? split_edge_pass_[v] : 0;
  }

  // `parent` must not live in cells_, which may move.
  void add_child(const Cell& parent, std::array<std::uint32_t, 4> c);

  // Quadtree subdivision into four: midpoints of the edges (shared with the neighbours) and
  // the centre.
  void subdivide(std::uint32_t index);

  // The view, its options and the §3 matching limits.
  const Ldi& ldi_;
  const View& view_;
  FaceType faces_;
  RefinementOptions options_;
  double min_facing_;
  double tolerance_;  // world units: the §3 match rejection threshold
  std::vector<glm::vec3> dirs_;
  double r_;

  // Vertices and cells.
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

// The steps, in the order refine_views runs them.

// §4 (iii): new top-level cells across open edges that hold a valid vertex, until none is
// left. Their far corners are LDI samples that match (§3 cost) or invalid vertices.
void grow(RefineState& rs);

// One pass's topology: marks cells, applies the templates, and lists the rays the new
// vertices need. Returns false when nothing was marked.
bool split(RefineState& rs);

// The answers to the stretches: stretch k's hits are [offsets[first + k],
// offsets[first + k + 1]) of `hits`.
void resolve(RefineState& rs, const RayHitList& hits, std::size_t first);

// The leaves as faces: quads as they are, triangles through the six templates. Faces with an
// invalid vertex are dropped; faces of grown cells are trimmed like §3.
RefinedView output(const RefineState& rs, RefinementStats& stats);

}  // namespace ldimesh::refine_detail

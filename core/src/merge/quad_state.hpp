// Internal to §5 (iv) quad mesh generation (quadrangulate.hpp): the region being converted
// (QuadRegion), the state the conversion's steps share — its own half-edge arrays, the length
// unit, the Dijkstra scratch, the vertex rings and the moved vertices — with the edits every
// step is built from (split an edge, split a face, add a vertex), and the steps, one file each:
// quad_pairing.cpp (greedy pairing), quad_paths.cpp (shortest paths between the remaining
// triangles), quad_cleanup.cpp (quad merges and valence flips), quad_smoothing.cpp;
// quadrangulate.cpp picks the region, runs the steps and writes the output.
//
// The conversion works on its own half-edge arrays rather than OpenMesh (merge.cpp): every step
// is a local rewrite of faces of at most six corners (edge splits, face splits, two-face merges
// and flips), faces briefly become hexagons, and the Dijkstra rounds need per-face scratch that
// is reset only where it was touched. Flat arrays keep each step O(1) without OpenMesh's
// status flags, deletion and garbage collection, and make the order of everything explicit
// (determinism). Open edges have no opposite half-edge (kNone).
//
// Threads: one QuadState per conversion, used by one thread (smoothing and link_opposites run
// their loops in parallel with the same result for any number of threads).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <vector>

#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/merge/crossings.hpp"
#include "ldimesh/core/merge/projection.hpp"
#include "ldimesh/core/merge/quadrangulate.hpp"

namespace ldimesh::quad_detail {

// The faces the conversion rewrites (QuadOptions::region_rings), numbered on their own: region
// vertices in input order. The whole input when `whole` (the same numbers, no copy).
struct QuadRegion {
  const Mesh* input = nullptr;
  bool whole = true;
  Mesh mesh;                          // the region's faces: its quads in input order, then all
                                      // triangles (empty when whole)
  std::vector<std::uint32_t> global;  // region vertex → input vertex
  std::vector<std::uint32_t> local;   // input vertex → region vertex (kNone: outside)
  std::vector<std::uint8_t> inside;   // per input quad: in the region
  std::vector<std::uint8_t> pinned;   // per region vertex: also a corner of a quad outside
  std::vector<std::uint64_t> cut;     // region half-edges (from << 32 | to) whose opposite lies
                                      // in a quad outside, sorted

  const Mesh& faces() const { return whole ? *input : mesh; }
  std::size_t vertices() const { return whole ? input->positions.size() : global.size(); }
  std::uint32_t to_input(std::uint32_t v) const { return whole ? v : global[v]; }
  std::uint32_t from_input(std::uint32_t v) const { return whole ? v : local[v]; }
};

struct QuadState {
  QuadState(const QuadRegion& region, const QuadOptions& options, QuadStats& stats);

  // f(face) for each face of v's fan through out_he_[v] (both ways from it where the fan is
  // open); returns how many.
  template <class F>
  std::size_t for_each_face_around(std::uint32_t v, F&& f) const {
    const std::uint32_t start = out_he_[v];
    std::uint32_t h = start;
    std::size_t count = 0;
    do {
      f(face_[h]), ++count;
      const std::uint32_t p = prev(h);
      if (opp_[p] == kNone) {
        for (h = start; opp_[h] != kNone;) {
          h = next_[opp_[h]];
          f(face_[h]), ++count;
        }
        return count;
      }
      h = opp_[p];
    } while (h != start);
    return count;
  }

  // Keeps where v is before a move (undo_crossing_moves takes a vertex's first entry: a path
  // vertex goes back to its edge's midpoint, not to where the projection put it).
  void remember(std::uint32_t v) { moved_.push_back({v, glm::vec3(pos_[v]), glm::vec3(nrm_[v])}); }

  // The output's moved vertices (projected path vertices, smoothed vertices) with where each was
  // before its first move (for undo_crossing_moves).
  const std::vector<VertexMove>& moved() const { return moved_; }
  double median_edge() const { return median_edge_; }

  // Opposite half-edges through the half-edges leaving each vertex (counting sort by start).
  void link_opposites();
  std::size_t face_size(std::uint32_t f) const;
  std::uint32_t prev(std::uint32_t h) const;
  bool is_cut(std::uint32_t h) const { return h < cut_.size() && cut_[h]; }
  bool is_pinned(std::uint32_t v) const { return v < region_.pinned.size() && region_.pinned[v]; }
  double length(std::uint32_t h) const { return glm::distance(pos_[from_[h]], pos_[to_[h]]); }
  double reach() const { return options_.projection_reach * median_edge_; }
  double quality(const std::array<std::uint32_t, 4>& v) const;
  bool faces_its_normals(const std::array<std::uint32_t, 4>& v) const;
  glm::dvec3 centroid(std::uint32_t f) const;
  glm::dvec3 midpoint(std::uint32_t h) const { return 0.5 * (pos_[from_[h]] + pos_[to_[h]]); }

  // A vertex at the mean of `vs` (normal: the normalised mean normal, scalar: the mean).
  std::uint32_t add_vertex(std::initializer_list<std::uint32_t> vs);
  std::uint32_t add_halfedge(std::uint32_t from, std::uint32_t to, std::uint32_t face);

  // Inserts vertex m into the edge of h (u→v): h becomes u→m, a new half-edge m→v follows it;
  // the opposite side likewise.
  void split_edge(std::uint32_t h, std::uint32_t m);

  // Splits the face of ha and hb by a new edge from to(ha) to to(hb); the part after hb becomes
  // a new face. Returns the new half-edge to(hb)→to(ha) (in the new face).
  std::uint32_t split_face(std::uint32_t ha, std::uint32_t hb);

  // Per vertex: one leaving half-edge, the number of edges, on an open boundary or not.
  void build_vertex_rings();

  // Whether an edge joins a and b: around a's fan, both ways from a leaving half-edge.
  bool adjacent(std::uint32_t a, std::uint32_t b) const;
  int ideal(std::uint32_t v) const { return boundary_[v] ? 3 : 4; }
  int energy(std::uint32_t v, int change) const;

  // The region, the options and the statistics filled in.
  const QuadRegion& region_;
  QuadOptions options_;
  QuadStats& stats_;
  std::vector<glm::dvec3> pos_, nrm_;
  std::vector<float> scalar_;

  // Half-edges: start and end vertex, next in the face, opposite (kNone: open), face (kNone:
  // removed). Faces: one half-edge (kNone: removed), view, made here (smoothing region).
  std::vector<std::uint32_t> from_, to_, next_, opp_, face_;
  std::vector<std::uint32_t> face_he_;
  std::vector<std::uint8_t> face_view_, face_new_;
  std::vector<std::uint8_t> cut_;  // per half-edge made in set-up: on the region's edge
  double median_edge_ = 0.0;

  // Dijkstra: face centroids (kept up to date by the paths), scratch reset where touched.
  std::vector<glm::vec3> centroid_;  // float: the search is bound by memory traffic
  struct Search {
    double dist = std::numeric_limits<double>::infinity();  // from the region's source
    double best = std::numeric_limits<double>::infinity();  // of a source: cheapest candidate
    std::uint32_t source = kNone, parent = kNone;
    std::uint32_t cross = kNone;         // the half-edge of the parent the region came over
    std::uint8_t settled = 0, used = 0;  // used: on a path of this round
  };
  std::vector<Search> search_;  // per face, one cache line for the hot loop
  std::vector<std::uint32_t> touched_;

  // Vertex rings for merges and flips.
  std::vector<std::uint32_t> out_he_, valence_;
  std::vector<std::uint8_t> boundary_;

  // Moved vertices (projection and smoothing) and where each was before.
  std::vector<VertexMove> moved_;  // this conversion's vertex numbers; output's after output()
};

// The steps, in the order quadrangulate runs them.

// Greedy pairing: triangle pairs across an edge, best quad (min/max edge ratio) first. A
// pair's quad does not change when other pairs are taken, so one sort is the priority queue.
void pair_triangles(QuadState& qs);

// Remaining triangles are paired along shortest paths over the faces (multi-source Dijkstra
// from all of them at once, Voronoi-style: a path runs where two regions meet, or to an open
// edge); the edges a path crosses are split, a quad crossed straight becomes two quads, one
// the path turns in three (Fig. 3(d)), the end triangles quads. Paths of one round are
// face-disjoint, shortest first; rounds repeat until no triangle is left.
void connect_triangles(QuadState& qs, const SurfaceProjection& project);

// Two quads around an interior vertex of valence 2 (they share two edges) become one.
void merge_quad_pairs(QuadState& qs);

// Quad edge flips toward valence 4 (3 on open boundaries): the two quads on an edge form a
// hexagon with three diagonals; the edge moves to the one that lowers Σ (valence − ideal)²
// if both new quads are convex and not much worse than the old ones. Only edges of faces
// this conversion made (the input's quads are the views' regular grids). Passes in edge
// order; after the first, an edge is looked at again only if a flip since its last look
// touched one of its faces' corners (what try_flip reads: their valences, the two faces, the
// fans of the new diagonal's ends): the result is the full passes' (on Marschner–Lobb 512²
// they looked at 283 k edges each for 1 217, 56 and 5 flips).
void flip_edges(QuadState& qs);

// Laplacian smoothing of the faces this conversion made (tangential steps toward the mean of
// the edge neighbours), then back onto the surface with `project` in one batch after the last
// step (tangential steps of a fraction of an edge stay well within its reach, and one batch
// of rays costs a quarter of one per step), or, without it, limited to max_unprojected_move
// median edges from where each vertex started. Open-boundary vertices stay.
void smooth(QuadState& qs, const SurfaceProjection& project);

// The whole mesh, written over the input mesh `m` (the one the region was selected from): the
// quads outside the region as they were, then the region's faces. In place, so that the
// output takes no fresh memory (fresh pages are costly to touch on these VMs:
// docs/history/benchmarks-log.md, "Less fresh memory, fewer passes"): every vertex and outside quad
// moves to the same or a lower place, so an entry is read before anything is written over it.
void output(QuadState& qs, Mesh& m);

}  // namespace ldimesh::quad_detail

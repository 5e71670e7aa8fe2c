#include "ldimesh/core/merge/quadrangulate.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <queue>
#include <stdexcept>
#include <string>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "../base/in_place.hpp"
#include "../base/mesh_util.hpp"
#include "face_rings.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/merge/crossings.hpp"

namespace ldimesh {
namespace {

// Shortest over longest edge of the quad p[0..3] if it is convex seen along its (Newell) normal
// and that normal points the way of `normals` (the sum of its vertex normals); 0 otherwise.
double quad_quality(const std::array<glm::dvec3, 4>& p, const glm::dvec3& normals) {
  const glm::dvec3 n = newell_normal(p);
  if (!(glm::dot(n, normals) > 0.0)) return 0.0;
  double shortest = std::numeric_limits<double>::infinity(), longest = 0.0;
  for (int i = 0; i < 4; ++i) {
    const glm::dvec3 in = p[i] - p[(i + 3) % 4], out = p[(i + 1) % 4] - p[i];
    if (!(glm::dot(glm::cross(in, out), n) > 0.0)) return 0.0;
    shortest = std::min(shortest, glm::length(out));
    longest = std::max(longest, glm::length(out));
  }
  return longest > 0.0 ? shortest / longest : 0.0;
}

// The faces the conversion rewrites (QuadOptions::region_rings), numbered on their own: region
// vertices in input order. The whole input when `whole` (the same numbers, no copy).
struct Region {
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

// The triangles and the quads within `rings` rings of them (sharing a vertex); the whole mesh
// for negative `rings` or when that is every quad.
Region select_region(const Mesh& m, int rings) {
  Region r;
  r.input = &m;
  if (rings < 0) return r;
  const std::size_t nv = m.positions.size(), nq = m.quad_count();
  // The triangles' corners seed the rings (the triangles themselves add no vertex).
  std::vector<std::uint8_t> in(nv, 0);
  std::vector<std::uint32_t> seeds;
  for (std::uint32_t v : m.triangles)
    if (!in[v]) in[v] = 1, seeds.push_back(v);
  r.inside.assign(m.face_count(), 0);
  grow_face_rings(m, VertexCorners(m), rings, std::move(seeds), in, r.inside);
  r.inside.resize(nq);  // per quad
  const std::size_t inside = std::size_t(std::count(r.inside.begin(), r.inside.end(), 1));
  if (inside == nq) {
    r.inside.clear();
    return r;
  }
  r.whole = false;
  r.local.assign(nv, kNone);
  for (std::uint32_t v = 0; v < nv; ++v)
    if (in[v]) {
      r.local[v] = std::uint32_t(r.global.size());
      r.global.push_back(v);
    }
  Mesh& sub = r.mesh;
  sub.view_dirs = m.view_dirs;
  sub.positions.reserve(r.global.size());
  sub.normals.reserve(r.global.size());
  for (std::uint32_t v : r.global) {
    sub.positions.push_back(m.positions[v]);
    sub.normals.push_back(m.normals[v]);
    if (!m.scalars.empty()) sub.scalars.push_back(m.scalars[v]);
  }
  sub.quads.reserve(4 * inside);
  if (!m.quad_view.empty()) sub.quad_view.reserve(inside);
  r.pinned.assign(r.global.size(), 0);
  for (std::uint32_t q = 0; q < nq; ++q) {
    const std::uint32_t* c = &m.quads[4 * std::size_t(q)];
    if (r.inside[q]) {
      for (int k = 0; k < 4; ++k)
        sub.quads.push_back(r.local[c[k]]);
      if (!m.quad_view.empty()) sub.quad_view.push_back(m.quad_view[q]);
      continue;
    }
    for (int k = 0; k < 4; ++k) {
      const std::uint32_t a = r.local[c[k]], b = r.local[c[(k + 1) % 4]];
      if (a != kNone) r.pinned[a] = 1;
      if (a != kNone && b != kNone) r.cut.push_back(directed_edge_key(b, a));
    }
  }
  std::sort(r.cut.begin(), r.cut.end());
  sub.triangles.reserve(m.triangles.size());
  for (std::uint32_t v : m.triangles)
    sub.triangles.push_back(r.local[v]);
  sub.triangle_view = m.triangle_view;
  return r;
}

// The conversion works on its own half-edge arrays rather than OpenMesh (merge.cpp): every step
// is a local rewrite of faces of at most six corners (edge splits, face splits, two-face merges
// and flips), faces briefly become hexagons, and the Dijkstra rounds need per-face scratch that
// is reset only where it was touched. Flat arrays keep each step O(1) without OpenMesh's
// status flags, deletion and garbage collection, and make the order of everything explicit
// (determinism). Open edges have no opposite half-edge (kNone).
class Quadrangulator {
 public:
  Quadrangulator(const Region& region, const QuadOptions& options, QuadStats& stats)
      : region_(region), options_(options), stats_(stats) {
    const Mesh& in = region.faces();
    const std::size_t nv = in.positions.size();
    // Room for what the paths add (Marschner–Lobb 512²: a fifth more half-edges, half as many
    // faces and vertices again): growing these arrays copied them over in the middle of the
    // paths. Reserved room costs address space only until it is used.
    const std::size_t faces = in.face_count(), halfedges = in.quads.size() + in.triangles.size();
    for (auto* v : {&pos_, &nrm_})
      v->reserve(nv + nv / 2);
    if (!in.scalars.empty()) scalar_.reserve(nv + nv / 2);
    for (auto* v : {&from_, &to_, &next_, &face_, &opp_})
      v->reserve(halfedges + halfedges / 2);
    face_he_.reserve(faces + faces / 2);
    for (auto* v : {&face_view_, &face_new_})
      v->reserve(faces + faces / 2);
    pos_.resize(nv);
    nrm_.resize(nv);
    for (std::size_t v = 0; v < nv; ++v) {
      pos_[v] = glm::dvec3(in.positions[v]);
      nrm_[v] = glm::dvec3(in.normals[v]);
    }
    scalar_.assign(in.scalars.begin(), in.scalars.end());
    stats_.region_faces = faces;
    auto add_faces = [&](const std::vector<std::uint32_t>& faces,
                         const std::vector<std::uint8_t>& views, std::size_t arity) {
      for (std::size_t f = 0; f * arity < faces.size(); ++f) {
        const std::uint32_t face = std::uint32_t(face_he_.size());
        const std::uint32_t first = std::uint32_t(to_.size());
        for (std::size_t k = 0; k < arity; ++k) {
          const std::uint32_t h = first + std::uint32_t(k);
          from_.push_back(faces[f * arity + k]);
          to_.push_back(faces[f * arity + (k + 1) % arity]);
          next_.push_back(k + 1 < arity ? h + 1 : first);
          face_.push_back(face);
        }
        face_he_.push_back(first);
        face_view_.push_back(views.empty() ? 0 : views[f]);
        face_new_.push_back(0);
      }
    };
    add_faces(in.quads, in.quad_view, 4);
    add_faces(in.triangles, in.triangle_view, 3);
    link_opposites();
    if (!region_.cut.empty()) {  // the region's edge to the quads outside
      cut_.assign(to_.size(), 0);
      for (std::uint32_t h = 0; h < to_.size(); ++h)
        if (opp_[h] == kNone)
          cut_[h] = std::binary_search(region_.cut.begin(), region_.cut.end(),
                                       directed_edge_key(from_[h], to_[h]));
    }
    // The length unit of the limits: the median edge.
    std::vector<double> lengths;
    for (std::uint32_t h = 0; h < to_.size(); ++h)
      if (opp_[h] == kNone || h < opp_[h]) lengths.push_back(length(h));
    median_edge_ = median_of(lengths, median_edge_);
    stats_.median_edge = median_edge_;
  }

  // Greedy pairing: triangle pairs across an edge, best quad (min/max edge ratio) first. A
  // pair's quad does not change when other pairs are taken, so one sort is the priority queue.
  void pair_triangles() {
    struct Pair {
      double quality;
      std::uint32_t h;
    };
    std::vector<Pair> pairs;
    for (std::uint32_t h = 0; h < to_.size(); ++h) {
      const std::uint32_t o = opp_[h];
      if (o == kNone || o < h || face_[h] == face_[o]) continue;
      if (face_size(face_[h]) != 3 || face_size(face_[o]) != 3) continue;
      const std::uint32_t c = to_[next_[h]], d = to_[next_[o]];
      if (c == d) continue;
      const double q = quality({from_[h], d, to_[h], c});
      if (q > 0.0 && q >= options_.min_pair_quality) pairs.push_back({q, h});
    }
    std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) {
      return a.quality != b.quality ? a.quality > b.quality : a.h < b.h;
    });
    std::vector<std::uint8_t> paired(face_he_.size(), 0);
    for (const Pair& p : pairs) {
      const std::uint32_t h = p.h, o = opp_[h];
      const std::uint32_t f = face_[h], g = face_[o];
      if (paired[f] || paired[g]) continue;
      paired[f] = paired[g] = 1;
      // f: h (a→b), h1 (b→c), h2 (c→a); g: o (b→a), o1 (a→d), o2 (d→b) → a→d→b→c.
      const std::uint32_t h1 = next_[h], h2 = next_[h1], o1 = next_[o], o2 = next_[o1];
      next_[h2] = o1;
      next_[o2] = h1;
      face_[o1] = face_[o2] = f;
      face_[h] = face_[o] = kNone;
      face_he_[f] = h1;
      face_he_[g] = kNone;
      face_new_[f] = 1;
      ++stats_.paired;
    }
  }

  // Remaining triangles are paired along shortest paths over the faces (multi-source Dijkstra
  // from all of them at once, Voronoi-style: a path runs where two regions meet, or to an open
  // edge); the edges a path crosses are split, a quad crossed straight becomes two quads, one
  // the path turns in three (Fig. 3(d)), the end triangles quads. Paths of one round are
  // face-disjoint, shortest first; rounds repeat until no triangle is left.
  void connect_triangles(const SurfaceProjection& project) {
    std::vector<std::uint32_t> triangles;
    for (std::uint32_t f = 0; f < face_he_.size(); ++f)
      if (face_he_[f] != kNone && face_size(f) == 3) triangles.push_back(f);
    const std::uint32_t first_new = std::uint32_t(pos_.size());
    centroid_.resize(face_he_.size());
    for (std::uint32_t f = 0; f < face_he_.size(); ++f)
      if (face_he_[f] != kNone) centroid_[f] = centroid(f);
    for (int round = 0; round < options_.max_path_rounds && !triangles.empty(); ++round) {
      ++stats_.path_rounds;
      if (run_paths(triangles) == 0) break;
      std::erase_if(triangles, [&](std::uint32_t f) { return face_size(f) != 3; });
    }
    stats_.leftover_triangles = triangles.size();
    project_new(first_new, project);
  }

  // Two quads around an interior vertex of valence 2 (they share two edges) become one.
  void merge_quad_pairs() {
    build_vertex_rings();
    std::vector<std::uint32_t> work;
    for (std::uint32_t v = 0; v < pos_.size(); ++v)
      if (valence_[v] == 2 && !boundary_[v] && !is_pinned(v)) work.push_back(v);
    std::reverse(work.begin(), work.end());  // a stack, lowest index first
    while (!work.empty()) {
      const std::uint32_t v = work.back();
      work.pop_back();
      if (valence_[v] != 2 || boundary_[v] || out_he_[v] == kNone) continue;
      const std::uint32_t h1 = out_he_[v];
      const std::uint32_t f1 = face_[h1];
      const std::uint32_t p1 = prev(h1);  // b→v
      const std::uint32_t h2 = opp_[p1];  // v→b
      if (h2 == kNone) continue;
      const std::uint32_t f2 = face_[h2];
      const std::uint32_t p2 = prev(h2);  // a→v
      if (f1 == f2 || opp_[p2] != h1 || face_size(f1) != 4 || face_size(f2) != 4) continue;
      // f1: v→a (h1), a→p (x1), p→b (x2), b→v; f2: v→b (h2), b→q (y1), q→a (y2), a→v.
      const std::uint32_t x1 = next_[h1], x2 = next_[x1], y1 = next_[h2], y2 = next_[y1];
      const std::uint32_t a = to_[h1], b = to_[h2];
      if (to_[x1] == to_[y1]) continue;
      // One of the two has a reflex corner at v already (their angles there sum to 360°), so
      // the merged quad need not be convex; it must face the way of its normals.
      if (!faces_its_normals({a, to_[x1], b, to_[y1]})) continue;
      next_[x2] = y1;
      next_[y2] = x1;
      face_[y1] = face_[y2] = f1;
      for (std::uint32_t h : {h1, p1, h2, p2})
        face_[h] = kNone;
      face_he_[f1] = x1;
      face_he_[f2] = kNone;
      face_new_[f1] = 1;
      out_he_[v] = kNone;
      valence_[v] = 0;
      out_he_[a] = x1;
      out_he_[b] = y1;
      for (std::uint32_t u : {a, b})
        if (--valence_[u] == 2 && !boundary_[u] && !is_pinned(u)) work.push_back(u);
      ++stats_.quad_merges;
    }
  }

  // Quad edge flips toward valence 4 (3 on open boundaries): the two quads on an edge form a
  // hexagon with three diagonals; the edge moves to the one that lowers Σ (valence − ideal)²
  // if both new quads are convex and not much worse than the old ones. Only edges of faces
  // this conversion made (the input's quads are the views' regular grids). Passes in edge
  // order; after the first, an edge is looked at again only if a flip since its last look
  // touched one of its faces' corners (what try_flip reads: their valences, the two faces, the
  // fans of the new diagonal's ends): the result is the full passes' (on Marschner–Lobb 512²
  // they looked at 283 k edges each for 1 217, 56 and 5 flips).
  void flip_edges() {
    build_vertex_rings();
    const std::size_t nf = face_he_.size();
    std::vector<std::uint8_t> dirty(nf, 1), dirty_next(nf, 0);  // per face
    for (int pass = 0; pass < options_.flip_passes; ++pass) {
      std::size_t flipped = 0;
      for (std::uint32_t h = 0; h < to_.size(); ++h) {
        const std::uint32_t o = opp_[h];
        if (o == kNone || o < h || face_[h] == kNone || face_[h] == face_[o]) continue;
        if (!dirty[face_[h]] && !dirty[face_[o]]) continue;
        if (!face_new_[face_[h]] && !face_new_[face_[o]]) continue;  // the input's own quads
        if (!try_flip(h)) continue;
        ++flipped;
        // The flipped pair holds the six corners whose valences or fans changed: their faces
        // are looked at again, later in this pass as in the next.
        for (std::uint32_t face : {face_[h], face_[o]}) {
          std::uint32_t c = face_he_[face];
          do {
            const std::uint32_t v = from_[c];
            const std::size_t seen =
                for_each_face_around(v, [&](std::uint32_t g) { dirty[g] = dirty_next[g] = 1; });
            // A vertex with more than one fan (not a manifold there): all faces, to be safe.
            if (seen != valence_[v] - boundary_[v]) {
              std::fill(dirty.begin(), dirty.end(), 1);
              std::fill(dirty_next.begin(), dirty_next.end(), 1);
            }
            c = next_[c];
          } while (c != face_he_[face]);
        }
      }
      stats_.flips += flipped;
      if (flipped == 0) break;
      dirty.swap(dirty_next);
      std::fill(dirty_next.begin(), dirty_next.end(), 0);
    }
  }

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

  // Laplacian smoothing of the faces this conversion made (tangential steps toward the mean of
  // the edge neighbours), then back onto the surface with `project` in one batch after the last
  // step (tangential steps of a fraction of an edge stay well within its reach, and one batch
  // of rays costs a quarter of one per step), or, without it, limited to max_unprojected_move
  // median edges from where each vertex started. Open-boundary vertices stay.
  void smooth(const SurfaceProjection& project) {
    if (options_.smoothing_iterations <= 0) return;
    const std::size_t nv = pos_.size();
    std::vector<std::uint8_t> moves(nv, 0), boundary(nv, 0);
    std::vector<std::uint32_t> count(nv + 1, 0);
    for (std::uint32_t h = 0; h < to_.size(); ++h) {
      if (face_[h] == kNone) continue;
      if (opp_[h] == kNone) boundary[from_[h]] = boundary[to_[h]] = 1;
      if (options_.smooth_all || face_new_[face_[h]]) moves[from_[h]] = 1;
      if (opp_[h] == kNone || h < opp_[h]) ++count[from_[h] + 1], ++count[to_[h] + 1];
    }
    for (std::size_t v = 0; v < nv; ++v)
      count[v + 1] += count[v];
    std::vector<std::uint32_t> neighbours(count[nv]), fill(count.begin(), count.end() - 1);
    for (std::uint32_t h = 0; h < to_.size(); ++h) {
      if (face_[h] == kNone || (opp_[h] != kNone && h > opp_[h])) continue;
      neighbours[fill[from_[h]]++] = to_[h];
      neighbours[fill[to_[h]]++] = from_[h];
    }
    std::vector<std::uint32_t> region;
    for (std::uint32_t v = 0; v < nv; ++v)
      if (moves[v] && !boundary[v] && !is_pinned(v) && count[v + 1] > count[v]) region.push_back(v);
    std::vector<glm::dvec3> start(region.size()), points(region.size()), normals(region.size());
    for (std::size_t i = 0; i < region.size(); ++i) {
      start[i] = pos_[region[i]];
      remember(region[i]);
    }
    const double limit = options_.max_unprojected_move * median_edge_;
    // Each step reads the old positions only (Jacobi), so the vertices go in parallel with the
    // same result for any number of threads.
    for (int it = 0; it < options_.smoothing_iterations; ++it) {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, region.size(), 2048),
                        [&](const auto& r) {
                          for (std::size_t i = r.begin(); i < r.end(); ++i) {
                            const std::uint32_t v = region[i];
                            glm::dvec3 mean(0.0);
                            for (std::uint32_t k = count[v]; k < count[v + 1]; ++k)
                              mean += pos_[neighbours[k]];
                            mean /= double(count[v + 1] - count[v]);
                            glm::dvec3 step = options_.smoothing_step * (mean - pos_[v]);
                            step -= glm::dot(step, nrm_[v]) * nrm_[v];
                            points[i] = pos_[v] + step;
                            if (!project) {
                              const glm::dvec3 moved = points[i] - start[i];
                              const double d = glm::length(moved);
                              if (d > limit) points[i] = start[i] + moved * (limit / d);
                            }
                          }
                        });
      for (std::size_t i = 0; i < region.size(); ++i)
        pos_[region[i]] = points[i];
    }
    if (!project) return;
    for (std::size_t i = 0; i < region.size(); ++i)
      normals[i] = nrm_[region[i]];
    stats_.projected += project(points, normals, reach());
    for (std::size_t i = 0; i < region.size(); ++i) {
      pos_[region[i]] = points[i];
      nrm_[region[i]] = normals[i];
    }
  }

  // Keeps where v is before a move (undo_crossing_moves takes a vertex's first entry: a path
  // vertex goes back to its edge's midpoint, not to where the projection put it).
  void remember(std::uint32_t v) { moved_.push_back({v, glm::vec3(pos_[v]), glm::vec3(nrm_[v])}); }

  // The output's moved vertices (projected path vertices, smoothed vertices) with where each was
  // before its first move (for undo_crossing_moves).
  const std::vector<VertexMove>& moved() const { return moved_; }
  double median_edge() const { return median_edge_; }

  // The whole mesh, written over the input mesh `m` (the one the region was selected from): the
  // quads outside the region as they were, then the region's faces. In place, so that the
  // output takes no fresh memory (on Marschner–Lobb 512² the fresh arrays' first touch was most
  // of the output's time): every vertex and outside quad moves to the same or a lower place, so
  // an entry is read before anything is written over it.
  void output(Mesh& m) {
    const std::size_t n_input = m.positions.size(), n_region = region_.vertices();
    // Output order: input vertices (by input number), then the new ones.
    auto number = [&](std::uint32_t v) {
      return v < n_region ? region_.to_input(v) : std::uint32_t(n_input + (v - n_region));
    };
    std::vector<std::uint32_t> index(n_input + (pos_.size() - n_region), kNone);
    std::size_t outside = 0;  // input quads outside the region
    for (std::uint32_t q = 0; q < region_.inside.size(); ++q)
      if (!region_.inside[q]) {
        ++outside;
        for (int k = 0; k < 4; ++k)
          index[m.quads[4 * std::size_t(q) + k]] = 0;
      }
    for (std::uint32_t h = 0; h < to_.size(); ++h)
      if (face_[h] != kNone) index[number(from_[h])] = 0;
    std::size_t used = 0, faces = outside;
    for (std::uint32_t x : index)
      used += x != kNone;
    for (std::uint32_t f = 0; f < face_he_.size(); ++f)
      if (face_he_[f] != kNone) ++faces;  // triangles left are few: room for all as quads
    const bool scalars = !m.scalars.empty();
    std::size_t w = 0;
    for (std::uint32_t g = 0; g < index.size(); ++g) {
      if (index[g] == kNone) continue;
      index[g] = std::uint32_t(w);
      const std::uint32_t v =
          g < n_input ? region_.from_input(g) : std::uint32_t(n_region + (g - n_input));
      if (v == kNone) {  // outside the region: as it was (w <= g: a move down or none)
        m.positions[w] = m.positions[g];
        m.normals[w] = m.normals[g];
        if (scalars) m.scalars[w] = m.scalars[g];
      } else {
        put_at(m.positions, w, glm::vec3(pos_[v]));
        put_at(m.normals, w, glm::vec3(nrm_[v]));
        if (scalars) put_at(m.scalars, w, scalar_[v]);
      }
      ++w;
    }
    m.positions.resize(used);
    m.normals.resize(used);
    if (scalars) m.scalars.resize(used);
    if (m.quad_view.empty()) m.quad_view.assign(m.quad_count(), 0);
    std::size_t kept = 0;  // outside quads written (kept <= q)
    for (std::uint32_t q = 0; q < region_.inside.size(); ++q) {
      if (region_.inside[q]) continue;
      for (int k = 0; k < 4; ++k)
        m.quads[4 * kept + k] = index[m.quads[4 * std::size_t(q) + k]];
      m.quad_view[kept++] = m.quad_view[q];
    }
    m.quads.resize(4 * kept);
    m.quad_view.resize(kept);
    m.quads.reserve(4 * faces);
    m.quad_view.reserve(faces);
    m.triangles.clear();
    m.triangle_view.clear();
    for (std::uint32_t f = 0; f < face_he_.size(); ++f) {
      if (face_he_[f] == kNone) continue;
      const std::size_t n = face_size(f);
      std::vector<std::uint32_t>& target = n == 4 ? m.quads : m.triangles;
      std::uint32_t h = face_he_[f];
      for (std::size_t k = 0; k < n; ++k, h = next_[h])
        target.push_back(index[number(from_[h])]);
      (n == 4 ? m.quad_view : m.triangle_view).push_back(face_view_[f]);
    }
    stats_.output_quads = m.quad_count();
    std::vector<std::uint32_t> renumber(pos_.size());
    for (std::uint32_t v = 0; v < pos_.size(); ++v)
      renumber[v] = index[number(v)];
    renumber_moves(moved_, renumber);
  }

 private:
  // Opposite half-edges through the half-edges leaving each vertex (counting sort by start).
  void link_opposites() {
    const std::size_t nv = pos_.size();
    std::vector<std::uint32_t> start(nv + 1, 0);
    for (std::uint32_t v : from_)
      ++start[v + 1];
    for (std::size_t v = 0; v < nv; ++v)
      start[v + 1] += start[v];
    std::vector<std::uint32_t> leaving(from_.size()), fill(start.begin(), start.end() - 1);
    for (std::uint32_t h = 0; h < from_.size(); ++h)
      leaving[fill[from_[h]]++] = h;
    opp_.assign(to_.size(), kNone);
    std::atomic<bool> twice{false};
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, std::uint32_t(to_.size()), 8192),
                      [&](const auto& r) {
                        for (std::uint32_t h = r.begin(); h < r.end(); ++h) {
                          const std::uint32_t u = from_[h], v = to_[h];
                          for (std::uint32_t k = start[u]; k < start[u + 1]; ++k)
                            if (leaving[k] != h && to_[leaving[k]] == v) twice = true;
                          for (std::uint32_t k = start[v]; k < start[v + 1]; ++k)
                            if (to_[leaving[k]] == u) opp_[h] = leaving[k];
                        }
                      });
    if (twice)
      throw std::invalid_argument(
          "quadrangulate: an edge is used twice in one direction (not an oriented manifold)");
  }

  std::size_t face_size(std::uint32_t f) const {
    std::size_t n = 0;
    std::uint32_t h = face_he_[f];
    do {
      ++n;
      h = next_[h];
    } while (h != face_he_[f]);
    return n;
  }

  std::uint32_t prev(std::uint32_t h) const {
    std::uint32_t p = h;
    while (next_[p] != h)
      p = next_[p];
    return p;
  }

  bool is_cut(std::uint32_t h) const { return h < cut_.size() && cut_[h]; }
  bool is_pinned(std::uint32_t v) const { return v < region_.pinned.size() && region_.pinned[v]; }

  double length(std::uint32_t h) const { return glm::distance(pos_[from_[h]], pos_[to_[h]]); }
  double reach() const { return options_.projection_reach * median_edge_; }

  double quality(const std::array<std::uint32_t, 4>& v) const {
    return quad_quality({pos_[v[0]], pos_[v[1]], pos_[v[2]], pos_[v[3]]},
                        nrm_[v[0]] + nrm_[v[1]] + nrm_[v[2]] + nrm_[v[3]]);
  }

  bool faces_its_normals(const std::array<std::uint32_t, 4>& v) const {
    const std::array<glm::dvec3, 4> p{pos_[v[0]], pos_[v[1]], pos_[v[2]], pos_[v[3]]};
    return glm::dot(newell_normal(p), nrm_[v[0]] + nrm_[v[1]] + nrm_[v[2]] + nrm_[v[3]]) > 0.0;
  }

  glm::dvec3 centroid(std::uint32_t f) const {
    glm::dvec3 c(0.0);
    double n = 0.0;
    std::uint32_t h = face_he_[f];
    do {
      c += pos_[to_[h]];
      n += 1.0;
      h = next_[h];
    } while (h != face_he_[f]);
    return c / n;
  }

  glm::dvec3 midpoint(std::uint32_t h) const { return 0.5 * (pos_[from_[h]] + pos_[to_[h]]); }

  // A vertex at the mean of `vs` (normal: the normalised mean normal, scalar: the mean).
  std::uint32_t add_vertex(std::initializer_list<std::uint32_t> vs) {
    glm::dvec3 p(0.0), n(0.0);
    double s = 0.0;
    for (std::uint32_t v : vs) {
      p += pos_[v];
      n += nrm_[v];
      if (!scalar_.empty()) s += scalar_[v];
    }
    const double count = double(vs.size());
    const double len = glm::length(n);
    pos_.push_back(p / count);
    nrm_.push_back(len > 0.0 ? n / len : nrm_[*vs.begin()]);
    if (!scalar_.empty()) scalar_.push_back(float(s / count));
    return std::uint32_t(pos_.size() - 1);
  }

  std::uint32_t add_halfedge(std::uint32_t from, std::uint32_t to, std::uint32_t face) {
    from_.push_back(from);
    to_.push_back(to);
    next_.push_back(kNone);
    opp_.push_back(kNone);
    face_.push_back(face);
    return std::uint32_t(to_.size() - 1);
  }

  // Inserts vertex m into the edge of h (u→v): h becomes u→m, a new half-edge m→v follows it;
  // the opposite side likewise.
  void split_edge(std::uint32_t h, std::uint32_t m) {
    const std::uint32_t o = opp_[h];
    const std::uint32_t h2 = add_halfedge(m, to_[h], face_[h]);
    next_[h2] = next_[h];
    next_[h] = h2;
    to_[h] = m;
    if (o == kNone) return;
    const std::uint32_t o2 = add_halfedge(m, to_[o], face_[o]);
    next_[o2] = next_[o];
    next_[o] = o2;
    to_[o] = m;
    opp_[h] = o2, opp_[o2] = h;
    opp_[h2] = o, opp_[o] = h2;
  }

  // Splits the face of ha and hb by a new edge from to(ha) to to(hb); the part after hb becomes
  // a new face. Returns the new half-edge to(hb)→to(ha) (in the new face).
  std::uint32_t split_face(std::uint32_t ha, std::uint32_t hb) {
    const std::uint32_t f = face_[ha];
    const std::uint32_t g = std::uint32_t(face_he_.size());
    face_he_.push_back(hb);
    face_view_.push_back(face_view_[f]);
    face_new_.push_back(1);
    const std::uint32_t an = next_[ha], bn = next_[hb];
    const std::uint32_t n = add_halfedge(to_[ha], to_[hb], f);
    const std::uint32_t n2 = add_halfedge(to_[hb], to_[ha], g);
    opp_[n] = n2, opp_[n2] = n;
    next_[ha] = n, next_[n] = bn;
    next_[hb] = n2, next_[n2] = an;
    for (std::uint32_t h = an; h != n2; h = next_[h])
      face_[h] = g;
    face_he_[f] = ha;
    return n2;
  }

  // One Dijkstra round; returns the number of paths applied.
  std::size_t run_paths(const std::vector<std::uint32_t>& sources) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    const std::size_t nf = face_he_.size();
    search_.resize(nf);
    touched_.clear();
    struct Item {
      double d;
      std::uint32_t f;
      bool operator>(const Item& o) const { return d != o.d ? d > o.d : f > o.f; }
    };
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
    for (std::uint32_t s : sources) {
      search_[s].dist = 0.0;
      search_[s].source = s;
      touched_.push_back(s);
      queue.push({0.0, s});
    }
    // A candidate path: the faces either side of the edge h where two regions meet (g = kNone:
    // h is open, the path ends there).
    struct Candidate {
      double cost;
      std::uint32_t h, f, g;
    };
    std::vector<Candidate> candidates;
    std::size_t without = sources.size();  // sources with no candidate yet
    double stop = kInf;  // once every source has one: the dearest of their cheapest
    auto note = [&](std::uint32_t s, double cost) {
      if (search_[s].best == kInf) --without;
      search_[s].best = std::min(search_[s].best, cost);
    };
    while (!queue.empty()) {
      const Item item = queue.top();
      queue.pop();
      const std::uint32_t x = item.f;
      if (search_[x].settled || item.d > search_[x].dist) continue;
      if (item.d > stop) break;
      search_[x].settled = 1;
      // A region grows no further than its source's cheapest candidate: beyond, it could only
      // find dearer ones for it (its neighbours still meet it here).
      const bool grow = item.d <= search_[search_[x].source].best;
      const glm::vec3 cx = centroid_[x];
      std::uint32_t hx = face_he_[x];
      do {
        const std::uint32_t o = opp_[hx];
        if (o == kNone) {
          if (!is_cut(hx)) {  // an open edge of the mesh, not the region's edge
            const double cost = item.d + glm::distance(glm::dvec3(cx), midpoint(hx));
            candidates.push_back({cost, hx, x, kNone});
            note(search_[x].source, cost);
          }
        } else if (const std::uint32_t y = face_[o]; y != x) {
          const double w = glm::distance(cx, centroid_[y]);
          if (search_[y].settled) {
            if (search_[y].source != search_[x].source) {
              const double cost = item.d + w + search_[y].dist;
              candidates.push_back({cost, hx, x, y});
              note(search_[x].source, cost);
              note(search_[y].source, cost);
            }
          } else if (grow && item.d + w < search_[y].dist) {  // never a triangle: those are sources
            if (search_[y].dist == kInf) touched_.push_back(y);
            search_[y].dist = item.d + w;
            search_[y].source = search_[x].source;
            search_[y].parent = x;
            search_[y].cross = hx;
            queue.push({search_[y].dist, y});
          }
        }
        hx = next_[hx];
      } while (hx != face_he_[x]);
      if (without == 0 && stop == kInf) {
        stop = 0.0;
        for (std::uint32_t s : sources)
          stop = std::max(stop, search_[s].best);
      }
    }
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
      return a.cost != b.cost ? a.cost < b.cost : a.h < b.h;
    });
    std::size_t applied = 0;
    std::vector<std::uint32_t> left, right, faces, crossings;
    // The faces from x back to its source, or false if one is on a path already (faces of an
    // applied path have changed; the walk stops at the first).
    auto chain = [&](std::uint32_t x, std::vector<std::uint32_t>& out) {
      out.clear();
      for (;; x = search_[x].parent) {
        if (search_[x].used) return false;
        out.push_back(x);
        if (x == search_[x].source) return true;
      }
    };
    for (const Candidate& c : candidates) {
      if (search_[search_[c.f].source].used || (c.g != kNone && search_[search_[c.g].source].used))
        continue;
      if (!chain(c.f, left)) continue;
      if (c.g != kNone && !chain(c.g, right)) continue;
      if (c.g == kNone) right.clear();
      // faces from one source to the other; crossings[i] lies in faces[i] with its opposite in
      // faces[i + 1] (the last one open for a path to the boundary).
      faces.assign(left.rbegin(), left.rend());
      crossings.clear();
      for (std::size_t i = 1; i < faces.size(); ++i)
        crossings.push_back(search_[faces[i]].cross);
      crossings.push_back(c.h);
      for (std::uint32_t x : right) {
        faces.push_back(x);
        if (x != search_[x].source) crossings.push_back(opp_[search_[x].cross]);
      }
      for (std::uint32_t x : faces)
        search_[x].used = 1;
      const std::uint32_t first_face = std::uint32_t(face_he_.size());
      apply_path(faces, crossings);
      centroid_.resize(face_he_.size());
      for (std::uint32_t x : faces)
        centroid_[x] = centroid(x);
      for (std::uint32_t x = first_face; x < face_he_.size(); ++x)
        centroid_[x] = centroid(x);
      ++applied;
    }
    for (std::uint32_t x : touched_)
      search_[x] = {};
    return applied;
  }

  void apply_path(const std::vector<std::uint32_t>& faces,
                  const std::vector<std::uint32_t>& crossings) {
    const bool to_boundary = crossings.size() == faces.size();
    ++(to_boundary ? stats_.boundary_splits : stats_.paths);
    // entry[i]/exit[i]: the half-edge of faces[i] that ends at the midpoint of its entry/exit.
    std::vector<std::uint32_t> entry(faces.size(), kNone), exit(faces.size(), kNone);
    for (std::size_t i = 0; i < crossings.size(); ++i) {
      const std::uint32_t h = crossings[i], o = opp_[h];
      split_edge(h, add_vertex({from_[h], to_[h]}));
      exit[i] = h;
      if (o != kNone) entry[i + 1] = o;
      ++stats_.path_splits;
    }
    for (std::size_t i = 0; i < faces.size(); ++i) {
      const std::uint32_t f = faces[i];
      face_new_[f] = 1;
      if (face_size(f) != 6) continue;  // an end triangle, now a quad
      std::array<std::uint32_t, 6> hs;
      std::uint32_t h = face_he_[f];
      int first = -1, second = -1;
      for (int k = 0; k < 6; ++k, h = next_[h]) {
        hs[k] = h;
        if (h == entry[i] || h == exit[i]) (first < 0 ? first : second) = k;
      }
      const int d = (second - first + 6) % 6;
      if (d == 3) {  // straight: two quads
        split_face(hs[first], hs[second]);
        continue;
      }
      // A turn (Fig. 3(d)): loop a, m1, b, m2, c, d with the midpoints m1, m2 either side of
      // corner b; edge m1–d with a centre vertex x on it, then x–m2: quads (a, m1, x, d),
      // (m1, b, m2, x), (x, m2, c, d).
      if (d == 4) std::swap(first, second);
      auto at = [&](int k) { return hs[(first + k) % 6]; };
      const std::uint32_t x =
          add_vertex({to_[at(5)], to_[at(1)], to_[at(3)], to_[at(4)]});  // a, b, c, d
      const std::uint32_t to_m2 = at(2);
      const std::uint32_t back = split_face(at(0), at(4));  // d→m1
      split_edge(opp_[back], x);                            // m1→x→d and d→x→m1
      split_face(back, to_m2);
      ++stats_.turns;
    }
  }

  void project_new(std::uint32_t first, const SurfaceProjection& project) {
    if (!project || first == pos_.size()) return;
    for (std::uint32_t v = first; v < pos_.size(); ++v)
      remember(v);
    std::vector<glm::dvec3> points(pos_.begin() + first, pos_.end());
    std::vector<glm::dvec3> normals(nrm_.begin() + first, nrm_.end());
    stats_.projected += project(points, normals, reach());
    std::copy(points.begin(), points.end(), pos_.begin() + first);
    std::copy(normals.begin(), normals.end(), nrm_.begin() + first);
  }

  // Per vertex: one leaving half-edge, the number of edges, on an open boundary or not.
  void build_vertex_rings() {
    const std::size_t nv = pos_.size();
    out_he_.assign(nv, kNone);
    valence_.assign(nv, 0);
    boundary_.assign(nv, 0);
    for (std::uint32_t h = 0; h < to_.size(); ++h) {
      if (face_[h] == kNone) continue;
      if (out_he_[from_[h]] == kNone) out_he_[from_[h]] = h;
      ++valence_[from_[h]];
      if (opp_[h] == kNone) {
        ++valence_[to_[h]];
        boundary_[from_[h]] = boundary_[to_[h]] = 1;
      }
    }
  }

  // Whether an edge joins a and b: around a's fan, both ways from a leaving half-edge.
  bool adjacent(std::uint32_t a, std::uint32_t b) const {
    const std::uint32_t start = out_he_[a];
    std::uint32_t h = start;
    do {
      if (to_[h] == b) return true;
      const std::uint32_t p = prev(h);
      if (opp_[p] == kNone) {
        if (from_[p] == b) return true;
        for (h = start; opp_[h] != kNone;) {
          h = next_[opp_[h]];
          if (to_[h] == b) return true;
        }
        return false;
      }
      h = opp_[p];
    } while (h != start);
    return false;
  }

  int ideal(std::uint32_t v) const { return boundary_[v] ? 3 : 4; }
  int energy(std::uint32_t v, int change) const {
    const int d = int(valence_[v]) + change - ideal(v);
    return d * d;
  }

  bool try_flip(std::uint32_t h) {
    const std::uint32_t o = opp_[h];
    const std::uint32_t f = face_[h], g = face_[o];
    // Removing the edge must help u or v, and leave both with three edges at least.
    const std::uint32_t u = from_[h], v = to_[h];
    if (valence_[u] <= 3 || valence_[v] <= 3) return false;
    if (int(valence_[u]) <= ideal(u) && int(valence_[v]) <= ideal(v)) return false;
    if (face_size(f) != 4 || face_size(g) != 4) return false;
    // f: h (u→v), fa1 (v→a1), fa2 (a1→a2), fa3 (a2→u); g: o (v→u), gb1 (u→b1), gb2, gb3 (b2→v).
    const std::uint32_t fa1 = next_[h], fa2 = next_[fa1], fa3 = next_[fa2];
    const std::uint32_t gb1 = next_[o], gb2 = next_[gb1], gb3 = next_[gb2];
    const std::uint32_t a1 = to_[fa1], a2 = to_[fa2], b1 = to_[gb1], b2 = to_[gb2];
    // Valences at the region's edge count only its own faces.
    for (std::uint32_t x : {u, v, a1, a2, b1, b2})
      if (is_pinned(x)) return false;
    const int before = energy(u, 0) + energy(v, 0);
    const int gain_a = before - energy(u, -1) - energy(v, -1) + energy(a1, 0) + energy(b1, 0) -
                       energy(a1, 1) - energy(b1, 1);
    const int gain_b = before - energy(u, -1) - energy(v, -1) + energy(a2, 0) + energy(b2, 0) -
                       energy(a2, 1) - energy(b2, 1);
    if (gain_a <= 0 && gain_b <= 0) return false;
    const double old_quality = std::min(quality({u, v, a1, a2}), quality({v, u, b1, b2}));
    auto acceptable = [&](std::uint32_t p, std::uint32_t q, const std::array<std::uint32_t, 4>& x,
                          const std::array<std::uint32_t, 4>& y) {
      if (p == q || adjacent(p, q)) return false;
      const double qx = quality(x), qy = quality(y);
      return qx > 0.0 && qy > 0.0 && std::min(qx, qy) >= 0.5 * old_quality;
    };
    const bool try_a_first = gain_a >= gain_b;
    for (int k = 0; k < 2; ++k) {
      const bool a_side = (k == 0) == try_a_first;
      if ((a_side ? gain_a : gain_b) <= 0) continue;
      if (a_side && acceptable(a1, b1, {a1, a2, u, b1}, {b1, b2, v, a1})) {
        // (a1, a2, u, b1): fa2, fa3, gb1, h (b1→a1); (b1, b2, v, a1): gb2, gb3, fa1, o (a1→b1).
        from_[h] = b1, to_[h] = a1, from_[o] = a1, to_[o] = b1;
        next_[fa2] = fa3, next_[fa3] = gb1, next_[gb1] = h, next_[h] = fa2;
        next_[gb2] = gb3, next_[gb3] = fa1, next_[fa1] = o, next_[o] = gb2;
        face_[gb1] = f, face_[fa1] = g;
        face_he_[f] = fa2, face_he_[g] = gb2;
        ++valence_[a1], ++valence_[b1];
      } else if (!a_side && acceptable(a2, b2, {a2, u, b1, b2}, {b2, v, a1, a2})) {
        // (a2, u, b1, b2): fa3, gb1, gb2, h (b2→a2); (b2, v, a1, a2): gb3, fa1, fa2, o (a2→b2).
        from_[h] = b2, to_[h] = a2, from_[o] = a2, to_[o] = b2;
        next_[fa3] = gb1, next_[gb1] = gb2, next_[gb2] = h, next_[h] = fa3;
        next_[gb3] = fa1, next_[fa1] = fa2, next_[fa2] = o, next_[o] = gb3;
        face_[gb1] = face_[gb2] = f, face_[fa1] = face_[fa2] = g;
        face_he_[f] = fa3, face_he_[g] = gb3;
        ++valence_[a2], ++valence_[b2];
      } else {
        continue;
      }
      --valence_[u], --valence_[v];
      out_he_[u] = gb1, out_he_[v] = fa1;
      face_new_[f] = face_new_[g] = 1;
      return true;
    }
    return false;
  }

  const Region& region_;
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

}  // namespace

Mesh quadrangulate(Mesh&& mesh, const QuadOptions& options, QuadStats& stats,
                   const SurfaceProjection& project) {
  stats = {};
  const auto start = std::chrono::steady_clock::now();
  if (const Status s = check_mesh(mesh, {.distinct_corners = true}); !s)
    throw std::invalid_argument("quadrangulate: " + s.message());
  const std::size_t input_quads = mesh.quad_count(), input_triangles = mesh.triangle_count();
  // Converts the region; false (nothing written) when a part of a region that is not the whole
  // mesh keeps an odd number of triangles with no open edge to take the last one.
  auto convert = [&](const Region& region) {
    auto stage = std::chrono::steady_clock::now();
    auto lap = [&stage](double& seconds) {
      seconds += seconds_since(stage);
      stage = std::chrono::steady_clock::now();
    };
    Quadrangulator q(region, options, stats);
    lap(stats.setup_seconds);
    q.pair_triangles();
    lap(stats.pair_seconds);
    q.connect_triangles(project);
    lap(stats.path_seconds);
    if (!region.whole && stats.leftover_triangles > 0) return false;
    q.merge_quad_pairs();
    q.flip_edges();
    lap(stats.cleanup_seconds);
    q.smooth(project);
    q.output(mesh);
    // Moved vertices whose faces pass through other faces go back (crossings.hpp): near Barth's
    // double points a path vertex projected onto the surface can land on the other sheet.
    if (!q.moved().empty() && q.median_edge() > 0.0)
      stats.crossings_undone = undo_crossing_moves(mesh, q.moved(), 2.0 * q.median_edge(),
                                                   options.crossing_min_move * q.median_edge());
    lap(stats.smooth_seconds);
    return true;
  };
  auto region_start = std::chrono::steady_clock::now();
  const Region region = select_region(mesh, options.region_rings);
  stats.setup_seconds = seconds_since(region_start);
  if (!convert(region)) {
    // Pair the triangles over the whole mesh instead (the times add up).
    stats = {};
    stats.setup_seconds = seconds_since(region_start);
    convert(select_region(mesh, -1));
  }
  stats.input_quads = input_quads;
  stats.input_triangles = input_triangles;
  stats.seconds = seconds_since(start);
  return std::move(mesh);
}

Mesh quadrangulate(const Mesh& mesh, const QuadOptions& options, QuadStats& stats,
                   const SurfaceProjection& project) {
  return quadrangulate(Mesh(mesh), options, stats, project);
}

}  // namespace ldimesh

#include "ldimesh/core/merge/merge.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <queue>
#include <span>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include "../base/in_place.hpp"
#include "../base/mesh_util.hpp"
#include "face_rings.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/base/timing.hpp"
#include "ldimesh/core/merge/crossings.hpp"

namespace ldimesh {
namespace {

// OpenMesh's half-edge mesh in double precision, with deletion (status) and per-vertex normals.
struct Traits : OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
  VertexAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  FaceAttributes(OpenMesh::Attributes::Status);
  EdgeAttributes(OpenMesh::Attributes::Status);
  HalfedgeAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::PrevHalfedge);
};
using HalfEdgeMesh = OpenMesh::PolyMesh_ArrayKernelT<Traits>;
using VH = OpenMesh::VertexHandle;
using HH = OpenMesh::HalfedgeHandle;
using FH = OpenMesh::FaceHandle;

// Where a face came from; the sewing region is everything but kInput.
enum class Kind : std::uint8_t { kInput, kBridge, kFill, kSplit };

glm::dvec3 to_glm(const OpenMesh::Vec3d& p) {
  return {p[0], p[1], p[2]};
}
OpenMesh::Vec3d to_om(glm::dvec3 p) {
  return {p.x, p.y, p.z};
}

struct UnionFind {
  std::vector<std::uint32_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t find(std::uint32_t a) {
    while (parent[a] != a)
      a = parent[a] = parent[parent[a]];
    return a;
  }
  void join(std::uint32_t a, std::uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

// The boundary layer's faces touch the region's seeds, their neighbours one ring further out:
// with fewer rings, removing the layer would open edges the region's mesh does not have.
constexpr int kMinRegionRings = 2;

// The part of the input that merging builds as a half-edge mesh (MergeOptions::region_rings):
// the faces within `rings` rings (faces sharing a vertex) of the vertices that are not inside a
// closed disk of faces: open-boundary vertices and any vertex where OpenMesh could refuse a face.
// Every step of merging happens within a ring or two of the open boundaries, so the other faces
// (most of a merged mesh: the views' regular grids) pass through as they are, and the mesh is the
// same as when all of it is built. Faces are numbered quads first, then triangles, as in the input.
struct InputRegion {
  bool whole = true;                      // every face is in the region, numbered as in the input
  std::vector<std::uint8_t> inside;       // per input face
  std::vector<std::uint32_t> local;       // input vertex → region vertex (kNone: outside)
  std::vector<std::uint32_t> global;      // region vertex → input vertex
  std::vector<std::uint8_t> pinned;       // per region vertex: also a corner of a face outside
  std::vector<std::uint8_t> used;         // per input vertex: a corner of some face
  std::vector<std::uint8_t> vertex_view;  // per input vertex: the view of the last face using it
  std::size_t faces = 0;                  // in the region
};

// Every face and vertex, numbered as in the input (no vertex pinned).
void make_whole(InputRegion& r, std::size_t faces) {
  r.whole = true;
  r.faces = faces;
  r.inside.assign(faces, 1);
  r.global.resize(r.used.size());
  std::iota(r.global.begin(), r.global.end(), 0u);
  r.local = r.global;
  r.pinned.clear();
}

InputRegion select_input_region(const Mesh& m, int rings) {
  InputRegion r;
  const std::size_t nv = m.positions.size(), nq = m.quad_count(), nf = nq + m.triangle_count();
  // The view each vertex gets: that of the last face using it (as building the mesh sets it).
  r.vertex_view.assign(nv, 0);
  r.used.assign(nv, 0);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto views = f < nq ? std::span(m.quad_view) : std::span(m.triangle_view);
    const std::size_t i = f < nq ? f : f - nq;
    for (std::uint32_t v : face_corners(m, f)) {
      r.used[v] = 1;
      if (i < views.size()) r.vertex_view[v] = views[i];
    }
  }
  if (rings < 0) {
    make_whole(r, nf);
    return r;
  }
  const VertexCorners at(m);
  const std::uint32_t quad_corners = at.quad_corners;
  // The corners after and before corner c in its face.
  auto around = [&](std::uint32_t c) {
    if (c < quad_corners) {
      const std::uint32_t base = c - c % 4;
      return std::pair(m.quads[base + (c + 1) % 4], m.quads[base + (c + 3) % 4]);
    }
    const std::uint32_t t = c - quad_corners, base = t - t % 3;
    return std::pair(m.triangles[base + (t % 3 + 1) % 3], m.triangles[base + (t % 3 + 2) % 3]);
  };
  // A vertex is inside a closed disk when the faces around it form one cycle in which each face's
  // incoming edge is the next face's outgoing edge, every edge used once each way: OpenMesh
  // accepts all those faces in any order. Anything else (an open boundary, a repeated or
  // one-way edge, two fans meeting at the vertex, a face with a repeated vertex) seeds the region.
  std::vector<std::uint8_t> in_vertex(nv, 0);
  std::vector<std::uint32_t> frontier;
  for (std::uint32_t v = 0; v < nv; ++v) {
    const std::span<const std::uint32_t> corners = at.at(v);
    const std::uint32_t n = std::uint32_t(corners.size());
    if (n == 0) continue;
    bool disk = n >= 3 && n <= 32;
    for (std::uint32_t i = 0; disk && i < n; ++i) {
      const auto [out, in] = around(corners[i]);
      if (out == v || in == v || out == in) disk = false;
    }
    if (disk) {
      // Walk: from a face, the next is the one whose outgoing edge runs back along this face's
      // incoming edge; exactly one must, and the walk must visit all n faces.
      std::uint32_t i = 0, visited = 0, seen = 0;
      do {
        const std::uint32_t in = around(corners[i]).second;
        std::uint32_t next = kNone, matches = 0;
        for (std::uint32_t j = 0; j < n; ++j)
          if (around(corners[j]).first == in) next = j, ++matches;
        if (matches != 1 || (seen >> next & 1u)) break;
        seen |= 1u << next;
        ++visited;
        i = next;
      } while (i != 0);
      disk = visited == n && seen == (n == 32 ? ~0u : (1u << n) - 1u);
    }
    if (!disk) {
      in_vertex[v] = 1;
      frontier.push_back(v);
    }
  }
  r.inside.assign(nf, 0);
  r.faces = grow_face_rings(m, at, rings + 1, std::move(frontier), in_vertex, r.inside);
  if (r.faces == nf) {
    make_whole(r, nf);
    return r;
  }
  r.whole = false;
  r.local.assign(nv, kNone);
  for (std::uint32_t v = 0; v < nv; ++v)
    if (in_vertex[v]) {
      r.local[v] = std::uint32_t(r.global.size());
      r.global.push_back(v);
    }
  r.pinned.assign(r.global.size(), 0);
  for (std::size_t f = 0; f < nf; ++f)
    if (!r.inside[f])
      for (std::uint32_t v : face_corners(m, f))
        if (r.local[v] != kNone) r.pinned[r.local[v]] = 1;
  return r;
}

// OpenMesh reports refused faces on its error stream; merging tests before adding and treats a
// refusal as "not added", so the stream is quiet while a Merger lives.
class QuietOpenMesh {
 public:
  QuietOpenMesh() : was_enabled_(omerr().is_enabled()) { omerr().disable(); }
  ~QuietOpenMesh() {
    if (was_enabled_) omerr().enable();
  }

 private:
  bool was_enabled_;
};

class Merger {
 public:
  Merger(const Mesh& in, const InputRegion& region, const MergeOptions& options, MergeStats& stats)
      : in_(in), region_(region), options_(options), stats_(stats) {
    mesh_.add_property(kind_);
    mesh_.add_property(view_);
    mesh_.add_property(scalar_);
    // Room for the region and the faces merging adds: growing OpenMesh's arrays one face at a
    // time copied them over and over. Deleted faces keep their slots (no garbage collection):
    // what merging adds is proportional to the open boundaries, which a region is built around,
    // so it takes three to six times the region's faces in all (Marschner–Lobb 512² 3.0, Barth
    // 128² 5.6), twice its edges and a third more vertices; the whole mesh, half as many faces
    // again. Reserved room costs address space only until it is used.
    const std::size_t nq = in.quad_count(), nf = nq + in.triangle_count();
    const std::size_t faces = region.faces, vertices = region.global.size();
    const std::size_t edges = 2 * faces + faces / 8;
    if (region.whole)
      mesh_.reserve(vertices + faces / 8, edges + edges / 2, faces + faces / 2);
    else
      mesh_.reserve(vertices + vertices / 2, 5 * edges / 2, 6 * faces);
    for (std::size_t i = 0; i < vertices; ++i) {
      const std::uint32_t v = region.global[i];
      const VH vh = mesh_.add_vertex({in.positions[v].x, in.positions[v].y, in.positions[v].z});
      mesh_.set_normal(vh, {in.normals[v].x, in.normals[v].y, in.normals[v].z});
      mesh_.property(scalar_, vh) = in.scalars.empty() ? 0.0f : in.scalars[v];
      mesh_.property(view_, vh) = region.vertex_view[v];
    }
    // The region's faces in input order.
    input_face_.assign(nf, FH());
    std::vector<VH> vs;
    for (std::size_t f = 0; f < nf; ++f) {
      if (!region.inside[f]) continue;
      vs.clear();
      for (std::uint32_t v : face_corners(in, f))
        vs.emplace_back(int(region.local[v]));
      input_face_[f] = insert(vs, Kind::kInput);
      if (!input_face_[f].is_valid()) ++stats_.dropped_faces;
    }
    built_faces_ = mesh_.n_faces();
    built_ = true;
    // The length scale for the limits: the LDI cell size when the caller knows it (refined
    // meshes have many short edges, their median would make every limit too tight), else the
    // median edge of the input.
    scale_ = options.cell_size;
    std::vector<double> lengths;
    if (!(scale_ > 0.0))
      for (const auto& e : mesh_.edges())
        lengths.push_back(length(e.halfedge(0)));
    scale_ = median_of(lengths, scale_);
  }

  void remove_boundary_layer() {
    std::vector<FH> layer;
    for (const auto& f : mesh_.faces())
      for (const auto& h : f.halfedges())
        if (is_open(h.opp())) {
          layer.push_back(f);
          break;
        }
    for (FH f : layer)
      erase(f, true);
    stats_.boundary_faces = layer.size();
  }

  // (i) One bridge per pair of patches that are close: the quad p→q→s→t on the open half-edges
  // p→q of patch a and s→t of patch b with the shortest connecting edges q–s and t–p, kept if
  // neither exceeds l = |e_a| + |e_b| (times options.bridge_limit).
  void bridge() {
    // Patches: connected pieces of the whole mesh, through shared vertices (input numbers: a
    // piece is named by its smallest vertex, as when the whole mesh is built).
    UnionFind pieces(in_.positions.size());
    for (const auto& f : mesh_.faces()) {
      const std::uint32_t first = global(f.halfedge().from());
      for (const auto& v : f.vertices())
        pieces.join(first, global(v));
    }
    for (std::size_t f = 0; f < region_.inside.size(); ++f)
      if (!region_.inside[f]) {
        const auto c = face_corners(in_, f);
        for (std::uint32_t v : c)
          pieces.join(c[0], v);
      }
    std::vector<HH> open;
    double longest = 0.0;
    for (const auto& h : mesh_.halfedges())
      if (is_open(h)) {
        open.push_back(h);
        longest = std::max(longest, length(h));
      }
    for (std::uint32_t g = 0; g < in_.positions.size(); ++g) {
      const std::uint32_t l = region_.local[g];
      const bool used = l == kNone ? bool(region_.used[g]) : alive(VH(int(l)));
      if (used && pieces.find(g) == g) ++stats_.patches;
    }
    if (open.empty() || scale_ <= 0.0) return;
    // Open half-edges by their start vertex in a uniform grid whose cells are as wide as the
    // longest connecting edge a bridge may have, so each half-edge looks at 27 cells.
    const double reach = options_.bridge_limit * std::min(2.0 * longest, 8.0 * scale_);
    const double cell = std::max(2.0 * scale_, reach);
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> grid;
    for (std::uint32_t k = 0; k < open.size(); ++k)
      grid[grid_cell_key(grid_cell(point(mesh_.from_vertex_handle(open[k])), cell))].push_back(k);

    struct Candidate {
      double cost;
      HH a, b;
    };
    struct PairBest {
      std::vector<Candidate> best;  // up to kKeep, cheapest first
      bool done = false;            // the paper's early stop: cost < l / 2 found
    };
    constexpr std::size_t kKeep = 4;
    std::unordered_map<std::uint64_t, PairBest> pairs;
    const int span = int(std::ceil(reach / cell));
    for (const HH ha : open) {
      const VH p = mesh_.from_vertex_handle(ha), q = mesh_.to_vertex_handle(ha);
      const std::uint32_t pa = pieces.find(global(p));
      const glm::dvec3 P = point(p), Q = point(q);
      const double la = glm::distance(P, Q);
      const glm::ivec3 c0 = grid_cell(Q, cell);
      for (int dz = -span; dz <= span; ++dz)
        for (int dy = -span; dy <= span; ++dy)
          for (int dx = -span; dx <= span; ++dx) {
            const auto it = grid.find(grid_cell_key(c0 + glm::ivec3(dx, dy, dz)));
            if (it == grid.end()) continue;
            for (std::uint32_t k : it->second) {
              const HH hb = open[k];
              const VH s = mesh_.from_vertex_handle(hb), t = mesh_.to_vertex_handle(hb);
              const std::uint32_t pb = pieces.find(global(s));
              if (pb == pa) continue;
              const std::uint64_t pair = std::uint64_t(std::min(pa, pb)) << 32 | std::max(pa, pb);
              const glm::dvec3 S = point(s), T = point(t);
              const double lb = glm::distance(S, T);
              const double l = options_.bridge_limit * (la + lb);
              const double qs = glm::distance(Q, S), tp = glm::distance(T, P);
              if (qs > l || tp > l) continue;
              if (glm::dot(Q - P, T - S) >= 0.0) continue;  // the open edges must run opposite
              PairBest& best = pairs[pair];
              if (best.done || !faces_its_normals({p, q, s, t})) continue;
              if (!spans_surface(q, s) || !spans_surface(t, p)) continue;
              const Candidate c{qs + tp, ha, hb};
              auto at = std::find_if(best.best.begin(), best.best.end(), [&](const Candidate& o) {
                return std::tie(c.cost, c.a, c.b) < std::tie(o.cost, o.a, o.b);
              });
              best.best.insert(at, c);
              if (best.best.size() > kKeep) best.best.pop_back();
              if (qs + tp < 0.5 * (la + lb)) best.done = true;
            }
          }
    }
    // Cheapest pairs first, so that where two pairs want the same open edge the better wins.
    std::vector<std::pair<double, std::uint64_t>> order;
    for (const auto& [pair, best] : pairs)
      if (!best.best.empty()) order.emplace_back(best.best.front().cost, pair);
    std::sort(order.begin(), order.end());
    stats_.bridge_pairs = order.size();
    for (const auto& [cost, pair] : order)
      for (const Candidate& c : pairs[pair].best) {
        if (!mesh_.is_boundary(c.a) || !mesh_.is_boundary(c.b)) continue;
        const VH p = mesh_.from_vertex_handle(c.a), q = mesh_.to_vertex_handle(c.a);
        const VH s = mesh_.from_vertex_handle(c.b), t = mesh_.to_vertex_handle(c.b);
        if (add({p, q, s, t}, Kind::kBridge)) {
          ++stats_.bridges;
          break;
        }
      }
  }

  // (ii) Ear cutting: repeatedly the shortest new edge u–w that closes a triangle u→v→w with two
  // consecutive open half-edges u→v, v→w, over all holes at once. Ears must turn the way the
  // surface does (convex) and face like their vertices' normals; a second round accepts any
  // convex ear. Holes left are counted.
  void fill_holes() {
    stats_.holes = count_loops();
    struct Ear {
      double length;
      int u, v, w;
      bool operator>(const Ear& o) const {
        return std::tie(length, u, v, w) > std::tie(o.length, o.u, o.v, o.w);
      }
    };
    for (int round = 0; round < 2; ++round) {
      const bool strict = round == 0;
      std::priority_queue<Ear, std::vector<Ear>, std::greater<Ear>> ears;
      auto consider = [&](HH in) {
        if (!in.is_valid() || !is_open(in)) return;
        const HH out = mesh_.next_halfedge_handle(in);
        const VH u = mesh_.from_vertex_handle(in), v = mesh_.to_vertex_handle(in);
        const VH w = mesh_.to_vertex_handle(out);
        if (u == w) return;
        ears.push({glm::distance(point(u), point(w)), u.idx(), v.idx(), w.idx()});
      };
      for (const auto& h : mesh_.halfedges())
        if (is_open(h)) consider(h);
      while (!ears.empty()) {
        const Ear e = ears.top();
        ears.pop();
        const VH u(e.u), v(e.v), w(e.w);
        const HH in = mesh_.find_halfedge(u, v);
        if (!in.is_valid() || !mesh_.is_boundary(in)) continue;
        const HH out = mesh_.next_halfedge_handle(in);
        if (mesh_.to_vertex_handle(out) != w) continue;
        const bool closes = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(out)) == u;
        if (!closes) {
          if (mesh_.find_halfedge(u, w).is_valid()) continue;  // u–w exists elsewhere
          if (e.length > options_.max_fill_edge * scale_) continue;
          if (!ear_is_convex(u, v, w, strict) || !spans_surface(u, w)) continue;
        }
        if (!add({u, v, w}, Kind::kFill)) continue;
        ++stats_.fill_triangles;
        if (closes) continue;
        const HH uw = mesh_.find_halfedge(u, w);
        consider(mesh_.prev_halfedge_handle(uw));
        consider(uw);
      }
    }
    stats_.unfilled_holes = count_loops();
  }

  // (iii) Quads next to fill triangles (and, when the sewing region is refined, bridges) split
  // into triangles; edge flips toward shorter edges; the sewing region's long edges split with
  // their new vertices moved onto the surface; flips again; 3-to-1 merges.
  void enhance(const SurfaceProjection& project) {
    const bool refine = bool(project);
    std::vector<FH> quads;
    for (const auto& f : mesh_.faces()) {
      if (refine && mesh_.property(kind_, f) == Kind::kBridge) quads.push_back(f);
      if (mesh_.property(kind_, f) != Kind::kFill) continue;
      for (const auto& g : f.faces())
        if (g.valence() == 4) quads.push_back(g);
    }
    std::sort(quads.begin(), quads.end());
    quads.erase(std::unique(quads.begin(), quads.end()), quads.end());
    for (FH f : quads) {
      std::vector<VH> c;
      for (const auto& v : mesh_.fv_range(f))
        c.push_back(v);
      // Bridges stay bridges (they are the sewing region already); input quads become kSplit.
      const Kind kind = mesh_.property(kind_, f) == Kind::kBridge ? Kind::kBridge : Kind::kSplit;
      erase(f, false);
      const bool along_02 =
          glm::distance(point(c[0]), point(c[2])) <= glm::distance(point(c[1]), point(c[3]));
      const bool ok = along_02 ? add({c[0], c[1], c[2]}, kind) && add({c[0], c[2], c[3]}, kind)
                               : add({c[0], c[1], c[3]}, kind) && add({c[1], c[2], c[3]}, kind);
      if (ok) {
        ++stats_.split_quads;
      } else {
        ++stats_.lost_faces;
      }
    }
    flip_all();
    if (refine) {
      refine_region(project);
      flip_all();
    }
    // Each corner of the region's faces once (its valence walks its fan), in index order.
    std::vector<std::uint8_t> seen(mesh_.n_vertices(), 0);
    for (FH f : region_faces_)
      if (!mesh_.status(f).deleted())
        for (const auto& v : mesh_.fv_range(f))
          seen[v.idx()] = 1;
    std::vector<VH> centres;
    for (std::size_t i = 0; i < seen.size(); ++i) {
      const VH v{int(i)};
      if (seen[i] && !mesh_.is_boundary(v) && mesh_.valence(v) == 3) centres.push_back(v);
    }
    for (VH v : centres)
      if (!mesh_.status(v).deleted() && try_merge(v)) ++stats_.merges;
  }

  // The whole mesh: vertices in input order (those some face uses), then the new ones; faces
  // in input order (outside the region as they were), then the new ones. With `in_place` (the
  // input mesh itself, quad output only) written over the input's arrays: a vertex or a quad
  // moves to the same or a lower place, so an entry is read before anything is written over it
  // (the input's triangles are read until the end, so the output's go to new arrays); this
  // spares the fresh arrays, whose first touch was most of the output's time on Marschner–Lobb
  // 512².
  Mesh output(FaceType faces, Mesh* in_place = nullptr) {
    Mesh fresh;
    Mesh& out = in_place ? *in_place : fresh;
    const std::size_t n_input = in_.positions.size();
    const std::size_t outside_faces = region_.inside.size() - region_.faces;
    const std::size_t most_vertices = mesh_.n_vertices() + (n_input - region_.global.size());
    std::vector<std::uint32_t> index(mesh_.n_vertices(), kNone);  // OpenMesh → output
    std::vector<std::uint32_t> outside(n_input, kNone);           // input → output
    const bool scalars = !in_.scalars.empty();
    // Room for every face (deleted slots included: an upper bound that costs address space
    // only), so the arrays are not copied over while they grow.
    const std::size_t most = mesh_.n_faces() + outside_faces;
    std::vector<std::uint32_t> triangles;
    std::vector<std::uint8_t> triangle_view;
    if (!in_place) {
      out.view_dirs = in_.view_dirs;
      out.positions.reserve(most_vertices);
      out.normals.reserve(most_vertices);
      if (scalars) out.scalars.reserve(most_vertices);
      if (faces == FaceType::quads) {
        out.quads.reserve(4 * most);
        out.quad_view.reserve(most);
      } else {
        triangles.reserve(6 * most);
        triangle_view.reserve(2 * most);
      }
    }
    std::size_t vertices = 0;
    auto emit = [&](const glm::vec3& p, const glm::vec3& n, float scalar) {
      put_at(out.positions, vertices, p);
      put_at(out.normals, vertices, n);
      if (scalars) put_at(out.scalars, vertices, scalar);
      return std::uint32_t(vertices++);
    };
    auto emit_vertex = [&](VH v) {
      if (alive(v))
        index[v.idx()] = emit(glm::vec3(point(v)), glm::vec3(to_glm(mesh_.normal(v))),
                              mesh_.property(scalar_, v));
    };
    for (std::uint32_t g = 0; g < n_input; ++g) {
      if (region_.local[g] != kNone) {
        emit_vertex(VH(int(region_.local[g])));
      } else if (region_.used[g]) {
        outside[g] = emit(in_.positions[g], in_.normals[g], scalars ? in_.scalars[g] : 0.0f);
      }
    }
    for (std::size_t v = region_.global.size(); v < mesh_.n_vertices(); ++v)
      emit_vertex(VH(int(v)));
    out.positions.resize(vertices);
    out.normals.resize(vertices);
    if (scalars) out.scalars.resize(vertices);
    UnionFind pieces(vertices);
    std::size_t quads = 0;
    // Corners one by one: a range insert of three or four numbers was a memmove call per face
    // (a twentieth of merging on Marschner–Lobb 512²).
    auto emit_face = [&](std::span<const std::uint32_t> c, std::uint8_t view) {
      for (std::size_t k = 1; k < c.size(); ++k)
        pieces.join(c[0], c[k]);
      if (c.size() == 3) {
        for (std::uint32_t v : c)
          triangles.push_back(v);
        triangle_view.push_back(view);
      } else if (faces == FaceType::quads) {
        for (std::size_t k = 0; k < 4; ++k)
          put_at(out.quads, 4 * quads + k, c[k]);
        put_at(out.quad_view, quads++, view);
      } else {
        append_quad_triangles(out.positions, c.data(), triangles);
        triangle_view.insert(triangle_view.end(), {view, view});
      }
    };
    std::vector<std::uint32_t> c;
    auto emit_mesh_face = [&](FH f) {
      if (mesh_.status(f).deleted()) return;
      c.clear();
      for (const auto& v : mesh_.fv_range(f))
        c.push_back(index[v.idx()]);
      emit_face(c, mesh_.property(view_, mesh_.from_vertex_handle(mesh_.halfedge_handle(f))));
    };
    // A face outside as OpenMesh keeps an added face: corners from the first on, its half-edge
    // from the last corner (whose view the face takes).
    for (std::size_t f = 0; f < region_.inside.size(); ++f) {
      if (region_.inside[f]) {
        if (input_face_[f].is_valid()) emit_mesh_face(input_face_[f]);
        continue;
      }
      const auto corners = face_corners(in_, f);
      c.clear();
      for (std::uint32_t v : corners)  // pinned corners are the region's
        c.push_back(region_.local[v] != kNone ? index[region_.local[v]] : outside[v]);
      emit_face(c, region_.vertex_view[corners.back()]);
    }
    for (std::size_t f = built_faces_; f < mesh_.n_faces(); ++f)
      emit_mesh_face(FH(int(f)));
    out.quads.resize(4 * quads);
    out.quad_view.resize(quads);
    out.triangles = std::move(triangles);
    out.triangle_view = std::move(triangle_view);
    for (std::uint32_t v = 0; v < out.positions.size(); ++v)
      if (pieces.find(v) == v) ++stats_.components;
    stats_.unfilled_holes = count_loops();
    renumber_moves(moves_, index);
    return in_place ? Mesh() : std::move(fresh);
  }

  // The output's vertices moved onto the surface, with their midpoints (for undo_crossing_moves).
  const std::vector<VertexMove>& moved() const { return moves_; }
  double scale() const { return scale_; }
  // Whether a step reached the region's edge: the result may differ from the whole mesh's.
  bool reached_region_edge() const { return cut_touched_ > 0; }

 private:
  glm::dvec3 point(VH v) const { return to_glm(mesh_.point(v)); }
  // Three steps along the face instead of OpenMesh's circulator (valence() was a tenth of the
  // merge on ML 512²: the split and flip passes ask it for every edge of the sewing region).
  bool is_triangle(FH f) const {
    const HH h = mesh_.halfedge_handle(f);
    return mesh_.next_halfedge_handle(mesh_.next_halfedge_handle(mesh_.next_halfedge_handle(h))) ==
           h;
  }
  double length(HH h) const {
    return glm::distance(point(mesh_.from_vertex_handle(h)), point(mesh_.to_vertex_handle(h)));
  }

  // Adds the face if the mesh stays a 2-manifold: no repeated corner, and OpenMesh accepts it
  // (add_face refuses a corner that is neither isolated nor on an open edge, and an edge that is
  // not new or open on the side the face takes).
  bool add(const std::vector<VH>& vs, Kind kind) { return insert(vs, kind).is_valid(); }
  FH insert(const std::vector<VH>& vs, Kind kind) {
    const std::size_t n = vs.size();
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j)
        if (vs[i] == vs[j]) return FH();
    // After the build, a face at the region's edge would differ from the whole mesh's (there
    // its vertices are inside closed disks and take no face): refused, and merging runs again
    // on the whole mesh.
    if (built_)
      for (VH v : vs)
        if (is_pinned(v)) {
          ++cut_touched_;
          return FH();
        }
    const FH f = mesh_.add_face(vs);
    if (!f.is_valid()) return FH();
    mesh_.property(kind_, f) = kind;
    if (kind != Kind::kInput) region_faces_.push_back(f);
    return f;
  }

  // The vertex's number in the whole mesh: its input number, or after the input's for a new one.
  std::uint32_t global(VH v) const {
    const std::uint32_t i = std::uint32_t(v.idx());
    return i < region_.global.size()
               ? region_.global[i]
               : std::uint32_t(in_.positions.size() + (i - region_.global.size()));
  }
  // Deletes a face; one at the region's edge is noted (see insert).
  void erase(FH f, bool delete_isolated_vertices) {
    if (built_)
      for (const auto& v : mesh_.fv_range(f))
        if (is_pinned(v)) ++cut_touched_;
    mesh_.delete_face(f, delete_isolated_vertices);
  }
  // Not deleted and in some face.
  bool alive(VH v) const { return !mesh_.status(v).deleted() && !mesh_.is_isolated(v); }
  // A corner of a face outside the region (never one of the whole mesh's new vertices).
  bool is_pinned(VH v) const {
    return std::size_t(v.idx()) < region_.pinned.size() && region_.pinned[v.idx()];
  }
  // A half-edge on the region's edge to the faces outside: open in the region's mesh, not in
  // the whole one (both ends pinned: a pinned vertex is inside a closed disk of the whole mesh,
  // so an open edge between two of them is one whose other face lies outside).
  bool is_cut(HH h) const {
    return mesh_.is_boundary(h) && is_pinned(mesh_.from_vertex_handle(h)) &&
           is_pinned(mesh_.to_vertex_handle(h));
  }
  // An open half-edge of the whole mesh.
  bool is_open(HH h) const { return mesh_.is_boundary(h) && !is_cut(h); }

  // The face through `vs` (counter-clockwise) faces the way the mean of their normals points.
  bool faces_its_normals(std::initializer_list<VH> vs) const {
    std::array<glm::dvec3, 4> p;  // triangles and quads
    std::size_t count = 0;
    glm::dvec3 n(0.0);
    for (VH v : vs) {
      p[count++] = point(v);
      n += to_glm(mesh_.normal(v));
    }
    const glm::dvec3 face = newell_normal(std::span(p.data(), count));
    const double a = glm::length(face), b = glm::length(n);
    return a > 0.0 && b > 0.0 && glm::dot(face, n) >= options_.min_facing * a * b;
  }

  // A new edge a–b can lie on the surface only if the normals at its ends do not oppose; if
  // they do, a and b sit on the two walls of a thin crest or valley and the edge would cut
  // through it (Marschner–Lobb's ripples at 64² are such walls, a cell or two apart).
  bool spans_surface(VH a, VH b) const {
    return glm::dot(to_glm(mesh_.normal(a)), to_glm(mesh_.normal(b))) >= options_.min_normal_dot;
  }

  bool ear_is_convex(VH u, VH v, VH w, bool strict) const {
    const glm::dvec3 U = point(u), V = point(v), W = point(w);
    const glm::dvec3 n = glm::cross(V - U, W - V);
    const double scale = glm::distance(U, V) * glm::distance(V, W);
    if (!(glm::length(n) > (strict ? 0.05 : 0.01) * scale)) return false;  // not a straight run
    if (strict) return faces_its_normals({u, v, w});
    const glm::dvec3 normals =
        to_glm(mesh_.normal(u)) + to_glm(mesh_.normal(v)) + to_glm(mesh_.normal(w));
    return glm::dot(n, normals) > 0.0;
  }

  std::size_t count_loops() const {
    std::vector<std::uint8_t> seen(mesh_.n_halfedges(), 0);
    std::size_t loops = 0;
    for (const auto& h : mesh_.halfedges()) {
      if (!is_open(h) || seen[h.idx()]) continue;
      ++loops;
      HH g = h;
      do {
        seen[g.idx()] = 1;
        g = mesh_.next_halfedge_handle(g);
      } while (g != HH(h) && !seen[g.idx()]);
    }
    return loops;
  }

  // The edges of the sewing region's live faces, each once (as its first half-edge), in index
  // order: what the flip and split passes look at, so that their cost follows the region, not
  // the whole mesh. Drops deleted faces from region_faces_ on the way.
  std::vector<HH> region_edges() {
    std::erase_if(region_faces_, [&](FH f) { return mesh_.status(f).deleted(); });
    // Marks instead of sorting: a scan over the marks is ordered and far cheaper than sorting
    // the region's half-edges (which made this a tenth of the merge on ML 512²).
    edge_mark_.assign(mesh_.n_edges(), 0);
    for (FH f : region_faces_)
      mark_edges(f);
    return marked_edges();
  }

  void mark_edges(FH f) {
    for (const auto& h : mesh_.fh_range(f))
      edge_mark_[mesh_.edge_handle(h).idx()] = 1;
  }

  // The marked edges (each as its first half-edge) in index order.
  std::vector<HH> marked_edges() const {
    std::vector<HH> edges;
    for (std::size_t e = 0; e < edge_mark_.size(); ++e)
      if (edge_mark_[e]) edges.push_back(mesh_.halfedge_handle(OpenMesh::EdgeHandle(int(e)), 0));
    return edges;
  }

  bool in_region(FH f) const { return f.is_valid() && mesh_.property(kind_, f) != Kind::kInput; }

  // Length flips in the sewing region until none applies (at most 8 passes): the first pass
  // looks at every region edge, each later one at the edges of the faces the previous pass made.
  void flip_all() {
    std::vector<HH> edges = region_edges();
    for (int pass = 0; pass < 8 && !edges.empty(); ++pass) {
      std::vector<HH> next;
      for (HH h : edges) {
        if (mesh_.status(mesh_.edge_handle(h)).deleted()) continue;
        const HH flipped = try_flip(h);
        if (!flipped.is_valid()) continue;
        ++stats_.flips;
        for (HH side : {flipped, mesh_.opposite_halfedge_handle(flipped)})
          for (const auto& g : mesh_.fh_range(mesh_.face_handle(side)))
            next.push_back(mesh_.halfedge_handle(mesh_.edge_handle(g), 0));
      }
      std::sort(next.begin(), next.end());
      next.erase(std::unique(next.begin(), next.end()), next.end());
      edges = std::move(next);
    }
  }

  // Splits the sewing region's long edges (both faces triangles, at least one of the region),
  // longest first and no two in one triangle per pass, and moves the pass's new vertices onto
  // the surface in one batch. A new vertex whose faces would no longer face their normals after
  // the move stays at its edge's midpoint.
  void refine_region(const SurfaceProjection& project) {
    const double limit = options_.split_length * scale_;
    if (!(limit > 0.0)) return;
    // The first pass looks at every edge of the region; a later one at the long edges the
    // previous pass left and the edges of the faces it made (no other edge's length or faces
    // changed).
    std::vector<HH> candidates = region_edges();
    for (int pass = 0; pass < options_.split_passes; ++pass) {
      std::vector<std::pair<double, HH>> long_edges;
      for (const HH h : candidates) {
        const HH o = mesh_.opposite_halfedge_handle(h);
        const FH f = mesh_.face_handle(h), g = mesh_.face_handle(o);
        if (!f.is_valid() || !g.is_valid() || !is_triangle(f) || !is_triangle(g)) continue;
        if (!in_region(f) && !in_region(g)) continue;
        const double l = length(h);
        if (l > limit) long_edges.emplace_back(l, h);
      }
      if (long_edges.empty()) break;
      std::sort(long_edges.begin(), long_edges.end(), [](const auto& x, const auto& y) {
        return x.first != y.first ? x.first > y.first : x.second < y.second;
      });
      std::vector<std::uint8_t> touched(mesh_.n_faces(), 0);
      const std::size_t first_new_face = region_faces_.size();
      std::vector<VH> fresh;
      std::vector<glm::dvec3> points, normals;
      for (const auto& [l, h] : long_edges) {
        const FH f = mesh_.face_handle(h), g = mesh_.face_handle(mesh_.opposite_halfedge_handle(h));
        // Faces made in this pass (indices past `touched`) took over edges of split triangles.
        auto done = [&](FH x) {
          return std::size_t(x.idx()) >= touched.size() || touched[x.idx()];
        };
        if (done(f) || done(g)) continue;
        const VH m = split(h);
        if (!m.is_valid()) continue;
        touched[f.idx()] = touched[g.idx()] = 1;
        fresh.push_back(m);
        points.push_back(point(m));
        normals.push_back(to_glm(mesh_.normal(m)));
      }
      if (fresh.empty()) break;
      stats_.split_edges += fresh.size();
      ++stats_.split_passes;
      edge_mark_.assign(mesh_.n_edges(), 0);
      for (const auto& [l, h] : long_edges)
        if (!mesh_.status(mesh_.edge_handle(h)).deleted())
          edge_mark_[mesh_.edge_handle(h).idx()] = 1;
      for (std::size_t i = first_new_face; i < region_faces_.size(); ++i)
        if (!mesh_.status(region_faces_[i]).deleted()) mark_edges(region_faces_[i]);
      candidates = marked_edges();
      const std::vector<glm::dvec3> mid = points, mid_normals = normals;
      project(points, normals, options_.project_reach * scale_);
      for (std::size_t k = 0; k < fresh.size(); ++k) {
        if (points[k] == mid[k]) continue;
        // The move must not turn any face of the new vertex over.
        std::vector<glm::dvec3> before;
        for (const auto& f : mesh_.vf_range(fresh[k]))
          before.push_back(face_normal(f));
        set_point(fresh[k], points[k], normals[k]);
        std::size_t i = 0;
        bool turned = false;
        for (const auto& f : mesh_.vf_range(fresh[k]))
          turned = turned || !(glm::dot(face_normal(f), before[i++]) > 0.0);
        if (turned) {
          set_point(fresh[k], mid[k], mid_normals[k]);
        } else {
          ++stats_.projected;
          moves_.push_back(
              {std::uint32_t(fresh[k].idx()), glm::vec3(mid[k]), glm::vec3(mid_normals[k])});
        }
      }
    }
  }

  // Splits the edge of h between the triangles a→b→c and b→a→d at its midpoint into four
  // triangles of the same kinds. Returns the new vertex, or an invalid handle (nothing changed).
  VH split(HH h) {
    const HH o = mesh_.opposite_halfedge_handle(h);
    const FH f = mesh_.face_handle(h), g = mesh_.face_handle(o);
    const VH a = mesh_.from_vertex_handle(h), b = mesh_.to_vertex_handle(h);
    const VH c = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h));
    const VH d = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(o));
    if (c == d) return VH();
    const Kind kf = mesh_.property(kind_, f), kg = mesh_.property(kind_, g);
    const glm::dvec3 n = to_glm(mesh_.normal(a)) + to_glm(mesh_.normal(b));
    const VH m = mesh_.add_vertex(mesh_.calc_edge_midpoint(mesh_.edge_handle(h)));
    mesh_.set_normal(m, glm::length(n) > 0.0 ? to_om(glm::normalize(n)) : mesh_.normal(a));
    mesh_.property(scalar_, m) = 0.5f * (mesh_.property(scalar_, a) + mesh_.property(scalar_, b));
    mesh_.property(view_, m) = mesh_.property(view_, a);
    erase(f, false);
    erase(g, false);
    if (add({a, m, c}, kf) && add({m, b, c}, kf) && add({b, m, d}, kg) && add({m, a, d}, kg))
      return m;
    // OpenMesh refused: take the new faces away (m stays isolated, output skips it) and put the
    // two triangles back.
    std::vector<FH> added;
    for (const auto& f2 : mesh_.vf_range(m))
      added.push_back(f2);
    for (FH f2 : added)
      erase(f2, false);
    if (!add({a, b, c}, kf) || !add({b, a, d}, kg)) ++stats_.lost_faces;
    return VH();
  }

  // Newell's normal of a triangle or quad (not normalised).
  glm::dvec3 face_normal(FH f) const {
    std::array<glm::dvec3, 4> p;
    std::size_t count = 0;
    for (const auto& v : mesh_.fv_range(f))
      if (count < p.size()) p[count++] = point(v);
    return newell_normal(std::span(p.data(), count));
  }

  void set_point(VH v, glm::dvec3 p, glm::dvec3 n) {
    mesh_.set_point(v, to_om(p));
    mesh_.set_normal(v, to_om(n));
  }

  // Flips the edge of h between two triangles of the sewing region if the other diagonal is
  // shorter and both new triangles face like their normals. Returns the new edge's half-edge
  // c→d, or an invalid handle if nothing was flipped.
  HH try_flip(HH h) {
    const HH o = mesh_.opposite_halfedge_handle(h);
    const FH f = mesh_.face_handle(h), g = mesh_.face_handle(o);
    if (!in_region(f) || !in_region(g) || !is_triangle(f) || !is_triangle(g)) return HH();
    const VH a = mesh_.from_vertex_handle(h), b = mesh_.to_vertex_handle(h);
    const VH c = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h));
    const VH d = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(o));
    // At the region's edge the valences are not the whole mesh's (see insert).
    if (is_pinned(a) || is_pinned(b) || is_pinned(c) || is_pinned(d)) {
      ++cut_touched_;
      return HH();
    }
    // Cheapest tests first: most edges of the region are not longer than their other diagonal.
    if (c == d || glm::distance(point(c), point(d)) >= glm::distance(point(a), point(b)))
      return HH();
    if (mesh_.find_halfedge(c, d).is_valid()) return HH();
    if (mesh_.valence(a) <= 3 || mesh_.valence(b) <= 3) return HH();
    if (!faces_its_normals({a, d, c}) || !faces_its_normals({d, b, c})) return HH();
    // The flip must not fold the pair more sharply than it is: where two sheets meet (Barth's
    // double points) the other diagonal of a folded pair cuts through the other sheet (without
    // this, Barth 64² kept three crossing pairs; with it none, and the same forward mean).
    auto cosine = [&](VH p, VH q, VH r, VH s, VH t, VH u) {
      const glm::dvec3 n1 = glm::cross(point(q) - point(p), point(r) - point(p));
      const glm::dvec3 n2 = glm::cross(point(t) - point(s), point(u) - point(s));
      return glm::dot(n1, n2) / (glm::length(n1) * glm::length(n2));
    };
    if (!(cosine(a, d, c, d, b, c) >= cosine(a, b, c, b, a, d))) return HH();
    const Kind kf = mesh_.property(kind_, f), kg = mesh_.property(kind_, g);
    erase(f, false);
    erase(g, false);
    if (add({a, d, c}, kf)) {
      if (add({d, b, c}, kg)) return mesh_.find_halfedge(c, d);
      erase(mesh_.face_handle(mesh_.find_halfedge(a, d)), false);
    }
    // Put the two triangles back as they were (OpenMesh refused the flip).
    if (!add({a, b, c}, kf) || !add({b, a, d}, kg)) ++stats_.lost_faces;
    return HH();
  }

  // Replaces the three triangles around a valence-3 vertex of the sewing region by one when the
  // vertex lies almost in the plane of its neighbours.
  bool try_merge(VH v) {
    std::vector<HH> outer;
    std::vector<FH> fan;
    for (const auto& h : mesh_.voh_range(v)) {
      const FH f = mesh_.face_handle(h);
      if (!in_region(f) || !is_triangle(f)) return false;
      fan.push_back(f);
      outer.push_back(mesh_.next_halfedge_handle(h));  // the edge of f opposite v
    }
    if (fan.size() != 3) return false;
    const VH a = mesh_.from_vertex_handle(outer[0]), b = mesh_.to_vertex_handle(outer[0]);
    VH c = mesh_.to_vertex_handle(outer[1]);
    if (mesh_.from_vertex_handle(outer[1]) != b) c = mesh_.to_vertex_handle(outer[2]);
    const glm::dvec3 V = point(v), A = point(a) - V, B = point(b) - V, C = point(c) - V;
    const double mean = (glm::length(A) + glm::length(B) + glm::length(C)) / 3.0;
    if (std::abs(glm::dot(A, glm::cross(B, C))) >= options_.coplanar * mean * mean * mean)
      return false;
    if (!faces_its_normals({a, b, c})) return false;
    for (FH f : fan)
      erase(f, true);
    if (add({a, b, c}, Kind::kFill)) return true;
    ++stats_.lost_faces;  // the fan's vertex is gone: the hole stays and is counted
    return false;
  }

  const Mesh& in_;
  const InputRegion& region_;
  MergeOptions options_;
  MergeStats& stats_;
  HalfEdgeMesh mesh_;
  OpenMesh::FPropHandleT<Kind> kind_;
  OpenMesh::VPropHandleT<std::uint8_t> view_;
  OpenMesh::VPropHandleT<float> scalar_;
  double scale_ = 0.0;            // the length scale of the limits: cell_size or the median edge
  std::vector<FH> region_faces_;  // faces added by bridging, filling and enhancement
  std::vector<std::uint8_t> edge_mark_;  // region_edges' scratch
  // The sewing region's vertices moved onto the surface, with their midpoint and its normal
  // (OpenMesh's vertex numbers; output() renumbers them as the output's).
  std::vector<VertexMove> moves_;
  // The region's input faces as added (invalid: refused or outside), per input face. Faces from
  // built_faces_ on are merging's own.
  std::vector<FH> input_face_;
  std::size_t built_faces_ = 0;
  bool built_ = false;
  std::size_t cut_touched_ = 0;  // steps refused at the region's edge (see insert)
};

}  // namespace

namespace {

// merge_views; with `writable` (the input mesh itself) and quad output, the result is written
// over the input's arrays.
Mesh merge_mesh(const Mesh& mesh, Mesh* writable, FaceType faces, const MergeOptions& options,
                MergeStats& stats, const SurfaceProjection& project) {
  stats = {};
  if (const Status s = check_mesh(mesh); !s)  // bad input gets a clear error
    throw std::invalid_argument("merge_views: " + s.message());
  const QuietOpenMesh quiet;
  const SurfaceProjection none;
  const SurfaceProjection& onto_surface = options.project ? project : none;
  // Views, boundary layer, bridges, holes, enhancement and the crossing check on the faces of
  // `region`; sets reached_edge when a step was refused at the region's edge.
  auto merge = [&](const InputRegion& region, bool& reached_edge) {
    auto start = std::chrono::steady_clock::now();
    Merger merger(mesh, region, options, stats);
    if (options.remove_boundary_layer) merger.remove_boundary_layer();
    merger.bridge();
    stats.bridge_seconds += seconds_since(start);
    start = std::chrono::steady_clock::now();
    merger.fill_holes();
    stats.sew_seconds = seconds_since(start);
    start = std::chrono::steady_clock::now();
    if (options.enhance) merger.enhance(onto_surface);
    reached_edge = merger.reached_region_edge();
    if (reached_edge) {  // merged again on the whole mesh
      stats.quality_seconds = seconds_since(start);
      return Mesh();
    }
    Mesh* in_place = faces == FaceType::quads ? writable : nullptr;
    Mesh out = merger.output(faces, in_place);
    if (in_place) out = std::move(*in_place);
    // Projected vertices whose faces pass through other faces go back to their edge midpoints
    // (crossings.hpp): without the moves no face crossed; with them, Barth's merged meshes had
    // crossing pairs near its double points, where the cone's two nappes are a cell or two
    // apart.
    if (!merger.moved().empty() && merger.scale() > 0.0) {
      stats.crossings_undone = undo_crossing_moves(
          out, merger.moved(), std::max(1.0, options.split_length) * merger.scale(),
          options.crossing_min_move * merger.scale());
      stats.projected -= stats.crossings_undone;
    }
    stats.quality_seconds = seconds_since(start);
    return out;
  };
  auto start = std::chrono::steady_clock::now();
  // The region needs the length scale up front (the median edge would need every edge).
  const bool by_region = options.region_rings >= 0 && options.cell_size > 0.0;
  InputRegion region =
      select_input_region(mesh, by_region ? std::max(options.region_rings, kMinRegionRings) : -1);
  stats.bridge_seconds = seconds_since(start);
  bool reached_edge = false;
  Mesh out = merge(region, reached_edge);
  stats.region_faces = region.faces;
  if (reached_edge) {
    // A step wanted a face at the region's edge: merge the whole mesh instead (the times add
    // up in the bridge column).
    const double first = stats.bridge_seconds + stats.sew_seconds + stats.quality_seconds;
    stats = {};
    start = std::chrono::steady_clock::now();
    region = select_input_region(mesh, -1);
    stats.bridge_seconds = first + seconds_since(start);
    out = merge(region, reached_edge);
    stats.region_faces = region.faces;
  }
  if (faces == FaceType::quads && options.all_quads) {
    start = std::chrono::steady_clock::now();
    out = quadrangulate(std::move(out), options.quads, stats.quads, onto_surface);
    stats.quality_seconds += seconds_since(start);
  }
  return out;
}

}  // namespace

Mesh merge_views(const Mesh& mesh, FaceType faces, const MergeOptions& options, MergeStats& stats,
                 const SurfaceProjection& project) {
  return merge_mesh(mesh, nullptr, faces, options, stats, project);
}

Mesh merge_views(Mesh&& mesh, FaceType faces, const MergeOptions& options, MergeStats& stats,
                 const SurfaceProjection& project) {
  return merge_mesh(mesh, &mesh, faces, options, stats, project);
}

}  // namespace ldimesh

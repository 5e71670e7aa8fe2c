// Internal to §5 merging: the state its steps share — the input, the region being rewritten
// (face_rings), OpenMesh's half-edge mesh of it with each face's kind, view and scalar
// properties, the length scale and the moved vertices — and the mesh edits every step is built
// from (insert and erase with the manifold and region checks, split, flip, merge). The steps
// are free functions over it, one file each: boundary_layer.cpp, bridges.cpp (i),
// hole_filling.cpp (ii), enhancement.cpp (iii); merge.cpp picks the region, runs them and
// writes the output.
//
// Threads: one MergeState per merge, used by one thread; everything is in a fixed order
// (deterministic).
#pragma once

#include <cstdint>
#include <initializer_list>
#include <numeric>
#include <vector>

#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/merge/crossings.hpp"
#include "ldimesh/core/merge/merge.hpp"
#include "ldimesh/core/merge/projection.hpp"

namespace ldimesh::merge_detail {

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

inline glm::dvec3 to_glm(const OpenMesh::Vec3d& p) {
  return {p[0], p[1], p[2]};
}
inline OpenMesh::Vec3d to_om(glm::dvec3 p) {
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

struct MergeState {
  MergeState(const Mesh& in, const InputRegion& region, const MergeOptions& options,
             MergeStats& stats);

  // The output's vertices moved onto the surface, with their midpoints (for undo_crossing_moves).
  const std::vector<VertexMove>& moved() const { return moves_; }
  double scale() const { return scale_; }
  // Whether a step reached the region's edge: the result may differ from the whole mesh's.
  bool reached_region_edge() const { return cut_touched_ > 0; }

  glm::dvec3 point(VH v) const { return to_glm(mesh_.point(v)); }
  // Three steps along the face instead of OpenMesh's circulator: the split and flip passes ask
  // it for every edge of the sewing region.
  bool is_triangle(FH f) const;
  double length(HH h) const;

  // Adds the face if the mesh stays a 2-manifold: no repeated corner, and OpenMesh accepts it
  // (add_face refuses a corner that is neither isolated nor on an open edge, and an edge that is
  // not new or open on the side the face takes).
  bool add(const std::vector<VH>& vs, Kind kind) { return insert(vs, kind).is_valid(); }
  FH insert(const std::vector<VH>& vs, Kind kind);

  // The vertex's number in the whole mesh: its input number, or after the input's for a new one.
  std::uint32_t global(VH v) const;
  // Deletes a face; one at the region's edge is noted (see insert).
  void erase(FH f, bool delete_isolated_vertices);
  // Not deleted and in some face.
  bool alive(VH v) const { return !mesh_.status(v).deleted() && !mesh_.is_isolated(v); }
  // A corner of a face outside the region (never one of the whole mesh's new vertices).
  bool is_pinned(VH v) const;
  // A half-edge on the region's edge to the faces outside: open in the region's mesh, not in
  // the whole one (both ends pinned: a pinned vertex is inside a closed disk of the whole mesh,
  // so an open edge between two of them is one whose other face lies outside).
  bool is_cut(HH h) const;
  // An open half-edge of the whole mesh.
  bool is_open(HH h) const { return mesh_.is_boundary(h) && !is_cut(h); }

  // The face through `vs` (counter-clockwise) faces the way the mean of their normals points.
  bool faces_its_normals(std::initializer_list<VH> vs) const;

  // A new edge a–b can lie on the surface only if the normals at its ends do not oppose; if
  // they do, a and b sit on the two walls of a thin crest or valley and the edge would cut
  // through it (Marschner–Lobb's ripples at 64² are such walls, a cell or two apart).
  bool spans_surface(VH a, VH b) const;

  bool ear_is_convex(VH u, VH v, VH w, bool strict) const;

  std::size_t count_loops() const;

  // The edges of the sewing region's live faces, each once (as its first half-edge), in index
  // order: what the flip and split passes look at, so that their cost follows the region, not
  // the whole mesh. Drops deleted faces from region_faces_ on the way.
  std::vector<HH> region_edges();

  void mark_edges(FH f);

  // The marked edges (each as its first half-edge) in index order.
  std::vector<HH> marked_edges() const;

  bool in_region(FH f) const { return f.is_valid() && mesh_.property(kind_, f) != Kind::kInput; }

  // Splits the edge of h between the triangles a→b→c and b→a→d at its midpoint into four
  // triangles of the same kinds. Returns the new vertex, or an invalid handle (nothing changed).
  VH split(HH h);

  // Newell's normal of a triangle or quad (not normalised).
  glm::dvec3 face_normal(FH f) const;

  void set_point(VH v, glm::dvec3 p, glm::dvec3 n);

  // Flips the edge of h between two triangles of the sewing region if the other diagonal is
  // shorter and both new triangles face like their normals. Returns the new edge's half-edge
  // c→d, or an invalid handle if nothing was flipped.
  HH try_flip(HH h);

  // Replaces the three triangles around a valence-3 vertex of the sewing region by one when the
  // vertex lies almost in the plane of its neighbours.
  bool try_merge(VH v);

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

// The steps, in the order merge_views runs them.
void remove_boundary_layer(MergeState& ms);

// (i) One bridge per pair of patches that are close: the quad p→q→s→t on the open half-edges
// p→q of patch a and s→t of patch b with the shortest connecting edges q–s and t–p, kept if
// neither exceeds l = |e_a| + |e_b| (times options.bridge_limit).
void bridge(MergeState& ms);

// (ii) Ear cutting: repeatedly the shortest new edge u–w that closes a triangle u→v→w with two
// consecutive open half-edges u→v, v→w, over all holes at once. Ears must turn the way the
// surface does (convex) and face like their vertices' normals; a second round accepts any
// convex ear. Holes left are counted.
void fill_holes(MergeState& ms);

// (iii) Quads next to fill triangles (and, when the sewing region is refined, bridges) split
// into triangles; edge flips toward shorter edges; the sewing region's long edges split with
// their new vertices moved onto the surface; flips again; 3-to-1 merges.
void enhance(MergeState& ms, const SurfaceProjection& project);

// Length flips in the sewing region until none applies (at most 8 passes): the first pass
// looks at every region edge, each later one at the edges of the faces the previous pass made.
void flip_all(MergeState& ms);

// Splits the sewing region's long edges (both faces triangles, at least one of the region),
// longest first and no two in one triangle per pass, and moves the pass's new vertices onto
// the surface in one batch. A new vertex whose faces would no longer face their normals after
// the move stays at its edge's midpoint.
void refine_region(MergeState& ms, const SurfaceProjection& project);

// The whole mesh: vertices in input order (those some face uses), then the new ones; faces
// in input order (outside the region as they were), then the new ones. With `in_place` (the
// input mesh itself, quad output only) written over the input's arrays: a vertex or a quad
// moves to the same or a lower place, so an entry is read before anything is written over it
// (the input's triangles are read until the end, so the output's go to new arrays); this
// spares the fresh arrays, whose first touch was most of the output's time on Marschner–Lobb
// 512².
Mesh output(MergeState& ms, FaceType faces, Mesh* in_place = nullptr);

}  // namespace ldimesh::merge_detail

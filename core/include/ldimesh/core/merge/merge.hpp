// Combining the per-view meshes into one (paper §5): boundary layer removal, bridges between
// patches, hole filling by ear cutting and triangle enhancement, on a half-edge mesh (OpenMesh).
#pragma once

#include <cstddef>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/merge/projection.hpp"
#include "ldimesh/core/merge/quadrangulate.hpp"
#include "ldimesh/core/refine/refine.hpp"

namespace ldimesh {

struct MergeOptions {
  bool enabled = false;
  // The length scale of the limits below, in world units: the LDIs' pixel size (mesh_ldis sets
  // it when it is 0). 0 in merge_views: the median edge of the input mesh.
  double cell_size = 0.0;
  // The faces built as a half-edge mesh: those within this many rings (faces sharing a vertex)
  // of the vertices not inside a closed disk of faces (open boundaries, and wherever the input
  // is not a manifold); the others (the views' regular grids, most of the mesh) pass through
  // unchanged, so merging costs what the boundaries hold. Every step happens within two rings of
  // an open boundary, so the result is the same as for the whole mesh; should a step reach the
  // region's edge, merging runs again on the whole mesh. Needs cell_size (the limits' scale);
  // at least 2 (fewer count as 2); negative: always the whole mesh.
  int region_rings = 3;
  // Remove the faces that have an open edge before bridging (§5: the ragged "boundary layer"
  // the r = 1 trim leaves).
  bool remove_boundary_layer = true;
  // (i) A bridge is kept if neither connecting edge exceeds bridge_limit · (|e_a| + |e_b|) (the
  // paper's l is factor 1; why ours is larger: docs/method.md).
  double bridge_limit = 1.5;
  // Bridges and fill triangles must face the way their vertices' normals do: the cosine between
  // the face normal and the mean vertex normal is at least this.
  double min_facing = 0.2;
  // A connecting edge (of a bridge or an ear) joins vertices whose normals' dot product is at
  // least this, so that it does not cut across a thin crest or valley of the surface.
  double min_normal_dot = 0.0;
  // (ii) Ears whose new edge is longer than this many times the length scale are not cut
  // (so a hole is never closed across the far side of the surface); such holes are reported.
  double max_fill_edge = 6.0;
  // (iii) Edge flips by length and 3-to-1 merges of almost coplanar triangle triples.
  bool enhance = true;
  // Vertices on the surface in the sewing region: bridges and fill triangles span gaps of a few
  // cells with flat faces between samples. Their edges longer than split_length times the length
  // scale are split, and the new vertices moved onto the surface (one projection batch per
  // pass, at most split_passes passes); the conversion to quads projects its new and smoothed
  // vertices too. Needs a SurfaceProjection; without one (or with project = false) nothing is
  // split and the quads' smoothing is limited instead.
  // A new vertex is looked for on the surface within project_reach times the length scale
  // along a view's ray: a long fill edge across a ripple has its midpoint that far off.
  bool project = true;
  double split_length = 1.5;
  double project_reach = 4.0;
  int split_passes = 6;
  // A moved vertex whose faces pass through another face goes back to its edge midpoint
  // (crossings.hpp); moves shorter than this times the length scale are not checked.
  double crossing_min_move = 0.05;
  // 3-to-1 merge: |det(a − v, b − v, c − v)| below this times the mean edge length cubed.
  double coplanar = 0.02;
  // (iv) For FaceType::quads output: convert to quads only (quadrangulate, with `quads`); false
  // keeps the untouched quads beside the triangles of the sewing region (quad-dominant).
  bool all_quads = true;
  QuadOptions quads;
};

// Whether merging with these options asks for samples (a SurfaceProjection): the pipeline makes
// one from its sample source, and in a parallel run every rank serves requests while it merges.
inline bool merging_projects(const MergeOptions& options) {
  return options.enabled && options.project;
}

struct MergeStats {
  std::size_t region_faces = 0;      // input faces built as a half-edge mesh (region_rings)
  std::size_t dropped_faces = 0;     // input faces that would have made the mesh non-manifold
  std::size_t boundary_faces = 0;    // faces removed as the boundary layer
  std::size_t patches = 0;           // connected pieces before bridging
  std::size_t bridge_pairs = 0;      // patch pairs close enough to test
  std::size_t bridges = 0;           // (i) bridge quads inserted
  std::size_t holes = 0;             // (ii) boundary loops before filling
  std::size_t fill_triangles = 0;    // (ii) triangles added by ear cutting
  std::size_t unfilled_holes = 0;    // boundary loops of the output (reported, not hidden)
  std::size_t split_quads = 0;       // (iii) quads next to fill triangles split
  std::size_t flips = 0;             // (iii) edge flips
  std::size_t merges = 0;            // (iii) 3-to-1 merges
  std::size_t split_edges = 0;       // sewing-region edges split (a new vertex each)
  std::size_t projected = 0;         // of those new vertices, moved onto the surface (and kept)
  std::size_t crossings_undone = 0;  // moves undone: a face of the vertex crossed another face
  std::size_t split_passes = 0;      // projection batches (round trips to the ray casters)
  std::size_t lost_faces = 0;        // (iii) faces OpenMesh refused to re-add (holes count them)
  std::size_t components = 0;        // connected pieces of the output
  double bridge_seconds = 0.0;       // layer removal, patches and bridges (Table 1 "Bridge")
  double sew_seconds = 0.0;          // hole filling (Table 1 "Sew")
  double quality_seconds = 0.0;      // enhancement, quads (iv) and output (Table 1 "Qual.")
  QuadStats quads;                   // (iv), for FaceType::quads output
};

// Merges the per-view meshes in `mesh` (faces of different views share no vertex; quads and/or
// triangles, each view's faces trimmed with r = 1 for best results) into one mesh: faces that
// cannot be added without making it non-manifold are dropped and counted, the boundary layer
// is removed, bridges join patches, holes are filled with triangles and improved. Output faces
// are triangles (each remaining quad split along its shorter diagonal) for FaceType::triangles,
// and quads only for FaceType::quads (§5 (iv), quadrangulate; a triangle it cannot convert is
// kept and counted in stats.quads.leftover_triangles; options.all_quads = false keeps the
// sewing region's triangles instead). Face views: the view of the face's first
// vertex. `project` (may be empty) moves the sewing region's new vertices onto the surface
// (options.project), and the new and smoothed vertices of the conversion to quads.
// Deterministic. Throws std::invalid_argument on array sizes that disagree or a face index out
// of range.
Mesh merge_views(const Mesh& mesh, FaceType faces, const MergeOptions& options, MergeStats& stats,
                 const SurfaceProjection& project = {});
// The same; with quad output written over the mesh's own arrays (no second copy of a large
// mesh: the pipeline hands its views' mesh over).
Mesh merge_views(Mesh&& mesh, FaceType faces, const MergeOptions& options, MergeStats& stats,
                 const SurfaceProjection& project = {});

}  // namespace ldimesh

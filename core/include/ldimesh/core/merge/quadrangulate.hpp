// §5 (iv) Quad mesh generation: a merged mesh of quads and triangles (the sewing region of hole
// filling and enhancement) becomes quads only. Triangle pairs are merged greedily by the quad
// they make, the remaining triangles are paired along shortest paths over the faces whose edges
// are split (Fig. 5(a)(iii), Fig. 3(d) for turns), then quads sharing two edges are merged, quad
// edge flips move valences toward four and Laplacian smoothing keeps the vertices on the surface.
#pragma once

#include <cstddef>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/merge/projection.hpp"

namespace ldimesh {

struct QuadOptions {
  // The faces converted: the triangles and the quads within this many rings of them (faces
  // sharing a vertex, ring by ring); the other quads (the views' regular grids, most of a merged
  // mesh) pass through unchanged, so the conversion costs what the sewing region holds. The
  // region's edge to the quads outside is fixed: no path crosses or ends there, its vertices
  // neither move nor flip. Should triangles be left that a region cannot pair (an odd number
  // in a part of the region with no open edge), the conversion runs again on the whole mesh.
  // Negative: always the whole mesh.
  int region_rings = 4;
  // Pairing: a triangle pair becomes a quad if the quad is convex (seen along its normal) and
  // its shortest edge is at least this fraction of its longest (the paper's quality metric).
  double min_pair_quality = 0.0;
  // Dijkstra rounds over the faces (each round pairs the remaining triangles along disjoint
  // shortest paths); triangles left after this many are kept and counted.
  int max_path_rounds = 64;
  // Valence-improving quad edge flips: passes over the edges of the faces this conversion made
  // (stops early when none flips).
  int flip_passes = 4;
  // Laplacian smoothing of the vertices of the faces this conversion made (all vertices with
  // smooth_all; open-boundary vertices stay): iterations and the fraction of the way to the
  // neighbours' mean, in the vertex's tangent plane.
  int smoothing_iterations = 4;
  double smoothing_step = 0.5;
  bool smooth_all = false;
  // Without a projection a vertex moves at most this many median edge lengths from where it
  // was before smoothing (it cannot be put back onto the surface).
  double max_unprojected_move = 0.25;
  // Projection reach, in median edge lengths of the input.
  double projection_reach = 1.0;
  // Moved vertices (projected, smoothed) whose faces pass through another face go back to where
  // they were (crossings.hpp); moves shorter than this many median edges are not checked. All
  // are by default: even tiny smoothing moves fold faces over their neighbours (docs/method.md).
  double crossing_min_move = 0.0;
};

struct QuadStats {
  std::size_t input_triangles = 0;
  std::size_t input_quads = 0;
  std::size_t region_faces = 0;        // input faces converted (all: the whole mesh, region_rings)
  std::size_t paired = 0;              // triangle pairs merged into one quad each
  std::size_t paths = 0;               // shortest paths between two triangles
  std::size_t path_rounds = 0;         // Dijkstra rounds
  std::size_t path_splits = 0;         // edges split along paths (open edges included)
  std::size_t turns = 0;               // quads a path turned in (three quads, Fig. 3(d))
  std::size_t quad_merges = 0;         // quad pairs sharing two edges merged
  std::size_t flips = 0;               // quad edge flips
  std::size_t boundary_splits = 0;     // paths from a triangle to an open edge, split there
  std::size_t leftover_triangles = 0;  // triangles that could not be converted (kept)
  std::size_t projected = 0;           // vertices the projection moved (all stages)
  std::size_t crossings_undone = 0;    // moved vertices put back: a face of theirs crossed another
  std::size_t output_quads = 0;
  double median_edge = 0.0;      // of the region: the unit of max_unprojected_move and the reach
  double setup_seconds = 0.0;    // checks, the region and its half-edges
  double pair_seconds = 0.0;     // greedy pairing
  double path_seconds = 0.0;     // Dijkstra rounds, splits and their projection
  double cleanup_seconds = 0.0;  // quad merges and flips
  double smooth_seconds = 0.0;   // smoothing, output and the crossing check
  double seconds = 0.0;          // all of it
};

// Converts a mesh of triangles and quads (an oriented 2-manifold: every edge in at most two
// faces, running opposite ways; open boundary loops allowed) into quads only (§5 (iv)).
// `project` (may be empty) moves points onto the surface: the new vertices of the paths (one
// call) and the smoothed vertices after the last smoothing iteration (one call); without it the
// smoothing is limited (options.max_unprojected_move). Moved vertices whose faces then cross
// another face go back to where they were (options.crossing_min_move, crossings.hpp). Output: the
// vertices that faces use (input vertices first, in input order, then new ones; positions, normals,
// and scalars if the input has them, new ones interpolated), quads wound like the input with
// quad_view the view of the face each came from (the quads outside the region first, in input
// order, then the region's), view_dirs copied, triangles empty unless a
// triangle could not be converted (counted in stats.leftover_triangles and kept as a triangle).
// Closed input gives closed output; an open edge stays open (it may be split). Deterministic:
// the same output for any number of threads (the half-edge links, the smoothing steps and the
// crossing check run in parallel; the pairing, paths, merges and flips in order). Throws
// std::invalid_argument on inconsistent array sizes, a face index out of range, a face with a
// repeated vertex, or an edge of the region used twice in one direction (so also by three
// faces).
Mesh quadrangulate(const Mesh& mesh, const QuadOptions& options, QuadStats& stats,
                   const SurfaceProjection& project = {});
// The same, written over the mesh's own arrays (no second copy of a large mesh).
Mesh quadrangulate(Mesh&& mesh, const QuadOptions& options, QuadStats& stats,
                   const SurfaceProjection& project = {});

}  // namespace ldimesh

// Adaptive refinement of the §3 meshes (paper §4): templates, extension sampling, growth toward
// boundaries and silhouettes.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/mesh/mesher.hpp"
#include "ldimesh/core/raycast/ldi.hpp"
#include "ldimesh/core/raycast/sample_source.hpp"

namespace ldimesh {

enum class FaceType { triangles, quads };

struct RefinementOptions {
  // Maximum subdivision level of a top-level cell (a §3 quad); 0 turns refinement off. Each
  // level halves the sample spacing, and each level is one refinement pass (one round trip).
  int levels = 0;
  // A cell is marked when the smallest dot product of two of its corner normals is below this
  // (the paper's 0.99), or when a corner is invalid (§4 (ii)).
  double min_normal_dot = 0.99;
  // §4 (iii): new top-level cells across the open edges of the §3 mesh, refined toward
  // boundaries and silhouettes.
  bool grow = true;
};

// What refinement did, over all views.
struct RefinementStats {
  int passes = 0;                          // refinement passes run (at most `levels`)
  std::size_t round_trips = 0;             // SampleSource::sample calls: one per pass
  std::vector<std::size_t> rays_per_pass;  // extension ray stretches requested per pass
  std::vector<double> seconds_per_pass;    // per pass: marking, templates, sampling, matching
  std::size_t grown_cells = 0;             // top-level cells added by growth (iii)
  std::size_t subdivided_cells = 0;        // cells split by templates, all passes
  std::size_t invalid_vertices = 0;        // vertices without a matching sample (interpolated)
  std::size_t removed_faces = 0;           // faces dropped for an invalid vertex at the end
  std::size_t trimmed_faces = 0;           // faces of grown cells trimmed like §3
  double seconds = 0.0;                    // all of it, sampling included
  double sample_seconds = 0.0;             // inside SampleSource::sample
};

// The §3 quads of one view, as refinement's input.
struct ViewQuads {
  // Quads kept by trimming (build_quads order and orientation): the top-level cells.
  std::vector<std::uint32_t> kept;
  // All quads build_quads made, before trimming: an edge of a kept quad that no other of these
  // shares is a boundary of the surface in this view (growth starts there); an edge that a
  // trimmed quad shares is not.
  std::vector<std::uint32_t> untrimmed;
};

// A refined view: its vertices and faces (quads or triangles), wound like the §3 output
// (counter-clockwise seen from the side the normals point to).
struct RefinedView {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;
  std::vector<float> scalars;        // empty when the LDI has none
  std::vector<std::uint32_t> faces;  // 4 (quads) or 3 (triangles) indices per face
};

// §4 on the §3 meshes of `ldis` (quads[k] belongs to ldis[k]; view k has index k in `samples`).
// Triangles: quadtree subdivision with the 1-level difference rule (an iterative pass) and six
// triangle templates; quads: 2-refinement with chessboard edge nodes, active edge nodes,
// transition cells and two templates. Every pass marks cells, applies the templates, and asks
// `samples` once for the new vertices of all views; a new vertex takes the hit on its ray that
// best matches its reference vertices by §3's depth prediction, or becomes invalid (depth and
// normal interpolated). Faces with an invalid vertex are removed at the end; faces descending
// from grown cells are trimmed against `all_dirs` with `r` like §3. Deterministic: the result
// does not depend on the thread count or on how `samples` splits its work.
// Throws std::invalid_argument for levels < 0 or > 16, or quads/ldis of different lengths.
std::vector<RefinedView> refine_views(std::span<const Ldi> ldis, std::span<const ViewQuads> quads,
                                      FaceType faces, const RefinementOptions& options,
                                      const MatchOptions& matching,
                                      std::span<const glm::dvec3> all_dirs, double r,
                                      SampleSource& samples, RefinementStats& stats);

}  // namespace ldimesh

// One isovalue's LDIs to one mesh: §3 match and trim, §4 refinement, §5 merging and quad
// conversion, as options ask (the root half of a step, transport/distributed.hpp).
//
// Threads: mesh_ldis runs its stages on the calling thread's TBB arena; several calls may run
// at once on different LDIs (no shared state). Determinism: the same LDIs and options give the
// same mesh, byte for byte, for any thread count.
#pragma once

#include <span>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/merge/merge.hpp"
#include "ldimesh/core/mesh/mesher.hpp"
#include "ldimesh/core/raycast/ldi.hpp"
#include "ldimesh/core/raycast/sample_source.hpp"
#include "ldimesh/core/refine/refine.hpp"

namespace ldimesh {

struct MeshingOptions {
  double r = 0.5;  // §3 trimming parameter in [0, 1]; the paper's recommended trade-off
  FaceType faces = FaceType::triangles;
  MatchOptions matching;
  RefinementOptions refinement;  // §4; levels > 0 needs a SampleSource
  // §5: trims with r = 1 instead of `r` when enabled; merging.project uses the SampleSource
  // when there is one.
  MergeOptions merging;
};

struct MeshingTimes {
  double match = 0.0;     // best matches and quads (§3)
  double trim = 0.0;      // trimming (§3)
  double refine = 0.0;    // §4 refinement, its sampling included
  double assemble = 0.0;  // vertices, triangle split, output arrays
  double bridge = 0.0;    // §5: boundary layer, patches, bridges
  double sew = 0.0;       // §5: hole filling
  double quality = 0.0;   // §5: enhancement and the merged output
};

struct MeshingResult {
  Mesh mesh;
  std::size_t samples = 0;          // samples in all LDIs
  std::size_t quads_untrimmed = 0;  // quads before trimming
  std::size_t quads = 0;            // quads after trimming
  MeshingTimes seconds;
  RefinementStats refinement;  // zeros unless refinement ran
  MergeStats merging;          // zeros unless merging ran
};

// The trimming parameter mesh_ldis uses: options.r, or 1 when merging (§5 trims with r = 1).
inline double trim_r(const MeshingOptions& options) {
  return options.merging.enabled ? 1.0 : options.r;
}

// Meshes each LDI (§3), trims against the directions of all of them with options.r, and
// assembles one mesh: vertices are the samples used by a kept face (one vertex per sample,
// shared by the faces of its view), faces are quads or triangles (each quad split along its
// shorter diagonal). With options.refinement.levels > 0 the trimmed meshes are refined (§4,
// refine_views) with extra samples from `samples` before assembly. With options.merging.enabled
// the views are trimmed with r = 1 and merged into one mesh (§5, merge_views; all quads for
// FaceType::quads); with `samples` the new vertices of its sewing region are moved onto the
// surface. Throws std::invalid_argument if r is outside [0, 1], more than 255 views, or
// refinement is asked for without a sample source, and passes on what the stages throw (their
// option checks: std::invalid_argument; the sample source's errors as it throws them).
MeshingResult mesh_ldis(std::span<const Ldi> ldis, const MeshingOptions& options = {},
                        SampleSource* samples = nullptr);

}  // namespace ldimesh

// The §3 pipeline on a set of LDIs: match, trim, assemble one mesh.
#pragma once

#include <span>

#include "ldimesh/core/ldi.hpp"
#include "ldimesh/core/mesh.hpp"
#include "ldimesh/core/mesher.hpp"

namespace ldimesh {

enum class FaceType { triangles, quads };

struct MeshingOptions {
  double r = 0.5;  // §3 trimming parameter in [0, 1]; the paper's recommended trade-off
  FaceType faces = FaceType::triangles;
  MatchOptions matching;
};

struct MeshingTimes {
  double match = 0.0;     // best matches and quads (§3)
  double trim = 0.0;      // trimming (§3)
  double assemble = 0.0;  // vertices, triangle split, output arrays
};

struct MeshingResult {
  Mesh mesh;
  std::size_t samples = 0;          // samples in all LDIs
  std::size_t quads_untrimmed = 0;  // quads before trimming
  std::size_t quads = 0;            // quads after trimming
  MeshingTimes seconds;
};

// Meshes each LDI (§3), trims against the directions of all of them with options.r, and
// assembles one mesh: vertices are the samples used by a kept face (one vertex per sample,
// shared by the faces of its view), faces are quads or triangles (each quad split along its
// shorter diagonal). Throws std::invalid_argument if r is outside [0, 1] or more than 255 views.
MeshingResult mesh_ldis(std::span<const Ldi> ldis, const MeshingOptions& options = {});

}  // namespace ldimesh

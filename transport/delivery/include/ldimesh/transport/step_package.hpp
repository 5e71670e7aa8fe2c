// A step as it is published, packaged once for the in situ adaptor and the command line
// (`ldimesh mesh --out X.glb`, `--steps-dir`): the root's isosurfaces joined into one mesh, the
// vertices without a finite colour value given their field's lowest colour, the GLB, and the
// step's metadata.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/base/view.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh {

// What describes a step besides its meshes.
struct StepDescription {
  std::uint64_t step = 0;
  double time = 0.0;
  std::vector<double> isovalues;  // one per meshing result
  std::vector<View> views;        // the step's views (the first sets the GLB's position grid)
  double r = 0.5;                 // the trimming parameter used (trim_r)
  // The colour fields' names, and each isosurface's field: surface_field[i] indexes
  // colour_fields, −1 for none. Empty surface_field: every surface by colour_fields[0] if any.
  std::vector<std::string> colour_fields;
  std::vector<int> surface_field;
  StepGlbSettings glb;
  bool encode = true;  // false: only the joined mesh (a PLY or OBJ to write), no GLB
};

// One isosurface of the step as the root meshed it (MeshingResult's mesh and counts): the
// packaging needs nothing else of the meshing, so the delivery side does not depend on core.
struct StepSurface {
  Mesh mesh;
  std::size_t samples = 0;  // samples in all LDIs
  std::size_t quads = 0;    // quads after trimming
};

struct PackagedStep {
  Mesh mesh;  // the isosurfaces joined, in isovalue order, the colour values repaired
  std::vector<std::uint8_t> glb;
  GlbInfo info;
  // describe_step's counts, the colour ranges and seconds["glb"]; the caller adds its own
  // seconds and in situ counters before make_snapshot.
  StepMetadata metadata;
  std::size_t uncoloured = 0;  // vertices given their field's lowest colour (not finite)
  double glb_seconds = 0.0;
};

// Joins `surfaces` (one per isovalue) and, with `description.encode`, encodes the GLB and
// describes the step. Several isovalues become one mesh each in the GLB (GlbOptions::surfaces);
// where the surfaces are not all coloured by one field, each field gets its own range
// (GlbOptions::scalar_groups, StepMetadata::surface_scalars), and a surface without a field
// beside coloured ones carries values the GLB leaves out. Errors: encode_glb's.
Status package_step(const StepDescription& description, std::vector<StepSurface> surfaces,
                    PackagedStep& out);

// Of the surfaces starting at vertices `surfaces` (empty: one surface) each coloured by field
// `groups[s]` (−1: none), the vertices without a finite colour take the lowest finite value of
// their field on the step's surfaces (0 where there is none); returns how many did.
std::size_t replace_nonfinite_colours(Mesh& mesh, const std::vector<std::uint32_t>& surfaces,
                                      const std::vector<int>& groups);

}  // namespace ldimesh

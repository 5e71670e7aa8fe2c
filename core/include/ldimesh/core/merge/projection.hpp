// Moving points onto the isosurface after the LDIs are taken: merging (§5) puts new vertices in
// the sewing region and smooths, and those vertices belong on the surface, not on the flat
// bridges and fill triangles between samples. The surface is asked through the same sample
// source refinement uses (the local ray caster in one process, the MPI round trip in a parallel
// run), so this works on the root without the field.
#pragma once

#include <cstddef>
#include <functional>
#include <span>
#include <vector>

#include "ldimesh/core/base/view.hpp"
#include "ldimesh/core/raycast/sample_source.hpp"

namespace ldimesh {

// Moves each points[i] (with the normal estimate normals[i]) onto the surface and sets
// normals[i] to the surface normal there; a point for which no surface lies within `reach`
// (world units) stays as it is. Returns how many points moved. One call is one batch (one
// round trip to the ray casters).
using SurfaceProjection = std::function<std::size_t(
    std::vector<glm::dvec3>& points, std::vector<glm::dvec3>& normals, double reach)>;

// A SurfaceProjection from extension samples: each point is moved along the axis of the view
// whose direction is closest to its normal, to the nearest hit of that view's ray through it
// within ± reach whose normal faces the same way as the estimate (positive dot product).
// `samples` and `views` must outlive the returned function; it calls samples.sample() once per
// call, so it is used one call at a time (as the source is) and passes on what sample() throws.
SurfaceProjection sample_projection(SampleSource& samples, std::span<const View> views);

}  // namespace ldimesh

// Metro-style distances between two meshes, and from a mesh to an implicit surface (a built-in
// analytic one, or any field given as a function: the polynomials of high-order data).
//
// After Cignoni, Rocchini and Scopigno, "Metro: measuring error on simplified surfaces",
// Computer Graphics Forum 17(2), 1998: the surface of one mesh is sampled (its vertices, points
// on its edges, points on its faces in proportion to their area) and each sample's distance to
// the closest point of the other mesh, or of the implicit surface, is measured. The method and
// its choices are in docs/method.md, "Distances".
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <string>

#include <glm/glm.hpp>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/field/surfaces.hpp"

namespace ldimesh {

struct DistanceOptions {
  // Samples of each sampled mesh, a target: every vertex that a face uses is a sample, points
  // on edges and on faces share the rest 1 : 3 (so the count is at least the vertex count).
  // 0: ten per triangle of the larger mesh (of the mesh, for surface_distance; a quad counts as
  // two triangles).
  std::uint64_t samples = 0;
};

// Where the samples of a mesh lie.
struct SampleCounts {
  std::uint64_t vertices = 0;
  std::uint64_t edges = 0;  // inside edges, in proportion to their length
  std::uint64_t faces = 0;  // inside faces, in proportion to their area
  std::uint64_t total() const { return vertices + edges + faces; }
};

// The distances of the samples of one mesh: mean, root mean square and maximum over the
// samples (absolute; divide by a diagonal for relative figures).
struct DistanceStats {
  SampleCounts samples;
  double mean = 0.0;
  double rms = 0.0;
  double max = 0.0;
  glm::dvec3 max_at{0.0};  // the first sample (in sample order) at the largest distance
};

struct MeshDistance {
  DistanceStats forward;   // samples of A, distance to the closest point of B
  DistanceStats backward;  // samples of B, distance to the closest point of A
  double diagonal = 0.0;   // of the bounding box of A ∪ B
  // The symmetric (sampled Hausdorff) distance.
  double max() const { return std::max(forward.max, backward.max); }
};

// Forward (A → B) and backward (B → A) distances between two meshes of triangles and/or quads
// (quads split into two triangles along the shorter diagonal). Closest points are exact
// point–triangle distances in double over an Embree BVH of the other mesh; distances below
// 2⁻⁴⁰ times the largest coordinate (rounding noise, far below what float vertices resolve)
// are 0, so a mesh is at distance 0 from itself. Uses all threads the caller allows (oneTBB);
// the figures are the same, to the bit, for any number of threads. Throws
// std::invalid_argument for a mesh without faces, a face index out of range or a non-finite
// vertex position, std::runtime_error if Embree fails.
MeshDistance mesh_distance(const Mesh& a, const Mesh& b, const DistanceOptions& options = {});

struct SurfaceDistance {
  DistanceStats forward;            // the samples measured: mesh → surface
  std::uint64_t not_converged = 0;  // samples left out: the projection did not converge
  std::uint64_t outside_clip = 0;   // samples left out: their closest surface point lies
                                    // outside the region the surface is clipped to
  double diagonal = 0.0;            // of the mesh's bounding box
};

// Distances of the samples of `mesh` to the surface field = isovalue of the built-in `surface`:
// each sample is projected onto the surface by Newton steps along the gradient, then slid along
// it until the offset is normal to the surface (the foot point). The surface is the part inside
// `surface.domain` and, where `surface.clip_radius` > 0, inside that ball (what the ray caster
// meshes); a sample whose foot point lies outside is counted in outside_clip, one whose
// projection fails (a vanishing gradient, no convergence) in not_converged, both left out of the
// statistics. Threads and determinism as mesh_distance; throws as mesh_distance.
SurfaceDistance surface_distance(const Mesh& mesh, const SurfaceInfo& surface, double isovalue,
                                 const DistanceOptions& options = {});

// The surface field = isovalue of any field: `field` returns its value at p and its gradient
// into `gradient`, or NaN where it is not defined (outside the data: a sample whose projection
// leaves the data counts as not converged; the gradient is not read then). Called from several
// threads at once. Throws std::invalid_argument without a field or for an empty domain.
struct ImplicitSurface {
  std::string name;
  std::function<double(const glm::dvec3& p, glm::dvec3& gradient)> field;
  Box domain;                // the part of the surface measured, as SurfaceInfo::domain
  double clip_radius = 0.0;  // > 0: and inside this ball around the origin
};
SurfaceDistance surface_distance(const Mesh& mesh, const ImplicitSurface& surface, double isovalue,
                                 const DistanceOptions& options = {});

}  // namespace ldimesh

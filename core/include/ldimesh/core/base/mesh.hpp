// Polygon meshes as the pipeline produces them.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/status.hpp"

namespace ldimesh {

// Vertices with a unit normal each; faces as quads and/or triangles, wound counter-clockwise
// when seen from the side the vertex normals point to; per face the index of the view it came
// from. `view_dirs[k]` is the direction of view k.
struct Mesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;
  std::vector<float> scalars;            // empty, or one value per vertex (a field to colour by)
  std::vector<std::uint32_t> quads;      // 4 vertex indices per quad
  std::vector<std::uint32_t> triangles;  // 3 vertex indices per triangle
  std::vector<std::uint8_t> quad_view;
  std::vector<std::uint8_t> triangle_view;
  std::vector<glm::dvec3> view_dirs;

  std::size_t vertex_count() const { return positions.size(); }
  std::size_t quad_count() const { return quads.size() / 4; }
  std::size_t triangle_count() const { return triangles.size() / 3; }
  std::size_t face_count() const { return quad_count() + triangle_count(); }
};

// What check_mesh tests beyond the structure every stage needs.
struct MeshChecks {
  bool views_per_face = false;    // quad_view and triangle_view one per face (else also empty)
  bool distinct_corners = false;  // no face with a repeated vertex
  bool finite = false;            // positions, normals and scalars finite
};

// Whether `m` is well formed, the one check of meshes a stage is given (merging, quad
// conversion, the GLB encoder): normals, and scalars if any, one per vertex; whole quads and
// triangles; quad_view and triangle_view empty or one per face; face indices below the vertex
// count; and what `checks` asks for. An invalid_argument Status saying what is wrong (callers
// prefix their name), else ok. O(vertices + faces); no allocation.
Status check_mesh(const Mesh& m, const MeshChecks& checks = {});

// Replaces the scalars that are not finite (a colour field with NaN/Inf values at a vertex) by
// the smallest finite one (0 when there is none), so that the mesh can be encoded; returns how
// many were replaced.
std::size_t replace_nonfinite_scalars(Mesh& m);
// The same over the values of `parts` together (the surfaces of one field in a mesh of several:
// the smallest finite value of all of them).
std::size_t replace_nonfinite_scalars(std::span<const std::span<float>> parts);

// Appends `b` to `a` (several surfaces in one mesh, e.g. a step's isovalues): b's vertices after
// a's, its faces renumbered, with their views; a takes b's view directions where it has none.
// Scalars are appended as they are (both meshes with them or both without keeps them one per
// vertex).
void append_mesh(Mesh& a, const Mesh& b);

// Appends the two triangles of quad v[0..3] to `triangles`: split along the shorter diagonal
// (ties take v0–v2), which cuts the obtuse corners of a skewed quad. The one rule of the mesher's
// triangle output, the GLB encoder and the distance sampler, so all see the same triangles.
inline void append_quad_triangles(const std::vector<glm::vec3>& positions, const std::uint32_t* v,
                                  std::vector<std::uint32_t>& triangles) {
  const auto dist2 = [&](int a, int b) {
    const glm::dvec3 d = glm::dvec3(positions[v[a]]) - glm::dvec3(positions[v[b]]);
    return glm::dot(d, d);
  };
  if (dist2(0, 2) <= dist2(1, 3))
    triangles.insert(triangles.end(), {v[0], v[1], v[2], v[0], v[2], v[3]});
  else
    triangles.insert(triangles.end(), {v[0], v[1], v[3], v[1], v[2], v[3]});
}

}  // namespace ldimesh

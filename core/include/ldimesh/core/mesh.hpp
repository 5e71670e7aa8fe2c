// Polygon meshes as the pipeline produces them.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

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

}  // namespace ldimesh

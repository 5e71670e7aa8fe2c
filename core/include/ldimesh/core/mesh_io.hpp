// Writing meshes for other tools: binary PLY and Wavefront OBJ.
#pragma once

#include <string>

#include "ldimesh/core/mesh.hpp"
#include "ldimesh/core/status.hpp"

namespace ldimesh {

// Binary little-endian PLY: vertex x y z nx ny nz (float), face vertex_indices (uchar count,
// uint indices) and view (uchar); one `comment view k dir x y z` line per view. Quads first,
// then triangles. Same mesh, same bytes.
Status write_ply(const std::string& path, const Mesh& mesh);

// OBJ with `v`, `vn` and `f a//a …` lines and one group `view_k` per run of faces of view k.
Status write_obj(const std::string& path, const Mesh& mesh);

// write_ply or write_obj by the extension of `path` (.ply or .obj, any case); an error for any
// other extension or a file that cannot be written.
Status write_mesh(const std::string& path, const Mesh& mesh);

}  // namespace ldimesh

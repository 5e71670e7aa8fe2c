// Writing meshes for other tools (binary PLY, Wavefront OBJ) and reading PLY back.
//
// Errors (Status codes): a mesh that fails check_mesh is invalid_argument (nothing is written);
// a file that cannot be opened, written or read is io; a PLY that is malformed, truncated or
// inconsistent is corrupt_input; an unknown extension is invalid_argument. Every function is
// reentrant (no shared state): calls on different files may run on any threads at once.
#pragma once

#include <string>
#include <string_view>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/base/status.hpp"

namespace ldimesh {

// Binary little-endian PLY: vertex x y z nx ny nz (float) and, when the mesh has scalars (a field
// to colour by), value (float), face vertex_indices (uchar count,
// uint indices) and view (uchar, 0 where the mesh has no views); one `comment view k dir x y z`
// line per view. Quads first, then triangles. Same mesh, same bytes.
Status write_ply(const std::string& path, const Mesh& mesh);

// OBJ with `v`, `vn` and `f a//a …` lines and one group `view_k` per run of faces of view k.
Status write_obj(const std::string& path, const Mesh& mesh);

// write_ply or write_obj by the extension of `path` (.ply or .obj, any case); an error for any
// other extension or a file that cannot be written.
Status write_mesh(const std::string& path, const Mesh& mesh);

// Reads a PLY file: ASCII, binary little- or big-endian; any property types. Needs a `vertex`
// element with x, y, z (nx, ny, nz optional: without them each vertex gets the area-weighted
// normal of its faces; a float `value`, when there, becomes the scalars) and takes faces from the
// list property `vertex_indices` (or `vertex_index`) of a `face` element: 3 indices a triangle, 4 a
// quad, more a fan of triangles. A face property `view` and `comment view k dir x y z` lines are
// read as write_ply writes them (views 0 without). Other elements and properties are skipped.
// Everything is checked against the header and the file's size (a truncated or hostile file, an
// index out of range, a non-finite coordinate or a face of fewer than 3 vertices is an error, never
// a crash); on error `mesh` is left empty.
Status read_ply(const std::string& path, Mesh& mesh);

// The same from the bytes of a PLY file in memory.
Status parse_ply(std::string_view bytes, Mesh& mesh);

}  // namespace ldimesh

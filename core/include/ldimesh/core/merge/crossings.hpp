// Faces that pass through each other, and undoing the vertex moves that made them. Merging and
// the conversion to quads move vertices onto the surface with samples (projection.hpp) and
// smooth them; where two sheets of the surface are a cell or two apart (Barth's conical double
// points) such a move can push a face through the other sheet. Both undo those moves with this,
// on the flat output mesh (one pass over plain arrays per round).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/base/mesh.hpp"

namespace ldimesh {

// A face's corners (at most 4: meshes hold triangles and quads) with their vertex ids.
struct CrossingPolygon {
  std::array<glm::dvec3, 4> p;
  std::array<std::uint32_t, 4> v;
  std::size_t n = 0;
};

// Whether a and b pass through each other: an edge of a triangle of one crosses a triangle of
// the other strictly inside both, for two triangles that share no vertex (neighbouring faces
// count too, through their other triangles: a face folded over its neighbour). A quad (not
// necessarily planar) counts as both its splits, (0, 1, 2) + (0, 2, 3) and (1, 2, 3) +
// (1, 3, 0). A face never crosses itself.
bool polygons_cross(const CrossingPolygon& a, const CrossingPolygon& b);

// A vertex that was moved, and where it was before (position and normal).
struct VertexMove {
  std::uint32_t vertex = 0;
  glm::vec3 position{0.0f}, normal{0.0f};
};

// Keeps the moves of the vertices `index` keeps (old → new vertex index; UINT32_MAX: dropped),
// in order, with their new indices: a mesh builder's moves for its output mesh. In place; never
// throws; moves whose vertex lies beyond `index` are dropped too. Deterministic.
void renumber_moves(std::vector<VertexMove>& moves, std::span<const std::uint32_t> index);

// Puts moved vertices back where they were when one of their faces crosses another face of the
// mesh (a vertex listed more than once goes back to its first entry). Moves shorter than `min_move`
// are left alone (their faces sweep no farther than that: they can only meet a face that was
// already that close; where faces are that close, as a smoothed face and its neighbour, even
// tiny moves matter; docs/method.md has the figures). The faces around the vertices to check (at
// first every moved one checked) go into a hash grid of `cell`-sized cells (any size finds the
// same crossings; about an edge is the cheapest), every face is tested against those in the cells
// of its box, and each still-moved vertex of a crossing pair is put back. Rounds repeat with the
// faces of the vertices put back (in their old places they can meet a face a moved neighbour made)
// while any is put back, at most `max_rounds`. Returns the number of vertices put back. Throws
// std::invalid_argument for a vertex index out of range or a cell size that is not positive.
// Deterministic: the faces are tested in parallel, with the same result for any number of threads.
std::size_t undo_crossing_moves(Mesh& mesh, std::span<const VertexMove> moves, double cell,
                                double min_move = 0.0, int max_rounds = 4);

}  // namespace ldimesh

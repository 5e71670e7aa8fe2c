// gmsh's node numbering of its reference elements (the MSH format's order), built for any order
// from the rule gmsh follows — vertices, then each edge's interior nodes (gmsh's edge table, from
// the edge's first vertex to its second), then each face's interior nodes (gmsh's face table; a
// triangle or quadrilateral of lower order numbered by the same rule, spanned from the face's
// first vertex along its second and last), then the interior (a cell of lower order one step
// in, numbered by the same rule) — and matched
// against VTK's numbering by position. tests/core/field/gmsh_order_test.cpp checks every order
// against gmsh's own library.
#include <array>
#include <cmath>
#include <map>
#include <vector>

#include "reference_cells.hpp"

namespace ldimesh {
namespace {

using Lattice = glm::ivec3;  // a node's position times the order, on gmsh's lattice

// gmsh's line of `order`: its ends, then the interior from the first: 0, p, 1, …, p − 1.
std::vector<int> gmsh_line(int order) {
  std::vector<int> out = {0};
  if (order == 0) return out;
  out.push_back(order);
  for (int i = 1; i < order; ++i)
    out.push_back(i);
  return out;
}

// A face's (or the whole 2D cell's) nodes: a triangle (vertices (0,0), (p,0), (0,p)) or a
// quadrilateral (vertices (0,0), (p,0), (p,p), (0,p)) of `order`, in gmsh's numbering, as (u, v).
std::vector<glm::ivec2> gmsh_polygon(bool quad, int order) {
  std::vector<glm::ivec2> out;
  if (order < 0) return out;
  if (order == 0) return {glm::ivec2(0)};
  const std::vector<glm::ivec2> v =
      quad ? std::vector<glm::ivec2>{{0, 0}, {order, 0}, {order, order}, {0, order}}
           : std::vector<glm::ivec2>{{0, 0}, {order, 0}, {0, order}};
  out = v;
  const int n = int(v.size());
  for (int e = 0; e < n; ++e) {
    const glm::ivec2 a = v[e], step = (v[(e + 1) % n] - a) / order;
    for (int i = 1; i < order; ++i)
      out.push_back(a + i * step);
  }
  for (const glm::ivec2 inner : gmsh_polygon(quad, order - (quad ? 2 : 3)))
    out.push_back(inner + 1);
  return out;
}

struct Shape {
  std::vector<Lattice> vertices;          // at order 1
  std::vector<std::array<int, 2>> edges;  // gmsh's edge table
  std::vector<std::array<int, 4>> faces;  // gmsh's face table (−1: a triangle)
};

// gmsh's reference elements (MTetrahedron, MPrism, MHexahedron): vertices on the unit lattice
// and their edge and face tables.
const Shape& shape(CellType type) {
  static const Shape tetrahedron{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}},
                                 {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}},
                                 {{0, 2, 1, -1}, {0, 1, 3, -1}, {0, 3, 2, -1}, {3, 1, 2, -1}}};
  static const Shape prism{
      {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {0, 1, 1}},
      {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 4}, {2, 5}, {3, 4}, {3, 5}, {4, 5}},
      {{0, 2, 1, -1}, {3, 4, 5, -1}, {0, 1, 4, 3}, {0, 3, 5, 2}, {1, 2, 5, 4}}};
  static const Shape hexahedron{
      {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}},
      {{0, 1},
       {0, 3},
       {0, 4},
       {1, 2},
       {1, 5},
       {2, 3},
       {2, 6},
       {3, 7},
       {4, 5},
       {4, 7},
       {5, 6},
       {6, 7}},
      {{0, 3, 2, 1}, {0, 1, 5, 4}, {0, 4, 7, 3}, {1, 2, 6, 5}, {2, 3, 7, 6}, {4, 5, 6, 7}}};
  switch (type) {
    case CellType::tetrahedron:
      return tetrahedron;
    case CellType::wedge:
    case CellType::serendipity_wedge:
      return prism;
    default:
      return hexahedron;
  }
}

// The nodes of a tetrahedron, prism or hexahedron of `order` in gmsh's numbering; `serendip`:
// vertices and edges only.
std::vector<Lattice> gmsh_nodes(CellType type, int order, bool serendip) {
  if (order == 0) return {Lattice(0)};
  const Shape& s = shape(type);
  std::vector<Lattice> out;
  for (const Lattice& v : s.vertices)
    out.push_back(order * v);
  const std::vector<Lattice> vertex(out);
  for (const auto& e : s.edges) {
    const Lattice a = vertex[e[0]], step = (vertex[e[1]] - a) / order;
    for (int i = 1; i < order; ++i)
      out.push_back(a + i * step);
  }
  if (serendip) return out;
  for (const auto& f : s.faces) {
    const bool quad = f[3] >= 0;
    const Lattice a = vertex[f[0]], u = (vertex[f[1]] - a) / order,
                  v = (vertex[quad ? f[3] : f[2]] - a) / order;
    for (const glm::ivec2 q : gmsh_polygon(quad, order - (quad ? 2 : 3)))
      out.push_back(a + (q.x + 1) * u + (q.y + 1) * v);
  }
  if (type == CellType::tetrahedron) {
    if (order >= 4)
      for (const Lattice& inner : gmsh_nodes(type, order - 4, false))
        out.push_back(inner + 1);
  } else if (type == CellType::wedge) {
    if (order >= 3)
      for (const glm::ivec2 t : gmsh_polygon(false, order - 3))
        for (const int k : gmsh_line(order - 2))
          out.push_back(Lattice(t.x + 1, t.y + 1, k + 1));
  } else if (order >= 2) {
    for (const Lattice& inner : gmsh_nodes(type, order - 2, false))
      out.push_back(inner + 1);
  }
  return out;
}

}  // namespace

std::vector<int> cell_gmsh_permutation(CellType type, int order) {
  // VTK's node i is gmsh's node perm[i].
  if (type == CellType::pyramid) {
    // gmsh's 5- and 13-node pyramids.
    if (order == 1) return {0, 1, 2, 3, 4};
    if (order == 2) return {0, 1, 2, 3, 4, 5, 8, 10, 6, 7, 9, 11, 12};
    return {};
  }
  if (type == CellType::pyramid14)  // the 13-node pyramid's, then the base's centre (gmsh's 13)
    return order == 2 ? std::vector<int>{0, 1, 2, 3, 4, 5, 8, 10, 6, 7, 9, 11, 12, 13}
                      : std::vector<int>{};
  if (cell_nodes(type, order) == 0) return {};
  // gmsh's own library describes no prism above order 2 ("FaceClosureFull not implemented for
  // prisms of order 3", gmsh 4.8): not taken.
  if (type == CellType::wedge && order > 2) return {};
  const bool serendip =
      type == CellType::serendipity_hexahedron || type == CellType::serendipity_wedge;
  const std::vector<glm::dvec3> vtk = cell_reference_nodes(type, order);
  const std::vector<Lattice> gmsh = gmsh_nodes(type, order, serendip);
  // Both on the lattice of the order: VTK's tetrahedron and prism triangle are gmsh's, and VTK's
  // [0, 1] axes are gmsh's [−1, 1] ones (prism height, hexahedron) scaled.
  std::map<std::array<int, 3>, int> index;
  for (std::size_t j = 0; j < gmsh.size(); ++j)
    index[{gmsh[j].x, gmsh[j].y, gmsh[j].z}] = int(j);
  std::vector<int> perm;
  for (const glm::dvec3& r : vtk) {
    const glm::dvec3 l = r * double(order);
    const auto found =
        index.find({int(std::lround(l.x)), int(std::lround(l.y)), int(std::lround(l.z))});
    if (found == index.end() || gmsh.size() != vtk.size()) return {};
    perm.push_back(found->second);
  }
  return perm;
}

}  // namespace ldimesh

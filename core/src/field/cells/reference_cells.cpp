#include "reference_cells.hpp"

#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>

namespace ldimesh::cells {
namespace {

using Lattice = glm::ivec3;  // a node's position times the order

// ---------------------------------------------------------------------------------------------
// Node orders (VTK's numbering; checked against VTK's own parametric coordinates in the tests)

// A triangle of `order` in VTK's recursive numbering, its corner at `o` and steps e1, e2 along
// its first and second edges: the vertices o, o + order·e1, o + order·e2; each edge's interior
// nodes from its first vertex to its second (0 → 1, 1 → 2, 2 → 0); then the interior, a triangle
// of order − 3 one step in, numbered the same way. Order 0 is the one node o.
void triangle_nodes(Lattice o, Lattice e1, Lattice e2, int order, std::vector<Lattice>& out) {
  if (order < 0) return;
  if (order == 0) {
    out.push_back(o);
    return;
  }
  const Lattice v[3] = {o, o + order * e1, o + order * e2};
  out.insert(out.end(), {v[0], v[1], v[2]});
  for (int edge = 0; edge < 3; ++edge) {
    const Lattice a = v[edge], step = (v[(edge + 1) % 3] - a) / order;
    for (int k = 1; k < order; ++k)
      out.push_back(a + k * step);
  }
  triangle_nodes(o + e1 + e2, e1, e2, order - 3, out);
}

// A tetrahedron of `order` in VTK's recursive numbering (vtkLagrangeTetra): vertices, the six
// edges 0–1, 1–2, 2–0, 0–3, 1–3, 2–3 (each from its first vertex), the four faces (0, 1, 3),
// (2, 3, 1), (0, 3, 2), (0, 2, 1) as triangles of order − 3 whose numbering starts at the face's
// first vertex, then the interior: a tetrahedron of order − 4 one step in.
void tetrahedron_nodes(Lattice o, int order, std::vector<Lattice>& out) {
  if (order < 0) return;
  if (order == 0) {
    out.push_back(o);
    return;
  }
  const Lattice v[4] = {o, o + Lattice(order, 0, 0), o + Lattice(0, order, 0),
                        o + Lattice(0, 0, order)};
  out.insert(out.end(), {v[0], v[1], v[2], v[3]});
  constexpr int edges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  for (const auto& e : edges) {
    const Lattice step = (v[e[1]] - v[e[0]]) / order;
    for (int k = 1; k < order; ++k)
      out.push_back(v[e[0]] + k * step);
  }
  constexpr int faces[4][3] = {{0, 1, 3}, {2, 3, 1}, {0, 3, 2}, {0, 2, 1}};
  for (const auto& f : faces) {
    const Lattice e1 = (v[f[1]] - v[f[0]]) / order, e2 = (v[f[2]] - v[f[0]]) / order;
    triangle_nodes(v[f[0]] + e1 + e2, e1, e2, order - 3, out);
  }
  tetrahedron_nodes(o + Lattice(1, 1, 1), order - 4, out);
}

// A wedge of `order` in VTK's numbering (vtkLagrangeWedge): the six vertices (the triangle at
// t = 0, then at t = 1); the edges of the bottom triangle (0–1, 1–2, 2–0), of the top one, then
// the vertical ones (0–3, 1–4, 2–5); the interiors of the bottom and the top triangle (row by
// row, r fastest: unlike the tetrahedron's faces, not recursive); the three quadrilateral faces
// along the edges 0–1, 1–2 and 2–0, each with the edge's direction fastest, then t; then the
// interior: the triangle's interior fastest, then t.
std::vector<Lattice> wedge_nodes(int p) {
  std::vector<Lattice> out;
  const Lattice tri[3] = {{0, 0, 0}, {p, 0, 0}, {0, p, 0}};
  const Lattice up(0, 0, p);
  for (int level = 0; level < 2; ++level)
    for (const Lattice& v : tri)
      out.push_back(v + level * up);
  for (int level = 0; level < 2; ++level)
    for (int edge = 0; edge < 3; ++edge) {
      const Lattice a = tri[edge], step = (tri[(edge + 1) % 3] - a) / p;
      for (int k = 1; k < p; ++k)
        out.push_back(a + k * step + level * up);
    }
  for (const Lattice& v : tri)
    for (int k = 1; k < p; ++k)
      out.push_back(v + Lattice(0, 0, k));
  std::vector<Lattice> inner;  // the triangle's interior nodes, row by row (not recursive)
  for (int j = 1; j <= p - 2; ++j)
    for (int i = 1; i <= p - 1 - j; ++i)
      inner.emplace_back(i, j, 0);
  for (int level = 0; level < 2; ++level)
    for (const Lattice& v : inner)
      out.push_back(v + level * up);
  for (int edge = 0; edge < 3; ++edge) {
    const Lattice a = tri[edge], step = (tri[(edge + 1) % 3] - a) / p;
    for (int k = 1; k < p; ++k)
      for (int i = 1; i < p; ++i)
        out.push_back(a + i * step + Lattice(0, 0, k));
  }
  for (int k = 1; k < p; ++k)
    for (const Lattice& v : inner)
      out.push_back(v + Lattice(0, 0, k));
  return out;
}

std::vector<Lattice> hexahedron_nodes(int p) {
  std::vector<Lattice> out(std::size_t(p + 1) * (p + 1) * (p + 1));
  for (int k = 0; k <= p; ++k)
    for (int j = 0; j <= p; ++j)
      for (int i = 0; i <= p; ++i)
        out[vtk_lagrange_index(i, j, k, p)] = Lattice(i, j, k);
  return out;
}

// The pyramid's nodes: base corners, apex, then the base's edges' midpoints (0–1, 1–2, 2–3, 3–0)
// and the slanted edges' (0–4, 1–4, 2–4, 3–4), at VTK's parametric coordinates (the slanted
// edges' midpoints at t = ½ above their base corner: the reference cube's top is the apex).
std::vector<Lattice> pyramid_nodes(int p) {
  std::vector<Lattice> out = {{0, 0, 0}, {p, 0, 0}, {p, p, 0}, {0, p, 0}, {0, 0, p}};
  if (p == 2)
    out.insert(
        out.end(),
        {{1, 0, 0}, {2, 1, 0}, {1, 2, 0}, {0, 1, 0}, {0, 0, 1}, {2, 0, 1}, {2, 2, 1}, {0, 2, 1}});
  return out;
}

// VTK_QUADRATIC_PYRAMID's 13 shape functions (VTK 9.1, vtkQuadraticPyramid), each as its
// coefficients of r^a s^b t^c, a fastest, a, b, c ≤ 2 — measured from VTK's own evaluation
// (polynomials of degree 2 per variable; the tests compare with VTK at random points).
constexpr int kQuadraticPyramid[13][27] = {
    {1,  -3, 2,  -3, 5, -2, 2, -2, 0,  -3,  7, -4,  7, -19,
     12, -4, 12, -8, 2, -4, 2, -4, 14, -10, 2, -10, 8},
    {0, -1, 2, 0, -1, -2, 0, 2, 0, 0, 1, -4, 0, -5, 12, 0, 4, -8, 0, 0, 2, 0, 6, -10, 0, -6, 8},
    {0, 0, 0, 0, -3, 2, 0, 2, 0, 0, 0, 0, 0, -3, 4, 0, 4, -8, 0, 0, 0, 0, 6, -6, 0, -6, 8},
    {0, 0, 0, -1, -1, 2, 2, -2, 0, 0, 0, 0, 1, -5, 4, -4, 12, -8, 0, 0, 0, 0, 6, -6, 2, -10, 8},
    {0, 0, 0, 0, 0, 0, 0, 0, 0, -1, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0},
    {0, 4, -4, 0, -4, 4, 0, 0, 0, 0, -8, 8, 0, 16, -16, 0, -8, 8, 0, 4, -4, 0, -12, 12, 0, 8, -8},
    {0, 0, 0, 0, 4, 0, 0, -4, 0, 0, 0, 0, 0, 0, -8, 0, 0, 8, 0, 0, 0, 0, -4, 8, 0, 4, -8},
    {0, 0, 0, 0, 4, -4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, -8, 8, 0, 0, 0, 0, -4, 4, 0, 8, -8},
    {0, 0, 0, 4, -4, 0, -4, 4, 0, 0, 0, 0, -8, 16, -8, 8, -16, 8, 0, 0, 0, 4, -12, 8, -4, 12, -8},
    {0, 0, 0, 0, 0, 0, 0, 0, 0, 4, -4, 0, -4, 4, 0, 0, 0, 0, -4, 4, 0, 4, -4, 0, 0, 0, 0},
    {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, 0, 0, -4, 0, 0, 0, 0, 0, -4, 0, 0, 4, 0, 0, 0, 0},
    {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, -4, 0, 0, 0, 0},
    {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, -4, 0, 0, 0, 0, 0, 0, 0, -4, 4, 0, 0, 0, 0},
};

// The 14-node pyramid's space (gmsh's complete quadratic pyramid, Bergot's): in gmsh's
// coordinates x = (2r − 1)(1 − t), y = (2s − 1)(1 − t), z = t, the monomials of P₂ and
// q·{1, x, y}, q² with q = xy/(1 − z) = (2r − 1)(2s − 1)(1 − t) — polynomials of degree ≤ 2 per
// variable in (r, s, t), defined at the apex too.
void pyramid14_space(glm::dvec3 r, double* g) {
  const double a = 2.0 * r.x - 1.0, b = 2.0 * r.y - 1.0, m = 1.0 - r.z;
  const double x = a * m, y = b * m, z = r.z, q = a * b * m;
  const double out[14] = {1.0,   x,     y,     z, x * x, y * y, z * z,
                          x * y, x * z, y * z, q, q * x, q * y, q * q};
  std::copy(out, out + 14, g);
}

// ---------------------------------------------------------------------------------------------
// Nodal bases

// The equispaced Lagrange factor Π_{k<a} (p x − k) / (k + 1): 1 at x = a/p, 0 at x = k/p for
// k < a (the simplex families' basis is a product of these over barycentric coordinates).
double lagrange_factor(int p, int a, double x) {
  double f = 1.0;
  for (int k = 0; k < a; ++k)
    f *= (p * x - k) / (k + 1);
  return f;
}

// The 1-D equispaced Lagrange polynomial of node i at x.
double lagrange_1d(int p, int i, double x) {
  double f = 1.0;
  for (int k = 0; k <= p; ++k)
    if (k != i) f *= (p * x - k) / (i - k);
  return f;
}

// The serendipity spaces' monomials r^a s^b t^c: the 20-node hexahedron's (exponents ≤ 2, at most
// one of them 2) and the 15-node wedge's (a + b ≤ 2 and c ≤ 1, and t², rt², st²).
std::vector<Lattice> serendipity_monomials(CellType type) {
  std::vector<Lattice> m;
  if (type == CellType::serendipity_hexahedron) {
    for (int c = 0; c <= 2; ++c)
      for (int b = 0; b <= 2; ++b)
        for (int a = 0; a <= 2; ++a)
          if ((a == 2) + (b == 2) + (c == 2) <= 1) m.emplace_back(a, b, c);
  } else {
    for (int c = 0; c <= 1; ++c)
      for (int b = 0; b <= 2; ++b)
        for (int a = 0; a + b <= 2; ++a)
          m.emplace_back(a, b, c);
    m.insert(m.end(), {{0, 0, 2}, {1, 0, 2}, {0, 1, 2}});
  }
  return m;
}

double monomial(Lattice e, glm::dvec3 r) {
  return std::pow(r.x, e.x) * std::pow(r.y, e.y) * std::pow(r.z, e.z);
}

// The inverse of the n × n matrix a (row-major) by Gauss–Jordan elimination with partial
// pivoting; throws where it is singular (a node set that does not determine the space).
std::vector<double> invert(std::vector<double> a, int n) {
  std::vector<double> inv(std::size_t(n) * n, 0.0);
  for (int i = 0; i < n; ++i)
    inv[std::size_t(i) * n + i] = 1.0;
  for (int col = 0; col < n; ++col) {
    int pivot = col;
    for (int r = col + 1; r < n; ++r)
      if (std::abs(a[std::size_t(r) * n + col]) > std::abs(a[std::size_t(pivot) * n + col]))
        pivot = r;
    if (!(std::abs(a[std::size_t(pivot) * n + col]) > 1e-12))
      throw std::logic_error("reference cell: singular nodal matrix");
    for (int k = 0; k < n; ++k) {
      std::swap(a[std::size_t(col) * n + k], a[std::size_t(pivot) * n + k]);
      std::swap(inv[std::size_t(col) * n + k], inv[std::size_t(pivot) * n + k]);
    }
    const double d = a[std::size_t(col) * n + col];
    for (int k = 0; k < n; ++k)
      a[std::size_t(col) * n + k] /= d, inv[std::size_t(col) * n + k] /= d;
    for (int r = 0; r < n; ++r) {
      if (r == col) continue;
      const double f = a[std::size_t(r) * n + col];
      if (f == 0.0) continue;
      for (int k = 0; k < n; ++k) {
        a[std::size_t(r) * n + k] -= f * a[std::size_t(col) * n + k];
        inv[std::size_t(r) * n + k] -= f * inv[std::size_t(col) * n + k];
      }
    }
  }
  return inv;
}

// The cells whose shape functions come from a basis of their space inverted at the nodes
// (ReferenceCell::inverse): the serendipity hexahedron and wedge (monomials) and the 14-node
// pyramid (Bergot's space).
bool inverted_at_nodes(CellType type) {
  return type == CellType::serendipity_hexahedron || type == CellType::serendipity_wedge ||
         type == CellType::pyramid14;
}

// That basis at reference point r: one value per node into g.
void space_basis(CellType type, glm::dvec3 r, double* g) {
  if (type == CellType::pyramid14) {
    pyramid14_space(r, g);
    return;
  }
  const std::vector<Lattice> m = serendipity_monomials(type);
  for (std::size_t j = 0; j < m.size(); ++j)
    g[j] = monomial(m[j], r);
}

void check_order(CellType type, int order) {
  if (order < 1 || order > max_cell_order(type) ||
      ((type == CellType::serendipity_hexahedron || type == CellType::serendipity_wedge ||
        type == CellType::pyramid14) &&
       order != 2))
    throw std::invalid_argument(std::string("cell source: a ") + cell_type_name(type) +
                                " of order " + std::to_string(order) + " does not exist");
}

std::unique_ptr<ReferenceCell> build(CellType type, int p) {
  auto cell = std::make_unique<ReferenceCell>();
  cell->type = type;
  cell->order = p;
  cell->degree = p;
  std::vector<Lattice> lattice;
  switch (type) {
    case CellType::hexahedron:
      lattice = hexahedron_nodes(p);
      break;
    case CellType::serendipity_hexahedron:
      lattice = hexahedron_nodes(2);
      lattice.resize(20);  // corners and edges: the triquadratic numbering's first 20
      break;
    case CellType::tetrahedron:
      tetrahedron_nodes(Lattice(0), p, lattice);
      cell->sub_hexahedra = 4;
      break;
    case CellType::wedge:
      lattice = wedge_nodes(p);
      cell->sub_hexahedra = 3;
      break;
    case CellType::serendipity_wedge:
      lattice = wedge_nodes(2);
      lattice.resize(15);  // vertices and edges: the 18-node numbering's first 15
      cell->sub_hexahedra = 3;
      break;
    case CellType::pyramid:
      lattice = pyramid_nodes(p);
      cell->top_collapsed = true;
      break;
    case CellType::pyramid14:
      lattice = pyramid_nodes(2);
      lattice.push_back({1, 1, 0});  // the base's centre
      cell->top_collapsed = true;
      break;
  }
  for (const Lattice& l : lattice)
    cell->nodes.push_back(glm::dvec3(l) / double(p));
  const int n = int(cell->nodes.size());
  if (inverted_at_nodes(type)) {
    std::vector<double> v(std::size_t(n) * n);
    for (int i = 0; i < n; ++i)
      space_basis(type, cell->nodes[i], &v[std::size_t(i) * n]);
    cell->inverse = invert(std::move(v), n);
  }
  if (type == CellType::tetrahedron) {
    // The Bernstein polynomials B_α = p!/(α₀! α₁! α₂! α₃!) λ^α, α from the node lattice, at
    // the nodes.
    const auto factorial = [](int k) {
      double f = 1.0;
      for (int i = 2; i <= k; ++i)
        f *= i;
      return f;
    };
    std::vector<double> v(std::size_t(n) * n);
    for (int i = 0; i < n; ++i) {
      const glm::dvec3 r = cell->nodes[i];
      const double lambda[4] = {1.0 - r.x - r.y - r.z, r.x, r.y, r.z};
      for (int j = 0; j < n; ++j) {
        const Lattice l = lattice[j];
        const int alpha[4] = {p - l.x - l.y - l.z, l.x, l.y, l.z};
        double b = factorial(p);
        for (int k = 0; k < 4; ++k)
          b *= std::pow(lambda[k], alpha[k]) / factorial(alpha[k]);
        v[std::size_t(i) * n + j] = b;
      }
    }
    cell->to_bernstein = invert(std::move(v), n);
  }
  // The sampling matrices of the sub-hexahedra.
  const int d = cell->degree, dm = d + 1;
  std::vector<double> phi(n);
  for (int k = 0; k < cell->sub_hexahedra; ++k)
    for (int c = 0; c < dm; ++c)
      for (int b = 0; b < dm; ++b)
        for (int a = 0; a < dm; ++a) {
          const glm::dvec3 u(double(a) / d, double(b) / d, double(c) / d);
          shape_functions(*cell, sub_hexahedron_point(*cell, k, u), phi.data());
          cell->sampling.insert(cell->sampling.end(), phi.begin(), phi.end());
        }
  return cell;
}

}  // namespace

void shape_functions(const ReferenceCell& cell, glm::dvec3 r, double* out) {
  const int p = cell.order;
  const std::size_t n = cell.nodes.size();
  switch (cell.type) {
    case CellType::hexahedron:
      for (std::size_t i = 0; i < n; ++i) {
        const Lattice l(glm::round(cell.nodes[i] * double(p)));
        out[i] = lagrange_1d(p, l.x, r.x) * lagrange_1d(p, l.y, r.y) * lagrange_1d(p, l.z, r.z);
      }
      return;
    case CellType::tetrahedron:
      // Π over the barycentric coordinates λ of the equispaced factor of the node's index.
      for (std::size_t i = 0; i < n; ++i) {
        const Lattice l(glm::round(cell.nodes[i] * double(p)));
        out[i] = lagrange_factor(p, p - l.x - l.y - l.z, 1.0 - r.x - r.y - r.z) *
                 lagrange_factor(p, l.x, r.x) * lagrange_factor(p, l.y, r.y) *
                 lagrange_factor(p, l.z, r.z);
      }
      return;
    case CellType::wedge:
      for (std::size_t i = 0; i < n; ++i) {
        const Lattice l(glm::round(cell.nodes[i] * double(p)));
        out[i] = lagrange_factor(p, p - l.x - l.y, 1.0 - r.x - r.y) * lagrange_factor(p, l.x, r.x) *
                 lagrange_factor(p, l.y, r.y) * lagrange_1d(p, l.z, r.z);
      }
      return;
    case CellType::serendipity_hexahedron:
    case CellType::serendipity_wedge:
    case CellType::pyramid14: {
      double g[20];
      space_basis(cell.type, r, g);
      for (std::size_t i = 0; i < n; ++i) {
        double s = 0.0;
        for (std::size_t j = 0; j < n; ++j)
          s += g[j] * cell.inverse[j * n + i];
        out[i] = s;
      }
      return;
    }
    case CellType::pyramid:
      if (p == 1) {
        const double rm = 1.0 - r.x, sm = 1.0 - r.y, tm = 1.0 - r.z;
        out[0] = rm * sm * tm, out[1] = r.x * sm * tm, out[2] = r.x * r.y * tm;
        out[3] = rm * r.y * tm, out[4] = r.z;
        return;
      }
      for (int i = 0; i < 13; ++i) {
        double s = 0.0;
        for (int c = 0, m = 0; c < 3; ++c)
          for (int b = 0; b < 3; ++b)
            for (int a = 0; a < 3; ++a, ++m)
              if (kQuadraticPyramid[i][m] != 0)
                s += kQuadraticPyramid[i][m] * std::pow(r.x, a) * std::pow(r.y, b) *
                     std::pow(r.z, c);
        out[i] = s;
      }
      return;
  }
}

glm::dvec3 sub_hexahedron_point(const ReferenceCell& cell, int k, glm::dvec3 u) {
  switch (cell.type) {
    case CellType::tetrahedron: {
      // The hexahedron at vertex k: its corner with bits (b₀, b₁, b₂) is the centroid of vertex
      // k and of the other vertices the set bits select (in increasing order).
      static constexpr glm::dvec3 v[4] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
      glm::dvec3 others[3];
      for (int j = 0, m = 0; j < 4; ++j)
        if (j != k) others[m++] = v[j];
      glm::dvec3 x(0.0);
      for (int c = 0; c < 8; ++c) {
        glm::dvec3 sum = v[k];
        int count = 1;
        for (int bit = 0; bit < 3; ++bit)
          if (c >> bit & 1) sum += others[bit], ++count;
        const double w =
            (c & 1 ? u.x : 1.0 - u.x) * (c & 2 ? u.y : 1.0 - u.y) * (c & 4 ? u.z : 1.0 - u.z);
        x += w * (sum / double(count));
      }
      return x;
    }
    case CellType::wedge:
    case CellType::serendipity_wedge: {
      // The triangle's quadrilateral at vertex k (vertex, the two edges' midpoints, the
      // centroid) times the height.
      static constexpr glm::dvec2 v[3] = {{0, 0}, {1, 0}, {0, 1}};
      glm::dvec2 others[2];
      for (int j = 0, m = 0; j < 3; ++j)
        if (j != k) others[m++] = v[j];
      glm::dvec2 x(0.0);
      for (int c = 0; c < 4; ++c) {
        glm::dvec2 sum = v[k];
        int count = 1;
        for (int bit = 0; bit < 2; ++bit)
          if (c >> bit & 1) sum += others[bit], ++count;
        x += (c & 1 ? u.x : 1.0 - u.x) * (c & 2 ? u.y : 1.0 - u.y) * (sum / double(count));
      }
      return glm::dvec3(x, u.z);
    }
    default:
      return u;
  }
}

const ReferenceCell& reference_cell(CellType type, int order) {
  check_order(type, order);
  static std::mutex mutex;
  static std::map<std::pair<int, int>, std::unique_ptr<ReferenceCell>> cells;
  const std::lock_guard<std::mutex> lock(mutex);
  std::unique_ptr<ReferenceCell>& cell = cells[{int(type), order}];
  if (!cell) cell = build(type, order);
  return *cell;
}

}  // namespace ldimesh::cells

namespace ldimesh {

const char* cell_type_name(CellType type) {
  switch (type) {
    case CellType::hexahedron:
      return "hexahedron";
    case CellType::serendipity_hexahedron:
      return "20-node hexahedron";
    case CellType::tetrahedron:
      return "tetrahedron";
    case CellType::wedge:
      return "wedge";
    case CellType::serendipity_wedge:
      return "15-node wedge";
    case CellType::pyramid:
      return "pyramid";
    case CellType::pyramid14:
      return "14-node pyramid";
  }
  return "unknown cell type";
}

int max_cell_order(CellType type) {
  switch (type) {
    case CellType::hexahedron:
    case CellType::tetrahedron:
    case CellType::wedge:
      return kMaxHexOrder;
    case CellType::serendipity_hexahedron:
    case CellType::serendipity_wedge:
    case CellType::pyramid:
    case CellType::pyramid14:
      return 2;
  }
  throw std::invalid_argument("cell source: unknown cell type " + std::to_string(int(type)));
}

std::size_t cell_node_count(CellType type, int order) {
  return cells::reference_cell(type, order).nodes.size();
}

std::vector<glm::dvec3> cell_reference_nodes(CellType type, int order) {
  return cells::reference_cell(type, order).nodes;
}

std::vector<double> cell_shape_functions(CellType type, int order, glm::dvec3 reference) {
  const cells::ReferenceCell& cell = cells::reference_cell(type, order);
  std::vector<double> out(cell.nodes.size());
  cells::shape_functions(cell, reference, out.data());
  return out;
}

}  // namespace ldimesh

#include "ldimesh/core/field/hex_source.hpp"

#include "bernstein_basis.hpp"
#include "colour_block.hpp"
#include "curved_element.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/field/hex_lookup.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <mutex>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace ldimesh {
namespace {

constexpr int kMaxNodes = kMaxHexOrder + 1;
constexpr int kMaxElementValues = kMaxNodes * kMaxNodes * kMaxNodes;
constexpr int kMaxRayDegree = 3 * kMaxHexOrder;  // f along a ray: degree p in each of ξ, η, ζ

// Below this width (in the ray parameter s ∈ [0, 1]) an interval that still has several sign
// variations is decided by its end values alone: a touching double root is dropped.
constexpr double kMinWidth = 1e-12;
// Roots are converged to this width in s, i.e. to 1e-13 of the segment, at most of the element
// (Halley's last step bounded rather than taken: see converge_lanes).
constexpr double kConverged = 1e-13;
// Bound on the intervals one element-ray search visits. Only a polynomial that is zero up to
// rounding over a stretch (a plateau at the isovalue) comes near it: its coefficients are noise
// whose sign variations would otherwise be split down to kMinWidth everywhere.
constexpr int kMaxIntervals = 4096;

int nodes_per_element(int order) {
  return (order + 1) * (order + 1) * (order + 1);
}

void check_order(int order) {
  if (order < 1 || order > kMaxHexOrder)
    throw std::invalid_argument("hex source: order " + std::to_string(order) + " outside 1.." +
                                std::to_string(kMaxHexOrder));
}

// Enums cast from a host code's integers may hold anything; they index tables here.
void check_node_set(NodeSet nodes) {
  if (nodes != NodeSet::gauss_lobatto_legendre && nodes != NodeSet::gauss_legendre &&
      nodes != NodeSet::equispaced)
    throw std::invalid_argument("hex source: unknown node set " + std::to_string(int(nodes)));
}

// ---------------------------------------------------------------------------------------------
// Nodes and the Lagrange → Bernstein conversion

// Legendre P_n(x) and P'_n(x) by the three-term recurrence; |x| < 1 for the derivative.
void legendre(int n, double x, double& p, double& dp) {
  double p0 = 1.0, p1 = x;
  if (n == 0) {
    p = 1.0, dp = 0.0;
    return;
  }
  for (int k = 1; k < n; ++k) {
    const double p2 = ((2 * k + 1) * x * p1 - k * p0) / (k + 1);
    p0 = p1;
    p1 = p2;
  }
  p = p1;
  dp = n * (x * p1 - p0) / (x * x - 1.0);
}

// Newton's method from a Chebyshev guess; the guesses are close enough to converge to the
// intended root for the orders used here (≤ 9 nodes).
template <class Residual>
double newton_root(double x, Residual residual) {
  for (int iter = 0; iter < 100; ++iter) {
    double r, dr;
    residual(x, r, dr);
    const double step = r / dr;
    x -= step;
    if (std::abs(step) < 1e-16) break;
  }
  return x;
}

// Nodes on [−1, 1], increasing, exactly antisymmetric.
std::vector<double> nodes_on_symmetric_interval(int order, NodeSet set) {
  const int n = order + 1;
  std::vector<double> x(n);
  const double pi = std::numbers::pi;
  switch (set) {
    case NodeSet::equispaced:
      for (int i = 0; i < n; ++i)
        x[i] = -1.0 + 2.0 * i / order;
      break;
    case NodeSet::gauss_legendre:  // roots of P_{p+1}
      for (int i = 0; i < n; ++i)
        x[i] = newton_root(-std::cos(pi * (i + 0.75) / (n + 0.5)),
                           [n](double t, double& r, double& dr) { legendre(n, t, r, dr); });
      break;
    case NodeSet::gauss_lobatto_legendre:  // ±1 and the roots of P'_p
      x[0] = -1.0, x[n - 1] = 1.0;
      for (int i = 1; i < order; ++i)
        x[i] = newton_root(-std::cos(pi * i / order), [order](double t, double& r, double& dr) {
          double p;
          legendre(order, t, p, r);
          dr = (2.0 * t * r - order * (order + 1) * p) / (1.0 - t * t);  // Legendre's equation
        });
      break;
  }
  for (int i = 0; i < n / 2; ++i) {
    const double h = 0.5 * (x[n - 1 - i] - x[i]);
    x[i] = -h, x[n - 1 - i] = h;
  }
  if (n % 2 == 1) x[n / 2] = 0.0;
  return x;
}

// Bernstein coefficients from nodal values, per axis: b = V⁻¹ u with V[m][n] = B_n^p(x_m).
using ConversionMatrix = std::array<double, kMaxNodes * kMaxNodes>;  // row-major, (p+1)²

ConversionMatrix bernstein_from_nodal(int order, NodeSet set) {
  const int n = order + 1;
  const std::vector<double> x = node_positions(order, set);
  // [V | I], reduced to [I | V⁻¹] by Gauss–Jordan elimination with partial pivoting.
  std::vector<double> a(std::size_t(n) * 2 * n, 0.0);
  auto at = [&](int r, int c) -> double& { return a[std::size_t(r) * 2 * n + c]; };
  for (int m = 0; m < n; ++m) {
    for (int k = 0; k <= order; ++k)
      at(m, k) = kBinomial[order][k] * std::pow(x[m], k) * std::pow(1.0 - x[m], order - k);
    at(m, n + m) = 1.0;
  }
  for (int col = 0; col < n; ++col) {
    int pivot = col;
    for (int r = col + 1; r < n; ++r)
      if (std::abs(at(r, col)) > std::abs(at(pivot, col))) pivot = r;
    for (int c = 0; c < 2 * n; ++c)
      std::swap(at(col, c), at(pivot, c));
    const double inv = 1.0 / at(col, col);
    for (int c = 0; c < 2 * n; ++c)
      at(col, c) *= inv;
    for (int r = 0; r < n; ++r) {
      if (r == col) continue;
      const double factor = at(r, col);
      for (int c = 0; c < 2 * n; ++c)
        at(r, c) -= factor * at(col, c);
    }
  }
  ConversionMatrix inverse{};
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c)
      inverse[r * n + c] = at(r, n + c);
  return inverse;
}

// All (order, node set) matrices, built once on first use (thread-safe static initialisation).
const ConversionMatrix& conversion_matrix(int order, NodeSet set) {
  static const auto table = [] {
    std::array<std::array<ConversionMatrix, 3>, kMaxHexOrder + 1> t{};
    for (int p = 1; p <= kMaxHexOrder; ++p)
      for (NodeSet s :
           {NodeSet::gauss_lobatto_legendre, NodeSet::gauss_legendre, NodeSet::equispaced})
        t[p][int(s)] = bernstein_from_nodal(p, s);
    return t;
  }();
  return table[order][int(set)];
}

// Calls fn(std::integral_constant<int, v>{}) for the runtime value v, one of Vs (the last one
// for any other value): a kernel instantiated per value, chosen at run time.
template <int V, int... Vs, class Fn>
[[gnu::always_inline]] inline decltype(auto) with_one_of(int v, Fn&& fn) {
  if constexpr (sizeof...(Vs) == 0) {
    return fn(std::integral_constant<int, V>{});
  } else {
    if (v == V) return fn(std::integral_constant<int, V>{});
    return with_one_of<Vs...>(v, std::forward<Fn>(fn));
  }
}
// The order p = 1..kMaxHexOrder as a constant.
template <class Fn>
[[gnu::always_inline]] inline decltype(auto) with_order(int p, Fn&& fn) {
  static_assert(kMaxHexOrder == 8);
  return with_one_of<1, 2, 3, 4, 5, 6, 7, 8>(p, std::forward<Fn>(fn));
}
// Sum factorisation: the 1-D conversion applied along ξ, then η, then ζ ((p + 1)⁴ operations
// instead of (p + 1)⁶). `in` and `out` hold (p + 1)³ values and may not overlap.
template <int P>
void convert_element_fixed(const ConversionMatrix& m, const double* in, double* out) {
  constexpr int n = P + 1;
  double work[2][kMaxElementValues];
  const double* src = in;
  for (int axis = 0; axis < 3; ++axis) {
    double* dst = axis == 2 ? out : work[axis];
    const int s = axis == 0 ? 1 : (axis == 1 ? n : n * n);
    // The lines along `axis`: indices a + b·s·n with a < s, each with its n values s apart.
    for (int b = 0; b < n * n * n / (s * n); ++b)
      for (int a = 0; a < s; ++a) {
        const int base = a + b * s * n;
        for (int r = 0; r < n; ++r) {
          double sum = 0.0;
          for (int c = 0; c < n; ++c)
            sum += m[r * n + c] * src[base + c * s];
          dst[base + r * s] = sum;
        }
      }
    src = dst;
  }
}
void convert_element(int order, const ConversionMatrix& m, const double* in, double* out) {
  with_order(order, [&](auto p) { convert_element_fixed<p>(m, in, out); });
}

// Copies the (p + 1)³ = n nodal values of `element` as doubles into `nodal`; returns how many
// are NaN or ±Inf.
// vtk_lagrange_index without the checks.
std::size_t vtk_index(int i, int j, int k, int p) {
  const bool ib = i == 0 || i == p, jb = j == 0 || j == p, kb = k == 0 || k == p;
  const int bounds = int(ib) + int(jb) + int(kb), e = p - 1;
  if (bounds == 3) return std::size_t((j == 0 ? (i == p) : (i == p ? 2 : 3)) + (k == p ? 4 : 0));
  if (bounds == 2) {
    int edge, t;
    if (!ib)
      edge = (j == 0 ? 0 : 2) + (k == p ? 4 : 0), t = i;
    else if (!jb)
      edge = (i == 0 ? 3 : 1) + (k == p ? 4 : 0), t = j;
    else
      edge = 8 + (i == 0 ? (j == 0 ? 0 : 3) : (j == 0 ? 1 : 2)), t = k;
    return std::size_t(8 + edge * e + t - 1);
  }
  if (bounds == 1) {
    int face, a, b;
    if (ib)
      face = i == 0 ? 0 : 1, a = j, b = k;
    else if (jb)
      face = j == 0 ? 2 : 3, a = i, b = k;
    else
      face = k == 0 ? 4 : 5, a = i, b = j;
    return std::size_t(8 + 12 * e + face * e * e + (a - 1) + e * (b - 1));
  }
  return std::size_t(8 + 12 * e + 6 * e * e + (i - 1) + e * ((j - 1) + e * (k - 1)));
}

// For each order, the position in the solver's array of the element's lexicographic node m.
const std::vector<std::uint16_t>& node_permutation(int order, NodeOrdering ordering) {
  static const auto tables = [] {
    std::array<std::array<std::vector<std::uint16_t>, 2>, kMaxHexOrder + 1> t;
    for (int p = 1; p <= kMaxHexOrder; ++p)
      for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
          for (int i = 0; i <= p; ++i) {
            t[p][0].push_back(std::uint16_t(i + (p + 1) * (j + (p + 1) * k)));
            t[p][1].push_back(std::uint16_t(vtk_index(i, j, k, p)));
          }
    return t;
  }();
  return tables[order][ordering == NodeOrdering::vtk_lagrange ? 1 : 0];
}

std::size_t read_nodal(const HexBlock& block, std::size_t element, std::size_t n, double* nodal) {
  const std::size_t first = element * block.element_stride;
  // One branch per element on the scalar type and the ordering, none per value.
  const auto read = [&](const auto* values) {
    if (block.ordering == NodeOrdering::lexicographic) {
      std::copy_n(values + first, n, nodal);
      return;
    }
    const std::vector<std::uint16_t>& at = node_permutation(block.order, block.ordering);
    for (std::size_t m = 0; m < n; ++m)
      nodal[m] = double(values[first + at[m]]);
  };
  if (block.type == ScalarType::float32)
    read(static_cast<const float*>(block.values));
  else
    read(static_cast<const double*>(block.values));
  std::size_t nonfinite = 0;
  for (std::size_t i = 0; i < n; ++i)
    nonfinite += !std::isfinite(nodal[i]);
  return nonfinite;
}

// ---------------------------------------------------------------------------------------------
// Element geometry

// x = origin + axes · ξ for ξ ∈ [0, 1]³ (axes' columns are the edges from corner 0).
struct AffineFrame {
  glm::dvec3 origin;
  glm::dmat3 axes;
};

glm::dvec3 corner(const double* corners, int c) {
  return {corners[3 * c], corners[3 * c + 1], corners[3 * c + 2]};
}

AffineFrame frame_of(const double* corners) {
  const glm::dvec3 o = corner(corners, 0);
  return {o, glm::dmat3(corner(corners, 1) - o, corner(corners, 2) - o, corner(corners, 4) - o)};
}

// The axis-aligned box around the parallelepiped.
Box bounding_box(const AffineFrame& f) {
  Box box{f.origin, f.origin};
  for (int edge = 0; edge < 3; ++edge) {
    box.lo += glm::min(f.axes[edge], 0.0);
    box.hi += glm::max(f.axes[edge], 0.0);
  }
  return box;
}

// ---------------------------------------------------------------------------------------------
// Evaluation. The kernels take the order p (and the degrees along a segment) as constants, so
// that their loops unroll and their sums stay in registers; with_order and with_degree turn a
// runtime value into one. The operations and their order do not depend on how a kernel is
// instantiated: every caller gets the same values, to the bit.

// A degree along a segment as a constant: P per reference axis the segment moves along, so
// d ∈ {0, P, 2P, 3P}.
template <int P, class Fn>
[[gnu::always_inline]] inline decltype(auto) with_degree(int d, Fn&& fn) {
  return with_one_of<0, P, 2 * P, 3 * P>(d, std::forward<Fn>(fn));
}

template <int P>
PolynomialSample evaluate_tensor(const double* coefficients, glm::dvec3 r) {
  constexpr int n = P + 1;
  double bx[kMaxNodes], dx[kMaxNodes], by[kMaxNodes], dy[kMaxNodes], bz[kMaxNodes], dz[kMaxNodes];
  bernstein_basis<P>(r.x, bx, dx);
  bernstein_basis<P>(r.y, by, dy);
  bernstein_basis<P>(r.z, bz, dz);
  PolynomialSample out;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j) {
      const double* row = coefficients + n * (j + n * k);
      double v = 0.0, dv = 0.0;
      for (int i = 0; i < n; ++i) {
        v += row[i] * bx[i];
        dv += row[i] * dx[i];
      }
      out.value += bz[k] * by[j] * v;
      out.gradient.x += bz[k] * by[j] * dv;
      out.gradient.y += bz[k] * dy[j] * v;
      out.gradient.z += dz[k] * by[j] * v;
    }
  return out;
}

// ---------------------------------------------------------------------------------------------
// The polynomial along a ray segment. Products are convolutions in the scaled Bernstein basis
// s^i (1 − s)^(n−i); coefficient i of a standard Bernstein polynomial is the scaled one divided
// by C(n, i) (Farouki & Rajan 1988, "Algorithms for polynomials in Bernstein form").

// out[0..M+N] = a[0..M] ⊛ b[0..N], accumulated (a factor of degree 0 is a scaling).
template <int M, int N>
[[gnu::always_inline]] inline void convolve_add(const double* a, const double* b, double* out) {
  for (int i = 0; i <= M; ++i)
    for (int j = 0; j <= N; ++j)
      out[i + j] += a[i] * b[j];
}

// Scaled coefficients in s of B_i^P(x(s)), i = 0..P, for x(s) = xa (1 − s) + xb s. Returns their
// degree in s: P, or 0 where the segment does not move along this axis (xa == xb, as for an
// axis-aligned ray through an axis-aligned element), which keeps the degree along the ray low.
template <int P>
[[gnu::always_inline]] inline int basis_along_segment(double xa, double xb,
                                                      double (*basis)[kMaxNodes]) {
  if (xa == xb) {
    double value[kMaxNodes], derivative[kMaxNodes];
    bernstein_basis<P>(xa, value, derivative);
    for (int i = 0; i <= P; ++i)
      basis[i][0] = value[i];
    return 0;
  }
  double x_pow[kMaxNodes][kMaxNodes] = {}, y_pow[kMaxNodes][kMaxNodes] = {};  // X^i, (1 − X)^i
  x_pow[0][0] = y_pow[0][0] = 1.0;
  for (int i = 1; i <= P; ++i)
    for (int l = 0; l <= i; ++l) {
      const double lo = l < i ? x_pow[i - 1][l] : 0.0, hi = l > 0 ? x_pow[i - 1][l - 1] : 0.0;
      x_pow[i][l] = xa * lo + xb * hi;
      const double ylo = l < i ? y_pow[i - 1][l] : 0.0, yhi = l > 0 ? y_pow[i - 1][l - 1] : 0.0;
      y_pow[i][l] = (1.0 - xa) * ylo + (1.0 - xb) * yhi;
    }
  for (int i = 0; i <= P; ++i) {
    std::fill(basis[i], basis[i] + P + 1, 0.0);
    for (int l = 0; l <= i; ++l)  // x_pow[i] ⊛ y_pow[P − i]
      for (int m = 0; m <= P - i; ++m)
        basis[i][l + m] += x_pow[i][l] * y_pow[P - i][m];
    for (int l = 0; l <= P; ++l)
      basis[i][l] *= kBinomial[P][i];
  }
  return P;
}

// The restriction to a segment in stages, one reference axis after the other (ξ, then η, then
// ζ): each stage contracts the coefficients with the basis of one axis along the segment. A
// stage's result depends only on the segment's coordinates along the axes contracted so far,
// so the coherent caster keeps it while those do not change (along a row of pixels).

// The basis of one axis along a segment from xa (s = 0) to xb (s = 1): scaled coefficients in
// s of B_i^p(x(s)), degree p, or degree 0 where xa == xb.
struct AxisBasis {
  int degree = 0;
  double b[kMaxNodes][kMaxNodes];
};
template <int P>
[[gnu::always_inline]] inline void segment_basis(double xa, double xb, AxisBasis& out) {
  out.degree = basis_along_segment<P>(xa, xb, out.b);
}
// After the ξ stage: g[k][j][l] = Σ_i c_ijk · bx_i[l], l ≤ bx.degree.
struct StageX {
  double g[kMaxNodes][kMaxNodes][kMaxNodes];
};
template <int P>
[[gnu::always_inline]] inline void contract_x(const double* c, const AxisBasis& bx, StageX& out) {
  with_degree<P>(bx.degree, [&](auto dx) {
    constexpr int n = P + 1, D = dx;
    if constexpr (D <= P)
      for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j) {
          double g[D + 1] = {};
          const double* row = c + n * (j + n * k);
          for (int i = 0; i < n; ++i)
            for (int l = 0; l <= D; ++l)
              g[l] += row[i] * bx.b[i][l];
          std::copy(g, g + D + 1, out.g[k][j]);
        }
  });
}
// After the η stage: h[k][l] = Σ_j g[k][j] ⊛ by_j, degree dx + by.degree.
struct StageY {
  double h[kMaxNodes][2 * kMaxHexOrder + 1];
};
template <int P>
[[gnu::always_inline]] inline void contract_y(const StageX& x, int dx, const AxisBasis& by,
                                              StageY& out) {
  with_degree<P>(dx, [&](auto dxc) {
    with_degree<P>(by.degree, [&](auto dyc) {
      constexpr int n = P + 1, DX = dxc, DY = dyc;
      if constexpr (DX <= P && DY <= P)
        for (int k = 0; k < n; ++k) {
          double h[DX + DY + 1] = {};
          for (int j = 0; j < n; ++j)
            convolve_add<DX, DY>(x.g[k][j], by.b[j], h);
          std::copy(h, h + DX + DY + 1, out.h[k]);
        }
    });
  });
}
// The ζ stage in the scaled basis (before the division by the binomials); returns the degree
// dxy + bz.degree.
template <int P>
[[gnu::always_inline]] inline int contract_z_scaled(const StageY& y, int dxy, const AxisBasis& bz,
                                                    double* f) {
  return with_degree<P>(dxy, [&](auto dxyc) {
    return with_degree<P>(bz.degree, [&](auto dzc) {
      constexpr int n = P + 1, DXY = dxyc, DZ = dzc;
      if constexpr (DXY <= 2 * P && DZ <= P) {
        double s[DXY + DZ + 1] = {};
        for (int k = 0; k < n; ++k)
          convolve_add<DXY, DZ>(y.h[k], bz.b[k], s);
        std::copy(s, s + DXY + DZ + 1, f);
      }
      return DXY + DZ;
    });
  });
}
[[gnu::always_inline]] inline void scaled_to_standard(int degree, double* f) {
  for (int l = 0; l <= degree; ++l)
    f[l] /= kBinomial[degree][l];
}
// The ζ stage: the standard Bernstein coefficients f[0..degree] along the segment.
template <int P>
int contract_z(const StageY& y, int dxy, const AxisBasis& bz, double* f) {
  const int degree = contract_z_scaled<P>(y, dxy, bz, f);
  scaled_to_standard(degree, f);
  return degree;
}

// The polynomial along a segment parallel to one reference axis w, the two others fixed (every
// pixel ray through an element whose edges lie along the world axes): the fixed axes are
// contracted first, u < v, with the bases at the segment's coordinates, leaving the P + 1
// coefficients h in x_w; the segment's matrix then takes them to s. (p + 1)³ + 2 (p + 1)²
// operations, and the coherent caster keeps the first contraction over a column of pixels and
// the matrix over the element.

// The reference axes of an axis-parallel segment: u < v fixed, w moving.
struct AxisSplit {
  int u = 0, v = 1, w = 2;
};

// Whether the segment a → b moves along exactly one reference axis, and which.
inline bool axis_parallel(glm::dvec3 a, glm::dvec3 b, AxisSplit& axes) {
  const bool mx = a.x != b.x, my = a.y != b.y, mz = a.z != b.z;
  if (int(mx) + int(my) + int(mz) != 1) return false;
  axes.w = mx ? 0 : my ? 1 : 2;
  axes.u = axes.w == 0 ? 1 : 0;
  axes.v = axes.w == 2 ? 1 : 2;
  return true;
}

// After the u contraction: g[j][l] = Σ_i c[i·s_u + j·s_v + l·s_w] · bu[i] (j along v, l along
// w), s_r = (P + 1)^r the coefficients' stride along reference axis r.
using FixedStage = double[kMaxNodes][kMaxNodes];
template <int P>
[[gnu::always_inline]] inline void contract_fixed_u(const double* c, AxisSplit axes,
                                                    const double* bu, FixedStage& g) {
  constexpr int n = P + 1;
  constexpr int stride[3] = {1, n, n * n};
  const int su = stride[axes.u], sv = stride[axes.v], sw = stride[axes.w];
  for (int j = 0; j < n; ++j)
    for (int l = 0; l < n; ++l) {
      const double* row = c + j * sv + l * sw;
      double sum = 0.0;
      for (int i = 0; i < n; ++i)
        sum += row[i * su] * bu[i];
      g[j][l] = sum;
    }
}

// The v contraction: h[l] = Σ_j g[j][l] · bv[j].
template <int P>
[[gnu::always_inline]] inline void contract_fixed_v(const FixedStage& g, const double* bv,
                                                    double* h) {
  constexpr int n = P + 1;
  for (int l = 0; l < n; ++l)
    h[l] = 0.0;
  for (int j = 0; j < n; ++j)
    for (int l = 0; l < n; ++l)
      h[l] += g[j][l] * bv[j];
}

// The standard Bernstein coefficients m[i][l] in s of B_i^P(x(s)), x(s) = xa (1 − s) + xb s:
// f = Σ_i h_i m[i] is h along the segment. The whole axis either way round is the identity or
// the reversal, exactly (the general form gives the same numbers: products with 0 and 1).
struct SegmentMatrix {
  enum Kind { identity, reversed, general } kind = identity;
  double m[kMaxNodes][kMaxNodes];
};
template <int P>
[[gnu::always_inline]] inline void segment_matrix(double xa, double xb, SegmentMatrix& out) {
  if (xa == 0.0 && xb == 1.0) {
    out.kind = SegmentMatrix::identity;
  } else if (xa == 1.0 && xb == 0.0) {
    out.kind = SegmentMatrix::reversed;
  } else {
    out.kind = SegmentMatrix::general;
    basis_along_segment<P>(xa, xb, out.m);
    for (int i = 0; i <= P; ++i)
      for (int l = 0; l <= P; ++l)
        out.m[i][l] /= kBinomial[P][l];
  }
}
template <int P>
[[gnu::always_inline]] inline void along_segment(const double* h, const SegmentMatrix& m,
                                                 double* f) {
  if (m.kind == SegmentMatrix::identity) {
    std::copy(h, h + P + 1, f);
  } else if (m.kind == SegmentMatrix::reversed) {
    std::reverse_copy(h, h + P + 1, f);
  } else {
    for (int l = 0; l <= P; ++l)
      f[l] = 0.0;
    for (int i = 0; i <= P; ++i)
      for (int l = 0; l <= P; ++l)
        f[l] += h[i] * m.m[i][l];
  }
}

// f[0..P] along the axis-parallel segment a → b; returns P.
template <int P>
int restrict_axis_parallel(const double* c, AxisSplit axes, glm::dvec3 a, glm::dvec3 b, double* f) {
  double bu[kMaxNodes], bv[kMaxNodes], unused[kMaxNodes], h[kMaxNodes];
  bernstein_basis<P>(a[axes.u], bu, unused);
  bernstein_basis<P>(a[axes.v], bv, unused);
  FixedStage g;
  contract_fixed_u<P>(c, axes, bu, g);
  contract_fixed_v<P>(g, bv, h);
  SegmentMatrix m;
  segment_matrix<P>(a[axes.w], b[axes.w], m);
  along_segment<P>(h, m, f);
  return P;
}

// Standard Bernstein coefficients f[0..n] on s ∈ [0, 1] of the tensor polynomial with
// coefficients `c` along the straight segment from reference point a (s = 0) to b (s = 1);
// returns the degree n ≤ 3P (P per reference axis the segment moves along).
template <int P>
int restrict_to_segment(const double* c, glm::dvec3 a, glm::dvec3 b, double* f) {
  if (AxisSplit axes; axis_parallel(a, b, axes)) return restrict_axis_parallel<P>(c, axes, a, b, f);
  AxisBasis bx, by, bz;
  segment_basis<P>(a.x, b.x, bx);
  segment_basis<P>(a.y, b.y, by);
  segment_basis<P>(a.z, b.z, bz);
  StageX x;
  StageY y;
  contract_x<P>(c, bx, x);
  contract_y<P>(x, bx.degree, by, y);
  return contract_z<P>(y, bx.degree + by.degree, bz, f);
}

// ---------------------------------------------------------------------------------------------
// Roots of a univariate Bernstein polynomial on [0, 1]

// Value and first two derivatives at u of the Bernstein polynomial c[0..n] on [0, 1] by
// Horner's rule in r = u / (1 − u) (or (1 − u) / u from the other end, for u > 1/2, so that
// |r| ≤ 1): Σ C(n, i) c_i u^i (1 − u)^(n−i) = (1 − u)^n Σ C(n, i) c_i r^i, and the derivatives
// likewise from the coefficients' first and second differences. O(n) per evaluation where
// de Casteljau's is O(n²); the three sums are independent chains. The degree n is a constant in
// these kernels, so that their loops unroll and their arrays stay in registers.
template <int n>
[[gnu::always_inline]] inline void bernstein_horner(const double* c, double u, double& value,
                                                    double& first, double& second) {
  const bool low = u <= 0.5;
  const double near = low ? 1.0 - u : u, r = (low ? u : 1.0 - u) / near;
  // From the far end: coefficient i of the sum is c[low ? i : n − i].
  const auto at = [&](int i) { return c[low ? i : n - i]; };
  const auto diff2 = [&](int i) { return at(i + 2) - 2.0 * at(i + 1) + at(i); };
  // f: Σ C(n, i) e_i r^i; d: Σ C(n − 1, i) Δe_i r^i; d2: Σ C(n − 2, i) Δ²e_i r^i; near^(n−2).
  double f = at(n), d = at(n) - at(n - 1), d2 = 0.0, power = 1.0;
  if constexpr (n >= 2) d2 = diff2(n - 2);
  for (int i = n - 1; i >= 0; --i) {
    f = f * r + kBinomial[n][i] * at(i);
    if (i > 0) d = d * r + kBinomial[n - 1][i - 1] * (at(i) - at(i - 1));
    if (i > 1) {
      d2 = d2 * r + kBinomial[n - 2][i - 2] * diff2(i - 2);
      power *= near;
    }
  }
  const double power1 = n >= 2 ? power * near : 1.0;  // near^(n−1)
  value = f * power1 * near;
  first = (low ? n : -n) * d * power1;        // d/du = −d/d(1 − u) from the far end
  second = double(n * (n - 1)) * d2 * power;  // the same from either end
}

// Splits c[0..n] at 1/2 into the coefficients of the left and right halves (de Casteljau). The
// halves share their middle coefficient exactly, so sign tests at the split agree. `left` (not
// `right`) may be `c`: c is read before the halves are written.
template <int n>
[[gnu::always_inline]] inline void split_in_half(const double* c, double* left, double* right) {
  // Unrolled whole, so that w lives in registers: vectorised, its overlapping pairs went through
  // the stack, and each level's loads waited on the last one's stores.
  double w[n + 1];
#pragma GCC unroll 16
  for (int i = 0; i <= n; ++i)
    w[i] = c[i];
  left[0] = w[0];
  right[n] = w[n];
#pragma GCC unroll 16
  for (int r = 1; r <= n; ++r) {
#pragma GCC unroll 16
    for (int i = 0; i <= n - r; ++i)
      w[i] = 0.5 * (w[i] + w[i + 1]);
    left[r] = w[0];
    right[n - r] = w[n - r];
  }
}

template <int n>
[[gnu::always_inline]] inline int sign_variations(const double* c) {
  int v = 0;
  for (int i = 0; i < n; ++i)
    v += positive(c[i]) != positive(c[i + 1]);
  return v;
}

// The single root in [0, 1] of each of L polynomials c[l][0..n], whose end values c[l][0] and
// c[l][n] differ in sign, to within tol[l]: Halley steps from the control polygon's crossing,
// falling back to bisection whenever they leave the bracket. The L lanes advance in lock step,
// each by exactly the operations it would take alone (converge is the one-lane case, so any
// lane count gives the same bits): their chains of divisions are independent and overlap.
template <int n, int L>
[[gnu::always_inline]] inline void converge_lanes(const double* const* c, const double* tol,
                                                  double* root) {
  double a[L], b[L], ga[L], u[L], noise[L], m2[L], m3[L];
  bool active[L];
  for (int l = 0; l < L; ++l) {
    const double* cl = c[l];
    // Exactly at the end: keep it exact (the half-open rule needs it).
    active[l] = cl[n] != 0.0;
    root[l] = 1.0;
    a[l] = 0.0, b[l] = 1.0, ga[l] = cl[0];
    // Start where the control polygon crosses zero (its one sign change): far closer than the
    // chord from c[0] to c[n] when the polynomial bends.
    double start = 0.5;
    for (int i = 0; i < n; ++i)
      if (positive(cl[i]) != positive(cl[i + 1])) {
        start = (i + cl[i] / (cl[i] - cl[i + 1])) / n;
        break;
      }
    u[l] = start > 0.0 && start < 1.0 ? start : 0.5;
    // A value within the evaluation's rounding error (about 2n operations, each within an ulp
    // or two of the coefficients' magnitude) is a root as far as the coefficients can tell:
    // further steps would chase rounding noise (slowly, near a double root).
    double magnitude = 0.0;
    for (int i = 0; i <= n; ++i)
      magnitude = std::max(magnitude, std::abs(cl[i]));
    noise[l] = 4.0 * (n + 1) * std::numeric_limits<double>::epsilon() * magnitude;
    // Bounds on |f''| and |f'''| over [0, 1]: n (n − 1) max |Δ²c| and n (n − 1) (n − 2)
    // max |Δ³c| (the derivatives' Bernstein coefficients).
    double d2 = 0.0, d3 = 0.0;
    for (int i = 0; i + 2 <= n; ++i)
      d2 = std::max(d2, std::abs(cl[i + 2] - 2.0 * cl[i + 1] + cl[i]));
    for (int i = 0; i + 3 <= n; ++i)
      d3 = std::max(d3, std::abs(cl[i + 3] - 3.0 * cl[i + 2] + 3.0 * cl[i + 1] - cl[i]));
    m2[l] = d2 * (n * (n - 1));
    m3[l] = d3 * (n * (n - 1) * (n - 2));
  }
  for (int iter = 0; iter < 64; ++iter) {
    bool any = false;
    for (int l = 0; l < L; ++l) {
      if (!active[l]) continue;
      const auto finish = [&](double r) { root[l] = r, active[l] = false; };
      if (!(b[l] - a[l] > tol[l])) {
        finish(u[l]);
        continue;
      }
      double g, dg, ddg;
      bernstein_horner<n>(c[l], u[l], g, dg, ddg);
      if (g == 0.0 || std::abs(g) <= noise[l]) {
        finish(u[l]);
        continue;
      }
      // The bracket's update without a branch: which side u falls on is a coin toss.
      const bool same_side = positive(g) == positive(ga[l]);
      a[l] = same_side ? u[l] : a[l];
      ga[l] = same_side ? g : ga[l];
      b[l] = same_side ? b[l] : u[l];
      // Halley's step: cubic convergence, so that from the polygon's start two evaluations
      // often do where Newton's steps take three.
      double next = u[l] - 2.0 * g * dg / (2.0 * dg * dg - g * ddg);
      const bool halley = next > a[l] && next < b[l];
      if (!halley) next = 0.5 * (a[l] + b[l]);
      // After a Halley step δ the error is about |f'''/(6 f') − (f''/(2 f'))²| δ³ at most:
      // stop once that bound (with the coefficients' bounds on f'' and f''') is below tol,
      // instead of taking one more step to see it.
      const double step = std::abs(next - u[l]), slope = std::abs(dg);
      if (step < tol[l] ||
          (halley && step * step * step * (m3[l] * slope * (2.0 / 3.0) + m2[l] * m2[l]) <
                         4.0 * tol[l] * slope * slope)) {
        finish(next);
        continue;
      }
      u[l] = next;
      any = true;
    }
    if (!any) return;
  }
  for (int l = 0; l < L; ++l)
    if (active[l]) root[l] = u[l];  // out of iterations
}

template <int n>
[[gnu::always_inline]] inline double converge(const double* c, double tol) {
  double root;
  converge_lanes<n, 1>(&c, &tol, &root);
  return root;
}

// Isolates the roots in [0, 1] of f = c[0..n], in increasing order: exact(s) for a root known
// exactly (a zero at the start), bracket(piece, s0, s1) for a stretch [s0, s1] holding exactly
// one sign change of f, with f's coefficients on it. Bernstein subdivision: by Descartes' rule
// of signs for the Bernstein basis, f has at most as many roots in a piece as its coefficients
// have sign variations. None: no sign change. One: the end coefficients (the end values) differ
// in sign, so exactly one simple root. More: split in half and look again.
template <int n, class Exact, class Bracket>
[[gnu::always_inline]] inline void isolate_roots(const double* c, Exact exact, Bracket bracket) {
  // Depth-first: the left half is looked at next (in local arrays), the right one waits on a
  // stack; at most one pending interval per level, and kMinWidth = 1e-12 > 2^-40 bounds the
  // levels.
  // A root exactly at the start belongs to this segment (the caster's half-open rule drops one
  // exactly at a shared end); the caster merges it with the same root found by subdivision.
  if (c[0] == 0.0) exact(0.0);
  struct Piece {
    double s0, s1;
    double c[n + 1];
  };
  constexpr int kStack = 64;
  Piece stack[kStack];
  int top = 0, visited = 0;
  double piece[n + 1], s0 = 0.0, s1 = 1.0;
  std::copy(c, c + n + 1, piece);
  for (;;) {
    const int variations = sign_variations<n>(piece);
    const double w = s1 - s0;
    if (variations > 1 && w >= kMinWidth && top + 2 <= kStack && ++visited < kMaxIntervals) {
      const double sm = 0.5 * (s0 + s1);
      Piece& right = stack[top++];
      split_in_half<n>(piece, piece, right.c);
      right.s0 = sm, right.s1 = s1;
      s1 = sm;
      continue;
    }
    // One variation: one root. Too small (or out of budget): a root only where the ends differ
    // in sign, so a touching double root without a sign change is dropped.
    if (variations > 0 && positive(piece[0]) != positive(piece[n])) bracket(piece, s0, s1);
    if (top == 0) break;
    const Piece& next = stack[--top];
    std::copy(next.c, next.c + n + 1, piece);
    s0 = next.s0, s1 = next.s1;
  }
}

// The tolerance in u of a piece [s0, s1] of a segment.
inline double piece_tolerance(double s0, double s1) {
  return kConverged / (s1 - s0);
}

// Calls found(s) for every s ∈ [0, 1] where f = c[0..n] changes sign (zero counts as positive),
// in increasing order: isolate_roots, each bracket converged at once.
template <int n, class Found>
[[gnu::always_inline]] inline void bernstein_roots(const double* c, Found found) {
  isolate_roots<n>(c, found, [&](const double* piece, double s0, double s1) {
    found(segment_point(s0, s1, converge<n>(piece, piece_tolerance(s0, s1))));
  });
}

// ---------------------------------------------------------------------------------------------
// The active elements of a bind: those whose coefficient range holds the isovalue.

// What the casters need of one active element.
struct ActiveElement {
  glm::dvec3 origin;               // corner 0 (affine elements)
  glm::dmat3 to_reference;         // inverse of the affine frame's axes (affine elements)
  glm::dvec3 lo, hi;               // axis-aligned bounds
  std::uint32_t curved = kAffine;  // a curved element's index in Activation::geometry
  static constexpr std::uint32_t kAffine = ~std::uint32_t(0);
};

struct Activation {
  int order = 1;
  std::size_t values_per_element = 0;
  std::vector<ActiveElement> elements;
  std::vector<double> coefficients;  // iso subtracted, values_per_element per active element
  std::uint64_t nonfinite = 0;
  // The curved active elements' geometry in Bernstein form, points_per_element each.
  int geometry_degree = 1;
  std::size_t points_per_element = 0;
  std::vector<glm::dvec3> geometry;
  const double* coefficients_of(std::size_t k) const {
    return &coefficients[k * values_per_element];
  }
  // Active element k as the curved intersection takes it (k must be curved).
  curved::Element curved_element(std::size_t k) const {
    return {order, geometry_degree, coefficients_of(k),
            &geometry[std::size_t(elements[k].curved) * points_per_element]};
  }
};

// The ray o + t·d clipped to affine element e: false if it misses, else [t0, t1] narrowed to
// the stretch inside and its ends a, b in reference coordinates. Both casters clip with it.
inline bool clip_to_element(const ActiveElement& e, glm::dvec3 org, glm::dvec3 dir, double& t0,
                            double& t1, glm::dvec3& a, glm::dvec3& b) {
  const glm::dvec3 ro = e.to_reference * (org - e.origin), rd = e.to_reference * dir;
  if (!clip_ray_to_box(ro, rd, glm::dvec3(0.0), glm::dvec3(1.0), t0, t1)) return false;
  a = glm::clamp(ro + t0 * rd, 0.0, 1.0), b = glm::clamp(ro + t1 * rd, 0.0, 1.0);
  return true;
}

// Every root in [t_min, t_max] of the ray o + t·d in element e (coefficients c), appended to
// `hits` with its normal: the ray in reference coordinates, clipped to the unit cube, the
// polynomial along the clipped segment, its roots by Bernstein subdivision. Both casters call
// this for a ray through an element (the coherent one where it has no shortcut).
template <int P>
void intersect_element(const ActiveElement& e, const double* c, glm::dvec3 org, glm::dvec3 dir,
                       double t_min, double t_max, std::vector<RayHit>& hits) {
  double t0 = t_min, t1 = t_max;
  glm::dvec3 a, b;
  if (!clip_to_element(e, org, dir, t0, t1, a, b)) return;

  double f[kMaxRayDegree + 1];
  const int degree = restrict_to_segment<P>(c, a, b, f);
  const glm::dmat3 to_world_gradient = glm::transpose(e.to_reference);  // ∇x f = A⁻ᵀ ∇ξ f
  with_degree<P>(degree, [&](auto n) {
    if constexpr (n > 0)  // else constant along the ray: no crossing
      bernstein_roots<n>(f, [&](double s) {
        const glm::dvec3 g = to_world_gradient * evaluate_tensor<P>(c, a + s * (b - a)).gradient;
        hits.push_back({segment_point(t0, t1, s), unit_normal(g, dir), 0.0f});
      });
  });
}

// The roots of active element k along a ray, whichever its geometry.
template <int P>
void intersect_active(const Activation& act, std::size_t k, glm::dvec3 org, glm::dvec3 dir,
                      double t_min, double t_max, std::vector<RayHit>& hits) {
  const ActiveElement& el = act.elements[k];
  if (el.curved != ActiveElement::kAffine)
    curved::intersect(act.curved_element(k), org, dir, t_min, t_max, hits);
  else
    intersect_element<P>(el, act.coefficients_of(k), org, dir, t_min, t_max, hits);
}

// ---------------------------------------------------------------------------------------------
// The Embree binding

class HexBinding final : public GeometryBinding {
 public:
  HexBinding(RTCDevice device, Activation active)
      : active_(std::move(active)),
        geometry_(device, active_.elements.size(), this, &HexBinding::bounds,
                  &HexBinding::intersect) {}

  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return active_.elements.size(); }
  std::uint64_t nonfinite_values() const override { return active_.nonfinite; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const HexBinding*>(args->geometryUserPtr);
    const ActiveElement& e = self->active_.elements[args->primID];
    write_padded_bounds(e.lo, e.hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const HexBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    const Activation& act = self->active_;
    with_order(act.order, [&](auto p) {
      intersect_active<p>(act, args->primID, q->org, q->dir, q->t_min, q->t_max, *q->hits);
    });
  }

  Activation active_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

// ---------------------------------------------------------------------------------------------
// The coherent caster of axis-parallel rays

// The active elements binned by their boxes across one ray axis: a uniform grid over the two
// other world axes (b < c), about one element wide, each element listed in every bin its box
// touches.
struct ElementBins {
  int b = 0, c = 1;
  double lo_b = 0.0, lo_c = 0.0, size_b = 1.0, size_c = 1.0;
  int nb = 1, nc = 1;
  std::vector<std::uint32_t> first;  // CSR over bins (b fastest)
  std::vector<std::uint32_t> elements;

  int bin_b(double x) const { return clamped_floor((x - lo_b) / size_b, 0, nb - 1); }
  int bin_c(double x) const { return clamped_floor((x - lo_c) / size_c, 0, nc - 1); }
};

ElementBins bin_elements(const std::vector<ActiveElement>& elements, int axis) {
  ElementBins bins;
  bins.b = axis == 0 ? 1 : 0;
  bins.c = axis == 2 ? 1 : 2;
  const std::size_t n = elements.size();
  if (n == 0) {
    bins.first.assign(2, 0);
    return bins;
  }
  double lo_b = INFINITY, hi_b = -INFINITY, lo_c = INFINITY, hi_c = -INFINITY;
  std::vector<double> eb(n), ec(n);
  for (std::size_t e = 0; e < n; ++e) {
    const ActiveElement& el = elements[e];
    lo_b = std::min(lo_b, el.lo[bins.b]), hi_b = std::max(hi_b, el.hi[bins.b]);
    lo_c = std::min(lo_c, el.lo[bins.c]), hi_c = std::max(hi_c, el.hi[bins.c]);
    eb[e] = el.hi[bins.b] - el.lo[bins.b];
    ec[e] = el.hi[bins.c] - el.lo[bins.c];
  }
  // Bins as wide as the median element, at most 2048 per axis.
  std::nth_element(eb.begin(), eb.begin() + n / 2, eb.end());
  std::nth_element(ec.begin(), ec.begin() + n / 2, ec.end());
  const auto layout = [](double lo, double hi, double median, double& size, int& count) {
    const double extent = std::max(hi - lo, 1e-300);
    count = int(std::clamp(std::ceil(extent / std::max(median, extent / 2048.0)), 1.0, 2048.0));
    size = extent / count;
  };
  bins.lo_b = lo_b, bins.lo_c = lo_c;
  layout(lo_b, hi_b, eb[n / 2], bins.size_b, bins.nb);
  layout(lo_c, hi_c, ec[n / 2], bins.size_c, bins.nc);
  const std::size_t cells = std::size_t(bins.nb) * std::size_t(bins.nc);
  bins.first.assign(cells + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::uint32_t> next;
    if (pass == 1) {
      for (std::size_t k = 0; k < cells; ++k)
        bins.first[k + 1] += bins.first[k];
      bins.elements.resize(bins.first[cells]);
      next.assign(bins.first.begin(), bins.first.end() - 1);
    }
    for (std::size_t e = 0; e < n; ++e) {
      const ActiveElement& el = elements[e];
      const int b0 = bins.bin_b(el.lo[bins.b]), b1 = bins.bin_b(el.hi[bins.b]);
      const int c0 = bins.bin_c(el.lo[bins.c]), c1 = bins.bin_c(el.hi[bins.c]);
      for (int cc = c0; cc <= c1; ++cc)
        for (int bb = b0; bb <= b1; ++bb) {
          const std::size_t k = std::size_t(bb) + std::size_t(bins.nb) * std::size_t(cc);
          if (pass == 0)
            ++bins.first[k + 1];
          else
            bins.elements[next[k]++] = std::uint32_t(e);
        }
    }
  }
  return bins;
}

// Coefficients this close to zero count as zero in the sign tests (far below any field's
// values, far above underflow).
constexpr double kTinyCoefficient = 1e-250;

// Whether values v[i·si + j·sj + l] (i < ni, j < nj, l < nl) all have the strict sign of
// the first, none near underflow (nor NaN); stops at the first that differs.
[[gnu::always_inline]] inline bool one_sign(const double* v, int ni, int nj, int si, int sj,
                                            int nl) {
  const double sign = v[0] > 0.0 ? 1.0 : -1.0;
  for (int i = 0; i < ni; ++i)
    for (int j = 0; j < nj; ++j)
      for (int l = 0; l < nl; ++l)
        if (!(sign * v[i * si + j * sj + l] > kTinyCoefficient)) return false;
  return true;
}

// B_i^P and dB_i^P/dx at one coordinate: the basis of a reference axis a segment does not move
// along, kept by the staged restriction for the gradient at its hits.
struct PointBasis {
  double value[kMaxNodes] = {}, derivative[kMaxNodes] = {};
};

// The polynomial along axis rays through one element, stage by stage (contract_x, _y, _z),
// each stage kept while the segment's coordinates it depends on do not change: over a row of
// pixels only the last stage is redone. The same arithmetic as restrict_to_segment, so the
// same coefficients, to the bit. Where ξ is fixed along the ray, the gradient at a root reuses
// the ξ stage and contracts the rest with the 1-D bases and derivatives at the point: (p + 1)²
// work instead of the full tensor evaluation's (p + 1)³.
template <int P>
class StagedRestriction {
 public:
  explicit StagedRestriction(const double* c) : c_(c) {}

  // Standard Bernstein coefficients along the segment a → b; returns the degree, or −1 when
  // a stage's values all have one strict sign: the bases that follow are nonnegative and sum to
  // one, so every coefficient of the polynomial has that sign, and it has no root (nor any
  // coefficient that is exactly zero: the values are far above underflow).
  [[gnu::always_inline]] int restrict(glm::dvec3 a, glm::dvec3 b, double* f) {
    if (!x_valid_ || a.x != ax_ || b.x != bx_) {
      axis_basis(0, a.x, b.x, basis_x_);
      contract_x<P>(c_, basis_x_, x_);
      ax_ = a.x, bx_ = b.x;
      x_valid_ = true;
      y_valid_ = dx_valid_ = false;
      constexpr int n = P + 1;
      x_uniform_ =
          one_sign(&x_.g[0][0][0], n, n, kMaxNodes * kMaxNodes, kMaxNodes, basis_x_.degree + 1);
    }
    if (x_uniform_) return -1;
    if (!y_valid_ || a.y != ay_ || b.y != by_) {
      axis_basis(1, a.y, b.y, basis_y_);
      contract_y<P>(x_, basis_x_.degree, basis_y_, y_);
      ay_ = a.y, by_ = b.y;
      y_valid_ = true;
      y_uniform_ = one_sign(&y_.h[0][0], P + 1, 1, 2 * kMaxHexOrder + 1, 0,
                            basis_x_.degree + basis_y_.degree + 1);
    }
    if (y_uniform_) return -1;
    if (!z_valid_ || a.z != az_ || b.z != bz_) {
      axis_basis(2, a.z, b.z, basis_z_);
      az_ = a.z, bz_ = b.z;
      z_valid_ = true;
    }
    a_ = a, b_ = b;
    const int degree = contract_z_scaled<P>(y_, basis_x_.degree + basis_y_.degree, basis_z_, f);
    // Scaled and standard coefficients differ by positive factors: one strict sign in the
    // scaled ones (far above underflow) means no root, and the divisions can wait.
    if (degree > 0 && one_sign(f, 1, 1, 0, 0, degree + 1)) return -1;
    scaled_to_standard(degree, f);
    return degree;
  }

  // ∇ξ at parameter s of the last restrict()'s segment; false where the segment moves along ξ
  // (then evaluate the tensor).
  bool gradient(double s, glm::dvec3& g) {
    if (a_.x != b_.x) return false;
    // G_kj = Σ_i c_ijk B_i(ξ) and its ξ-derivative are the ξ stage itself where ξ is fixed along
    // the ray (kept over the row).
    // The hit's reference point, as evaluate_tensor would be given it, and the 1-D bases and
    // their derivatives there (those of a fixed axis from the restriction).
    const glm::dvec3 q = a_ + s * (b_ - a_);
    const PointBasis& y = point_at(1, a_.y == b_.y, q.y);
    const PointBasis& z = point_at(2, a_.z == b_.z, q.z);
    if (!dx_valid_) {
      AxisBasis d;
      derivative_basis(fixed_[0], d);
      contract_x<P>(c_, d, dx_);
      dx_valid_ = true;
    }
    constexpr int n = P + 1;
    g = glm::dvec3(0.0);
    for (int k = 0; k < n; ++k) {
      double sx = 0.0, sy = 0.0, sz = 0.0;
      for (int j = 0; j < n; ++j) {
        const double v = x_.g[k][j][0], d = dx_.g[k][j][0];
        sx += d * y.value[j];
        sy += v * y.derivative[j];
        sz += v * y.value[j];
      }
      g.x += sx * z.value[k];
      g.y += sy * z.value[k];
      g.z += sz * z.derivative[k];
    }
    return true;
  }

 private:
  // The basis of reference axis r along the segment xa → xb; where the axis is fixed, with its
  // derivative kept in fixed_[r] for the gradient.
  [[gnu::always_inline]] void axis_basis(int r, double xa, double xb, AxisBasis& out) {
    if (xa != xb) {
      segment_basis<P>(xa, xb, out);
      return;
    }
    bernstein_basis<P>(xa, fixed_[r].value, fixed_[r].derivative);
    out.degree = 0;
    for (int i = 0; i <= P; ++i)
      out.b[i][0] = fixed_[r].value[i];
  }

  // The point basis of axis r at the hit: the restriction's where the axis is fixed, else
  // computed at x.
  const PointBasis& point_at(int r, bool fixed, double x) {
    if (fixed) return fixed_[r];
    bernstein_basis<P>(x, at_hit_[r].value, at_hit_[r].derivative);
    return at_hit_[r];
  }

  static void derivative_basis(const PointBasis& at, AxisBasis& out) {
    out.degree = 0;
    for (int i = 0; i <= P; ++i)
      out.b[i][0] = at.derivative[i];
  }

  const double* c_;
  bool x_uniform_ = false, y_uniform_ = false;
  AxisBasis basis_x_, basis_y_, basis_z_;
  // The point bases of the fixed axes at the segment, and of the moving ones at a hit.
  PointBasis fixed_[3], at_hit_[3];
  StageX x_, dx_;
  StageY y_;
  double ax_ = 0, bx_ = 0, ay_ = 0, by_ = 0, az_ = 0, bz_ = 0;
  bool x_valid_ = false, y_valid_ = false, z_valid_ = false, dx_valid_ = false;
  glm::dvec3 a_{0.0}, b_{0.0};
};

// A root of one pixel's polynomial along a line of an element's pixels (pixel q of the line):
// known exactly (s), or bracketed by [s0, s1] with the polynomial's coefficients there, to be
// converged.
template <int P>
struct LineRoot {
  LineRoot() {}  // left uninitialised: filled where it is appended
  int q;
  bool exact;
  double s0, s1, s;
  double c[P + 1];
};

template <int P>
std::vector<LineRoot<P>>& line_roots() {
  thread_local std::vector<LineRoot<P>> roots;
  return roots;
}

// Converges the bracketed roots, four lanes at a time (converge_lanes: the same bits as one by
// one).
template <int P>
void converge_roots(std::vector<LineRoot<P>>& roots) {
  constexpr int kLanes = 4;
  const auto solve = [&]<int L>(std::integral_constant<int, L>, LineRoot<P>* const* lane) {
    const double* c[L];
    double tol[L], u[L];
    for (int l = 0; l < L; ++l)
      c[l] = lane[l]->c, tol[l] = piece_tolerance(lane[l]->s0, lane[l]->s1);
    converge_lanes<P, L>(c, tol, u);
    for (int l = 0; l < L; ++l)
      lane[l]->s = segment_point(lane[l]->s0, lane[l]->s1, u[l]);
  };
  LineRoot<P>* lane[kLanes];
  int filled = 0;
  for (LineRoot<P>& root : roots) {
    if (root.exact) continue;
    lane[filled++] = &root;
    if (filled == kLanes) solve(std::integral_constant<int, kLanes>{}, lane), filled = 0;
  }
  for (int l = 0; l < filled; ++l)
    solve(std::integral_constant<int, 1>{}, lane + l);
}

// Object order for the pixel rays of axis views: each active element loops over the pixels its
// box covers, each pixel's ray clipped to the element exactly as intersect_element clips it,
// the polynomial along it from the staged restriction (rows of pixels share its first stages),
// the roots by the same subdivision. Rays of other queries (single points) find their elements
// through the bins. Both give the roots of the Embree binding, to the bit, for affine elements;
// curved ones are searched piece by piece here and whole there: the same roots to rounding.
class HexAxisBinding final : public AxisBinding {
 public:
  explicit HexAxisBinding(Activation active) : active_(std::move(active)) {}

  std::size_t primitive_count() const override { return active_.elements.size(); }
  std::uint64_t nonfinite_values() const override { return active_.nonfinite; }

  void prepare(int axis) const override {
    std::call_once(bins_once_[axis], [&] { bins_[axis] = bin_elements(active_.elements, axis); });
    std::call_once(pieces_once_, [&] {  // the curved elements' pieces, for every axis
      pieces_.resize(active_.elements.size());
      const double width = 0.25;
      // Isolated: a thread waiting in call_once must not take a task that waits on it.
      tbb::this_task_arena::isolate([&] {
        tbb::parallel_for(std::size_t(0), active_.elements.size(), [&](std::size_t k) {
          if (active_.elements[k].curved != ActiveElement::kAffine)
            pieces_[k].emplace(active_.curved_element(k), width);
        });
      });
    });
  }

  void cast(const AxisRays& rays, AxisHits& out) const override {
    if (active_.elements.empty() || rays.rays.empty()) return;
    const int axis = rays.axis;
    prepare(axis);
    const ElementBins& bins = bins_[axis];
    std::vector<RayHit> hits;
    // The pixel loops below take whole rows (never given otherwise: prefers_column_tasks).
    if (!rays.lattice || rays.width() != rays.lattice->width) {
      for (std::size_t k = 0; k < rays.rays.size(); ++k) {
        const AxisRay& ray = rays.rays[k];
        if (!(ray.t0 <= ray.t1)) continue;
        const std::size_t bin = std::size_t(bins.bin_b(ray.org[bins.b])) +
                                std::size_t(bins.nb) * std::size_t(bins.bin_c(ray.org[bins.c]));
        hits.clear();
        with_order(active_.order, [&](auto p) {
          for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
            const std::uint32_t e = bins.elements[m];
            intersect_active<p>(active_, e, ray.org, rays.dir, ray.t0, ray.t1, hits);
          }
        });
        for (const RayHit& h : hits)
          out.push_back({std::uint32_t(k), h});
      }
      return;
    }
    // The rectangle the rays cover, in bins; each element once, from the first of its bins in
    // the rectangle.
    double lo_b = INFINITY, hi_b = -INFINITY, lo_c = INFINITY, hi_c = -INFINITY;
    for (const AxisRay& ray : rays.rays) {
      lo_b = std::min(lo_b, ray.org[bins.b]), hi_b = std::max(hi_b, ray.org[bins.b]);
      lo_c = std::min(lo_c, ray.org[bins.c]), hi_c = std::max(hi_c, ray.org[bins.c]);
    }
    const int qb0 = bins.bin_b(lo_b), qb1 = bins.bin_b(hi_b);
    const int qc0 = bins.bin_c(lo_c), qc1 = bins.bin_c(hi_c);
    Scratch scratch;
    scratch.read_lattice(rays);
    for (int cc = qc0; cc <= qc1; ++cc)
      for (int bb = qb0; bb <= qb1; ++bb) {
        const std::size_t bin = std::size_t(bb) + std::size_t(bins.nb) * std::size_t(cc);
        for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
          const std::uint32_t e = bins.elements[m];
          const ActiveElement& el = active_.elements[e];
          if (std::max(bins.bin_b(el.lo[bins.b]), qb0) != bb ||
              std::max(bins.bin_c(el.lo[bins.c]), qc0) != cc)
            continue;
          cast_element(e, rays, out, scratch);
        }
      }
  }

 private:
  // What the separable path of cast_element_order needs of a lattice query, found once per
  // query, and what it keeps per line of an element's pixels (reused from element to element).
  struct Scratch {
    // Whether the query's rays form a regular lattice: every ray (t0 ≤ t1) of column i and
    // row r of the query starts at column_org[i] along the view's u axis, row_org[r] along v and
    // depth_org along the rays, with one range [t0, t1].
    bool regular = false;
    double depth_org = 0.0, t0 = 0.0, t1 = 0.0;
    std::vector<double> column_org, row_org;
    void read_lattice(const AxisRays& rays) {
      const View& view = *rays.lattice;
      const int ua = exact_axis(view.u), va = exact_axis(view.v), width = view.width;
      const int rows = int(rays.rays.size() / std::size_t(width));
      column_org.resize(std::size_t(width));
      row_org.resize(std::size_t(rows));
      for (int i = 0; i < width; ++i)
        column_org[i] = rays.rays[i].org[ua];
      for (int r = 0; r < rows; ++r)
        row_org[r] = rays.rays[std::size_t(r) * std::size_t(width)].org[va];
      regular = ua >= 0 && va >= 0;
      bool first = true;
      for (std::size_t k = 0; k < rays.rays.size() && regular; ++k) {
        const AxisRay& ray = rays.rays[k];
        if (!(ray.t0 <= ray.t1)) continue;
        if (first) depth_org = ray.org[rays.axis], t0 = ray.t0, t1 = ray.t1, first = false;
        regular = ray.org[ua] == column_org[k % width] && ray.org[va] == row_org[k / width] &&
                  ray.org[rays.axis] == depth_org && ray.t0 == t0 && ray.t1 == t1;
      }
    }
    // Per line of the element's pixels: whether its rays are inside the element along the
    // reference axis its image axis maps to, and the basis there.
    struct Line {
      bool inside;
      PointBasis basis;
    };
    std::vector<Line> outer, inner;
    std::vector<double> inner_values, h;  // n rows of one value per inner pixel
    std::vector<int> candidates;          // the inner pixels that may have a root
    std::vector<curved::RayRef> batch;    // the pixel rays through a curved element's piece
  };

  // The pixels of the lattice query `rays` whose centres element e's box covers,
  // in the order that keeps the staged restriction's first stages: rows of the image axis
  // whose world axis maps to the lower of the two reference axes across the ray.
  void cast_element(std::uint32_t e, const AxisRays& rays, AxisHits& out, Scratch& scratch) const {
    with_order(active_.order, [&](auto p) { cast_element_order<p>(e, rays, out, scratch); });
  }

  template <int P>
  void cast_element_order(std::uint32_t e, const AxisRays& rays, AxisHits& out,
                          Scratch& scratch) const {
    const View& view = *rays.lattice;
    const ActiveElement& el = active_.elements[e];
    const int ua = exact_axis(view.u), va = exact_axis(view.v), wa = rays.axis;
    const int rows = int(rays.rays.size() / std::size_t(view.width));
    // Pixels whose centres lie in the box (an affine element lies in its box), with a margin
    // far above rounding: the exact test is the clip below.
    // The pixels whose centres lie in the box [lo, hi] (with a margin far above rounding: the
    // exact tests come later), in this query's rows; false if none.
    const auto pixels_of = [&](glm::dvec3 lo, glm::dvec3 hi, int& i0, int& i1, int& j0, int& j1) {
      const auto range = [&](int axis, double sign, int count, int& first, int& last) {
        const double x0 = (lo[axis] - view.origin[axis]) / (view.spacing * sign),
                     x1 = (hi[axis] - view.origin[axis]) / (view.spacing * sign);
        first = int(std::max(0.0, std::ceil(std::min(x0, x1) - 0.5 - 1e-6)));
        last = int(std::min(double(count - 1), std::floor(std::max(x0, x1) - 0.5 + 1e-6)));
      };
      range(ua, view.u[ua], view.width, i0, i1);
      range(va, view.v[va], view.height, j0, j1);
      j0 = std::max(j0, rays.row_begin);
      j1 = std::min(j1, rays.row_begin + rows - 1);
      return i0 <= i1 && j0 <= j1;
    };
    int i0, i1, j0, j1;
    if (!pixels_of(el.lo, el.hi, i0, i1, j0, j1)) return;  // an affine element lies in its box
    const auto index = [&](int i, int j) {
      return std::size_t(j - rays.row_begin) * std::size_t(view.width) + std::size_t(i);
    };
    if (el.curved != ActiveElement::kAffine) {
      // Each piece of the element that may hold the isosurface, with the pixel rays of its box
      // at once (they share the search's boxes).
      std::vector<curved::RayRef>& batch = scratch.batch;
      const curved::Pieces& pieces = *pieces_[e];
      for (std::size_t piece = 0; piece < pieces.pieces().size(); ++piece) {
        const curved::Piece& box = pieces.pieces()[piece];
        if (!pixels_of(box.world_lo, box.world_hi, i0, i1, j0, j1)) continue;
        batch.clear();
        for (int j = j0; j <= j1; ++j)
          for (int i = i0; i <= i1; ++i) {
            const std::size_t k = index(i, j);
            const AxisRay& ray = rays.rays[k];
            if (ray.t0 <= ray.t1) batch.push_back({std::uint32_t(k), ray.org, ray.t0, ray.t1});
          }
        if (!batch.empty()) pieces.intersect(piece, batch, rays.dir, out);
      }
      return;
    }

    // The reference axis each world axis maps to (−1: none, 3: several).
    const glm::dmat3& m = el.to_reference;
    const auto reference_of = [&](int world) {
      int r = -1;
      for (int k = 0; k < 3; ++k)
        if (m[world][k] != 0.0) r = r < 0 ? k : 3;
      return r;
    };
    const int ru = reference_of(ua), rv = reference_of(va), rw = reference_of(wa);
    // The image axis whose reference axis is the lower of the two across the ray goes in the
    // outer loop, so that the first stage of the restriction is kept along the inner one.
    const bool columns_outer = ru >= 0 && ru < 3 && rv >= 0 && rv < 3 && ru < rv;
    const int outer0 = columns_outer ? i0 : j0, outer1 = columns_outer ? i1 : j1;
    const int inner0 = columns_outer ? j0 : i0, inner1 = columns_outer ? j1 : i1;
    const auto pixel = [&](int outer, int inner) {
      return columns_outer ? index(outer, inner) : index(inner, outer);
    };

    const double* c = active_.coefficients_of(e);
    const glm::dvec3 rd = m * rays.dir;
    const glm::dmat3 to_world_gradient = glm::transpose(m);
    // The hit at parameter s of pixel k's clipped stretch [t0, t1], with reference gradient g.
    const auto hit_at = [&](std::size_t k, double s, double t0, double t1, glm::dvec3 g) {
      out.push_back(
          {std::uint32_t(k),
           {segment_point(t0, t1, s), unit_normal(to_world_gradient * g, rays.dir), 0.0f}});
    };
    // The roots of f[0..n] along the clipped stretch [t0, t1] of pixel k's ray, with the
    // reference gradient at parameter s from `gradient`.
    const auto emit = [&]<int n>(std::integral_constant<int, n>, std::size_t k, const double* f,
                                 double t0, double t1, auto gradient) {
      bernstein_roots<n>(f, [&](double s) { hit_at(k, s, t0, t1, gradient(s)); });
    };

    // Any pixel on its own, as intersect_element does it (the clip, the restriction and the
    // roots), with the staged restriction keeping the stages that rows of pixels share.
    StagedRestriction<P> staged(c);
    const auto cast_pixel = [&](std::size_t k) {
      const AxisRay& ray = rays.rays[k];
      double t0 = ray.t0, t1 = ray.t1;
      glm::dvec3 a, b;
      if (!clip_to_element(el, ray.org, rays.dir, t0, t1, a, b)) return;
      const auto tensor_gradient = [&](double s) {
        return evaluate_tensor<P>(c, a + s * (b - a)).gradient;
      };
      double f[kMaxRayDegree + 1] = {};  // zeroed: not every degree writes all of it
      if (AxisSplit axes; axis_parallel(a, b, axes)) {
        restrict_axis_parallel<P>(c, axes, a, b, f);
        emit(std::integral_constant<int, P>{}, k, f, t0, t1, tensor_gradient);
        return;
      }
      const int degree = staged.restrict(a, b, f);
      if (degree <= 0) return;  // constant along the ray, or no root possible
      with_degree<P>(degree, [&](auto n) {
        if constexpr (n > 0)
          emit(n, k, f, t0, t1, [&](double s) {
            glm::dvec3 g;
            if (!staged.gradient(s, g)) g = tensor_gradient(s);
            return g;
          });
      });
    };

    const bool separable = ru >= 0 && ru < 3 && rv >= 0 && rv < 3 && rw >= 0 && rw < 3 &&
                           ru != rv && ru != rw && rv != rw;
    if (!separable || !scratch.regular) {
      for (int outer = outer0; outer <= outer1; ++outer)
        for (int inner = inner0; inner <= inner1; ++inner)
          if (const std::size_t k = pixel(outer, inner); rays.rays[k].t0 <= rays.rays[k].t1)
            cast_pixel(k);
      return;
    }

    // An element whose edges lie along the world axes (each world axis maps to one reference
    // axis) in a regular lattice: every pixel's segment is parallel to reference axis rw, and
    // the clip separates. A pixel's reference coordinate across the ray depends on its column
    // alone along ru and on its row alone along rv (the other terms of the product are exact
    // zeros); its stretch along the ray on neither. So the clip is done once per column, row
    // and element, the bases once per column and row, the u contraction once per outer line
    // and the segment's matrix once: the same operations as restrict_axis_parallel on each
    // pixel, so the same bits.
    const AxisSplit axes{std::min(ru, rv), std::max(ru, rv), rw};
    const auto origin_of = [&](int i, int j) {  // the ray origin of pixel (i, j), as a ray has it
      glm::dvec3 org;
      org[ua] = scratch.column_org[i];
      org[va] = scratch.row_org[j - rays.row_begin];
      org[wa] = scratch.depth_org;
      return m * (org - el.origin);
    };
    const glm::dvec3 ro0 = origin_of(i0, j0);
    const double inv = 1.0 / rd[rw];
    double ta = (0.0 - ro0[rw]) * inv, tb = (1.0 - ro0[rw]) * inv;
    if (ta > tb) std::swap(ta, tb);
    const double t0 = std::max(scratch.t0, ta), t1 = std::min(scratch.t1, tb);
    if (!(t0 < t1)) return;
    const double a_w = std::clamp(ro0[rw] + t0 * rd[rw], 0.0, 1.0);
    const double b_w = std::clamp(ro0[rw] + t1 * rd[rw], 0.0, 1.0);
    SegmentMatrix segment;
    segment_matrix<P>(a_w, b_w, segment);
    const auto fill = [&](std::vector<Scratch::Line>& lines, int r, int lo, int hi, bool outer) {
      lines.resize(std::size_t(hi - lo + 1));
      for (int q = lo; q <= hi; ++q) {
        const double x = (outer == columns_outer ? origin_of(q, j0) : origin_of(i0, q))[r];
        Scratch::Line& line = lines[q - lo];
        line.inside = !(x < 0.0 || x > 1.0);
        bernstein_basis<P>(std::clamp(x + t0 * rd[r], 0.0, 1.0), line.basis.value,
                           line.basis.derivative);
      }
    };
    fill(scratch.outer, axes.u, outer0, outer1, true);
    fill(scratch.inner, axes.v, inner0, inner1, false);

    constexpr int n = P + 1;
    const int count = inner1 - inner0 + 1;
    const std::size_t inner_step = columns_outer ? std::size_t(view.width) : 1;
    // The inner bases' values as rows (B_j at every inner pixel), so that a line's polynomials
    // are computed with the pixels in the vector lanes.
    scratch.inner_values.resize(std::size_t(n) * count);
    scratch.h.resize(std::size_t(n) * count);
    scratch.candidates.resize(std::size_t(count));
    for (int j = 0; j < n; ++j)
      for (int q = 0; q < count; ++q)
        scratch.inner_values[std::size_t(j) * count + q] = scratch.inner[q].basis.value[j];
    for (int outer = outer0; outer <= outer1; ++outer) {
      const Scratch::Line& o = scratch.outer[outer - outer0];
      if (!o.inside) continue;
      FixedStage g, dg;
      contract_fixed_u<P>(c, axes, o.basis.value, g);
      // One strict sign over the line: the bases that follow are nonnegative and sum to one,
      // so no pixel of the line has a root.
      if (one_sign(&g[0][0], n, 1, kMaxNodes, 0, n)) continue;
      // The v contraction of every pixel of the line, h[l][q] = Σ_j g[j][l] · B_j(x_v(q)), in
      // the order contract_fixed_v takes (the same bits); then the pixels whose h does not
      // have one strict sign, without a branch on it.
      double* h = scratch.h.data();
      const double* bv = scratch.inner_values.data();
      for (int l = 0; l < n; ++l) {
        double* hl = h + std::size_t(l) * count;
        std::fill(hl, hl + count, 0.0);
        for (int j = 0; j < n; ++j) {
          const double gjl = g[j][l], *bj = bv + std::size_t(j) * count;
          for (int q = 0; q < count; ++q)
            hl[q] += gjl * bj[q];
        }
      }
      int candidates = 0;
      std::size_t k = pixel(outer, inner0);
      for (int q = 0; q < count; ++q, k += inner_step) {
        double lo = h[q], hi = h[q];
        for (int l = 1; l < n; ++l)
          lo = std::min(lo, h[std::size_t(l) * count + q]),
          hi = std::max(hi, h[std::size_t(l) * count + q]);
        const bool keep = scratch.inner[q].inside && rays.rays[k].t0 <= rays.rays[k].t1 &&
                          !(lo > kTinyCoefficient || hi < -kTinyCoefficient);
        scratch.candidates[candidates] = q;
        candidates += keep;
      }
      // Every candidate's roots isolated first, then converged four at a time (their chains of
      // divisions are independent and overlap, where one root after the other each waits on its
      // own), then appended in the order found: pixel by pixel, along each ray — the same hits,
      // to the bit, as emit on each pixel.
      std::vector<LineRoot<P>>& roots = line_roots<P>();
      roots.clear();
      for (int m = 0; m < candidates; ++m) {
        const int q = scratch.candidates[m];
        double hq[kMaxNodes], f[kMaxNodes];
        for (int l = 0; l < n; ++l)
          hq[l] = h[std::size_t(l) * count + q];
        along_segment<P>(hq, segment, f);
        isolate_roots<P>(
            f,
            [&](double s) {
              LineRoot<P>& root = roots.emplace_back();
              root.q = q, root.exact = true, root.s = s;
            },
            [&](const double* piece, double s0, double s1) {
              LineRoot<P>& root = roots.emplace_back();
              root.q = q, root.exact = false, root.s0 = s0, root.s1 = s1;
              std::copy(piece, piece + P + 1, root.c);
            });
      }
      converge_roots<P>(roots);
      bool dg_valid = false;
      for (const LineRoot<P>& root : roots) {
        const int q = root.q;
        const PointBasis& bq = scratch.inner[q].basis;
        // ∂/∂w from h, ∂/∂v from g with B_j'(x_v), ∂/∂u from the u contraction with B_i'(x_u)
        // (once per line, at its first hit), all at the hit's x_w.
        if (!dg_valid) {
          contract_fixed_u<P>(c, axes, o.basis.derivative, dg);
          dg_valid = true;
        }
        const double s = root.s;
        double bw[kMaxNodes], dbw[kMaxNodes];
        bernstein_basis<P>(a_w + s * (b_w - a_w), bw, dbw);
        double gu = 0.0, gv = 0.0, gw = 0.0;  // in registers: the axes are known at run time
        for (int l = 0; l < n; ++l) {
          double du = 0.0, dv = 0.0;
          for (int j = 0; j < n; ++j) {
            du += dg[j][l] * bq.value[j];
            dv += g[j][l] * bq.derivative[j];
          }
          gu += du * bw[l];
          gv += dv * bw[l];
          gw += h[std::size_t(l) * count + q] * dbw[l];
        }
        glm::dvec3 grad;
        grad[axes.u] = gu, grad[axes.v] = gv, grad[axes.w] = gw;
        hit_at(pixel(outer, inner0 + q), s, t0, t1, grad);
      }
    }
  }

  Activation active_;
  mutable std::array<ElementBins, 3> bins_;
  mutable std::array<std::once_flag, 3> bins_once_;
  // A curved element's pieces (the pixel rays share the search's first levels): boxes of a
  // quarter of the reference cube's width per axis (an eighth measured slower since the search is
  // preconditioned, and takes 8× the memory), only those where the field allows the isovalue;
  // the pixel rays through a piece are searched together (they share its boxes).
  mutable std::vector<std::optional<curved::Pieces>> pieces_;
  mutable std::once_flag pieces_once_;
};

}  // namespace

std::size_t vtk_lagrange_index(int i, int j, int k, int order) {
  check_order(order);
  if (std::min({i, j, k}) < 0 || std::max({i, j, k}) > order)
    throw std::invalid_argument("vtk_lagrange_index: node (" + std::to_string(i) + ", " +
                                std::to_string(j) + ", " + std::to_string(k) +
                                ") outside an element of order " + std::to_string(order));
  return vtk_index(i, j, k, order);
}

std::vector<double> node_positions(int order, NodeSet nodes) {
  check_order(order);
  check_node_set(nodes);
  std::vector<double> x = nodes_on_symmetric_interval(order, nodes);
  for (double& v : x)
    v = 0.5 * (v + 1.0);
  return x;
}

void lagrange_to_bernstein(int order, NodeSet nodes, std::span<const double> nodal,
                           std::span<double> bernstein) {
  check_order(order);
  check_node_set(nodes);
  const std::size_t n = nodes_per_element(order);
  if (nodal.size() != n || bernstein.size() != n)
    throw std::invalid_argument("lagrange_to_bernstein: spans must hold (order + 1)^3 values");
  if (std::less<const double*>()(nodal.data(), bernstein.data() + n) &&
      std::less<const double*>()(bernstein.data(), nodal.data() + n))
    throw std::invalid_argument("lagrange_to_bernstein: the spans overlap");
  convert_element(order, conversion_matrix(order, nodes), nodal.data(), bernstein.data());
}

PolynomialSample evaluate_bernstein(int order, std::span<const double> bernstein,
                                    glm::dvec3 reference) {
  check_order(order);
  if (bernstein.size() != std::size_t(nodes_per_element(order)))
    throw std::invalid_argument("evaluate_bernstein: span must hold (order + 1)^3 values");
  return with_order(order, [&](auto p) { return evaluate_tensor<p>(bernstein.data(), reference); });
}

namespace {

// The value and colour arrays' element types.
void check_scalar_types(const HexBlock& block) {
  const auto known = [](ScalarType t) {
    return t == ScalarType::float32 || t == ScalarType::float64;
  };
  if (!known(block.type)) throw std::invalid_argument("hex source: unknown scalar type");
  if (block.colour && !known(block.colour_type))
    throw std::invalid_argument("hex source: unknown scalar type of the colour field");
}

}  // namespace

HexElementSource::HexElementSource(const HexBlock& block, bool top_collapsed) : block_(block) {
  check_order(block.order);
  check_node_set(block.nodes);
  const std::size_t n = nodes_per_element(block.order);
  const int q = block.geometry_order;
  if (block.element_count == 0) throw std::invalid_argument("hex source: no elements");
  if (q < 0 || q > kMaxHexOrder)
    throw std::invalid_argument("hex source: geometry order " + std::to_string(q) + " outside 0.." +
                                std::to_string(kMaxHexOrder));
  if (q > 0 && !block.geometry) throw std::invalid_argument("hex source: null geometry array");
  if (q == 0 && !block.corners) throw std::invalid_argument("hex source: null corner array");
  if (!block.values) throw std::invalid_argument("hex source: null value array");
  if (block.ordering != NodeOrdering::lexicographic && block.ordering != NodeOrdering::vtk_lagrange)
    throw std::invalid_argument("hex source: unknown node ordering");
  check_scalar_types(block);
  if (block_.element_stride == 0) block_.element_stride = n;
  if (block_.element_stride < n)
    throw std::invalid_argument("hex source: element stride " +
                                std::to_string(block_.element_stride) +
                                " below (order + 1)^3 = " + std::to_string(n));

  // Each element's geometry in Bernstein form (degree q, or 1 for corners: a trilinear map's
  // Bernstein coefficients are its corners); affine ones keep the parallelepiped path, the
  // others are kept for the curved intersection.
  geometry_degree_ = q > 0 ? q : 1;
  const int gm = geometry_degree_ + 1;
  const std::size_t gn = std::size_t(gm) * gm * gm;
  const auto prepared = std::make_shared<Prepared>();
  geometry_ = prepared;
  prepared->corners.resize(24 * block.element_count);
  prepared->curved_of.assign(block.element_count, kNotCurved);
  std::vector<glm::dvec3> x(gn);
  std::vector<double> nodal(gn), bernstein(gn);
  constexpr double inf = std::numeric_limits<double>::infinity();
  bounds_ = {glm::dvec3(inf), glm::dvec3(-inf)};
  const auto vertex = [&](int c) {
    return std::size_t((c & 1) * geometry_degree_) +
           std::size_t(gm) * (std::size_t(((c >> 1) & 1) * geometry_degree_) +
                              std::size_t(gm) * std::size_t(((c >> 2) & 1) * geometry_degree_));
  };
  for (std::size_t e = 0; e < block.element_count; ++e) {
    if (q > 0) {
      const double* nodes = block.geometry + 3 * gn * e;
      const std::vector<std::uint16_t>& at = node_permutation(q, block.ordering);
      for (int axis = 0; axis < 3; ++axis) {
        for (std::size_t m = 0; m < gn; ++m)
          nodal[m] = nodes[3 * at[m] + axis];
        convert_element(q, conversion_matrix(q, block.nodes), nodal.data(), bernstein.data());
        for (std::size_t m = 0; m < gn; ++m)
          x[m][axis] = bernstein[m];
      }
      for (int c = 0; c < 8; ++c)
        for (int axis = 0; axis < 3; ++axis)
          prepared->corners[24 * e + 3 * c + axis] = x[vertex(c)][axis];
    } else {
      std::copy_n(block.corners + 24 * e, 24, &prepared->corners[24 * e]);
      for (int c = 0; c < 8; ++c)
        x[c] = corner(block.corners + 24 * e, c);
    }
    for (const glm::dvec3& v : x)
      if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
        throw std::invalid_argument("hex source: element " + std::to_string(e) +
                                    " has a non-finite geometry node");
    const AffineFrame f = frame_of(corners_of(e));
    const glm::dvec3 e1 = f.axes[0], e2 = f.axes[1], e3 = f.axes[2];
    const double size = glm::length(e1) + glm::length(e2) + glm::length(e3);
    bool affine = true;
    for (int k = 0; k < gm && affine; ++k)
      for (int j = 0; j < gm && affine; ++j)
        for (int i = 0; i < gm && affine; ++i) {
          const glm::dvec3 a = f.origin + (double(i) / geometry_degree_) * e1 +
                               (double(j) / geometry_degree_) * e2 +
                               (double(k) / geometry_degree_) * e3;
          affine = glm::length(x[i + gm * (j + gm * k)] - a) <= 1e-9 * size;
        }
    Box box;
    if (affine) {
      if (!(std::abs(glm::determinant(f.axes)) >
            1e-12 * glm::length(e1) * glm::length(e2) * glm::length(e3)))
        throw std::invalid_argument("hex source: element " + std::to_string(e) +
                                    " is degenerate (zero volume)");
      box = bounding_box(f);
    } else {
      check_jacobian(e, x, top_collapsed);
      prepared->curved_of[e] = std::uint32_t(prepared->curved.size() / gn);
      prepared->curved.insert(prepared->curved.end(), x.begin(), x.end());
      box = {x[0], x[0]};
      for (const glm::dvec3& v : x)  // the convex hull property
        box.lo = glm::min(box.lo, v), box.hi = glm::max(box.hi, v);
    }
    bounds_.lo = glm::min(bounds_.lo, box.lo);
    bounds_.hi = glm::max(bounds_.hi, box.hi);
  }
}

HexElementSource::HexElementSource(const HexElementSource& prepared, const HexBlock& block)
    : block_(block),
      bounds_(prepared.bounds_),
      geometry_degree_(prepared.geometry_degree_),
      geometry_(prepared.geometry_) {
  const HexBlock& p = prepared.block_;
  if (block.order != p.order || block.nodes != p.nodes || block.ordering != p.ordering ||
      block.element_count != p.element_count || block.geometry_order != p.geometry_order)
    throw std::invalid_argument(
        "hex source: the block's layout (order, node set, ordering, element count, geometry "
        "order) differs from the prepared source's");
  if (!block.values) throw std::invalid_argument("hex source: null value array");
  check_scalar_types(block);
  const std::size_t n = nodes_per_element(block.order);
  if (block_.element_stride == 0) block_.element_stride = n;
  if (block_.element_stride < n)
    throw std::invalid_argument("hex source: element stride " +
                                std::to_string(block_.element_stride) +
                                " below (order + 1)^3 = " + std::to_string(n));
}

HexElementSource::HexElementSource(const HexElementSource& prepared, const HexBlock& block,
                                   std::vector<std::uint8_t> held)
    : HexElementSource(prepared, block) {
  if (held.size() != block_.element_count)
    throw std::invalid_argument("hex source: " + std::to_string(held.size()) +
                                " element flags for " + std::to_string(block_.element_count) +
                                " elements");
  held_ = std::make_shared<const std::vector<std::uint8_t>>(std::move(held));
}

namespace {

// Calls range(e, lo, hi) with the least and greatest Bernstein coefficient of every element e of
// `source` whose values it holds (HexElementSource::held) and that has no non-finite nodal
// value, in parallel, converting each element; returns how many non-finite nodal values the
// others have.
template <class Range>
std::uint64_t coefficient_ranges(const HexElementSource& source, Range range) {
  const HexBlock& block = source.block();
  const int p = block.order;
  const std::size_t n = nodes_per_element(p);
  const std::span<const std::uint8_t> held = source.held();
  const ConversionMatrix& matrix = conversion_matrix(p, block.nodes);
  std::atomic<std::uint64_t> nonfinite{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, block.element_count, 64),
                    [&](const tbb::blocked_range<std::size_t>& elements) {
                      double nodal[kMaxElementValues], b[kMaxElementValues];
                      std::uint64_t bad = 0;
                      for (std::size_t e = elements.begin(); e != elements.end(); ++e) {
                        if (!held.empty() && !held[e]) continue;
                        if (const std::size_t k = read_nodal(block, e, n, nodal); k > 0) {
                          bad += k;
                          continue;
                        }
                        convert_element(p, matrix, nodal, b);
                        const auto [lo, hi] = std::minmax_element(b, b + n);
                        range(e, *lo, *hi);
                      }
                      if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
                    });
  return nonfinite.load();
}

}  // namespace

std::vector<std::uint8_t> HexElementSource::needed_elements(
    std::span<const double> isovalues) const {
  // The elements bind() keeps for one of the isovalues, and those it leaves out for a NaN or
  // ±Inf value (flagged first, then cleared where the range comes).
  std::vector<std::uint8_t> needed(block_.element_count, 1);
  for (std::size_t e = 0; e < needed.size(); ++e)
    if (held_ && !(*held_)[e]) needed[e] = 0;
  coefficient_ranges(*this, [&](std::size_t e, double lo, double hi) {
    needed[e] = std::any_of(isovalues.begin(), isovalues.end(),
                            [&](double iso) { return lo <= iso && iso <= hi; });
  });
  return needed;
}

namespace {

// The colour field of an element block: a source over the colour's nodal values with the block's
// prepared geometry, and a lookup of the element that holds a point (its values read when
// bound, as bind() reads the isovalue's field).
class HexScalarProbe final : public ScalarProbe {
 public:
  HexScalarProbe(const HexElementSource& prepared, const HexBlock& colour)
      : source_(prepared, colour), sources_{&source_}, lookup_(sources_) {}
  HexScalarProbe(const HexScalarProbe&) = delete;  // the lookup points at source_
  HexScalarProbe& operator=(const HexScalarProbe&) = delete;
  double at(glm::dvec3 p) const override { return value(p, false); }
  double near(glm::dvec3 p) const override { return value(p, true); }

 private:
  double value(glm::dvec3 p, bool extrapolate) const {
    // Each thread's last element first: a row of pixels' hits lie in few elements. The hint
    // cannot change the answer (HexFieldLookup::sample).
    thread_local HexFieldLookup::Hint hint;
    double v = 0.0;
    return lookup_.value(p, v, hint, extrapolate) ? v : std::numeric_limits<double>::quiet_NaN();
  }

  HexElementSource source_;
  std::array<const HexElementSource*, 1> sources_;
  HexFieldLookup lookup_;
};

}  // namespace

std::unique_ptr<ScalarProbe> HexElementSource::bind_scalar() const {
  if (!block_.colour) return nullptr;
  return std::make_unique<HexScalarProbe>(*this, colour_as_values(block_));
}

// A curved element's Jacobian determinant has one strict sign (either: a mirrored element is
// fine) at the (q + 2)³ points of a uniform lattice of its reference cube; zero or a change of
// sign there means a folded (inverted) or degenerate element. A necessary condition, checked
// where the solver's mesh generator would have gone wrong.
void HexElementSource::check_jacobian(std::size_t element, const std::vector<glm::dvec3>& x,
                                      bool top_collapsed) const {
  // The Jacobian at the lattice by sum factorization over the geometry's Bernstein form: the
  // 1-D basis and its derivative at the lattice's coordinates, then one axis contracted at a
  // time (O(q⁴) per element instead of a full evaluation per point).
  const int q = geometry_degree_, m = q + 1, points = q + 2;
  std::vector<double> basis(std::size_t(points) * m), derivative(std::size_t(points) * m);
  for (int a = 0; a < points; ++a) {
    const double t = double(a) / (points - 1);
    // B_{i,n}(t) for n = q − 1 (the derivative's basis) and n = q.
    std::vector<double> lower(m, 0.0), upper(m, 0.0);
    upper[0] = 1.0;
    for (int n = 1; n <= q; ++n) {
      if (n == q) lower = upper;  // degree q − 1
      for (int i = n; i >= 0; --i)
        upper[i] = (i > 0 ? t * upper[i - 1] : 0.0) + (i < n ? (1.0 - t) * upper[i] : 0.0);
    }
    for (int i = 0; i < m; ++i) {
      basis[a * m + i] = upper[i];
      // d/dt B_{i,q} = q (B_{i−1,q−1} − B_{i,q−1})
      derivative[a * m + i] = q * ((i > 0 ? lower[i - 1] : 0.0) - (i < q ? lower[i] : 0.0));
    }
  }
  // Contract ξ: value and ∂ξ per (point a, coefficient j, k).
  const std::size_t mm = std::size_t(m) * m;
  std::vector<glm::dvec3> v1(points * mm), d1(points * mm);
  for (int a = 0; a < points; ++a)
    for (std::size_t jk = 0; jk < mm; ++jk) {
      glm::dvec3 v(0.0), d(0.0);
      for (int i = 0; i < m; ++i) {
        v += basis[a * m + i] * x[i + m * jk];
        d += derivative[a * m + i] * x[i + m * jk];
      }
      v1[a * mm + jk] = v;
      d1[a * mm + jk] = d;
    }
  // Contract η: value, ∂ξ and ∂η per (a, b, coefficient k).
  const std::size_t pp = std::size_t(points) * points;
  std::vector<glm::dvec3> v2(pp * m), dx2(pp * m), dy2(pp * m);
  for (int b = 0; b < points; ++b)
    for (int a = 0; a < points; ++a)
      for (int k = 0; k < m; ++k) {
        glm::dvec3 v(0.0), dx(0.0), dy(0.0);
        for (int j = 0; j < m; ++j) {
          const std::size_t from = a * mm + j + std::size_t(m) * k;
          v += basis[b * m + j] * v1[from];
          dx += basis[b * m + j] * d1[from];
          dy += derivative[b * m + j] * v1[from];
        }
        const std::size_t to = (a + std::size_t(points) * b) * m + k;
        v2[to] = v;
        dx2[to] = dx;
        dy2[to] = dy;
      }
  // Contract ζ at each lattice point, in the order of the lattice (ξ fastest), and test.
  int sign = 0;
  for (int c = 0; c < points - (top_collapsed ? 1 : 0); ++c)
    for (int b = 0; b < points; ++b)
      for (int a = 0; a < points; ++a) {
        glm::dmat3 jac(0.0);
        const std::size_t from = (a + std::size_t(points) * b) * m;
        for (int k = 0; k < m; ++k) {
          jac[0] += basis[c * m + k] * dx2[from + k];
          jac[1] += basis[c * m + k] * dy2[from + k];
          jac[2] += derivative[c * m + k] * v2[from + k];
        }
        // Relative to the columns' lengths, as the affine test: thin elements are fine.
        const double det = glm::determinant(jac),
                     tol = 1e-10 * glm::length(jac[0]) * glm::length(jac[1]) * glm::length(jac[2]);
        const int s = det > tol ? 1 : det < -tol ? -1 : 0;
        if (s == 0 || (sign != 0 && s != sign)) {
          const glm::dvec3 xi(double(a) / (points - 1), double(b) / (points - 1),
                              double(c) / (points - 1));
          throw std::invalid_argument(
              "hex source: element " + std::to_string(element) +
              " is inverted or degenerate (its Jacobian determinant vanishes or changes sign "
              "near reference point (" +
              std::to_string(xi.x) + ", " + std::to_string(xi.y) + ", " + std::to_string(xi.z) +
              "))");
        }
        sign = s;
      }
}

Box HexElementSource::bounds() const {
  return bounds_;
}

const double* HexElementSource::corners_of(std::size_t element) const {
  return &geometry_->corners[24 * element];
}

std::span<const glm::dvec3> HexElementSource::curved_geometry(std::size_t element) const {
  const std::uint32_t k = geometry_->curved_of[element];
  if (k == kNotCurved) return {};
  const std::size_t gn =
      std::size_t(geometry_degree_ + 1) * (geometry_degree_ + 1) * (geometry_degree_ + 1);
  return {&geometry_->curved[k * gn], gn};
}

glm::dvec3 HexElementSource::to_world(std::size_t element, glm::dvec3 reference) const {
  if (is_curved(element)) {
    const curved::Element ce{block_.order, geometry_degree_, nullptr,
                             curved_geometry(element).data()};
    return curved::evaluate(ce, reference).x;
  }
  const AffineFrame f = frame_of(corners_of(element));
  return f.origin + f.axes * reference;
}

glm::dvec3 HexElementSource::to_reference(std::size_t element, glm::dvec3 world) const {
  if (is_curved(element)) {
    const curved::Element ce{block_.order, geometry_degree_, nullptr,
                             curved_geometry(element).data()};
    glm::dvec3 xi;
    return curved::invert(ce, world, xi) ? xi
                                         : glm::dvec3(std::numeric_limits<double>::quiet_NaN());
  }
  const AffineFrame f = frame_of(corners_of(element));
  return glm::inverse(f.axes) * (world - f.origin);
}

void HexElementSource::element_bernstein(std::size_t element, std::span<double> out) const {
  const int p = block_.order;
  const std::size_t n = nodes_per_element(p);
  if (out.size() != n)
    throw std::invalid_argument("element_bernstein: span must hold (order + 1)^3 values");
  double nodal[kMaxElementValues];
  read_nodal(block_, element, n, nodal);
  convert_element(p, conversion_matrix(p, block_.nodes), nodal, out.data());
}

namespace {

// The elements of `source` whose Bernstein coefficient range holds `isovalue`, with their
// coefficients (iso subtracted) and frames, in element order (the same for any thread count).
Activation activate(const HexElementSource& source, double isovalue) {
  const HexBlock& block = source.block();
  const int p = block.order;
  const std::size_t n = nodes_per_element(p);
  const std::size_t count = block.element_count;

  // Pass 1: which elements may hold the isosurface (convex hull of the Bernstein coefficients).
  // Flags only, so memory does not grow with the block. An element with a non-finite nodal
  // value has no polynomial to intersect: it is left out.
  std::vector<std::uint8_t> active(count, 0);
  const std::uint64_t nonfinite = coefficient_ranges(
      source,
      [&](std::size_t e, double lo, double hi) { active[e] = lo <= isovalue && isovalue <= hi; });
  std::vector<std::size_t> kept;
  for (std::size_t e = 0; e < count; ++e)
    if (active[e]) kept.push_back(e);

  // Pass 2: the kept elements' coefficients (converted again: usually few are kept) and frames.
  Activation out;
  out.order = p;
  out.values_per_element = n;
  out.nonfinite = nonfinite;
  out.elements.resize(kept.size());
  out.coefficients.resize(kept.size() * n);
  // The curved ones' geometry, numbered in element order.
  out.geometry_degree = source.geometry_degree();
  out.points_per_element =
      std::size_t(out.geometry_degree + 1) * (out.geometry_degree + 1) * (out.geometry_degree + 1);
  std::size_t curved = 0;
  for (std::size_t k = 0; k < kept.size(); ++k)
    if (source.is_curved(kept[k])) out.elements[k].curved = std::uint32_t(curved++);
  out.geometry.resize(curved * out.points_per_element);
  tbb::parallel_for(std::size_t(0), kept.size(), [&](std::size_t k) {
    const std::size_t e = kept[k];
    const std::span<double> b(&out.coefficients[k * n], n);
    source.element_bernstein(e, b);
    for (double& v : b)
      v -= isovalue;
    ActiveElement& el = out.elements[k];
    if (el.curved != ActiveElement::kAffine) {
      const std::span<const glm::dvec3> x = source.curved_geometry(e);
      std::copy(x.begin(), x.end(), &out.geometry[el.curved * out.points_per_element]);
      el.origin = glm::dvec3(0.0);
      el.to_reference = glm::dmat3(1.0);
      el.lo = el.hi = x[0];
      for (const glm::dvec3& v : x)  // the convex hull property
        el.lo = glm::min(el.lo, v), el.hi = glm::max(el.hi, v);
      return;
    }
    const AffineFrame f = frame_of(source.corners_of(e));
    el.origin = f.origin;
    el.to_reference = glm::inverse(f.axes);
    const Box box = bounding_box(f);
    el.lo = box.lo;
    el.hi = box.hi;
  });
  return out;
}

}  // namespace

std::unique_ptr<GeometryBinding> HexElementSource::bind(RTCDevice device, double isovalue) const {
  return std::make_unique<HexBinding>(device, activate(*this, isovalue));
}

std::unique_ptr<AxisBinding> HexElementSource::bind_axis(double isovalue) const {
  return std::make_unique<HexAxisBinding>(activate(*this, isovalue));
}

}  // namespace ldimesh

#include "ldimesh/core/hex_source.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace ldimesh {
namespace {

constexpr int kMaxNodes = kMaxHexOrder + 1;
constexpr int kMaxElementValues = kMaxNodes * kMaxNodes * kMaxNodes;
constexpr int kMaxRayDegree = 3 * kMaxHexOrder;  // f along a ray: degree p in each of ξ, η, ζ

// Below this width (in the ray parameter s ∈ [0, 1]) an interval that still has several sign
// variations is decided by its end values alone: a touching double root is dropped.
constexpr double kMinWidth = 1e-12;
// Roots are converged to this width in s, i.e. to 1e-13 of the segment, at most of the element.
constexpr double kConverged = 1e-13;
// Bound on the intervals one element-ray search visits. Only a polynomial that is zero up to
// rounding over a stretch (a plateau at the isovalue) comes near it: its coefficients are noise
// whose sign variations would otherwise be split down to kMinWidth everywhere.
constexpr int kMaxIntervals = 4096;

constexpr std::array<std::array<double, kMaxRayDegree + 1>, kMaxRayDegree + 1> kBinomial = [] {
  std::array<std::array<double, kMaxRayDegree + 1>, kMaxRayDegree + 1> c{};
  for (int n = 0; n <= kMaxRayDegree; ++n) {
    c[n][0] = c[n][n] = 1.0;
    for (int k = 1; k < n; ++k)
      c[n][k] = c[n - 1][k - 1] + c[n - 1][k];
  }
  return c;
}();

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

// Sum factorisation: the 1-D conversion applied along ξ, then η, then ζ ((p + 1)⁴ operations
// instead of (p + 1)⁶). `in` and `out` hold (p + 1)³ values and may not overlap.
void convert_element(int order, const ConversionMatrix& m, const double* in, double* out) {
  const int n = order + 1;
  double work[2][kMaxElementValues];
  const double* src = in;
  const int strides[3] = {1, n, n * n};
  for (int axis = 0; axis < 3; ++axis) {
    double* dst = axis == 2 ? out : work[axis];
    const int s = strides[axis];
    // Lines along `axis` start at every index whose `axis` digit is zero.
    for (int base = 0; base < n * n * n; ++base) {
      if ((base / s) % n != 0) continue;
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

// Copies the (p + 1)³ = n nodal values of `element` as doubles into `nodal`; returns how many
// are NaN or ±Inf.
std::size_t read_nodal(const HexBlock& block, std::size_t element, std::size_t n, double* nodal) {
  const std::size_t first = element * block.element_stride;
  // One branch per element on the scalar type, none per value.
  if (block.type == ScalarType::float32)
    std::copy_n(static_cast<const float*>(block.values) + first, n, nodal);
  else
    std::copy_n(static_cast<const double*>(block.values) + first, n, nodal);
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
// Evaluation

// B_i^p(x) and dB_i^p/dx for i = 0..p, from the triangle B_i^r = (1 − x) B_i^{r−1} + x
// B_{i−1}^{r−1} and dB_i^p/dx = p (B_{i−1}^{p−1} − B_i^{p−1}).
void bernstein_basis(int p, double x, double* value, double* derivative) {
  double b[kMaxNodes] = {1.0};
  for (int r = 1; r < p; ++r) {
    b[r] = x * b[r - 1];
    for (int i = r - 1; i > 0; --i)
      b[i] = (1.0 - x) * b[i] + x * b[i - 1];
    b[0] *= 1.0 - x;
  }
  for (int i = 0; i <= p; ++i) {
    const double left = i > 0 ? b[i - 1] : 0.0, right = i < p ? b[i] : 0.0;
    derivative[i] = p * (left - right);
    value[i] = (1.0 - x) * right + x * left;
  }
}

PolynomialSample evaluate_tensor(int p, const double* coefficients, glm::dvec3 r) {
  const int n = p + 1;
  double bx[kMaxNodes], dx[kMaxNodes], by[kMaxNodes], dy[kMaxNodes], bz[kMaxNodes], dz[kMaxNodes];
  bernstein_basis(p, r.x, bx, dx);
  bernstein_basis(p, r.y, by, dy);
  bernstein_basis(p, r.z, bz, dz);
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

// out[0..m+n] = a[0..m] ⊛ b[0..n], accumulated.
void convolve_add(const double* a, int m, const double* b, int n, double* out) {
  for (int i = 0; i <= m; ++i)
    for (int j = 0; j <= n; ++j)
      out[i + j] += a[i] * b[j];
}

// Scaled coefficients in s of B_i^p(x(s)), i = 0..p, for x(s) = xa (1 − s) + xb s. Returns their
// degree in s: p, or 0 where the segment does not move along this axis (xa == xb, as for an
// axis-aligned ray through an axis-aligned element), which keeps the degree along the ray low.
int basis_along_segment(int p, double xa, double xb, double (*basis)[kMaxNodes]) {
  if (xa == xb) {
    double value[kMaxNodes], derivative[kMaxNodes];
    bernstein_basis(p, xa, value, derivative);
    for (int i = 0; i <= p; ++i)
      basis[i][0] = value[i];
    return 0;
  }
  double x_pow[kMaxNodes][kMaxNodes] = {}, y_pow[kMaxNodes][kMaxNodes] = {};  // X^i, (1 − X)^i
  x_pow[0][0] = y_pow[0][0] = 1.0;
  for (int i = 1; i <= p; ++i)
    for (int l = 0; l <= i; ++l) {
      const double lo = l < i ? x_pow[i - 1][l] : 0.0, hi = l > 0 ? x_pow[i - 1][l - 1] : 0.0;
      x_pow[i][l] = xa * lo + xb * hi;
      const double ylo = l < i ? y_pow[i - 1][l] : 0.0, yhi = l > 0 ? y_pow[i - 1][l - 1] : 0.0;
      y_pow[i][l] = (1.0 - xa) * ylo + (1.0 - xb) * yhi;
    }
  for (int i = 0; i <= p; ++i) {
    std::fill(basis[i], basis[i] + p + 1, 0.0);
    convolve_add(x_pow[i], i, y_pow[p - i], p - i, basis[i]);
    for (int l = 0; l <= p; ++l)
      basis[i][l] *= kBinomial[p][i];
  }
  return p;
}

// Standard Bernstein coefficients f[0..n] on s ∈ [0, 1] of the tensor polynomial with
// coefficients `c` along the straight segment from reference point a (s = 0) to b (s = 1);
// returns the degree n ≤ 3p (p per reference axis the segment moves along).
int restrict_to_segment(int p, const double* c, glm::dvec3 a, glm::dvec3 b, double* f) {
  const int n = p + 1;
  double bx[kMaxNodes][kMaxNodes], by[kMaxNodes][kMaxNodes], bz[kMaxNodes][kMaxNodes];
  const int dx = basis_along_segment(p, a.x, b.x, bx);
  const int dy = basis_along_segment(p, a.y, b.y, by);
  const int dz = basis_along_segment(p, a.z, b.z, bz);
  const int degree = dx + dy + dz;
  std::fill(f, f + degree + 1, 0.0);
  for (int k = 0; k < n; ++k) {
    double h[2 * kMaxHexOrder + 1] = {};  // H_k = Σ_j G_jk · By_j, degree dx + dy
    for (int j = 0; j < n; ++j) {
      double g[kMaxNodes] = {};  // G_jk = Σ_i c_ijk Bx_i, degree dx
      const double* row = c + n * (j + n * k);
      for (int i = 0; i < n; ++i)
        for (int l = 0; l <= dx; ++l)
          g[l] += row[i] * bx[i][l];
      convolve_add(g, dx, by[j], dy, h);
    }
    convolve_add(h, dx + dy, bz[k], dz, f);
  }
  for (int l = 0; l <= degree; ++l)
    f[l] /= kBinomial[degree][l];
  return degree;
}

// ---------------------------------------------------------------------------------------------
// Roots of a univariate Bernstein polynomial on [0, 1]

// Value and derivative at u of the Bernstein polynomial c[0..n] on [0, 1] (de Casteljau).
void de_casteljau(const double* c, int n, double u, double& value, double& derivative) {
  double w[kMaxRayDegree + 1];
  std::copy(c, c + n + 1, w);
  for (int r = n; r > 1; --r)
    for (int i = 0; i < r; ++i)
      w[i] = (1.0 - u) * w[i] + u * w[i + 1];
  value = (1.0 - u) * w[0] + u * w[1];
  derivative = n * (w[1] - w[0]);
}

// Splits c[0..n] at 1/2 into the coefficients of the left and right halves (de Casteljau). The
// halves share their middle coefficient exactly, so sign tests at the split agree.
void split_in_half(const double* c, int n, double* left, double* right) {
  double w[kMaxRayDegree + 1];
  std::copy(c, c + n + 1, w);
  left[0] = w[0];
  right[n] = w[n];
  for (int r = 1; r <= n; ++r) {
    for (int i = 0; i <= n - r; ++i)
      w[i] = 0.5 * (w[i] + w[i + 1]);
    left[r] = w[0];
    right[n - r] = w[n - r];
  }
}

int sign_variations(const double* c, int n) {
  int v = 0;
  for (int i = 0; i < n; ++i)
    v += positive(c[i]) != positive(c[i + 1]);
  return v;
}

// The single root in [0, 1] of c[0..n], whose end values c[0] and c[n] differ in sign: Newton
// steps from a regula falsi start, falling back to bisection whenever they leave the bracket.
double converge(const double* c, int n, double tol) {
  if (c[n] == 0.0) return 1.0;  // exactly at the end: keep it exact (the half-open rule needs it)
  double a = 0.0, b = 1.0, ga = c[0];
  double u = c[0] / (c[0] - c[n]);
  if (!(u > a && u < b)) u = 0.5;
  for (int iter = 0; iter < 64 && b - a > tol; ++iter) {
    double g, dg;
    de_casteljau(c, n, u, g, dg);
    if (g == 0.0) return u;
    if (positive(g) == positive(ga)) {
      a = u;
      ga = g;
    } else {
      b = u;
    }
    double next = u - g / dg;
    if (!(next > a && next < b)) next = 0.5 * (a + b);
    if (std::abs(next - u) < tol) return next;
    u = next;
  }
  return u;
}

// Calls found(s) for every s ∈ [0, 1] where f = c[0..n] changes sign (zero counts as positive),
// in increasing order. Bernstein subdivision: by Descartes' rule of signs for the Bernstein
// basis, f has at most as many roots in a piece as its coefficients have sign variations. None:
// no sign change. One: the end coefficients (the end values) differ in sign, so exactly one
// simple root. More: split in half and look again.
template <class Found>
void bernstein_roots(const double* c, int n, Found found) {
  struct Piece {
    double s0, s1;
    double c[kMaxRayDegree + 1];
  };
  // Depth-first with the right half pushed first: at most one pending interval per level, and
  // kMinWidth = 1e-12 > 2^-40 bounds the levels.
  // A root exactly at the start belongs to this segment (the caster's half-open rule drops one
  // exactly at a shared end); the caster merges it with the same root found by subdivision.
  if (c[0] == 0.0) found(0.0);
  Piece stack[64];
  int top = 0;
  stack[top].s0 = 0.0, stack[top].s1 = 1.0;
  std::copy(c, c + n + 1, stack[top].c);
  ++top;
  int visited = 0;
  while (top > 0) {
    const Piece& iv = stack[--top];
    const int variations = sign_variations(iv.c, n);
    if (variations == 0) continue;
    const double w = iv.s1 - iv.s0;
    if (variations > 1 && w >= kMinWidth && top + 2 <= int(std::size(stack)) &&
        ++visited < kMaxIntervals) {
      // Copy out before the pushes overwrite this slot.
      double parent[kMaxRayDegree + 1];
      std::copy(iv.c, iv.c + n + 1, parent);
      const double s0 = iv.s0, s1 = iv.s1, sm = 0.5 * (s0 + s1);
      Piece& right = stack[top++];
      Piece& left = stack[top++];
      split_in_half(parent, n, left.c, right.c);
      left.s0 = s0, left.s1 = sm;
      right.s0 = sm, right.s1 = s1;
      continue;
    }
    // One variation: one root. Too small (or out of budget): a root only where the ends differ
    // in sign, so a touching double root without a sign change is dropped.
    if (positive(iv.c[0]) == positive(iv.c[n])) continue;
    const double u = converge(iv.c, n, kConverged / w);
    found(u == 1.0 ? iv.s1 : iv.s0 + w * u);
  }
}

// ---------------------------------------------------------------------------------------------
// The Embree binding

// What the intersect callback needs of one active element.
struct ActiveElement {
  glm::dvec3 origin;        // corner 0
  glm::dmat3 to_reference;  // inverse of the affine frame's axes
  glm::dvec3 lo, hi;        // axis-aligned bounds
};

class HexBinding final : public GeometryBinding {
 public:
  HexBinding(RTCDevice device, int order, std::vector<ActiveElement> elements,
             std::vector<double> coefficients, std::uint64_t nonfinite)
      : order_(order),
        values_per_element_(nodes_per_element(order)),
        elements_(std::move(elements)),
        coefficients_(std::move(coefficients)),
        nonfinite_(nonfinite),
        geometry_(device, elements_.size(), this, &HexBinding::bounds, &HexBinding::intersect) {}

  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return elements_.size(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const HexBinding*>(args->geometryUserPtr);
    const ActiveElement& e = self->elements_[args->primID];
    write_padded_bounds(e.lo, e.hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const HexBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    const ActiveElement& e = self->elements_[args->primID];
    const double* c = &self->coefficients_[std::size_t(args->primID) * self->values_per_element_];
    const int p = self->order_;

    // The ray in reference coordinates, clipped to the unit cube in double.
    const glm::dvec3 ro = e.to_reference * (q->org - e.origin), rd = e.to_reference * q->dir;
    double t0 = q->t_min, t1 = q->t_max;
    if (!clip_ray_to_box(ro, rd, glm::dvec3(0.0), glm::dvec3(1.0), t0, t1)) return;
    const glm::dvec3 a = glm::clamp(ro + t0 * rd, 0.0, 1.0), b = glm::clamp(ro + t1 * rd, 0.0, 1.0);

    double f[kMaxRayDegree + 1];
    const int degree = restrict_to_segment(p, c, a, b, f);
    const glm::dmat3 to_world_gradient = glm::transpose(e.to_reference);  // ∇x f = A⁻ᵀ ∇ξ f
    if (degree == 0) return;  // constant along the ray: no crossing
    bernstein_roots(f, degree, [&](double s) {
      const glm::dvec3 g = to_world_gradient * evaluate_tensor(p, c, a + s * (b - a)).gradient;
      const double len = glm::length(g);
      // At singular points (∇f = 0) the normal faces the viewer, as for analytic sources.
      const glm::vec3 normal = len > 0.0 ? glm::vec3(g / len) : glm::vec3(-q->dir);
      q->hits->push_back({s == 1.0 ? t1 : t0 + s * (t1 - t0), normal, 0.0f});
    });
  }

  int order_;
  std::size_t values_per_element_;
  std::vector<ActiveElement> elements_;
  std::vector<double> coefficients_;  // iso subtracted, values_per_element_ per active element
  std::uint64_t nonfinite_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

}  // namespace

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
  convert_element(order, conversion_matrix(order, nodes), nodal.data(), bernstein.data());
}

PolynomialSample evaluate_bernstein(int order, std::span<const double> bernstein,
                                    glm::dvec3 reference) {
  check_order(order);
  if (bernstein.size() != std::size_t(nodes_per_element(order)))
    throw std::invalid_argument("evaluate_bernstein: span must hold (order + 1)^3 values");
  return evaluate_tensor(order, bernstein.data(), reference);
}

HexElementSource::HexElementSource(const HexBlock& block) : block_(block) {
  check_order(block.order);
  check_node_set(block.nodes);
  const std::size_t n = nodes_per_element(block.order);
  if (block.element_count == 0) throw std::invalid_argument("hex source: no elements");
  if (!block.corners) throw std::invalid_argument("hex source: null corner array");
  if (!block.values) throw std::invalid_argument("hex source: null value array");
  if (block.type != ScalarType::float32 && block.type != ScalarType::float64)
    throw std::invalid_argument("hex source: unknown scalar type");
  if (block_.element_stride == 0) block_.element_stride = n;
  if (block_.element_stride < n)
    throw std::invalid_argument("hex source: element stride " +
                                std::to_string(block_.element_stride) +
                                " below (order + 1)^3 = " + std::to_string(n));

  constexpr double inf = std::numeric_limits<double>::infinity();
  bounds_ = {glm::dvec3(inf), glm::dvec3(-inf)};
  for (std::size_t e = 0; e < block.element_count; ++e) {
    const double* corners = block.corners + 24 * e;
    const AffineFrame f = frame_of(corners);
    const glm::dvec3 e1 = f.axes[0], e2 = f.axes[1], e3 = f.axes[2];
    const double size = glm::length(e1) + glm::length(e2) + glm::length(e3);
    for (int c = 0; c < 8; ++c) {
      const glm::dvec3 affine =
          f.origin + double(c & 1) * e1 + double((c >> 1) & 1) * e2 + double((c >> 2) & 1) * e3;
      // Written so that NaN corners fail too.
      if (!(glm::length(corner(corners, c) - affine) <= 1e-9 * size))
        throw std::invalid_argument(
            "hex source: element " + std::to_string(e) + " is not a parallelepiped (corner " +
            std::to_string(c) +
            " is off the affine map of corners 0, 1, 2, 4); non-parallelepiped (non-affine "
            "trilinear) and curved isoparametric elements are a documented later step");
    }
    if (!(std::abs(glm::determinant(f.axes)) >
          1e-12 * glm::length(e1) * glm::length(e2) * glm::length(e3)))
      throw std::invalid_argument("hex source: element " + std::to_string(e) +
                                  " is degenerate (zero volume)");
    const Box box = bounding_box(f);
    bounds_.lo = glm::min(bounds_.lo, box.lo);
    bounds_.hi = glm::max(bounds_.hi, box.hi);
  }
}

Box HexElementSource::bounds() const {
  return bounds_;
}

glm::dvec3 HexElementSource::to_reference(std::size_t element, glm::dvec3 world) const {
  const AffineFrame f = frame_of(block_.corners + 24 * element);
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

std::unique_ptr<GeometryBinding> HexElementSource::bind(RTCDevice device, double isovalue) const {
  const int p = block_.order;
  const std::size_t n = nodes_per_element(p);
  const std::size_t count = block_.element_count;

  // Pass 1: which elements may hold the isosurface (convex hull of the Bernstein coefficients).
  // Flags only, so memory does not grow with the block. An element with a non-finite nodal
  // value has no polynomial to intersect: it is left out.
  std::vector<std::uint8_t> active(count);
  std::atomic<std::uint64_t> nonfinite{0};
  const ConversionMatrix& matrix = conversion_matrix(p, block_.nodes);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      double nodal[kMaxElementValues], b[kMaxElementValues];
                      std::uint64_t bad = 0;
                      for (std::size_t e = range.begin(); e != range.end(); ++e) {
                        if (const std::size_t k = read_nodal(block_, e, n, nodal); k > 0) {
                          bad += k;
                          active[e] = 0;
                          continue;
                        }
                        convert_element(p, matrix, nodal, b);
                        const auto [lo, hi] = std::minmax_element(b, b + n);
                        active[e] = *lo <= isovalue && isovalue <= *hi;
                      }
                      if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
                    });
  std::vector<std::size_t> kept;
  for (std::size_t e = 0; e < count; ++e)
    if (active[e]) kept.push_back(e);

  // Pass 2: the kept elements' coefficients (converted again: usually few are kept) and frames,
  // in element order, so the binding is the same for any thread count.
  std::vector<ActiveElement> elements(kept.size());
  std::vector<double> coefficients(kept.size() * n);
  tbb::parallel_for(std::size_t(0), kept.size(), [&](std::size_t k) {
    const std::size_t e = kept[k];
    const std::span<double> b(&coefficients[k * n], n);
    element_bernstein(e, b);
    for (double& v : b)
      v -= isovalue;
    const AffineFrame f = frame_of(block_.corners + 24 * e);
    ActiveElement& out = elements[k];
    out.origin = f.origin;
    out.to_reference = glm::inverse(f.axes);
    const Box box = bounding_box(f);
    out.lo = box.lo;
    out.hi = box.hi;
  });
  return std::make_unique<HexBinding>(device, p, std::move(elements), std::move(coefficients),
                                      nonfinite.load());
}

}  // namespace ldimesh

// Part of the Bernstein–Bézier toolkit (internal): a tensor-product polynomial of degree p per
// axis in Bernstein form on [0, 1]³ — its value and gradient at a point, and its restriction to a
// segment (general or parallel to a reference axis) as a univariate Bernstein polynomial.
#pragma once

#include <glm/glm.hpp>

#include "basis.hpp"
#include "conversion.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh::bernstein {

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

}  // namespace ldimesh::bernstein

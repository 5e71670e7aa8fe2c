// Part of the Bernstein–Bézier toolkit (internal): every root on [0, 1] of a univariate
// Bernstein polynomial — de Casteljau splits, sign variations (the variation-diminishing
// property) and a safeguarded Newton–Halley convergence, four lanes at a time.
#pragma once

#include <algorithm>
#include <cmath>

#include "basis.hpp"
#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh::bernstein {

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

}  // namespace ldimesh::bernstein

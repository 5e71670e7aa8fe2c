// Interval arithmetic for robust culling and root isolation of implicit surfaces
// (Knoll et al. 2009, "Fast ray tracing of arbitrary implicit surfaces with interval and affine
// arithmetic"). An Interval encloses every value an expression can take when its inputs range
// over their intervals.
//
// Rounding is round-to-nearest, not outward: enclosures can be short by an ulp or so. The ray
// caster only uses them to discard sub-intervals that cannot hold a root, and confirms every
// root by a sign change of point values, so an ulp never creates a hit; it could only lose a
// grazing double root, which has no sign change anyway.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>

namespace ldimesh {

struct Interval {
  double lo = 0.0;
  double hi = 0.0;

  constexpr Interval() = default;
  constexpr Interval(double v) : lo(v), hi(v) {}  // NOLINT: a number is a degenerate interval
  constexpr Interval(double l, double h) : lo(l), hi(h) {}

  constexpr bool contains(double v) const { return lo <= v && v <= hi; }
  constexpr double width() const { return hi - lo; }
  constexpr double mid() const { return 0.5 * (lo + hi); }
};

namespace interval_detail {
// 0 * inf is NaN in IEEE arithmetic but 0 for enclosures (the factor really is zero).
inline double mul0(double a, double b) {
  double p = a * b;
  return p != p ? 0.0 : p;
}
}  // namespace interval_detail

inline Interval operator+(Interval a, Interval b) {
  return {a.lo + b.lo, a.hi + b.hi};
}
inline Interval operator-(Interval a, Interval b) {
  return {a.lo - b.hi, a.hi - b.lo};
}
inline Interval operator-(Interval a) {
  return {-a.hi, -a.lo};
}
inline Interval operator*(Interval a, Interval b) {
  using interval_detail::mul0;
  double p0 = mul0(a.lo, b.lo), p1 = mul0(a.lo, b.hi), p2 = mul0(a.hi, b.lo), p3 = mul0(a.hi, b.hi);
  return {std::min(std::min(p0, p1), std::min(p2, p3)),
          std::max(std::max(p0, p1), std::max(p2, p3))};
}
inline Interval operator*(double s, Interval a) {
  return s >= 0 ? Interval{s * a.lo, s * a.hi} : Interval{s * a.hi, s * a.lo};
}
inline Interval operator*(Interval a, double s) {
  return s * a;
}
inline Interval operator/(Interval a, Interval b) {
  if (b.lo <= 0.0 && b.hi >= 0.0) return {-INFINITY, INFINITY};
  return a * Interval{1.0 / b.hi, 1.0 / b.lo};
}
inline Interval& operator+=(Interval& a, Interval b) {
  return a = a + b;
}
inline Interval& operator-=(Interval& a, Interval b) {
  return a = a - b;
}
inline Interval& operator*=(Interval& a, Interval b) {
  return a = a * b;
}

inline Interval intersect(Interval a, Interval b) {
  return {std::max(a.lo, b.lo), std::min(a.hi, b.hi)};
}
inline Interval hull(Interval a, Interval b) {
  return {std::min(a.lo, b.lo), std::max(a.hi, b.hi)};
}

// x², tighter than x*x when x straddles zero.
inline Interval sqr(Interval a) {
  double l = a.lo * a.lo, h = a.hi * a.hi;
  if (a.lo >= 0) return {l, h};
  if (a.hi <= 0) return {h, l};
  return {0.0, std::max(l, h)};
}
inline double sqr(double a) {
  return a * a;
}

inline Interval sqrt(Interval a) {
  return {std::sqrt(std::max(a.lo, 0.0)), std::sqrt(std::max(a.hi, 0.0))};
}

inline Interval cos(Interval a) {
  constexpr double pi = std::numbers::pi, two_pi = 2 * std::numbers::pi;
  if (!(a.hi - a.lo < two_pi)) return {-1.0, 1.0};
  double c0 = std::cos(a.lo), c1 = std::cos(a.hi);
  Interval r{std::min(c0, c1), std::max(c0, c1)};
  // Maxima at 2kπ, minima at (2k+1)π.
  if (std::floor(a.hi / two_pi) > std::floor(a.lo / two_pi)) r.hi = 1.0;
  if (std::floor((a.hi - pi) / two_pi) > std::floor((a.lo - pi) / two_pi)) r.lo = -1.0;
  return r;
}
inline Interval sin(Interval a) {
  constexpr double half_pi = 0.5 * std::numbers::pi;
  return cos(a - Interval(half_pi));
}

}  // namespace ldimesh

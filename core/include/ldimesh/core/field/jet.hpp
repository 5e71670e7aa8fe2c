// Forward-mode automatic differentiation over a value type T (double or Interval).
//
// A Jet<T, N> carries a value and N partial derivatives. Fields are written once as templates
// (see analytic_fields.hpp) and evaluated with
//   - T = double, N = 0 implicitly (plain double): the value;
//   - Jet<double, 3>: value and gradient (normals);
//   - Jet<double, 1>: value and derivative along a ray (Newton steps);
//   - Jet<Interval, 1>: enclosures of the value and of the derivative along a ray segment
//     (culling and monotonicity tests during root isolation).
#pragma once

#include <array>
#include <cmath>
#include <type_traits>

#include "ldimesh/core/field/interval.hpp"

namespace ldimesh {

template <class T, int N>
struct Jet {
  T v{};
  std::array<T, N> d{};

  Jet() = default;
  Jet(double c) : v(c) {  // NOLINT: constants have zero derivatives
    d.fill(T(0.0));
  }
  Jet(T value, const std::array<T, N>& derivs) : v(value), d(derivs) {}
};

template <class T, int N>
Jet<T, N> operator+(const Jet<T, N>& a, const Jet<T, N>& b) {
  Jet<T, N> r;
  r.v = a.v + b.v;
  for (int i = 0; i < N; ++i)
    r.d[i] = a.d[i] + b.d[i];
  return r;
}
template <class T, int N>
Jet<T, N> operator-(const Jet<T, N>& a, const Jet<T, N>& b) {
  Jet<T, N> r;
  r.v = a.v - b.v;
  for (int i = 0; i < N; ++i)
    r.d[i] = a.d[i] - b.d[i];
  return r;
}
template <class T, int N>
Jet<T, N> operator-(const Jet<T, N>& a) {
  Jet<T, N> r;
  r.v = -a.v;
  for (int i = 0; i < N; ++i)
    r.d[i] = -a.d[i];
  return r;
}
template <class T, int N>
Jet<T, N> operator*(const Jet<T, N>& a, const Jet<T, N>& b) {
  Jet<T, N> r;
  r.v = a.v * b.v;
  for (int i = 0; i < N; ++i)
    r.d[i] = a.d[i] * b.v + a.v * b.d[i];
  return r;
}
template <class T, int N>
Jet<T, N> operator*(double s, const Jet<T, N>& a) {
  Jet<T, N> r;
  r.v = s * a.v;
  for (int i = 0; i < N; ++i)
    r.d[i] = s * a.d[i];
  return r;
}
template <class T, int N>
Jet<T, N> operator*(const Jet<T, N>& a, double s) {
  return s * a;
}
template <class T, int N>
Jet<T, N> operator+(const Jet<T, N>& a, double s) {
  Jet<T, N> r = a;
  r.v = r.v + T(s);
  return r;
}
template <class T, int N>
Jet<T, N> operator+(double s, const Jet<T, N>& a) {
  return a + s;
}
template <class T, int N>
Jet<T, N> operator-(const Jet<T, N>& a, double s) {
  return a + (-s);
}
template <class T, int N>
Jet<T, N> operator-(double s, const Jet<T, N>& a) {
  return (-a) + s;
}

template <class T, int N>
Jet<T, N> sqr(const Jet<T, N>& a) {
  Jet<T, N> r;
  r.v = sqr(a.v);
  for (int i = 0; i < N; ++i)
    r.d[i] = 2.0 * (a.v * a.d[i]);
  return r;
}

template <class T, int N>
Jet<T, N> sqrt(const Jet<T, N>& a) {
  using std::sqrt;
  Jet<T, N> r;
  r.v = sqrt(a.v);
  // d√a = da / (2√a); at a = 0 the interval quotient is unbounded (operator/ says so).
  if constexpr (std::is_same_v<T, double>) {
    // Where the radicand vanishes (e.g. on the axis of a rotationally symmetric field) the
    // symmetric limit of the derivative is zero; avoid inf/NaN normals there.
    if (r.v == 0.0) return Jet<T, N>(0.0);
  }
  for (int i = 0; i < N; ++i)
    r.d[i] = a.d[i] / (T(2.0) * r.v);
  return r;
}

template <class T, int N>
Jet<T, N> sin(const Jet<T, N>& a) {
  using std::cos;
  using std::sin;
  Jet<T, N> r;
  r.v = sin(a.v);
  T c = cos(a.v);
  for (int i = 0; i < N; ++i)
    r.d[i] = c * a.d[i];
  return r;
}

template <class T, int N>
Jet<T, N> cos(const Jet<T, N>& a) {
  using std::cos;
  using std::sin;
  Jet<T, N> r;
  r.v = cos(a.v);
  T s = sin(a.v);
  for (int i = 0; i < N; ++i)
    r.d[i] = -(s * a.d[i]);
  return r;
}

}  // namespace ldimesh

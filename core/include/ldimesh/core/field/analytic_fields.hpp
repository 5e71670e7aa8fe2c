// Analytic scalar fields, each defined once as a template over the number type T so that the
// same formula is evaluated as a double, as an Interval (culling, root isolation) and as a Jet
// (gradients and derivatives along rays). See docs/surfaces.md for the formulas and sources.
#pragma once

#include <cmath>
#include <numbers>

#include "ldimesh/core/field/interval.hpp"
#include "ldimesh/core/field/jet.hpp"

namespace ldimesh::fields {

using std::cos;
using std::sin;
using std::sqrt;

// f = x² + y² + z²; the isosurface f = R² is the sphere of radius R.
struct Sphere {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    return sqr(x) + sqr(y) + sqr(z);
  }
};

// Ring torus around the z axis, major radius R, tube radius a, as the quartic
// f = (x² + y² + z² + R² − a²)² − 4R²(x² + y²), isosurface f = 0.
struct Torus {
  double R = 1.0;
  double a = 0.4;
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    T rho2 = sqr(x) + sqr(y);
    return sqr(rho2 + sqr(z) + (R * R - a * a)) - (4.0 * R * R) * rho2;
  }
};

// Barth sextic (W. Barth 1996), with φ the golden ratio and w = 1:
// f = 4(φ²x² − y²)(φ²y² − z²)(φ²z² − x²) − (1 + 2φ)(x² + y² + z² − w²)² w², isosurface f = 0.
// The surface is unbounded; it is clipped to a ball (see surfaces.cpp).
struct BarthSextic {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    constexpr double phi = std::numbers::phi;
    constexpr double phi2 = phi * phi;
    const T x2 = sqr(x), y2 = sqr(y), z2 = sqr(z);
    return 4.0 * ((phi2 * x2 - y2) * (phi2 * y2 - z2) * (phi2 * z2 - x2)) -
           (1.0 + 2.0 * phi) * sqr(x2 + y2 + z2 - 1.0);
  }
};

// Klein bottle (immersion as an algebraic surface, as in Knoll et al. 2009):
// f = (x²+y²+z²+2y−1)((x²+y²+z²−2y−1)² − 8z²) + 16xz(x²+y²+z²−2y−1), isosurface f = 0.
struct KleinBottle {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    const T r2 = sqr(x) + sqr(y) + sqr(z);
    const T a = r2 + 2.0 * y - 1.0;
    const T b = r2 - 2.0 * y - 1.0;
    return a * (sqr(b) - 8.0 * sqr(z)) + 16.0 * (x * z * b);
  }
};

// Marschner–Lobb test signal (Marschner & Lobb 1994) on [−1, 1]³ with f_M = 6, α = 0.25:
// f = (1 − sin(πz/2) + α(1 + ρ(√(x² + y²)))) / (2(1 + α)), ρ(r) = cos(2π f_M cos(πr/2)),
// isosurface f = 0.5.
struct MarschnerLobb {
  double fM = 6.0;
  double alpha = 0.25;
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    constexpr double pi = std::numbers::pi;
    const T r = sqrt(sqr(x) + sqr(y));
    const T rho = cos((2.0 * pi * fM) * cos((0.5 * pi) * r));
    return (1.0 / (2.0 * (1.0 + alpha))) * ((1.0 + alpha) - sin((0.5 * pi) * z) + alpha * rho);
  }
};

// The paper's "Slices" data set (§6, Fig. 6 j–l): f = x² + y² + z² + sin(5x + 15y + 6z) − 1,
// isosurface f = 0.
struct Slices {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    return sqr(x) + sqr(y) + sqr(z) + sin(5.0 * x + 15.0 * y + 6.0 * z) - 1.0;
  }
};

}  // namespace ldimesh::fields

#include <algorithm>
#include <cmath>
#include <vector>

#include "../bernstein/basis.hpp"
#include "../bernstein/conversion.hpp"
#include "curved_tensor.hpp"

namespace ldimesh::curved {
namespace {

// Value and gradient at r of the tensor of degree n (1..kMaxHexOrder, with_order: the loops
// unrolled) with `count` interleaved components
// (coefficient m's component c at c[m·count + c]), by sum factorisation: ξ contracted first
// (value and ξ-derivative per row), then η, then ζ.
template <int count>
void evaluate_components(int n, const double* c, glm::dvec3 r, double* value,
                         glm::dvec3* gradient) {
  bernstein::with_order(n, [&](auto degree) {
    constexpr int N = degree, m = N + 1;
    double bx[kMaxNodes], dx[kMaxNodes], by[kMaxNodes], dy[kMaxNodes], bz[kMaxNodes], dz[kMaxNodes];
    bernstein_basis<N>(r.x, bx, dx);
    bernstein_basis<N>(r.y, by, dy);
    bernstein_basis<N>(r.z, bz, dz);
    for (int k = 0; k < count; ++k) {
      double f = 0.0, fx = 0.0, fy = 0.0, fz = 0.0;
      for (int kz = 0; kz < m; ++kz) {
        double g = 0.0, gx = 0.0, gy = 0.0;  // the ζ-layer kz contracted over ξ and η
        for (int jy = 0; jy < m; ++jy) {
          const double* row = c + count * m * (jy + m * kz) + k;
          double h = 0.0, hx = 0.0;
          for (int ix = 0; ix < m; ++ix)
            h += row[count * ix] * bx[ix], hx += row[count * ix] * dx[ix];
          g += h * by[jy], gx += hx * by[jy], gy += h * dy[jy];
        }
        f += g * bz[kz], fx += gx * bz[kz], fy += gy * bz[kz], fz += g * dz[kz];
      }
      value[k] = f, gradient[k] = glm::dvec3(fx, fy, fz);
    }
  });
}

}  // namespace

// The ray's frame: d and two unit normals to it.
void ray_frame(glm::dvec3 d, glm::dvec3& n1, glm::dvec3& n2) {
  const glm::dvec3 a = std::abs(d.x) <= std::abs(d.y) && std::abs(d.x) <= std::abs(d.z)
                           ? glm::dvec3(1, 0, 0)
                       : std::abs(d.y) <= std::abs(d.z) ? glm::dvec3(0, 1, 0)
                                                        : glm::dvec3(0, 0, 1);
  // Axis rays get exact coordinate axes (no rounding in the planes).
  const int axis = exact_axis(d);
  if (axis >= 0) {
    n1 = glm::dvec3(0.0), n2 = glm::dvec3(0.0);
    n1[axis == 0 ? 1 : 0] = 1.0;
    n2[axis == 2 ? 1 : 2] = 1.0;
    return;
  }
  n1 = glm::normalize(glm::cross(d, a));
  n2 = glm::normalize(glm::cross(d, n1));
}

// The sign tests' margin for the field: rounding in the subdivision scales with the element's
// coefficients.
double field_margin(const Element& e) {
  const int pm = e.p + 1;
  double scale = 0.0;
  for (int m = 0; m < pm * pm * pm; ++m)
    scale = std::max(scale, std::abs(e.field[m]));
  return kSignMargin * scale;
}

// The tensor `in` of degree a per axis (`count` interleaved components) as one of degree n ≥ a
// (the same polynomial) in `out` (not `in`): coefficient i of degree n is
// Σ_j C(a, j) C(n − a, i − j) / C(n, i) c_j along each axis, applied axis by axis to whole
// rows of the slabs [outer][i][inner] (as split_quads_along).
void elevate(const double* in, int a, int n, int count, double* out) {
  const int am = a + 1, nm = n + 1;
  if (a == n) {
    std::copy(in, in + std::size_t(count) * am * am * am, out);
    return;
  }
  int size[3] = {am, am, am};
  thread_local std::vector<double> buffer[2];
  const double* from = in;
  for (int axis = 0; axis < 3; ++axis) {
    int inner = count, outer = 1;
    for (int k = 0; k < axis; ++k)
      inner *= size[k];
    for (int k = axis + 1; k < 3; ++k)
      outer *= size[k];
    double* to = out;
    if (axis < 2) {
      buffer[axis].resize(std::size_t(outer) * nm * inner);
      to = buffer[axis].data();
    }
    for (int o = 0; o < outer; ++o)
      for (int i = 0; i < nm; ++i) {
        double* row = to + (std::size_t(o) * nm + i) * inner;
        std::fill(row, row + inner, 0.0);
        for (int j = std::max(0, i - (n - a)); j <= std::min(a, i); ++j) {
          const double w = kBinomial[a][j] * kBinomial[n - a][i - j] / kBinomial[n][i];
          const double* source = from + (std::size_t(o) * am + j) * inner;
          for (int l = 0; l < inner; ++l)
            row[l] += w * source[l];
        }
      }
    size[axis] = nm;
    from = to;
  }
}

Sample evaluate(const Element& e, glm::dvec3 xi) {
  Sample s;
  double x[3];
  glm::dvec3 gx[3];
  evaluate_components<3>(e.q, &e.geometry[0].x, xi, x, gx);
  s.x = glm::dvec3(x[0], x[1], x[2]);
  // Columns ∂x/∂ξ_k: row r of the Jacobian is the gradient of x_r.
  for (int k = 0; k < 3; ++k)
    s.jacobian[k] = glm::dvec3(gx[0][k], gx[1][k], gx[2][k]);
  if (e.field) evaluate_components<1>(e.p, e.field, xi, &s.f, &s.gradient);
  return s;
}

bool invert(const Element& e, glm::dvec3 world, glm::dvec3& xi) {
  // Newton's method with backtracking: a step that does not reduce |x(ξ) − world| is halved.
  xi = glm::dvec3(0.5);
  Sample s = evaluate(e, xi);
  double residual = glm::length(s.x - world);
  const double size =
      glm::length(e.geometry[0] - e.geometry[(e.q + 1) * (e.q + 1) * (e.q + 1) - 1]);
  for (int iter = 0; iter < 100; ++iter) {
    if (residual <= 1e-14 * size) return true;
    if (!(std::abs(glm::determinant(s.jacobian)) > 0.0)) return false;
    const glm::dvec3 step = glm::inverse(s.jacobian) * (s.x - world);
    double scale = 1.0;
    bool progress = false;
    for (int half = 0; half < 30 && !progress; ++half, scale *= 0.5) {
      const glm::dvec3 next = xi - scale * step;
      const Sample t = evaluate(e, next);
      const double r = glm::length(t.x - world);
      if (r < residual) xi = next, s = t, residual = r, progress = true;
    }
    if (!progress) break;
    if (scale * std::max({std::abs(step.x), std::abs(step.y), std::abs(step.z)}) < 1e-15)
      return residual <= 1e-9 * size;  // no further progress
    if (!(glm::length(xi) < 1e3)) return false;
  }
  return residual <= 1e-9 * size;
}

}  // namespace ldimesh::curved

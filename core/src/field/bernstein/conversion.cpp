#include "conversion.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "basis.hpp"

namespace ldimesh::bernstein {
namespace {

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
}  // namespace

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

namespace {

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

}  // namespace

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

void convert_element(int order, const ConversionMatrix& m, const double* in, double* out) {
  with_order(order, [&](auto p) { convert_element_fixed<p>(m, in, out); });
}

}  // namespace ldimesh::bernstein

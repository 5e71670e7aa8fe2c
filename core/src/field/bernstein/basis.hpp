// The 1-D Bernstein basis and its derivative, shared by the element kernels (internal).
#pragma once

#include <array>

#include "ldimesh/core/field/blocks.hpp"

namespace ldimesh {

// Binomial coefficients C(n, k), n up to 3 kMaxHexOrder (a tensor of degree p along a line in
// general position has degree 3p).
inline constexpr int kMaxBinomial = 3 * kMaxHexOrder;
inline constexpr std::array<std::array<double, kMaxBinomial + 1>, kMaxBinomial + 1> kBinomial = [] {
  std::array<std::array<double, kMaxBinomial + 1>, kMaxBinomial + 1> c{};
  for (int n = 0; n <= kMaxBinomial; ++n) {
    c[n][0] = c[n][n] = 1.0;
    for (int k = 1; k < n; ++k)
      c[n][k] = c[n - 1][k - 1] + c[n - 1][k];
  }
  return c;
}();

// B_i^P(x) and dB_i^P/dx for i = 0..P, from the triangle B_i^r = (1 − x) B_i^{r−1} + x
// B_{i−1}^{r−1} and dB_i^P/dx = P (B_{i−1}^{P−1} − B_i^{P−1}). The degree is a constant, so that
// the loops unroll.
template <int P>
[[gnu::always_inline]] inline void bernstein_basis(double x, double* value, double* derivative) {
  double b[kMaxHexOrder + 1] = {1.0};
  for (int r = 1; r < P; ++r) {
    b[r] = x * b[r - 1];
    for (int i = r - 1; i > 0; --i)
      b[i] = (1.0 - x) * b[i] + x * b[i - 1];
    b[0] *= 1.0 - x;
  }
  for (int i = 0; i <= P; ++i) {
    const double left = i > 0 ? b[i - 1] : 0.0, right = i < P ? b[i] : 0.0;
    derivative[i] = P * (left - right);
    value[i] = (1.0 - x) * right + x * left;
  }
}

}  // namespace ldimesh

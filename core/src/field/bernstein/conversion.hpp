// Part of the Bernstein–Bézier toolkit every element family uses (internal): the 1-D node sets,
// the conversion of nodal values on a tensor lattice to Bernstein coefficients (sum
// factorisation), and the dispatch of a runtime order to kernels instantiated per order.
#pragma once

#include <array>
#include <type_traits>
#include <utility>
#include <vector>

#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh::bernstein {

constexpr int kMaxNodes = kMaxHexOrder + 1;
constexpr int kMaxElementValues = kMaxNodes * kMaxNodes * kMaxNodes;
constexpr int kMaxRayDegree = 3 * kMaxHexOrder;  // f along a ray: degree p in each of ξ, η, ζ

// The 1-D nodes of `set` on [−1, 1], increasing, exactly antisymmetric.
std::vector<double> nodes_on_symmetric_interval(int order, NodeSet set);

// Bernstein coefficients from nodal values, per axis: b = V⁻¹ u with V[m][n] = B_n^p(x_m).
using ConversionMatrix = std::array<double, kMaxNodes * kMaxNodes>;  // row-major, (p+1)²

// The 1-D conversion matrix of (order, set), built once on first use (thread-safe).
const ConversionMatrix& conversion_matrix(int order, NodeSet set);

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
// The (p + 1)³ nodal values `in` (lexicographic) as Bernstein coefficients `out`.
void convert_element(int order, const ConversionMatrix& m, const double* in, double* out);

}  // namespace ldimesh::bernstein

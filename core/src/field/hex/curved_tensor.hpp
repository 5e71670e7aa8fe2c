// The curved search's tensors of Bernstein coefficients (curved_element.cpp): four components
// side by side (Quad), evaluated, split at a box's middle and bounded with the loops unrolled
// per degree; and the helpers it shares with the element's evaluation (curved_tensor.cpp).
// Internal to the core library; included by the search only.
#pragma once

#include <algorithm>
#include <cstring>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "../bernstein/basis.hpp"
#include "curved_element.hpp"

namespace ldimesh::curved {

constexpr int kMaxNodes = kMaxHexOrder + 1;
// Sign tests and the Krawczyk inclusion keep this margin, relative to the coefficients'
// magnitude and to the box: rounding in the subdivision (a few ulps per level) never drops a
// box that holds a solution.
constexpr double kSignMargin = 1e-12;

// The ray's frame: d and two unit normals to it.
void ray_frame(glm::dvec3 d, glm::dvec3& n1, glm::dvec3& n2);

// The sign tests' margin for the field: rounding in the subdivision scales with the element's
// coefficients.
double field_margin(const Element& e);

// The tensor `in` of degree a per axis (`count` interleaved components) as one of degree n ≥ a
// (the same polynomial) in `out` (not `in`).
void elevate(const double* in, int a, int n, int count, double* out);

// Four doubles side by side: one coefficient's components — an element's (x, y, z, f), a
// search box's (n₁·x, n₂·x, f, d·x / |d|²) — so that one operation on all four is one vector
// operation (GCC's and Clang's vector extensions: two SSE2 halves, or one AVX2 register in the
// search's AVX2 copy below). Each component sees the same operations in the same order as
// one scalar at a time would, so every copy gives the same bits. Passed by pointer or
// reference only: a 32-byte vector by value changes the calling convention between the copies.
using Quad = double __attribute__((vector_size(32), aligned(32)));

// A growable array of quads on 32-byte boundaries (std::vector<Quad> would drop the type's
// alignment attribute, and the type alone is 16-byte aligned where AVX is off).
class Quads {
 public:
  Quad* data() { return &slots_.data()->q; }
  Quad& operator[](std::size_t k) { return slots_[k].q; }
  std::size_t size() const { return slots_.size(); }
  void resize(std::size_t n) { slots_.resize(n); }

 private:
  struct alignas(32) Slot {
    Quad q;
  };
  std::vector<Slot> slots_;
};

// The quad at p (any alignment).
[[gnu::always_inline]] inline void load_quad(const double* p, Quad& q) {
  std::memcpy(&q, p, sizeof q);
}

// lo = min(lo, v), hi = max(hi, v) per component. `wide`: as one 32-byte select (the AVX2
// copy); else as two 16-byte ones (GCC splits a 32-byte select into scalars through memory
// where AVX is off). Finite values: the same result either way.
template <bool wide>
[[gnu::always_inline]] inline void min_max(const Quad& v, Quad& lo, Quad& hi) {
  if constexpr (wide) {
    lo = v < lo ? v : lo;
    hi = v > hi ? v : hi;
  } else {
    using Half = double __attribute__((vector_size(16)));
    const Half v0{v[0], v[1]}, v1{v[2], v[3]};
    Half l0{lo[0], lo[1]}, l1{lo[2], lo[3]}, h0{hi[0], hi[1]}, h1{hi[2], hi[3]};
    l0 = v0 < l0 ? v0 : l0, l1 = v1 < l1 ? v1 : l1;
    h0 = v0 > h0 ? v0 : h0, h1 = v1 > h1 ? v1 : h1;
    lo = Quad{l0[0], l0[1], l1[0], l1[1]}, hi = Quad{h0[0], h0[1], h1[0], h1[1]};
  }
}

// Value (out[0]) and derivatives along ξ, η, ζ (out[1..3]) at r of the tensor c of degree N,
// all four components at once, by sum factorisation: ξ contracted first (value and
// ξ-derivative per row), then η, then ζ.
template <int N>
[[gnu::always_inline]] inline void evaluate_quads(const Quad* c, const glm::dvec3& r, Quad* out) {
  constexpr int m = N + 1;
  double bx[m], dx[m], by[m], dy[m], bz[m], dz[m];
  bernstein_basis<N>(r.x, bx, dx);
  bernstein_basis<N>(r.y, by, dy);
  bernstein_basis<N>(r.z, bz, dz);
  Quad f{}, fx{}, fy{}, fz{};
  for (int kz = 0; kz < m; ++kz) {
    Quad g{}, gx{}, gy{};  // the ζ-layer kz contracted over ξ and η
    for (int jy = 0; jy < m; ++jy) {
      const Quad* row = c + m * (jy + m * kz);
      Quad h{}, hx{};
      for (int ix = 0; ix < m; ++ix)
        h += row[ix] * bx[ix], hx += row[ix] * dx[ix];
      g += h * by[jy], gx += hx * by[jy], gy += h * dy[jy];
    }
    f += g * bz[kz], fx += gx * bz[kz], fy += gy * bz[kz], fz += g * dz[kz];
  }
  out[0] = f, out[1] = fx, out[2] = fy, out[3] = fz;
}

// Splits the tensor c (degree N) at the middle of `axis`: c becomes the right half, `left` the
// left one (de Casteljau along every line of that axis, in place: after level r, row i holds
// level r's point i, and the rows at the end of each level are the right half's; the left
// half's row r is row 0 after level r). The tensor is taken as slabs [outer][i][inner] (i along
// `axis`, inner the contiguous quads below it), and de Casteljau's levels run over whole rows of
// a slab: independent operations side by side instead of one dependent chain per line.
template <int N, int axis>
[[gnu::always_inline]] inline void split_quads_along(Quad* c, Quad* left) {
  constexpr int m = N + 1;
  constexpr int inner = axis == 0 ? 1 : axis == 1 ? m : m * m;
  constexpr int outer = axis == 0 ? m * m : axis == 1 ? m : 1;
  for (int o = 0; o < outer; ++o) {
    Quad* w = c + o * m * inner;  // the slab: m rows of `inner` quads
    Quad* l = left + o * m * inner;
    for (int j = 0; j < inner; ++j)
      l[j] = w[j];
    for (int r = 1; r <= N; ++r) {
      for (int i = 0; i <= N - r; ++i) {
        Quad* row = w + i * inner;
        const Quad* next = row + inner;
        for (int j = 0; j < inner; ++j)
          row[j] = 0.5 * (row[j] + next[j]);
      }
      for (int j = 0; j < inner; ++j)
        l[r * inner + j] = w[j];
    }
  }
}
template <int N>
[[gnu::always_inline]] inline void split_quads(int axis, Quad* c, Quad* left) {
  if (axis == 0)
    split_quads_along<N, 0>(c, left);
  else if (axis == 1)
    split_quads_along<N, 1>(c, left);
  else
    split_quads_along<N, 2>(c, left);
}

// Minimum and maximum of each component over the tensor c (degree N). Four partial minima and
// maxima side by side, so that their chains overlap; the values are finite (non-finite geometry
// is refused, a non-finite field deactivates its element), so the order does not change the
// result.
template <int N, bool wide>
[[gnu::always_inline]] inline void range_quads(const Quad* c, Quad& lo, Quad& hi) {
  constexpr int total = (N + 1) * (N + 1) * (N + 1);
  Quad l[4] = {c[0], c[0], c[0], c[0]}, h[4] = {c[0], c[0], c[0], c[0]};
  int i = 0;
  for (; i + 3 < total; i += 4)
    for (int a = 0; a < 4; ++a)
      min_max<wide>(c[i + a], l[a], h[a]);
  for (; i < total; ++i)
    min_max<wide>(c[i], l[0], h[0]);
  for (int a = 1; a < 4; ++a)
    min_max<wide>(l[a], l[0], h[0]), min_max<wide>(h[a], l[0], h[0]);
  lo = l[0], hi = h[0];
}

// Bounds of ∂/∂s_axis of each component of c (degree N) over the box: the derivative's
// Bernstein coefficients N (c_{i+1} − c_i) along that axis.
template <int N, bool wide>
[[gnu::always_inline]] inline void derivative_range_quads(int axis, const Quad* c, Quad& lo,
                                                          Quad& hi) {
  constexpr int m = N + 1;
  const int stride = axis == 0 ? 1 : axis == 1 ? m : m * m;
  const int inner = stride, outer = m * m * m / (stride * m);
  // One partial minimum and maximum per position along the lines, so that their chains overlap.
  Quad l[N], h[N];
  for (int i = 0; i < N; ++i)
    l[i] = h[i] = N * (c[(i + 1) * stride] - c[i * stride]);
  for (int o = 0; o < outer; ++o)
    for (int j = 0; j < inner; ++j) {
      const Quad* line = c + o * m * inner + j;
      for (int i = 0; i < N; ++i)
        min_max<wide>(N * (line[(i + 1) * stride] - line[i * stride]), l[i], h[i]);
    }
  for (int i = 1; i < N; ++i)
    min_max<wide>(l[i], l[0], h[0]), min_max<wide>(h[i], l[0], h[0]);
  lo = l[0], hi = h[0];
}

// One box of a subdivision: its extent in ξ. Its coefficients lie in a pool at its position in
// the stack.
struct Box {
  glm::dvec3 lo, hi;
};

// The halves of box b along `axis`, left then right.
inline std::pair<Box, Box> halves(const Box& b, int axis) {
  Box left = b, right = b;
  const double mid = 0.5 * (b.lo[axis] + b.hi[axis]);
  left.hi[axis] = mid, right.lo[axis] = mid;
  return {left, right};
}

}  // namespace ldimesh::curved

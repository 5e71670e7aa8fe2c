// What a grid block's two casters share (grid_source.cpp binds them): the block's points as
// typed values (GridView), its bricks, the trilinear maths of a cell — values, roots along a
// segment, normals — and the brick culling. Templates and inline functions: the casters solve
// cells with them per ray. Internal to the core library.
#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "ldimesh/core/field/axis_caster.hpp"
#include "ldimesh/core/field/grid_source.hpp"

namespace ldimesh::grid {

// The functions have internal linkage (unnamed namespaces; the types, which the bindings'
// signatures name, do not): each caster's file gets its own copies, which GCC specialises and
// inlines as it did when all of this was one file. As inline functions of external linkage the
// Embree binding ran slower: GCC specialised them less (ldimesh_bench_sources --only grid
// --embree against the previous build).
namespace {

constexpr const char* kAxis[3] = {"x", "y", "z"};

inline double eval_cubic(const double c[4], double s) {
  return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

// The trilinear interpolant at local point p: Σ w_n · corner[n] with w_n = wx·wy·wz, summed in
// corner order. Where p lies on a face (a coordinate exactly 0 or 1) the other side's weights
// are exact zeros, and the cell on the other side of that face computes the same sum of the
// same products: the value on a shared face does not depend on the cell.
inline double trilinear_value(const double corner[8], glm::dvec3 p) {
  double v = 0.0;
  for (int n = 0; n < 8; ++n) {
    const double wx = (n & 1) ? p.x : 1.0 - p.x, wy = (n & 2) ? p.y : 1.0 - p.y,
                 wz = (n & 4) ? p.z : 1.0 - p.z;
    v += wx * wy * wz * corner[n];
  }
  return v;
}

// The single root of the cubic in [a, b] where it changes sign: Newton steps kept inside the
// bracket, bisection when a step leaves it.
inline double converge_cubic(const double c[4], double a, double b, double fa, double fb) {
  if (fb == 0.0) return b;  // exactly at the end: keep it exact (the half-open rule needs it)
  double t = 0.5 * (a + b);
  for (int iter = 0; iter < 60 && b - a > 1e-15; ++iter) {
    const double ft = eval_cubic(c, t);
    if (ft == 0.0) return t;
    if (positive(ft) == positive(fa)) {
      a = t;
      fa = ft;
    } else {
      b = t;
    }
    const double slope = (3.0 * c[3] * t + 2.0 * c[2]) * t + c[1];
    double next = t - ft / slope;
    if (!(next > a && next < b)) next = 0.5 * (a + b);
    if (std::abs(next - t) < 1e-15) return next;
    t = next;
  }
  return t;
}

}  // namespace

// Grid geometry and values as the casters read them.
template <class T>
struct GridView {
  const T* values;
  std::array<std::int64_t, 3> strides;
  glm::dvec3 origin, spacing;
  std::array<const double*, 3> coords;  // all null: uniform
  bool rectilinear;
  std::array<std::int64_t, 3> dims;  // points per axis, ghosts included
  glm::dvec3 inv_2h;                 // 1 / (2 spacing): the normals' central differences
  // Per brick (x fastest): its points are there to be read; null: all are (GridSource::held).
  const std::uint8_t* held = nullptr;

  double coord(int a, std::int64_t i) const {
    return rectilinear ? coords[a][i] : origin[a] + double(i) * spacing[a];
  }
  double value(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return double(values[i * strides[0] + j * strides[1] + k * strides[2]]);
  }
};

// A brick: owned cells lo[a] … hi[a] (lower corner indices) and the box they cover.
struct Brick {
  std::array<std::int64_t, 3> lo, hi;
  glm::dvec3 box_lo, box_hi;
  // Some corner point of its cells is NaN or ±Inf: its cells check their corners.
  bool nonfinite = false;
};

namespace {

// Bit i: v[i] ≥ threshold (false for NaN); bit i of `finite`: v[i] is neither NaN nor ±Inf.
// The axis caster's bind pass (classify_cells) classifies every point so; with SSE2 (every x86-64)
// four floats or two doubles per comparison (the portable loop, one point per comparison, is
// the fallback).
template <class T>
std::uint64_t sign_bits(const T* v, T threshold, std::uint64_t& finite) {
#if defined(__SSE2__)
  std::uint64_t word = 0, ok = 0;
  if constexpr (std::is_same_v<T, float>) {
    const __m128 t = _mm_set1_ps(threshold), top = _mm_set1_ps(std::numeric_limits<T>::max());
    const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
    for (int i = 0; i < 64; i += 4) {
      const __m128 x = _mm_loadu_ps(v + i);
      word |= std::uint64_t(_mm_movemask_ps(_mm_cmpge_ps(x, t))) << i;
      ok |= std::uint64_t(_mm_movemask_ps(_mm_cmple_ps(_mm_and_ps(x, magnitude), top))) << i;
    }
  } else {
    const __m128d t = _mm_set1_pd(threshold), top = _mm_set1_pd(std::numeric_limits<T>::max());
    const __m128d magnitude = _mm_castsi128_pd(_mm_set1_epi64x(0x7fffffffffffffffll));
    for (int i = 0; i < 64; i += 2) {
      const __m128d x = _mm_loadu_pd(v + i);
      word |= std::uint64_t(_mm_movemask_pd(_mm_cmpge_pd(x, t))) << i;
      ok |= std::uint64_t(_mm_movemask_pd(_mm_cmple_pd(_mm_and_pd(x, magnitude), top))) << i;
    }
  }
  finite = ok;
  return word;
#else
  std::uint8_t flags[64];
  finite = 0;
  for (int i = 0; i < 64; ++i) {
    flags[i] = v[i] >= threshold;
    finite |= std::uint64_t(std::abs(v[i]) <= std::numeric_limits<T>::max()) << i;
  }
  std::uint64_t word = 0;
  for (int i = 0; i < 64; i += 8) {  // eight 0/1 bytes into eight bits
    std::uint64_t bytes;
    std::memcpy(&bytes, flags + i, 8);
    word |= ((bytes * 0x0102040810204080ull) >> 56) << i;
  }
  return word;
#endif
}

// ∇ of the trilinear interpolant at local point p, per unit length (inv_size: one over the
// cell's edges; corner[n] at corner n = x + 2y + 4z): along each axis the bilinear blend, across
// it, of the cell's four edge differences along it. Written out: the hits' gradients and
// divisions were a large part of the axis casts (a loop over the axes compiled to index
// arithmetic and branches; one division per cell instead of three per hit).
inline glm::dvec3 trilinear_gradient(const double c[8], glm::dvec3 p, glm::dvec3 inv_size) {
  const glm::dvec3 q = 1.0 - p;
  // The blend of edge differences d00 (lower, lower) … d11 across an axis, u the first of the
  // other two axes in x, y, z order after it (cyclic) and v the second.
  const auto blend = [](double d00, double d10, double d01, double d11, double pu, double qu,
                        double pv, double qv) {
    return qv * (qu * d00 + pu * d10) + pv * (qu * d01 + pu * d11);
  };
  return {
      blend(c[1] - c[0], c[3] - c[2], c[5] - c[4], c[7] - c[6], p.y, q.y, p.z, q.z) * inv_size.x,
      blend(c[2] - c[0], c[6] - c[4], c[3] - c[1], c[7] - c[5], p.z, q.z, p.x, q.x) * inv_size.y,
      blend(c[4] - c[0], c[5] - c[1], c[6] - c[2], c[7] - c[3], p.x, q.x, p.y, q.y) * inv_size.z};
}

// The shading gradient at local point p of cell c: the trilinear blend of the gradients at the
// cell's 8 corner points, each by central differences ((v[i+1] − v[i−1]) / (x[i+1] − x[i−1])
// along each axis; one-sided where the block has no point beyond, ghost points included, or
// where the value beyond is NaN or ±Inf). Unlike the interpolant's own gradient
// (trilinear_gradient), whose jumps at cell faces show as bands in shading, it is continuous
// across cells; the hits' positions stay those of the interpolant. Every caster computes hits'
// normals through a CellNormals, so that they agree bit for bit.
//
// On a uniform grid, away from the block's edges (the fast form), the blend along axis k is the
// difference of the transverse bilinear interpolants on the four point layers c[k] − 1 …
// c[k] + 2: ((1 − p)(L₂ − L₀) + p(L₃ − L₁)) / 2h, i.e. the bilinear blend over the cell's four
// edges along k of A + p·B, with A and B from the edge's two corners (which the caster has read
// already) and the points beyond them. A and B are computed once per cell (a lattice cell
// solves several rays), from 24 reads; a hit costs what the interpolant's own gradient did.
// Elsewhere, or where the fast form is not finite, the general form: per corner and axis the
// central (or one-sided) difference, then the blend; where even that is not finite, the
// interpolant's gradient.
template <class T>
class CellNormals {
 public:
  // Cell c of `g`; corner[n] = value − iso at corner n (x + 2y + 4z), as the casters hold them.
  CellNormals(const GridView<T>& g, const std::array<std::int64_t, 3>& c, const double corner[8],
              double iso)
      : g_(g), c_(c), corner_(corner), iso_(iso) {
    fast_ = !g.rectilinear && c[0] >= 1 && c[1] >= 1 && c[2] >= 1 && c[0] + 2 < g.dims[0] &&
            c[1] + 2 < g.dims[1] && c[2] + 2 < g.dims[2];
    if (!fast_) return;
    const T* cell = g.values + c[0] * g.strides[0] + c[1] * g.strides[1] + c[2] * g.strides[2];
    for (int k = 0; k < 3; ++k) {
      const int u = k == 0 ? 1 : 0, w = k == 2 ? 1 : 2;  // the transverse axes, u < w
      const std::int64_t sk = g.strides[k], su = g.strides[u], sw = g.strides[w];
      for (int m = 0; m < 4; ++m) {
        // Along the cell's edge m across k: the values below the cell, at its two corners and
        // above it. Per edge, (1 − p)(v₂ − v₀) + p(v₃ − v₁) = A + p·B.
        const std::int64_t across = (m & 1) * su + (m >> 1) * sw;
        const int lower = ((m & 1) << u) | ((m >> 1) << w);
        const double v0 = double(cell[across - sk]) - iso, v1 = corner[lower];
        const double v2 = corner[lower | (1 << k)], v3 = double(cell[across + 2 * sk]) - iso;
        a_[k][m] = v2 - v0;
        b_[k][m] = (v3 - v2) - (v1 - v0);
      }
    }
  }

  // The gradient at local point p; `inv_size` one over the cell's edges (the fallback's).
  glm::dvec3 at(glm::dvec3 p, glm::dvec3 inv_size) const {
    if (fast_) {
      glm::dvec3 grad;
      for (int k = 0; k < 3; ++k) {
        const int u = k == 0 ? 1 : 0, w = k == 2 ? 1 : 2;
        const double e0 = a_[k][0] + p[k] * b_[k][0], e1 = a_[k][1] + p[k] * b_[k][1];
        const double e2 = a_[k][2] + p[k] * b_[k][2], e3 = a_[k][3] + p[k] * b_[k][3];
        const double lo = e0 + p[u] * (e1 - e0), hi = e2 + p[u] * (e3 - e2);
        grad[k] = (lo + p[w] * (hi - lo)) * g_.inv_2h[k];
      }
      if (finite(grad)) return grad;
    }
    const glm::dvec3 grad = general(p);
    return finite(grad) ? grad : trilinear_gradient(corner_, p, inv_size);
  }

 private:
  static bool finite(glm::dvec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  }

  // The general form: per corner and axis the central difference, one-sided where the point
  // beyond is missing or not finite, then the trilinear blend.
  glm::dvec3 general(glm::dvec3 p) const {
    const T* cell =
        g_.values + c_[0] * g_.strides[0] + c_[1] * g_.strides[1] + c_[2] * g_.strides[2];
    glm::dvec3 sum(0.0);
    for (int n = 0; n < 8; ++n) {
      const std::int64_t q[3] = {c_[0] + (n & 1), c_[1] + ((n >> 1) & 1), c_[2] + ((n >> 2) & 1)};
      const T* at = cell + (n & 1) * g_.strides[0] + ((n >> 1) & 1) * g_.strides[1] +
                    ((n >> 2) & 1) * g_.strides[2];
      glm::dvec3 grad;
      for (int k = 0; k < 3; ++k) {
        std::int64_t lo = q[k], hi = q[k];
        double v_lo = corner_[n], v_hi = v_lo;
        if (q[k] > 0) {
          const double v = double(at[-g_.strides[k]]);
          if (std::isfinite(v)) v_lo = v - iso_, lo = q[k] - 1;
        }
        if (q[k] + 1 < g_.dims[k]) {
          const double v = double(at[g_.strides[k]]);
          if (std::isfinite(v)) v_hi = v - iso_, hi = q[k] + 1;
        }
        // A uniform grid's spacing, not differences of coordinates: the same bits in any part
        // of the grid (grid_part moves the origin).
        const double dx =
            g_.rectilinear ? g_.coord(k, hi) - g_.coord(k, lo) : double(hi - lo) * g_.spacing[k];
        grad[k] = (v_hi - v_lo) / dx;
      }
      const double w = ((n & 1) ? p.x : 1.0 - p.x) * (((n >> 1) & 1) ? p.y : 1.0 - p.y) *
                       (((n >> 2) & 1) ? p.z : 1.0 - p.z);
      sum += w * grad;
    }
    return sum;
  }

  const GridView<T>& g_;
  std::array<std::int64_t, 3> c_;
  const double* corner_;
  double iso_;
  bool fast_ = false;
  double a_[3][4], b_[3][4];  // per axis and edge across it (u the lower bit), see above
};

// The value on a cell face crossed by an axis ray: the bilinear interpolation of the face's
// four points (f[0..3], b the lower bit) with weights w (trilinear_value's products with the
// weight along the ray exactly 1), summed in that order. Both axis paths evaluate faces here, so
// that a face shared by two cells has one value.
inline double face_value(const double w[4], const double f[4]) {
  return ((w[0] * f[0] + w[1] * f[1]) + w[2] * f[2]) + w[3] * f[3];
}

// The hit of an axis ray (along a, direction `dir`) in a cell whose face values fa (entry) and
// fb (exit) differ in sign, entered at ta and left at tb: the root of the linear function between
// the faces (as trilinear_segment_roots computes it for a segment along one axis) and the
// normal there (as solve_cell, from the cell's `normals`). `local` holds the ray's local
// coordinates across it, `inv_size` one over the cell's edges.
template <class T>
RayHit axis_root(const CellNormals<T>& normals, int a, int step, glm::dvec3 local,
                 glm::dvec3 inv_size, double fa, double fb, double ta, double tb, glm::dvec3 dir) {
  const double s = fa / (fa - fb);
  local[a] = step > 0 ? s : 1.0 - s;
  return {segment_point(ta, tb, s), unit_normal(normals.at(local, inv_size), dir), 0.0f};
}

// The roots of one cell c on the ray segment [ta, tb], appended to `hits`: the cell's cubic
// (Marmitt et al.). `entry_face`/`exit_face` say along which axes the segment starts/ends
// exactly on a cell face (the local coordinate is then exactly 0 or 1, so that a face point is
// evaluated by the same arithmetic in both cells that share it). With kSkipNonfinite, a cell
// with a NaN or ±Inf corner produces no hits. Both casters solve cells here (the coherent one
// where its shortcut does not decide).
template <bool kSkipNonfinite, class T>
void solve_cell(const GridView<T>& g, double iso, glm::dvec3 org, glm::dvec3 dir,
                const std::array<std::int64_t, 3>& c, const std::array<int, 3>& step, double ta,
                double tb, const std::array<bool, 3>& entry_face,
                const std::array<bool, 3>& exit_face, std::vector<RayHit>& hits) {
  double corner[8];
  bool any_positive = false, any_negative = false;
  for (int n = 0; n < 8; ++n) {
    const double v = g.value(c[0] + (n & 1), c[1] + ((n >> 1) & 1), c[2] + ((n >> 2) & 1));
    if constexpr (kSkipNonfinite) {
      if (!std::isfinite(v)) return;  // no interpolant in this cell
    }
    corner[n] = v - iso;
    (positive(corner[n]) ? any_positive : any_negative) = true;
  }
  if (!any_positive || !any_negative) return;  // the interpolant lies between its corners
  glm::dvec3 lo, size, a, b;
  const glm::dvec3 pa = org + ta * dir, pb = org + tb * dir;
  for (int k = 0; k < 3; ++k) {
    lo[k] = g.coord(k, c[k]);
    size[k] = g.coord(k, c[k] + 1) - lo[k];
    // Exactly 0 or 1 on the face the ray enters or leaves through.
    a[k] =
        entry_face[k] ? (step[k] > 0 ? 0.0 : 1.0) : std::clamp((pa[k] - lo[k]) / size[k], 0.0, 1.0);
    b[k] =
        exit_face[k] ? (step[k] > 0 ? 1.0 : 0.0) : std::clamp((pb[k] - lo[k]) / size[k], 0.0, 1.0);
  }
  double roots[3];
  const int n = trilinear_segment_roots(corner, a, b, roots);
  if (n == 0) return;
  const glm::dvec3 inv_size = 1.0 / size;
  const CellNormals<T> normals(g, c, corner, iso);
  for (int r = 0; r < n; ++r) {
    const glm::dvec3 p = a + roots[r] * (b - a);
    const double t = segment_point(ta, tb, roots[r]);
    hits.push_back({t, unit_normal(normals.at(p, inv_size), dir), 0.0f});
  }
}

// Folds points i0 … i1 (at least two) of row (j, k) into the running minimum and maximum
// (NaNs left out; ±Inf in) and clears `finite` where one of them is NaN or ±Inf (v − v is 0
// exactly for the finite ones). A row in memory order goes two doubles or four floats per
// instruction with SSE2 (every x86-64), at memory speed where the scalar loop was not
// (docs/history/benchmarks-log.md, "The solver waits 8 ms"). The scalar loop
// keeps two points per step in separate accumulators, so that no chain of dependent operations
// bounds it.
template <class T>
void scan_row(const GridView<T>& g, std::int64_t i0, std::int64_t i1, std::int64_t j,
              std::int64_t k, double& lo, double& hi, bool& finite) {
#if defined(__SSE2__)
  if (g.strides[0] == 1) {
    const T* p = g.values + (i0 + j * g.strides[1] + k * g.strides[2]);
    const std::int64_t n = i1 - i0 + 1;
    std::int64_t i = 0;
    if constexpr (std::is_same_v<T, float>) {
      __m128 l = _mm_set1_ps(INFINITY), h = _mm_set1_ps(-INFINITY), z = _mm_setzero_ps();
      const auto fold = [&](__m128 x) {  // min/max keep their second operand for a NaN
        l = _mm_min_ps(x, l);
        h = _mm_max_ps(x, h);
        z = _mm_add_ps(z, _mm_sub_ps(x, x));
      };
      for (; i + 4 <= n; i += 4)
        fold(_mm_loadu_ps(p + i));
      for (; i < n; ++i)
        fold(_mm_set1_ps(p[i]));
      l = _mm_min_ps(l, _mm_movehl_ps(l, l));
      h = _mm_max_ps(h, _mm_movehl_ps(h, h));
      z = _mm_add_ps(z, _mm_movehl_ps(z, z));
      l = _mm_min_ss(l, _mm_shuffle_ps(l, l, 1));
      h = _mm_max_ss(h, _mm_shuffle_ps(h, h, 1));
      z = _mm_add_ss(z, _mm_shuffle_ps(z, z, 1));
      lo = std::min(lo, double(_mm_cvtss_f32(l)));
      hi = std::max(hi, double(_mm_cvtss_f32(h)));
      finite = finite && _mm_cvtss_f32(z) == 0.0f;
    } else {
      __m128d l = _mm_set1_pd(INFINITY), h = _mm_set1_pd(-INFINITY), z = _mm_setzero_pd();
      const auto fold = [&](__m128d x) {
        l = _mm_min_pd(x, l);
        h = _mm_max_pd(x, h);
        z = _mm_add_pd(z, _mm_sub_pd(x, x));
      };
      for (; i + 2 <= n; i += 2)
        fold(_mm_loadu_pd(p + i));
      if (i < n) fold(_mm_set1_pd(p[i]));
      l = _mm_min_sd(l, _mm_unpackhi_pd(l, l));
      h = _mm_max_sd(h, _mm_unpackhi_pd(h, h));
      z = _mm_add_sd(z, _mm_unpackhi_pd(z, z));
      lo = std::min(lo, _mm_cvtsd_f64(l));
      hi = std::max(hi, _mm_cvtsd_f64(h));
      finite = finite && _mm_cvtsd_f64(z) == 0.0;
    }
    return;
  }
#endif
  double lo1 = lo, hi1 = hi, z0 = 0.0, z1 = 0.0;
  std::int64_t i = i0;
  for (; i < i1; i += 2) {
    const double v0 = g.value(i, j, k), v1 = g.value(i + 1, j, k);
    lo = std::min(lo, v0);
    hi = std::max(hi, v0);
    z0 += v0 - v0;
    lo1 = std::min(lo1, v1);
    hi1 = std::max(hi1, v1);
    z1 += v1 - v1;
  }
  if (i == i1) {
    const double v = g.value(i, j, k);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
    z0 += v - v;
  }
  lo = std::min(lo, lo1);
  hi = std::max(hi, hi1);
  finite = finite && z0 + z1 == 0.0;
}

}  // namespace

// The bricks of a block, which of them may hold the isosurface, and the non-finite count.
struct BrickCulling {
  std::vector<Brick> bricks;         // all, x fastest
  std::vector<std::uint8_t> active;  // per brick: its value range holds the isovalue
  std::uint64_t nonfinite = 0;
  std::size_t active_count = 0;
};

namespace {

// Bricks the view does not hold (GridView::held) are not read: none of them is active or holds a
// non-finite value (GridSource::needed_bricks).
template <class T>
BrickCulling cull_bricks(const GridView<T>& grid, double iso,
                         const std::array<std::int64_t, 3>& first,
                         const std::array<std::int64_t, 3>& last,
                         const std::array<std::int64_t, 3>& bricks, int brick_cells) {
  const std::int64_t total = bricks[0] * bricks[1] * bricks[2];
  BrickCulling out;
  out.active.resize(total);
  out.bricks.resize(total);
  std::atomic<std::uint64_t> nonfinite{0};
  tbb::parallel_for(std::int64_t(0), total, [&](std::int64_t n) {
    const std::array<std::int64_t, 3> idx{n % bricks[0], (n / bricks[0]) % bricks[1],
                                          n / (bricks[0] * bricks[1])};
    Brick& b = out.bricks[n];
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = first[a] + idx[a] * brick_cells;
      b.hi[a] = std::min(last[a], b.lo[a] + brick_cells - 1);
      b.box_lo[a] = grid.coord(a, b.lo[a]);
      b.box_hi[a] = grid.coord(a, b.hi[a] + 1);
    }
    if (grid.held && !grid.held[n]) return;
    // Range of the trilinear interpolant over the brick = range of its points. A closer look
    // only where one of them is NaN or ±Inf.
    double lo = INFINITY, hi = -INFINITY;
    bool finite = true;
    for (std::int64_t k = b.lo[2]; k <= b.hi[2] + 1; ++k)
      for (std::int64_t j = b.lo[1]; j <= b.hi[1] + 1; ++j)
        scan_row(grid, b.lo[0], b.hi[0] + 1, j, k, lo, hi, finite);
    if (!finite) [[unlikely]] {
      // Non-finite points are left out of the range (their cells produce no hits, the others
      // keep theirs) and counted by the one brick that owns them: a brick owns the points below
      // its upper layer of points along each axis, which the next brick reads as its lower
      // layer, and the last brick along an axis owns that layer too. So every point read is
      // counted exactly once.
      std::array<std::int64_t, 3> owned_hi;
      for (int a = 0; a < 3; ++a)
        owned_hi[a] = b.hi[a] == last[a] ? b.hi[a] + 1 : b.hi[a];
      lo = INFINITY, hi = -INFINITY;
      std::uint64_t bad = 0;
      for (std::int64_t k = b.lo[2]; k <= b.hi[2] + 1; ++k)
        for (std::int64_t j = b.lo[1]; j <= b.hi[1] + 1; ++j)
          for (std::int64_t i = b.lo[0]; i <= b.hi[0] + 1; ++i) {
            const double v = grid.value(i, j, k);
            if (std::isfinite(v)) {
              lo = std::min(lo, v);
              hi = std::max(hi, v);
            } else {
              b.nonfinite = true;
              bad += i <= owned_hi[0] && j <= owned_hi[1] && k <= owned_hi[2];
            }
          }
      if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
    }
    out.active[n] = lo <= iso && iso <= hi;
  });
  out.nonfinite = nonfinite.load();
  for (std::uint8_t f : out.active)
    out.active_count += f;
  return out;
}

}  // namespace

// The axis caster's bind-time pass (grid_classify.cpp) over cells first … first + cells − 1:
// each cell's straddle bit (its corners' signs against `iso` differ; rows along x, 64 cells per
// word) into `straddle`, and the non-finite points into `nonfinite_count`. With a held mask
// (GridView::held) only the held bricks' points count and only their cells straddle: the
// others' points may be anything (a snapshot did not copy them), but none of them is non-finite
// and none of their cells straddles (GridSource::needed_bricks), so the result is the one of the
// whole field.
template <class T>
void classify_cells(const GridView<T>& g, double iso, const std::array<std::int64_t, 3>& first,
                    const std::array<std::int64_t, 3>& cells,
                    const std::array<std::int64_t, 3>& bricks, int brick_cells,
                    std::vector<std::uint64_t>& straddle, std::uint64_t& nonfinite_count);

// The Embree binding of the block's active bricks (grid_embree.cpp), and its coherent caster of
// axis rays (grid_axis.cpp): for T = float and double.
template <class T>
std::unique_ptr<GeometryBinding> bind_grid(RTCDevice device, const GridView<T>& grid, double iso,
                                           const std::array<std::int64_t, 3>& first,
                                           const std::array<std::int64_t, 3>& last,
                                           const std::array<std::int64_t, 3>& bricks,
                                           int brick_cells);
template <class T>
std::unique_ptr<AxisCaster> bind_grid_axis(const GridView<T>& grid, double iso,
                                           std::array<std::int64_t, 3> first,
                                           std::array<std::int64_t, 3> last,
                                           std::array<std::int64_t, 3> bricks, int brick_cells,
                                           std::shared_ptr<const std::vector<std::uint8_t>> held);

}  // namespace ldimesh::grid

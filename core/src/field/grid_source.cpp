#include "ldimesh/core/field/grid_source.hpp"

#include "colour_block.hpp"

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

namespace ldimesh {
namespace {

const char* kAxis[3] = {"x", "y", "z"};

double eval_cubic(const double c[4], double s) {
  return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

// The trilinear interpolant at local point p: Σ w_n · corner[n] with w_n = wx·wy·wz, summed in
// corner order. Where p lies on a face (a coordinate exactly 0 or 1) the other side's weights
// are exact zeros, and the cell on the other side of that face computes the same sum of the
// same products: the value on a shared face does not depend on the cell.
double trilinear_value(const double corner[8], glm::dvec3 p) {
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
double converge_cubic(const double c[4], double a, double b, double fa, double fb) {
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

// Bit i: v[i] ≥ threshold (false for NaN); bit i of `finite`: v[i] is neither NaN nor ±Inf.
// The grid caster's binding classifies every point so; with SSE2 (every x86-64) four floats or
// two doubles per comparison — the portable loop took about three cycles per point.
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

template <class T>
class GridBinding final : public GeometryBinding {
 public:
  GridBinding(RTCDevice device, const GridView<T>& grid, double iso, std::vector<Brick> bricks,
              std::array<std::int64_t, 3> last, std::uint64_t nonfinite)
      : grid_(grid),
        iso_(iso),
        bricks_(std::move(bricks)),
        last_(last),
        nonfinite_(nonfinite),
        geometry_(device, bricks_.size(), this, &GridBinding::bounds, &GridBinding::intersect) {}
  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return bricks_.size(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const GridBinding*>(args->geometryUserPtr);
    const Brick& b = self->bricks_[args->primID];
    write_padded_bounds(b.box_lo, b.box_hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const GridBinding*>(args->geometryUserPtr);
    RayQuery& q = *reinterpret_cast<RayQuery*>(args->context);
    const Brick& b = self->bricks_[args->primID];
    if (b.nonfinite)
      self->template intersect_brick<true>(q, b);
    else
      self->template intersect_brick<false>(q, b);
  }

  // Walks the cells of the brick along the ray (3D DDA) and solves each cell's cubic. With
  // kSkipNonfinite, cells with a NaN or ±Inf corner produce no hits; bricks without such values
  // take the path without the check.
  template <bool kSkipNonfinite>
  void intersect_brick(RayQuery& q, const Brick& b) const {
    double t0 = q.t_min, t1 = q.t_max;
    if (!clip_ray_to_box(q.org, q.dir, b.box_lo, b.box_hi, t0, t1)) return;
    // A ray in the plane of a face between two bricks belongs to the upper one (as a ray in a
    // cell face plane belongs to the upper cell below): each ray point lies in one cell.
    for (int a = 0; a < 3; ++a)
      if (q.dir[a] == 0.0 && q.org[a] == b.box_hi[a] && b.hi[a] != last_[a]) return;
    const GridView<T>& g = grid_;
    std::array<std::int64_t, 3> cell;
    std::array<int, 3> step;
    std::array<double, 3> t_next, inv;
    // Axes along which the current cell's entry point lies exactly on a face. A face point is
    // then evaluated by the same arithmetic in both cells that share the face (and in both
    // bricks or ranks), so the sign tests at segment ends agree and no root is lost or doubled.
    std::array<bool, 3> on_entry_face{false, false, false};
    const glm::dvec3 entry = q.org + t0 * q.dir;
    for (int a = 0; a < 3; ++a) {
      std::int64_t i = b.lo[a];
      while (i < b.hi[a] && g.coord(a, i + 1) <= entry[a])
        ++i;  // at most brick_cells steps
      // On a cell face, start in the cell the ray goes into.
      if (q.dir[a] < 0.0 && i > b.lo[a] && g.coord(a, i) == entry[a]) --i;
      cell[a] = i;
      step[a] = q.dir[a] > 0.0 ? 1 : (q.dir[a] < 0.0 ? -1 : 0);
      // t at a face as clip_ray_to_box computes it: (face − o) · (1 / d).
      inv[a] = step[a] == 0 ? 0.0 : 1.0 / q.dir[a];
      t_next[a] =
          step[a] == 0 ? INFINITY : (g.coord(a, step[a] > 0 ? i + 1 : i) - q.org[a]) * inv[a];
      on_entry_face[a] =
          step[a] != 0 && (g.coord(a, step[a] > 0 ? i : i + 1) - q.org[a]) * inv[a] == t0;
    }
    double t = t0;
    while (t < t1) {
      const double t_exit = std::min({t_next[0], t_next[1], t_next[2], t1});
      std::array<bool, 3> on_exit_face;
      for (int a = 0; a < 3; ++a)
        on_exit_face[a] = t_next[a] == t_exit;
      if (t_exit > t)
        solve_cell<kSkipNonfinite>(g, iso_, q.org, q.dir, cell, step, t, t_exit, on_entry_face,
                                   on_exit_face, *q.hits);
      t = std::max(t, t_exit);  // a face behind t (rounding at the entry) moves nothing back
      // Advance along every axis whose face the ray leaves through (several at an edge).
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        on_entry_face[a] = on_exit_face[a];
        if (!on_exit_face[a]) continue;
        cell[a] += step[a];
        if (cell[a] < b.lo[a] || cell[a] > b.hi[a])
          inside = false;
        else
          t_next[a] = (g.coord(a, step[a] > 0 ? cell[a] + 1 : cell[a]) - q.org[a]) * inv[a];
      }
      if (!inside) break;
    }
  }

  GridView<T> grid_;
  double iso_;
  std::vector<Brick> bricks_;
  std::array<std::int64_t, 3> last_;
  std::uint64_t nonfinite_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

// Folds points i0 … i1 (at least two) of row (j, k) into the running minimum and maximum
// (NaNs left out; ±Inf in) and clears `finite` where one of them is NaN or ±Inf (v − v is 0
// exactly for the finite ones). A row in memory order goes two doubles or four floats per
// instruction with SSE2 (every x86-64): 2.3 times faster than the scalar loop over the Gray–Scott
// block's bricks (6.5 → 2.8 ms for 194 × 194 × 98 doubles, needed_bricks' pass). The scalar loop
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

// The bricks of a block, which of them may hold the isosurface, and the non-finite count.
struct BrickCulling {
  std::vector<Brick> bricks;         // all, x fastest
  std::vector<std::uint8_t> active;  // per brick: its value range holds the isovalue
  std::uint64_t nonfinite = 0;
  std::size_t active_count = 0;
};

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

template <class T>
std::unique_ptr<GeometryBinding> bind_grid(RTCDevice device, const GridView<T>& grid, double iso,
                                           const std::array<std::int64_t, 3>& first,
                                           const std::array<std::int64_t, 3>& last,
                                           const std::array<std::int64_t, 3>& bricks,
                                           int brick_cells) {
  BrickCulling culled = cull_bricks(grid, iso, first, last, bricks, brick_cells);
  std::vector<Brick> kept;
  kept.reserve(culled.active_count);
  for (std::size_t n = 0; n < culled.bricks.size(); ++n)
    if (culled.active[n]) kept.push_back(culled.bricks[n]);
  return std::make_unique<GridBinding<T>>(device, grid, iso, std::move(kept), last,
                                          culled.nonfinite);
}

// The coherent caster of a grid block for rays parallel to an axis. Along such a ray the
// trilinear interpolant is linear inside each cell: its value on a cell face the ray crosses
// is the bilinear interpolation of the face's four points, shared by the two cells, and the
// root in a cell is one division.
//
// Empty space is skipped with bits instead of a walk: at bind time one pass over the points
// gives each point's sign (v − iso ≥ 0, as solve_cell tests it) and each cell a bit "its
// corners have both signs" — only such cells can hold a root in either caster (solve_cell
// returns at once for the others). Per axis, each column of cells gets one bit per 4 cells
// along the axis (any such cell among them). A ray reads its column's words, and visits only
// the cells whose bit is set, in ray order. Each of them is solved exactly as the Embree
// binding's walk would solve it: the same segment ends and face flags (derived from the same
// brick clipping), the same face values (the same products summed in the same order), and
// solve_cell itself where the shortcut does not decide (a segment end inside a cell, a face
// value that is zero or not finite). The Embree binding solves a segment along one axis as a
// line too (trilinear_segment_roots), so both give the same roots, to the bit, at every
// degenerate spot as well.
//
// An axis view's pixel rays (a lattice query) are cast in object order instead (cast_lattice):
// the straddling cells of the rows' slab, visited once each in memory order, solve the rays
// through them with the same arithmetic; only rays whose segment ends inside the block walk
// their columns as above.
template <class T>
class GridAxisBinding final : public AxisBinding {
 public:
  // `held`: the source's (GridSource::held_), kept alive for primitive_count().
  GridAxisBinding(const GridView<T>& grid, double iso, std::array<std::int64_t, 3> first,
                  std::array<std::int64_t, 3> last, std::array<std::int64_t, 3> bricks,
                  int brick_cells, std::shared_ptr<const std::vector<std::uint8_t>> held)
      : g_(grid),
        held_(std::move(held)),
        iso_(iso),
        first_(first),
        last_(last),
        bricks_(bricks),
        brick_cells_(brick_cells) {
    g_.held = held_ ? held_->data() : nullptr;
    for (int a = 0; a < 3; ++a)
      cells_[a] = last_[a] - first_[a] + 1;
    classify();
  }

  std::size_t primitive_count() const override {
    // The Embree binding's figure (its bricks after culling), computed when asked.
    std::call_once(count_once_, [this] {
      // Isolated: a thread waiting here inside a task must not pick up another of its caller's.
      tbb::this_task_arena::isolate([this] {
        active_bricks_ = cull_bricks(g_, iso_, first_, last_, bricks_, brick_cells_).active_count;
      });
    });
    return active_bricks_;
  }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

  bool prefers_column_tasks(const View& view) const override {
    const int ua = exact_axis(view.u), va = exact_axis(view.v);
    return ua >= 0 && va >= 0 && std::abs(g_.strides[va]) < std::abs(g_.strides[ua]);
  }

  void prepare(int a) const override {
    std::call_once(column_once_[a], [this, a] { build_columns(a); });
  }

  void cast(const AxisRays& rays, AxisHits& out) const override {
    const int a = rays.axis;
    prepare(a);
    if (rays.lattice && cast_lattice(rays, out)) return;
    std::vector<RayHit> hits;
    const auto cast_one = [&](std::size_t k) {
      const AxisRay& ray = rays.rays[k];
      if (!(ray.t0 <= ray.t1)) return;
      hits.clear();
      cast_ray(a, rays.dir, ray, hits);
      for (const RayHit& h : hits)
        out.push_back({std::uint32_t(k), h});
    };
    // Rays in the order that keeps the points they read in cache: along the image axis whose
    // world axis is the block's faster one in memory (neighbouring rays then read the same
    // cache lines).
    const View* view = rays.lattice;
    if (view && prefers_column_tasks(*view)) {
      const std::size_t width = std::size_t(rays.width()), rows = rays.rays.size() / width;
      for (std::size_t i = 0; i < width; ++i)
        for (std::size_t j = 0; j < rows; ++j)
          cast_one(j * width + i);
      return;
    }
    for (std::size_t k = 0; k < rays.rays.size(); ++k)
      cast_one(k);
  }

 private:
  static constexpr int kColumnBlock = 4;  // cells per bit of a column word

  // A brick's cells along the ray axis (lo … hi), the t of its entry face, and its stretch of
  // the ray [t0, t1] as clip_ray_to_box clips it.
  struct Stretch {
    std::int64_t lo, hi;
    double face_in, t0, t1;
  };

  std::size_t row_words() const { return std::size_t((cells_[0] + 63) / 64); }
  // Bits from … to (inclusive) of a row of words.
  static void set_bits(std::uint64_t* words, std::int64_t from, std::int64_t to) {
    for (std::int64_t i = from; i <= to; ++i)
      words[i / 64] |= std::uint64_t(1) << (i % 64);
  }
  // The bricks along one axis whose points include relative point index i: brick b holds points
  // b·brick_cells … b·brick_cells + brick_cells (the last one up to the last point).
  std::pair<std::int64_t, std::int64_t> bricks_of_point(int a, std::int64_t i) const {
    const std::int64_t hi = std::min(i / brick_cells_, bricks_[a] - 1);
    return {i % brick_cells_ == 0 && i > 0 ? i / brick_cells_ - 1 : hi, hi};
  }

  // The sign bits of the points and the cells' straddle bits, and the non-finite count. With a
  // held mask (GridView::held) only the held bricks' points count and only their cells
  // straddle: the others' points may be anything (a snapshot did not copy them), but none of
  // them is non-finite and none of their cells straddles (GridSource::needed_bricks), so the
  // result is the one of the whole field.
  void classify() {
    const std::int64_t px = cells_[0] + 1, py = cells_[1] + 1, pz = cells_[2] + 1;
    const std::size_t pw = std::size_t((px + 63) / 64), cw = row_words();
    std::vector<std::uint64_t> sign(pw * std::size_t(py * pz), 0);
    std::atomic<std::uint64_t> nonfinite{0};
    // Per brick row (y fastest): the held bricks' cells and points along x.
    std::vector<std::uint64_t> held_cells, held_points;
    if (g_.held) {
      const std::int64_t rows = bricks_[1] * bricks_[2];
      held_cells.assign(std::size_t(rows) * cw, 0);
      held_points.assign(std::size_t(rows) * pw, 0);
      for (std::int64_t r = 0; r < rows; ++r)
        for (std::int64_t b = 0; b < bricks_[0]; ++b) {
          if (!g_.held[b + bricks_[0] * r]) continue;
          const std::int64_t lo = b * brick_cells_, hi = std::min(lo + brick_cells_, cells_[0]);
          set_bits(&held_cells[std::size_t(r) * cw], lo, hi - 1);
          set_bits(&held_points[std::size_t(r) * pw], lo, hi);
        }
    }
    // The sign test in T: for a float v, v − iso ≥ 0 in double iff v ≥ the least float whose
    // double is ≥ iso (NaN fails both), so the rows compare in their own type, in bulk.
    T threshold = T(iso_);
    if (double(threshold) < iso_) threshold = std::nextafter(threshold, T(INFINITY));
    tbb::parallel_for(std::int64_t(0), pz, [&](std::int64_t z) {
      std::uint64_t bad = 0;
      T line[64];
      std::vector<std::uint64_t> held(g_.held ? pw : 0);  // this row's held points
      for (std::int64_t y = 0; y < py; ++y) {
        std::uint64_t* row = &sign[std::size_t(y + py * z) * pw];
        if (g_.held) {
          std::fill(held.begin(), held.end(), 0);
          const auto [y0, y1] = bricks_of_point(1, y);
          const auto [z0, z1] = bricks_of_point(2, z);
          for (std::int64_t bz = z0; bz <= z1; ++bz)
            for (std::int64_t by = y0; by <= y1; ++by)
              for (std::size_t w = 0; w < pw; ++w)
                held[w] |= held_points[std::size_t(by + bricks_[1] * bz) * pw + w];
        }
        const T* v = g_.values + (first_[0]) * g_.strides[0] + (first_[1] + y) * g_.strides[1] +
                     (first_[2] + z) * g_.strides[2];
        const std::int64_t sx = g_.strides[0];
        for (std::int64_t x0 = 0; x0 < px; x0 += 64) {
          // No held point here: not read at all (a snapshot may have given these pages back to
          // the system; reading them would fault zero pages in).
          if (g_.held && held[std::size_t(x0 / 64)] == 0) continue;
          const int n = int(std::min<std::int64_t>(64, px - x0));
          const T* src = v + x0 * sx;
          if (sx != 1 || n < 64) {  // into a padded line (the padding: clear, not counted)
            for (int i = 0; i < n; ++i)
              line[i] = src[i * sx];
            std::fill(line + n, line + 64, T(-INFINITY));
            src = line;
          }
          std::uint64_t finite = 0;
          row[x0 / 64] = sign_bits(src, threshold, finite);
          if (g_.held)
            bad += std::uint64_t(std::popcount(~finite & held[x0 / 64]));
          else
            bad += std::uint64_t(64 - std::popcount(finite)) - std::uint64_t(64 - n);
        }
      }
      if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
    });
    nonfinite_ = nonfinite.load();
    // A cell straddles iff its 8 corner bits are neither all set nor all clear.
    straddle_.assign(cw * std::size_t(cells_[1] * cells_[2]), 0);
    tbb::parallel_for(std::int64_t(0), cells_[2], [&](std::int64_t z) {
      for (std::int64_t y = 0; y < cells_[1]; ++y) {
        const std::uint64_t* r[4] = {&sign[std::size_t(y + py * z) * pw],
                                     &sign[std::size_t(y + 1 + py * z) * pw],
                                     &sign[std::size_t(y + py * (z + 1)) * pw],
                                     &sign[std::size_t(y + 1 + py * (z + 1)) * pw]};
        std::uint64_t* out = &straddle_[std::size_t(y + cells_[1] * z) * cw];
        for (std::size_t w = 0; w < cw; ++w) {
          std::uint64_t any = 0, all = ~std::uint64_t(0);
          for (const std::uint64_t* row : r) {
            const std::uint64_t here = row[w];
            const std::uint64_t next = (here >> 1) | (w + 1 < pw ? row[w + 1] << 63 : 0);
            any |= here | next;
            all &= here & next;
          }
          std::uint64_t bits = any & ~all;
          const std::int64_t valid = cells_[0] - std::int64_t(w) * 64;
          if (valid < 64) bits &= (std::uint64_t(1) << valid) - 1;
          if (g_.held)
            bits &=
                held_cells[std::size_t(y / brick_cells_ + bricks_[1] * (z / brick_cells_)) * cw +
                           w];
          out[w] = bits;
        }
      }
    });
  }

  // Axis a's column words: bit q of column (b, c) (the transverse cell indices, relative) is set
  // iff one of its cells 4q … 4q + 3 along a straddles.
  std::size_t column_words(int a) const {
    return std::size_t(((cells_[a] + kColumnBlock - 1) / kColumnBlock + 63) / 64);
  }
  void build_columns(int a) const {
    // Isolated: should a thread get here inside one of the caster's tasks (prepare() not
    // called), it must not pick up another of them while it waits (they share its buffers).
    tbb::this_task_arena::isolate([this, a] { build_columns_isolated(a); });
  }
  void build_columns_isolated(int a) const {
    const int b = a == 0 ? 1 : 0, c = a == 2 ? 1 : 2;
    const std::size_t wpc = column_words(a);
    std::vector<std::uint64_t>& col = columns_[a];
    col.assign(wpc * std::size_t(cells_[b] * cells_[c]), 0);
    const std::size_t cw = row_words();
    const auto set = [&](std::int64_t cb, std::int64_t cc, std::int64_t q) {
      col[std::size_t(cb + cells_[b] * cc) * wpc + std::size_t(q / 64)] |= std::uint64_t(1)
                                                                           << (q % 64);
    };
    if (a == 0) {
      tbb::parallel_for(std::int64_t(0), cells_[2], [&](std::int64_t z) {
        for (std::int64_t y = 0; y < cells_[1]; ++y) {
          const std::uint64_t* row = &straddle_[std::size_t(y + cells_[1] * z) * cw];
          for (std::size_t w = 0; w < cw; ++w)
            for (std::uint64_t bits = row[w]; bits; bits &= bits - 1)
              set(y, z, (std::int64_t(w) * 64 + std::countr_zero(bits)) / kColumnBlock);
        }
      });
      return;
    }
    // a = y: columns (x, z); a = z: columns (x, y). OR the rows of each block along a, then
    // set the bit of every x whose cells straddle.
    const std::int64_t outer = a == 1 ? cells_[2] : cells_[1];
    tbb::parallel_for(std::int64_t(0), outer, [&](std::int64_t o) {
      std::vector<std::uint64_t> merged(cw);
      for (std::int64_t q = 0; q * kColumnBlock < cells_[a]; ++q) {
        std::fill(merged.begin(), merged.end(), 0);
        for (std::int64_t k = q * kColumnBlock; k < std::min(cells_[a], (q + 1) * kColumnBlock);
             ++k) {
          const std::int64_t y = a == 1 ? k : o, z = a == 1 ? o : k;
          const std::uint64_t* row = &straddle_[std::size_t(y + cells_[1] * z) * cw];
          for (std::size_t w = 0; w < cw; ++w)
            merged[w] |= row[w];
        }
        for (std::size_t w = 0; w < cw; ++w)
          for (std::uint64_t bits = merged[w]; bits; bits &= bits - 1)
            set(std::int64_t(w) * 64 + std::countr_zero(bits), o, q);
      }
    });
  }

  // The pixel columns (or rows) of a lattice by the cell they lie in along one axis: pixels
  // pixels[first[q]] … pixels[first[q + 1] − 1] lie in cell first_ + q, at local coordinate p
  // (per pixel) across the rays, as cast_ray computes it; cells lo … hi (relative) hold some.
  struct PixelIndex {
    std::vector<std::uint32_t> first, pixels, next;
    std::vector<std::int64_t> cell;  // per pixel: its relative cell, −1 outside the block
    std::vector<double> p;
    std::int64_t lo = 0, hi = -1;
    // Pixels per cell that holds any.
    double density() const {
      std::size_t cells = 0;
      for (std::size_t q = 0; q + 1 < first.size(); ++q)
        cells += first[q + 1] > first[q];
      return cells == 0 ? 0.0 : double(pixels.size()) / double(cells);
    }
  };
  struct LatticeScratch {
    PixelIndex columns, rows;
    std::vector<std::uint8_t> whole;  // per ray: its segment covers the block along the axis
    std::vector<RayHit> hits;
  };
  static LatticeScratch& lattice_scratch() {
    thread_local LatticeScratch scratch;
    return scratch;
  }

  template <class Coordinate>
  void index_pixels(int axis, std::size_t count, Coordinate coordinate, PixelIndex& ix) const {
    ix.cell.assign(count, -1);
    ix.p.assign(count, 0.0);
    ix.first.assign(std::size_t(cells_[axis]) + 1, 0);
    ix.lo = cells_[axis];
    ix.hi = -1;
    const double lowest = g_.coord(axis, first_[axis]), highest = g_.coord(axis, last_[axis] + 1);
    for (std::size_t m = 0; m < count; ++m) {
      const double x = coordinate(m);
      if (x < lowest || x > highest) continue;
      const std::int64_t c = cell_index(axis, x);
      const double lo = g_.coord(axis, c);
      ix.p[m] = std::clamp((x - lo) / (g_.coord(axis, c + 1) - lo), 0.0, 1.0);
      const std::int64_t q = c - first_[axis];
      ix.cell[m] = q;
      ++ix.first[std::size_t(q) + 1];
      ix.lo = std::min(ix.lo, q);
      ix.hi = std::max(ix.hi, q);
    }
    for (std::size_t q = 1; q < ix.first.size(); ++q)
      ix.first[q] += ix.first[q - 1];
    ix.pixels.resize(ix.first.back());
    ix.next.assign(ix.first.begin(), ix.first.end() - 1);
    for (std::size_t m = 0; m < count; ++m)
      if (ix.cell[m] >= 0) ix.pixels[ix.next[std::size_t(ix.cell[m])]++] = std::uint32_t(m);
  }

  // Object order for the pixel rays of an axis view's rows (AxisRays::lattice): the straddling
  // cells of the rows' slab of the block are visited once each, in memory order, and each
  // solves the rays through it, instead of each ray walking its own column (at 512² of a 256³
  // block four rays share a column, and the column walks read the block out of order). The rays
  // whose segment covers the block's whole stretch along the axis — a view, or a rank's
  // fragment of its own block — are solved so; the others by cast_ray. Per ray and cell the
  // arithmetic is cast_ray's (its whole-segment case): the same cell across the ray, the same
  // face values (face_value), roots and gradients (axis_root), and solve_cell where a face value
  // is zero or not finite. Returns false where the rays do not form a lattice of this view
  // (cast() then casts them one by one).
  bool cast_lattice(const AxisRays& rays, AxisHits& out) const {
    const View& view = *rays.lattice;
    const int a = rays.axis;
    const int ua = exact_axis(view.u), va = exact_axis(view.v);
    if (ua < 0 || va < 0 || ua == a || va == a || rays.width() <= 0) return false;
    const std::span<const AxisRay> ray = rays.rays;
    const std::size_t width = std::size_t(rays.width()), n = ray.size();
    if (n == 0) return true;
    if (n % width != 0) return false;
    const double oa = ray[0].org[a];
    for (std::size_t row = 0; row < n; row += width)
      for (std::size_t i = 0; i < width; ++i) {
        const glm::dvec3 o = ray[row + i].org;
        if (o[ua] != ray[i].org[ua] || o[va] != ray[row].org[va] || o[a] != oa) return false;
      }

    const glm::dvec3 dir = rays.dir;
    const double inv = 1.0 / dir[a];
    const auto t_at = [&](std::int64_t node) { return (g_.coord(a, node) - oa) * inv; };
    const double t_lo = std::min(t_at(first_[a]), t_at(last_[a] + 1));
    const double t_hi = std::max(t_at(first_[a]), t_at(last_[a] + 1));
    LatticeScratch& x = lattice_scratch();
    index_pixels(
        ua, width, [&](std::size_t i) { return ray[i].org[ua]; }, x.columns);
    index_pixels(
        va, n / width, [&](std::size_t j) { return ray[j * width].org[va]; }, x.rows);
    // Object order pays where the rays are about as dense as the cells or denser: it streams the
    // block, while each ray's walk of its column misses the cache on most faces (measured on
    // Marschner–Lobb 256³ in alternating runs: 20–40 % faster at 2 × 2 rays per cell, 3–8 % at
    // one ray per cell, 3–6 % slower at 0.75 × 0.75): below 0.75 rays per column of cells on
    // average the rays walk their columns.
    if (x.columns.density() * x.rows.density() < 0.75) return false;
    x.whole.assign(n, 0);
    for (std::size_t k = 0; k < n; ++k) {
      const AxisRay& r = ray[k];
      if (!(r.t0 <= r.t1)) continue;
      if (r.t0 <= t_lo && r.t1 >= t_hi) {
        x.whole[k] = 1;
        continue;
      }
      x.hits.clear();
      cast_ray(a, dir, r, x.hits);
      for (const RayHit& h : x.hits)
        out.push_back({std::uint32_t(k), h});
    }
    if (x.columns.hi < x.columns.lo || x.rows.hi < x.rows.lo) return true;

    // The slab: every cell along a, the cells that hold pixels across.
    std::array<std::int64_t, 3> lo{0, 0, 0}, hi{cells_[0] - 1, cells_[1] - 1, cells_[2] - 1};
    lo[ua] = x.columns.lo;
    hi[ua] = x.columns.hi;
    lo[va] = x.rows.lo;
    hi[va] = x.rows.hi;
    const Lattice lattice{ray, width, oa, dir, lo, hi};
    // The axes as template constants: the slab solver for (a, whether u is the lower transverse
    // axis).
    using Solver = void (GridAxisBinding::*)(const Lattice&, LatticeScratch&, AxisHits&) const;
    static constexpr Solver kSolvers[6] = {
        &GridAxisBinding::solve_slab<0, false>, &GridAxisBinding::solve_slab<0, true>,
        &GridAxisBinding::solve_slab<1, false>, &GridAxisBinding::solve_slab<1, true>,
        &GridAxisBinding::solve_slab<2, false>, &GridAxisBinding::solve_slab<2, true>};
    (this->*kSolvers[a * 2 + int(ua < va)])(lattice, x, out);
    return true;
  }

  // What solve_slab needs of a lattice query: its rays (ray k is pixel (k % width, k / width)),
  // their common origin along the ray axis, the direction, and the slab's cells (relative).
  struct Lattice {
    std::span<const AxisRay> ray;
    std::size_t width;
    double oa;
    glm::dvec3 dir;
    std::array<std::int64_t, 3> lo, hi;
  };

  // The straddling cells of the slab, by their bits (rows along x), each solving the rays
  // through it: along axis A, B < C the transverse axes; kUIsB: the image's u axis (pixel
  // columns) is B, else C. The axes as constants keep the coordinates in registers.
  template <int A, bool kUIsB>
  void solve_slab(const Lattice& l, LatticeScratch& x, AxisHits& out) const {
    constexpr int B = A == 0 ? 1 : 0, C = A == 2 ? 1 : 2;
    const PixelIndex& along_b = kUIsB ? x.columns : x.rows;
    const PixelIndex& along_c = kUIsB ? x.rows : x.columns;
    const std::size_t stride_b = kUIsB ? 1 : l.width, stride_c = kUIsB ? l.width : 1;
    const std::array<std::int64_t, 3> s = g_.strides;
    std::int64_t offsets[8];
    for (int m = 0; m < 8; ++m)
      offsets[m] = (m & 1) * s[0] + ((m >> 1) & 1) * s[1] + ((m >> 2) & 1) * s[2];
    // Corner index of face point m (β = m & 1 along B, γ = m >> 1 along C) on the entry and the
    // exit face.
    const int step = l.dir[A] > 0.0 ? 1 : -1;
    const double inv = 1.0 / l.dir[A];
    const int in = step > 0 ? 0 : 1;
    int face_in[4], face_out[4];
    for (int m = 0; m < 4; ++m) {
      face_in[m] = (in << A) | ((m & 1) << B) | ((m >> 1) << C);
      face_out[m] = ((1 - in) << A) | ((m & 1) << B) | ((m >> 1) << C);
    }
    const auto t_at = [&](std::int64_t node) { return (g_.coord(A, node) - l.oa) * inv; };

    // The rays of a cell whose face values differ in sign, solved after its loop (no branch on
    // the outcome, which is near random).
    struct Candidate {
      std::uint32_t k;
      double fa, fb, pb, pc;
    };
    constexpr int kCandidates = 64;
    Candidate candidates[kCandidates];
    int n_candidates = 0;
    double corner[8];
    std::array<std::int64_t, 3> cell;
    // The cell's stretch of the rays [t_in, t_out] and its inverse edges, computed when a ray
    // needs them (most straddling cells at one ray per cell have no hit); a cell without
    // thickness along the rays (t_out ≤ t_in) has none.
    double t_in = 0.0, t_out = 0.0;
    glm::dvec3 inv_size;
    bool extent_known = false, extent_ok = false;
    const auto extent = [&] {
      if (!extent_known) {
        const std::int64_t i = cell[A];
        t_in = t_at(step > 0 ? i : i + 1);
        t_out = t_at(step > 0 ? i + 1 : i);
        extent_ok = t_out > t_in;
        glm::dvec3 size;
        size[A] = g_.coord(A, i + 1) - g_.coord(A, i);
        size[B] = g_.coord(B, cell[B] + 1) - g_.coord(B, cell[B]);
        size[C] = g_.coord(C, cell[C] + 1) - g_.coord(C, cell[C]);
        inv_size = 1.0 / size;
        extent_known = true;
      }
      return extent_ok;
    };
    const auto flush = [&] {
      if (n_candidates == 0) return;
      if (!extent()) {
        n_candidates = 0;
        return;
      }
      const CellNormals<T> normals(g_, cell, corner, iso_);  // once for the cell's rays
      for (int m = 0; m < n_candidates; ++m) {
        const Candidate& h = candidates[m];
        glm::dvec3 local;
        local[B] = h.pb;
        local[C] = h.pc;
        out.push_back(
            {h.k, axis_root(normals, A, step, local, inv_size, h.fa, h.fb, t_in, t_out, l.dir)});
      }
      n_candidates = 0;
    };
    const auto solve_cell_rays = [&](std::int64_t rx, std::int64_t ry, std::int64_t rz) {
      const std::int64_t rel[3] = {rx, ry, rz};
      const std::size_t qb = std::size_t(rel[B]), qc = std::size_t(rel[C]);
      const std::uint32_t b0 = along_b.first[qb], b1 = along_b.first[qb + 1];
      const std::uint32_t c0 = along_c.first[qc], c1 = along_c.first[qc + 1];
      if (b0 == b1 || c0 == c1) return;
      for (int k = 0; k < 3; ++k)
        cell[k] = first_[k] + rel[k];
      extent_known = false;
      const T* lower = g_.values + cell[0] * s[0] + cell[1] * s[1] + cell[2] * s[2];
      for (int m = 0; m < 8; ++m)
        corner[m] = double(lower[offsets[m]]) - iso_;
      double f_in[4], f_out[4];
      for (int m = 0; m < 4; ++m) {
        f_in[m] = corner[face_in[m]];
        f_out[m] = corner[face_out[m]];
      }
      for (std::uint32_t mc = c0; mc < c1; ++mc) {
        const std::uint32_t pixel_c = along_c.pixels[mc];
        const double pc = along_c.p[pixel_c];
        for (std::uint32_t mb = b0; mb < b1; ++mb) {
          const std::uint32_t pixel_b = along_b.pixels[mb];
          const std::size_t k = pixel_b * stride_b + pixel_c * stride_c;
          if (!x.whole[k]) continue;
          const double pb = along_b.p[pixel_b];
          const double wb[2] = {1.0 - pb, pb}, wc[2] = {1.0 - pc, pc};
          const double w[4] = {wb[0] * wc[0], wb[1] * wc[0], wb[0] * wc[1], wb[1] * wc[1]};
          const double fa = face_value(w, f_in), fb = face_value(w, f_out);
          if (std::isfinite(fa) && std::isfinite(fb) && fa != 0.0 && fb != 0.0) [[likely]] {
            candidates[n_candidates] = {std::uint32_t(k), fa, fb, pb, pc};
            n_candidates += positive(fa) != positive(fb);
            if (n_candidates == kCandidates) flush();
            continue;
          }
          // A face value zero or not finite: solve_cell decides, as in cast_ray.
          if (!extent()) continue;
          std::array<int, 3> steps{0, 0, 0};
          steps[A] = step;
          std::array<bool, 3> entry_face{false, false, false}, exit_face{false, false, false};
          entry_face[A] = exit_face[A] = true;
          x.hits.clear();
          solve_cell<true>(g_, iso_, l.ray[k].org, l.dir, cell, steps, t_in, t_out, entry_face,
                           exit_face, x.hits);
          for (const RayHit& h : x.hits)
            out.push_back({std::uint32_t(k), h});
        }
      }
      flush();
    };

    const std::size_t cw = row_words();
    const std::size_t w0 = std::size_t(l.lo[0]) / 64, w1 = std::size_t(l.hi[0]) / 64;
    for (std::int64_t z = l.lo[2]; z <= l.hi[2]; ++z)
      for (std::int64_t y = l.lo[1]; y <= l.hi[1]; ++y) {
        const std::uint64_t* row = &straddle_[std::size_t(y + cells_[1] * z) * cw];
        for (std::size_t w = w0; w <= w1; ++w) {
          std::uint64_t bits = row[w];
          if (w == w0) bits &= ~std::uint64_t(0) << (l.lo[0] % 64);
          if (w == w1 && l.hi[0] % 64 != 63) bits &= (std::uint64_t(1) << (l.hi[0] % 64 + 1)) - 1;
          for (; bits; bits &= bits - 1)
            solve_cell_rays(std::int64_t(w) * 64 + std::countr_zero(bits), y, z);
        }
      }
  }

  // The cell along transverse axis b that holds coordinate x ∈ [coord(first), coord(last + 1)]:
  // the last cell whose lower face is at or below x (the upper cell on a shared face, as the
  // Embree binding's walk starts).
  std::int64_t cell_index(int b, double x) const {
    if (g_.rectilinear) {
      const double* c = g_.coords[b];
      return std::int64_t(std::upper_bound(c + first_[b] + 1, c + last_[b] + 1, x) - c) - 1;
    }
    const double guess = std::floor((x - g_.origin[b]) / g_.spacing[b]);
    std::int64_t i = std::clamp(std::int64_t(std::clamp(guess, -1e18, 1e18)), first_[b], last_[b]);
    while (i < last_[b] && g_.coord(b, i + 1) <= x)
      ++i;
    while (i > first_[b] && g_.coord(b, i) > x)
      --i;
    return i;
  }

  void cast_ray(int a, glm::dvec3 dir, const AxisRay& ray, std::vector<RayHit>& hits) const {
    const int b = a == 0 ? 1 : 0, c = a == 2 ? 1 : 2;  // the transverse axes, b < c
    const glm::dvec3 o = ray.org;
    if (o[b] < g_.coord(b, first_[b]) || o[b] > g_.coord(b, last_[b] + 1) ||
        o[c] < g_.coord(c, first_[c]) || o[c] > g_.coord(c, last_[c] + 1))
      return;
    std::array<std::int64_t, 3> cell;
    cell[b] = cell_index(b, o[b]);
    cell[c] = cell_index(c, o[c]);
    const std::uint64_t* column =
        &columns_[a][std::size_t(cell[b] - first_[b] + cells_[b] * (cell[c] - first_[c])) *
                     column_words(a)];
    // No straddling cell in the column: nothing to find (solve_cell finds nothing elsewhere).
    if (std::all_of(column, column + column_words(a), [](std::uint64_t w) { return w == 0; }))
      return;
    // Local coordinates across the ray, as solve_cell computes them.
    double p[3];
    glm::dvec3 inv_size(0.0);  // one over the cells' edges across the ray (the gradients')
    for (int k : {b, c}) {
      const double lo = g_.coord(k, cell[k]), size = g_.coord(k, cell[k] + 1) - lo;
      p[k] = std::clamp((o[k] - lo) / size, 0.0, 1.0);
      inv_size[k] = 1.0 / size;
    }
    // The four face points' weights in trilinear_value's order (b is the lower bit).
    const double wb[2] = {1.0 - p[b], p[b]}, wc[2] = {1.0 - p[c], p[c]};
    const double w[4] = {wb[0] * wc[0], wb[1] * wc[0], wb[0] * wc[1], wb[1] * wc[1]};
    const std::int64_t sa = g_.strides[a], sb = g_.strides[b], sc = g_.strides[c];
    const T* points = g_.values + cell[b] * sb + cell[c] * sc;
    const auto face = [&](std::int64_t node) {
      const T* q = points + node * sa;
      const double f[4] = {double(q[0]) - iso_, double(q[sb]) - iso_, double(q[sc]) - iso_,
                           double(q[sb + sc]) - iso_};
      return face_value(w, f);
    };
    // Where corner n of a cell (index x + 2y + 4z, as solve_cell has them) lies from the cell's
    // lowest point.
    std::int64_t offsets[8];
    for (int n = 0; n < 8; ++n)
      offsets[n] = ((n >> a) & 1) * sa + ((n >> b) & 1) * sb + ((n >> c) & 1) * sc;
    const int step = dir[a] > 0.0 ? 1 : -1;
    const double inv = 1.0 / dir[a];
    std::array<int, 3> steps{0, 0, 0};
    steps[a] = step;
    const auto t_at = [&](std::int64_t node) { return (g_.coord(a, node) - o[a]) * inv; };

    // The face value last computed, by node index (consecutive cells share a face).
    std::int64_t cached_node = -1;
    double cached_value = 0.0;
    const auto face_cached = [&](std::int64_t node) {
      if (node != cached_node) {
        cached_value = face(node);
        cached_node = node;
      }
      return cached_value;
    };
    // The hit in cell i on [ta, tb] whose face values fa, fb (finite, nonzero) differ in sign:
    // the one root of the linear function between the faces (as trilinear_segment_roots
    // computes it for a segment along one axis), and the gradient there, as solve_cell.
    const auto emit_root = [&](std::int64_t i, double fa, double fb, double ta, double tb) {
      double corner[8];
      const T* lower = points + i * sa;
      for (int n = 0; n < 8; ++n)
        corner[n] = double(lower[offsets[n]]) - iso_;
      glm::dvec3 local(0.0), inv_cell = inv_size;  // across the ray: the column's, once
      local[b] = p[b];
      local[c] = p[c];
      inv_cell[a] = 1.0 / (g_.coord(a, i + 1) - g_.coord(a, i));
      std::array<std::int64_t, 3> at = cell;
      at[a] = i;
      const CellNormals<T> normals(g_, at, corner, iso_);
      hits.push_back(axis_root(normals, a, step, local, inv_cell, fa, fb, ta, tb, dir));
    };
    // The cells whose face values differ in sign, solved (emit_root) in ray order when the
    // buffer fills, before solve_cell adds a hit and at the end.
    struct Pending {
      std::int64_t i;
      double fa, fb, ta, tb;
    };
    constexpr int kPending = 32;
    Pending pending[kPending];
    int n_pending = 0;
    const auto flush = [&] {
      for (int k = 0; k < n_pending; ++k)
        emit_root(pending[k].i, pending[k].fa, pending[k].fb, pending[k].ta, pending[k].tb);
      n_pending = 0;
    };
    // Cell i on [ta, tb], entered / left exactly on its faces or not: the shortcut where it
    // decides, solve_cell (the Embree binding's) where it does not.
    const auto solve = [&](std::int64_t i, double ta, double tb, bool on_entry,
                           bool on_exit) [[gnu::always_inline]] {
      if (on_entry && on_exit) {
        const double fa = face_cached(step > 0 ? i : i + 1);
        const double fb = face_cached(step > 0 ? i + 1 : i);
        if (std::isfinite(fa) && std::isfinite(fb) && fa != 0.0 && fb != 0.0) {
          // A candidate whatever the signs, kept only where they differ: no branch on the
          // outcome, which is near random.
          pending[n_pending] = {i, fa, fb, ta, tb};
          n_pending += positive(fa) != positive(fb);
          if (n_pending == kPending) flush();
          return;
        }
      }
      flush();
      cell[a] = i;
      std::array<bool, 3> entry_face{false, false, false}, exit_face{false, false, false};
      entry_face[a] = on_entry;
      exit_face[a] = on_exit;
      // Checking corners for NaN and ±Inf changes nothing for a cell without them.
      solve_cell<true>(g_, iso_, o, dir, cell, steps, ta, tb, entry_face, exit_face, hits);
    };

    // The brick (the Embree binding's primitive) of cell i along a, and its stretch of the ray
    // clipped as clip_ray_to_box clips it.
    const auto stretch_of = [&](std::int64_t i) {
      Stretch st;
      st.lo = first_[a] + (i - first_[a]) / brick_cells_ * brick_cells_;
      st.hi = std::min(last_[a], st.lo + brick_cells_ - 1);
      double ta = t_at(st.lo), tb = t_at(st.hi + 1);
      if (ta > tb) std::swap(ta, tb);
      st.face_in = ta;
      st.t0 = std::max(ray.t0, ta);
      st.t1 = std::min(ray.t1, tb);
      return st;
    };

    // The column's straddle bits: word and bit of its cell at relative index k along a.
    const std::size_t cw = row_words();
    const std::int64_t rb = cell[b] - first_[b], rc = cell[c] - first_[c];
    std::size_t base = 0, along = 0;  // word of cell 0 along a, words between cells along a
    unsigned bit0 = 0;
    if (a == 0) {
      base = std::size_t(rb + cells_[1] * rc) * cw;
    } else {
      base = (a == 1 ? std::size_t(cells_[1]) * std::size_t(rc) : std::size_t(rc)) * cw +
             std::size_t(rb) / 64;
      along = a == 1 ? cw : std::size_t(cells_[1]) * cw;
      bit0 = unsigned(rb % 64);
    }
    const auto straddling = [&](std::int64_t k) {
      if (a == 0) return bool((straddle_[base + std::size_t(k) / 64] >> (k % 64)) & 1u);
      return bool((straddle_[base + std::size_t(k) * along] >> bit0) & 1u);
    };

    // The brick the ray's segment starts inside (not on its face): the Embree binding walks it
    // from the segment's start point; so does this caster, cell by cell.
    std::int64_t start_lo = -1, start_hi = -2;
    {
      const double t_first = std::min(t_at(first_[a]), t_at(last_[a] + 1));
      if (ray.t0 > t_first) {
        const double e = o[a] + ray.t0 * dir[a];
        std::int64_t guess = first_[a];
        if (e >= g_.coord(a, last_[a] + 1)) {
          guess = last_[a];
        } else if (e > g_.coord(a, first_[a])) {
          guess = cell_index(a, e);
        }
        for (std::int64_t i : {guess, guess - step, guess + step}) {
          if (i < first_[a] || i > last_[a]) continue;
          const Stretch st = stretch_of(i);
          if (st.t0 > st.face_in && st.t0 < st.t1) {
            start_lo = st.lo;
            start_hi = st.hi;
            // solve_cell finds nothing in a cell that does not straddle: only those are solved.
            walk(a, st, o, dir, step, inv,
                 [&](std::int64_t k, double ta, double tb, bool on_entry, bool on_exit) {
                   if (straddling(k - first_[a])) solve(k, ta, tb, on_entry, on_exit);
                 });
            break;
          }
        }
      }
    }

    // Whether the segment covers the block's whole stretch along a: then every brick is entered
    // and left on its faces, and so is every cell (no clipping to compute).
    const bool whole = ray.t0 <= std::min(t_at(first_[a]), t_at(last_[a] + 1)) &&
                       ray.t1 >= std::max(t_at(first_[a]), t_at(last_[a] + 1));
    // The straddling cells, in ray order.
    const std::int64_t n_blocks = (cells_[a] + kColumnBlock - 1) / kColumnBlock;
    const std::size_t wpc = column_words(a);
    for (std::size_t wi = 0; wi < wpc; ++wi) {
      const std::size_t w = step > 0 ? wi : wpc - 1 - wi;
      std::uint64_t bits = column[w];
      while (bits) {
        const int bit = step > 0 ? std::countr_zero(bits) : 63 - std::countl_zero(bits);
        bits &= ~(std::uint64_t(1) << bit);
        const std::int64_t q = std::int64_t(w) * 64 + bit;
        if (q >= n_blocks) continue;
        const std::int64_t k0 = first_[a] + q * kColumnBlock;
        const std::int64_t k1 = std::min(last_[a], k0 + kColumnBlock - 1);
        for (std::int64_t m = 0; m <= k1 - k0; ++m) {
          const std::int64_t i = step > 0 ? k0 + m : k1 - m;
          if (i >= start_lo && i <= start_hi) continue;  // walked above
          if (!straddling(i - first_[a])) continue;
          const double t_in = t_at(step > 0 ? i : i + 1), t_out = t_at(step > 0 ? i + 1 : i);
          if (whole) {
            if (t_out > t_in) solve(i, t_in, t_out, true, true);
            continue;
          }
          const Stretch st = stretch_of(i);
          if (!(st.t0 < st.t1)) continue;  // the Embree binding skips the brick
          const double ta = std::max(st.t0, t_in), tb = std::min(st.t1, t_out);
          if (tb > ta) solve(i, ta, tb, t_in == ta, t_out <= st.t1);
        }
      }
    }
    flush();
  }

  // The Embree binding's walk through the cells of one brick's stretch of the ray, step by
  // step (GridBinding::intersect_brick, here along axis a only).
  template <class Solve>
  void walk(int a, const Stretch& st, glm::dvec3 o, glm::dvec3 dir, int step, double inv,
            const Solve& solve) const {
    const double entry = o[a] + st.t0 * dir[a];
    std::int64_t i = st.lo;
    if (g_.coord(a, st.hi) <= entry) {
      i = st.hi;
    } else {
      while (i < st.hi && g_.coord(a, i + 1) <= entry)
        ++i;
    }
    if (step < 0 && i > st.lo && g_.coord(a, i) == entry) --i;
    double t_next = (g_.coord(a, step > 0 ? i + 1 : i) - o[a]) * inv;
    bool on_entry = (g_.coord(a, step > 0 ? i : i + 1) - o[a]) * inv == st.t0;
    double t = st.t0;
    while (t < st.t1) {
      const double t_exit = std::min(t_next, st.t1);
      const bool on_exit = t_next == t_exit;
      if (t_exit > t) solve(i, t, t_exit, on_entry, on_exit);
      t = std::max(t, t_exit);
      on_entry = on_exit;
      if (!on_exit) break;
      i += step;
      if (i < st.lo || i > st.hi) break;
      t_next = (g_.coord(a, step > 0 ? i + 1 : i) - o[a]) * inv;
    }
  }

  GridView<T> g_;
  std::shared_ptr<const std::vector<std::uint8_t>> held_;
  double iso_;
  std::array<std::int64_t, 3> first_, last_, bricks_, cells_;
  int brick_cells_;
  std::uint64_t nonfinite_ = 0;
  std::vector<std::uint64_t> straddle_;  // per cell row along x, 64 cells per word
  mutable std::array<std::vector<std::uint64_t>, 3> columns_;
  mutable std::array<std::once_flag, 3> column_once_;
  mutable std::once_flag count_once_;
  mutable std::size_t active_bricks_ = 0;
};

}  // namespace

int trilinear_segment_roots(const double corner[8], glm::dvec3 a, glm::dvec3 b, double roots[3]) {
  const glm::dvec3 d = b - a;
  if (int(d.x != 0.0) + int(d.y != 0.0) + int(d.z != 0.0) == 1) {
    // Along one axis the interpolant is linear: its root from the end values, evaluated as on a
    // face (see trilinear_value), with no rounding of cubic coefficients in between. This is
    // what the coherent caster of axis rays computes, to the bit.
    const double fa = trilinear_value(corner, a), fb = trilinear_value(corner, b);
    if (fa == 0.0) {
      roots[0] = 0.0;  // a root exactly at the start belongs to this segment (see below)
      return 1;
    }
    if (positive(fa) == positive(fb)) return 0;
    roots[0] = fa / (fa - fb);
    return 1;
  }
  // Each local coordinate is linear in s: x(s) = a + (b − a)s, and 1 − x(s) likewise; the
  // interpolant Σ corner · X·Y·Z is their product, a cubic in s (power basis, c[k] of s^k).
  const double L[3][2][2] = {{{1.0 - a.x, -d.x}, {a.x, d.x}},
                             {{1.0 - a.y, -d.y}, {a.y, d.y}},
                             {{1.0 - a.z, -d.z}, {a.z, d.z}}};
  double c[4] = {0.0, 0.0, 0.0, 0.0};
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 2; ++y) {
      const double* Y = L[1][y];
      const double* Z = L[2][z];
      const double q0 = Y[0] * Z[0], q1 = Y[0] * Z[1] + Y[1] * Z[0], q2 = Y[1] * Z[1];
      for (int x = 0; x < 2; ++x) {
        const double v = corner[x + 2 * y + 4 * z];
        const double* X = L[0][x];
        c[0] += v * X[0] * q0;
        c[1] += v * (X[0] * q1 + X[1] * q0);
        c[2] += v * (X[0] * q2 + X[1] * q1);
        c[3] += v * X[1] * q2;
      }
    }
  // Split [0, 1] at the extrema (roots of 3c3 s² + 2c2 s + c1) into monotone pieces.
  double cuts[4] = {0.0, 0.0, 0.0, 0.0};
  int n_cuts = 0;
  cuts[n_cuts++] = 0.0;
  const double A = 3.0 * c[3], B = 2.0 * c[2], C = c[1];
  double ext[2];
  int n_ext = 0;
  if (A != 0.0) {
    const double disc = B * B - 4.0 * A * C;
    if (disc > 0.0) {
      // Stable quadratic roots.
      const double qd = -0.5 * (B + std::copysign(std::sqrt(disc), B));
      ext[n_ext++] = qd / A;
      if (qd != 0.0) ext[n_ext++] = C / qd;
    }
  } else if (B != 0.0) {
    ext[n_ext++] = -C / B;
  }
  if (n_ext == 2 && ext[0] > ext[1]) std::swap(ext[0], ext[1]);
  for (int e = 0; e < n_ext; ++e)
    if (ext[e] > 0.0 && ext[e] < 1.0) cuts[n_cuts++] = ext[e];
  cuts[n_cuts++] = 1.0;

  int n = 0;
  // The end values by direct interpolation, not from the cubic: on a shared face both cells
  // compute them with the same arithmetic (see trilinear_value).
  double fa = trilinear_value(corner, a);
  if (fa == 0.0) {
    // A root exactly at the start belongs to this segment (the caster's half-open rule drops
    // one exactly at a shared end). Continue with the sign just after it, so that it is not
    // found again by the first piece.
    roots[n++] = 0.0;
    fa = c[1] != 0.0 ? c[1] : (c[2] != 0.0 ? c[2] : c[3]);
  }
  const double f_end = trilinear_value(corner, b);
  for (int k = 0; k + 1 < n_cuts; ++k) {
    const double fb = k + 2 == n_cuts ? f_end : eval_cubic(c, cuts[k + 1]);
    if (positive(fa) != positive(fb)) roots[n++] = converge_cubic(c, cuts[k], cuts[k + 1], fa, fb);
    fa = fb;
  }
  return n;
}

GridPart grid_part(const GridBlock& whole, std::array<int, 3> blocks, std::array<int, 3> index) {
  const GridSource source(whole);  // validates `whole`; its coordinates define the faces
  GridPart part{whole, {}};
  GridBlock& b = part.block;
  if (b.strides == std::array<std::int64_t, 3>{0, 0, 0})
    b.strides = {1, whole.dims[0], whole.dims[0] * whole.dims[1]};
  std::int64_t offset = 0;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t first = source.first_cell()[a];
    const std::int64_t cells = source.last_cell()[a] - first + 1;
    const std::int64_t c0 = first + cells * index[a] / blocks[a];
    const std::int64_t c1 = first + cells * (index[a] + 1) / blocks[a];  // one past the last cell
    if (c1 <= c0) throw std::invalid_argument("grid block: more parts than cells along an axis");
    const bool last_part = index[a] + 1 == blocks[a];
    // Points c0 … c1, where c1 belongs to the next part (a ghost here); the last part keeps
    // whatever `whole` has above. And one more point on each side where `whole` has it (ghosts),
    // for the central differences of the normals at the owned cells' corners: the parts' hits
    // then carry the normals the whole block gives.
    const std::int64_t below = c0 > 0 ? 1 : 0;
    const std::int64_t above = !last_part && c1 + 1 < whole.dims[a] ? 1 : 0;
    const std::int64_t p0 = c0 - below;
    b.dims[a] = (last_part ? whole.dims[a] - c0 : c1 - c0 + 1 + above) + below;
    b.ghost_lo[a] = int(below);
    b.ghost_hi[a] = last_part ? whole.ghost_hi[a] : int(1 + above);
    offset += p0 * b.strides[a];
    if (whole.coords[0]) {
      b.coords[a] = whole.coords[a] + p0;
    } else {
      b.origin[a] = whole.origin[a] + double(p0) * whole.spacing[a];
    }
    part.owned.lo[a] = source.coordinate(a, c0);
    part.owned.hi[a] = source.coordinate(a, c1);
  }
  b.values =
      static_cast<const char*>(whole.values) + offset * std::int64_t(scalar_size(whole.type));
  if (whole.colour)
    b.colour = static_cast<const char*>(whole.colour) +
               offset * std::int64_t(scalar_size(whole.colour_type));
  return part;
}

GridSource::GridSource(const GridBlock& block, int brick_cells, std::vector<std::uint8_t> held)
    : GridSource(block, brick_cells) {
  if (held.size() != brick_count())
    throw std::invalid_argument("grid block: " + std::to_string(held.size()) + " brick flags for " +
                                std::to_string(brick_count()) + " bricks");
  held_ = std::make_shared<const std::vector<std::uint8_t>>(std::move(held));
}

GridSource::GridSource(const GridBlock& block, int brick_cells)
    : block_(block), brick_cells_(brick_cells) {
  if (brick_cells < 1)
    throw std::invalid_argument("grid block: brick size must be at least one cell");
  if (!block_.values) throw std::invalid_argument("grid block: values pointer is null");
  for (const ScalarType t : {block_.type, block_.colour ? block_.colour_type : block_.type})
    if (t != ScalarType::float32 && t != ScalarType::float64)
      throw std::invalid_argument("grid block: unknown scalar type");
  if (block_.strides == std::array<std::int64_t, 3>{0, 0, 0})
    block_.strides = {1, block_.dims[0], block_.dims[0] * block_.dims[1]};
  const bool rectilinear = block_.coords[0] && block_.coords[1] && block_.coords[2];
  if (!rectilinear && (block_.coords[0] || block_.coords[1] || block_.coords[2]))
    throw std::invalid_argument(
        "grid block: rectilinear coordinates must be given for all three axes");
  for (int a = 0; a < 3; ++a) {
    const std::string axis = kAxis[a];
    const std::int64_t n = block_.dims[a];
    if (n < 2) throw std::invalid_argument("grid block: need at least 2 points along " + axis);
    if (block_.strides[a] == 0)
      throw std::invalid_argument("grid block: stride along " + axis + " is 0");
    if (block_.ghost_lo[a] < 0 || block_.ghost_hi[a] < 0)
      throw std::invalid_argument("grid block: negative ghost layer count along " + axis);
    first_cell_[a] = block_.ghost_lo[a];
    last_cell_[a] = std::min(n - 1 - block_.ghost_hi[a], n - 2);
    if (last_cell_[a] < first_cell_[a])
      throw std::invalid_argument("grid block: ghost layers leave no owned cell along " + axis);
    if (rectilinear) {
      for (std::int64_t i = 0; i + 1 < n; ++i)
        if (!(block_.coords[a][i] < block_.coords[a][i + 1]))
          throw std::invalid_argument("grid block: coordinates along " + axis +
                                      " are not increasing");
    } else if (!(block_.spacing[a] > 0.0) || !std::isfinite(block_.spacing[a])) {
      throw std::invalid_argument("grid block: spacing along " + axis + " must be positive");
    }
    const std::int64_t cells = last_cell_[a] - first_cell_[a] + 1;
    bricks_[a] = (cells + brick_cells - 1) / brick_cells;
  }
}

double GridSource::coordinate(int axis, std::int64_t i) const {
  if (block_.coords[0]) return block_.coords[axis][i];
  return block_.origin[axis] + double(i) * block_.spacing[axis];
}

double GridSource::value(std::int64_t i, std::int64_t j, std::int64_t k) const {
  const std::int64_t at = i * block_.strides[0] + j * block_.strides[1] + k * block_.strides[2];
  return block_.type == ScalarType::float32 ? double(static_cast<const float*>(block_.values)[at])
                                            : static_cast<const double*>(block_.values)[at];
}

double GridSource::interpolate(glm::dvec3 p, double slack) const {
  std::array<std::int64_t, 3> cell{};
  glm::dvec3 f(0.0);
  for (int a = 0; a < 3; ++a) {
    const std::int64_t n = block_.dims[a];
    std::int64_t i = 0;
    if (block_.coords[0]) {
      const double* c = block_.coords[a];
      i = std::int64_t(std::upper_bound(c, c + n, p[a]) - c) - 1;
    } else {
      const double u = (p[a] - block_.origin[a]) / block_.spacing[a];
      if (!(u > -1.0 && u < double(n))) return std::numeric_limits<double>::quiet_NaN();
      i = std::int64_t(std::floor(u));
    }
    i = std::clamp<std::int64_t>(i, 0, n - 2);
    const double x0 = coordinate(a, i), x1 = coordinate(a, i + 1);
    const double t = (p[a] - x0) / (x1 - x0);
    if (!(t >= -slack && t <= 1.0 + slack)) return std::numeric_limits<double>::quiet_NaN();
    cell[a] = i;
    f[a] = std::clamp(t, 0.0, 1.0);
  }
  if (held_ && !cell_held(cell)) return std::numeric_limits<double>::quiet_NaN();
  const auto [i, j, k] = cell;
  const auto lerp = [](double u, double v, double t) { return u + t * (v - u); };
  const double c00 = lerp(value(i, j, k), value(i + 1, j, k), f.x);
  const double c10 = lerp(value(i, j + 1, k), value(i + 1, j + 1, k), f.x);
  const double c01 = lerp(value(i, j, k + 1), value(i + 1, j, k + 1), f.x);
  const double c11 = lerp(value(i, j + 1, k + 1), value(i + 1, j + 1, k + 1), f.x);
  const double v = lerp(lerp(c00, c10, f.y), lerp(c01, c11, f.y), f.z);
  return std::isfinite(v) ? v : std::numeric_limits<double>::quiet_NaN();
}

namespace {

// The colour field of a grid block: its interpolant, read in place (a source over the colour
// array with the block's held mask).
class GridScalarProbe final : public ScalarProbe {
 public:
  explicit GridScalarProbe(GridSource colour) : grid_(std::move(colour)) {}
  double at(glm::dvec3 p) const override { return grid_.interpolate(p, 0.0); }
  // Points rounded onto the wrong side of the block's faces.
  double near(glm::dvec3 p) const override { return grid_.interpolate(p, 1e-6); }

 private:
  GridSource grid_;
};

}  // namespace

std::unique_ptr<ScalarProbe> GridSource::bind_scalar() const {
  if (!block_.colour) return nullptr;
  GridSource colour = *this;
  colour.block_ = colour_as_values(block_);
  return std::make_unique<GridScalarProbe>(std::move(colour));
}

bool GridSource::cell_held(const std::array<std::int64_t, 3>& cell) const {
  // Per axis, the bricks whose copy holds both point layers of the cell: cells lo − 1 … hi + 1.
  std::array<std::array<std::int64_t, 3>, 3> bricks;
  std::array<int, 3> count{};
  for (int a = 0; a < 3; ++a) {
    const std::int64_t rel = cell[a] - first_cell_[a];
    const std::int64_t q =
        std::clamp<std::int64_t>(rel < 0 ? -1 : rel / brick_cells_, 0, bricks_[a] - 1);
    for (std::int64_t b = std::max<std::int64_t>(0, q - 1); b <= std::min(bricks_[a] - 1, q + 1);
         ++b) {
      const std::int64_t lo = first_cell_[a] + b * brick_cells_,
                         hi = std::min(last_cell_[a], lo + brick_cells_ - 1);
      if (cell[a] >= lo - 1 && cell[a] <= hi + 1) bricks[a][count[a]++] = b;
    }
  }
  for (int z = 0; z < count[2]; ++z)
    for (int y = 0; y < count[1]; ++y)
      for (int x = 0; x < count[0]; ++x)
        if ((*held_)[std::size_t(bricks[0][x] +
                                 bricks_[0] * (bricks[1][y] + bricks_[1] * bricks[2][z]))])
          return true;
  return false;
}

Box GridSource::bounds() const {
  Box box;
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = coordinate(a, first_cell_[a]);
    box.hi[a] = coordinate(a, last_cell_[a] + 1);
  }
  return box;
}

std::size_t GridSource::brick_count() const {
  return std::size_t(bricks_[0] * bricks_[1] * bricks_[2]);
}

namespace {

// The casters' view of `block` (strides filled in) with `values` and the held mask.
template <class T>
GridView<T> make_view(const GridBlock& block, const T* values,
                      const std::shared_ptr<const std::vector<std::uint8_t>>& held) {
  return {values,        block.strides,       block.origin,
          block.spacing, block.coords,        block.coords[0] != nullptr,
          block.dims,    0.5 / block.spacing, held ? held->data() : nullptr};
}

}  // namespace

// Calls f(begin, end) over layers 0 … n − 1 of `layer_points` points each: on the calling thread
// where they hold at most 8 Mi points, else in tasks of a layer or more on all cores. The
// snapshot's scan and copies (needed_bricks, for_each_needed_run) run on the solver's thread;
// where ranks share cores (the Gray–Scott bench: 2 ranks on 2 cores), waiting there for TBB's
// workers, which another rank's threads can hold off a core, cost more than they saved: the scan
// of a 194 × 194 × 98 block (3.7 M points) took 2.1–8 ms (median 4.3) in tasks, 3.8–4.0 ms on
// the solver's thread. A larger block (a rank with many cores to itself) is still spread.
template <class F>
void for_layers(std::int64_t n, std::int64_t layer_points, F&& f) {
  if (n <= 0) return;
  if (layer_points <= (std::int64_t(8) << 20) / n) {
    f(std::int64_t(0), n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n),
                    [&](const tbb::blocked_range<std::int64_t>& r) { f(r.begin(), r.end()); });
}

std::vector<std::uint8_t> GridSource::needed_bricks(std::span<const double> isovalues) const {
  std::vector<std::uint8_t> needed = needed_bricks_by_isovalue(isovalues);
  for (std::uint8_t& n : needed)
    n = n != 0;
  return needed;
}

std::vector<std::uint8_t> GridSource::needed_bricks_by_isovalue(
    std::span<const double> isovalues) const {
  // The bricks' ranges from the rows of points in memory order (a brick at a time would jump
  // between rows and pages: three times slower on the Gray–Scott block), layers of bricks along
  // z (for_layers). A brick with a NaN or ±Inf is needed whatever its range: a superset of the
  // bricks a bind keeps or finds non-finite values in, which is all the snapshot needs.
  const std::size_t count = brick_count();
  std::vector<double> lo(count, INFINITY), hi(count, -INFINITY);
  std::vector<std::uint8_t> bad(count, 0);
  const auto scan = [&](const auto* values) {
    const auto g = make_view(block_, values, held_);
    const std::int64_t layer = block_.dims[0] * block_.dims[1] * (brick_cells_ + 1);
    for_layers(bricks_[2], layer, [&](std::int64_t begin, std::int64_t end) {
      for (std::int64_t bz = begin; bz < end; ++bz) {
        const std::int64_t z0 = first_cell_[2] + bz * brick_cells_,
                           z1 = std::min(last_cell_[2], z0 + brick_cells_ - 1) + 1;
        for (std::int64_t k = z0; k <= z1; ++k)
          for (std::int64_t by = 0; by < bricks_[1]; ++by) {
            const std::int64_t y0 = first_cell_[1] + by * brick_cells_,
                               y1 = std::min(last_cell_[1], y0 + brick_cells_ - 1) + 1;
            const std::size_t row = std::size_t(bricks_[0] * (by + bricks_[1] * bz));
            for (std::int64_t j = y0; j <= y1; ++j)
              for (std::int64_t bx = 0; bx < bricks_[0]; ++bx) {
                const std::size_t n = row + std::size_t(bx);
                if (g.held && !g.held[n]) continue;
                const std::int64_t x0 = first_cell_[0] + bx * brick_cells_,
                                   x1 = std::min(last_cell_[0], x0 + brick_cells_ - 1) + 1;
                bool finite = true;
                scan_row(g, x0, x1, j, k, lo[n], hi[n], finite);
                if (!finite) bad[n] = 1;
              }
          }
      }
    });
  };
  if (block_.type == ScalarType::float32)
    scan(static_cast<const float*>(block_.values));
  else
    scan(static_cast<const double*>(block_.values));
  std::uint8_t every = 0;
  for (std::size_t i = 0; i < isovalues.size(); ++i)
    every |= std::uint8_t(1u << std::min<std::size_t>(i, 7));
  std::vector<std::uint8_t> needed(count, 0);
  for (std::size_t n = 0; n < count; ++n) {
    if (held_ && !(*held_)[n]) continue;
    std::uint8_t bits = bad[n] ? every : 0;
    for (std::size_t i = 0; i < isovalues.size(); ++i)
      if (lo[n] <= isovalues[i] && isovalues[i] <= hi[n])
        bits |= std::uint8_t(1u << std::min<std::size_t>(i, 7));
    needed[n] = bits;
  }
  return needed;
}

void GridSource::for_each_needed_run(
    std::span<const std::uint8_t> held,
    const std::function<void(std::int64_t, std::int64_t, std::int64_t, std::int64_t)>& f) const {
  if (held.size() != brick_count())
    throw std::invalid_argument("for_each_needed_run: " + std::to_string(held.size()) +
                                " brick flags for " + std::to_string(brick_count()) + " bricks");
  // Per axis and point index: the bricks of cells lo … hi whose points lo − 1 … hi + 2 include
  // it (a few consecutive ones).
  std::array<std::vector<std::pair<std::int64_t, std::int64_t>>, 3> near;
  for (int a = 0; a < 3; ++a) {
    near[a].assign(std::size_t(block_.dims[a]), {0, -1});
    for (std::int64_t b = 0; b < bricks_[a]; ++b) {
      const std::int64_t lo = first_cell_[a] + b * brick_cells_,
                         hi = std::min(last_cell_[a], lo + brick_cells_ - 1);
      for (std::int64_t i = std::max<std::int64_t>(0, lo - 1);
           i <= std::min(block_.dims[a] - 1, hi + 2); ++i) {
        auto& [b0, b1] = near[a][std::size_t(i)];
        if (b1 < b0) b0 = b;
        b1 = b;
      }
    }
  }
  for_layers(
      block_.dims[2], block_.dims[0] * block_.dims[1], [&](std::int64_t begin, std::int64_t end) {
        std::vector<std::uint8_t> row(static_cast<std::size_t>(bricks_[0]));
        for (std::int64_t k = begin; k < end; ++k) {
          const auto [z0, z1] = near[2][std::size_t(k)];
          if (z1 < z0) continue;
          for (std::int64_t j = 0; j < block_.dims[1]; ++j) {
            const auto [y0, y1] = near[1][std::size_t(j)];
            if (y1 < y0) continue;
            std::fill(row.begin(), row.end(), 0);
            for (std::int64_t bz = z0; bz <= z1; ++bz)
              for (std::int64_t by = y0; by <= y1; ++by) {
                const std::uint8_t* h = &held[std::size_t(bricks_[0] * (by + bricks_[1] * bz))];
                for (std::size_t bx = 0; bx < row.size(); ++bx)
                  row[bx] |= h[bx];
              }
            // The held bricks' points along x with their margins, joined where they touch.
            std::int64_t run_lo = 0, run_hi = -2;
            for (std::int64_t bx = 0; bx < bricks_[0]; ++bx) {
              if (!row[std::size_t(bx)]) continue;
              const std::int64_t lo = first_cell_[0] + bx * brick_cells_,
                                 hi = std::min(last_cell_[0], lo + brick_cells_ - 1);
              const std::int64_t i0 = std::max<std::int64_t>(0, lo - 1),
                                 i1 = std::min(block_.dims[0] - 1, hi + 2);
              if (i0 > run_hi + 1) {
                if (run_hi >= run_lo) f(j, k, run_lo, run_hi);
                run_lo = i0;
              }
              run_hi = i1;
            }
            if (run_hi >= run_lo) f(j, k, run_lo, run_hi);
          }
        }
      });
}

std::unique_ptr<AxisBinding> GridSource::bind_axis(double isovalue) const {
  auto bind_typed = [&](const auto* values) -> std::unique_ptr<AxisBinding> {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(values)>>;
    return std::make_unique<GridAxisBinding<T>>(make_view(block_, values, held_), isovalue,
                                                first_cell_, last_cell_, bricks_, brick_cells_,
                                                held_);
  };
  if (block_.type == ScalarType::float32)
    return bind_typed(static_cast<const float*>(block_.values));
  return bind_typed(static_cast<const double*>(block_.values));
}

std::unique_ptr<GeometryBinding> GridSource::bind(RTCDevice device, double isovalue) const {
  auto bind_typed = [&](const auto* values) {
    return bind_grid(device, make_view(block_, values, held_), isovalue, first_cell_, last_cell_,
                     bricks_, brick_cells_);
  };
  if (block_.type == ScalarType::float32)
    return bind_typed(static_cast<const float*>(block_.values));
  return bind_typed(static_cast<const double*>(block_.values));
}

}  // namespace ldimesh

#include "curved_element.hpp"

#include "bernstein_basis.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <type_traits>
#include <utility>

#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh::curved {
namespace {

constexpr int kMaxNodes = kMaxHexOrder + 1;
// Boxes narrower than this (in ξ, along every axis) are not split again: a solution there that
// the Krawczyk test could not prove (a tangent ray, a root on a box face) is taken at Newton's
// point, or at the box centre when Newton leaves the box.
constexpr double kMinWidth = 1e-9;
// Bound on the boxes one ray–element search looks at (a field that is zero up to rounding over
// a region — a plateau at the isovalue — would otherwise be split down to kMinWidth everywhere).
constexpr int kMaxBoxes = 4096;
// Sign tests and the Krawczyk inclusion keep this margin, relative to the coefficients'
// magnitude and to the box: rounding in the subdivision (a few ulps per level) never drops a
// box that holds a solution.
constexpr double kSignMargin = 1e-12;
constexpr double kBoxMargin = 1e-9;

// Calls fn(std::integral_constant<int, n>) for the degree n (1..kMaxHexOrder): kernels with
// the degree as a constant, so that their loops unroll and their sums stay in registers.
template <class Fn>
decltype(auto) with_degree(int n, Fn&& fn) {
  switch (n) {
    case 1:
      return fn(std::integral_constant<int, 1>{});
    case 2:
      return fn(std::integral_constant<int, 2>{});
    case 3:
      return fn(std::integral_constant<int, 3>{});
    case 4:
      return fn(std::integral_constant<int, 4>{});
    case 5:
      return fn(std::integral_constant<int, 5>{});
    case 6:
      return fn(std::integral_constant<int, 6>{});
    case 7:
      return fn(std::integral_constant<int, 7>{});
    default:
      return fn(std::integral_constant<int, 8>{});
  }
}

// Value and gradient at r of the tensor of degree n with `count` interleaved components
// (coefficient m's component c at c[m·count + c]), by sum factorisation: ξ contracted first
// (value and ξ-derivative per row), then η, then ζ.
template <int count>
void evaluate_tensor(int n, const double* c, glm::dvec3 r, double* value, glm::dvec3* gradient) {
  with_degree(n, [&](auto degree) {
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

// Splits the tensor c (degree n, `count` interleaved components) at the middle of `axis`
// into left and right halves (de Casteljau along every line of that axis). `right` may be
// `c` (each slab is read before its halves are written). The tensor is taken as slabs
// [outer][i][inner] (i along `axis`, inner the contiguous values below it), and de Casteljau's
// levels run over whole rows of a slab: the same operations on each line as line by line, so
// the same values, but independent ones side by side (the vector lanes) instead of one
// dependent chain per line.
// The axis is a constant too, so that the rows' lengths are: copies of a few values inline
// instead of a call to memmove each (perf: 7 % of a curved cast in memmove).
template <int count, int n, int axis>
void split_axis(const double* c, double* left, double* right) {
  constexpr int m = n + 1;
  constexpr int inner = axis == 0 ? count : axis == 1 ? count * m : count * m * m;
  constexpr int outer = axis == 0 ? m * m : axis == 1 ? m : 1;
  double w[m * inner];  // a slab: m rows of `inner` values
  for (int o = 0; o < outer; ++o) {
    const int base = o * m * inner;
    std::copy(c + base, c + base + m * inner, w);
    std::copy(w, w + inner, left + base);
    std::copy(w + n * inner, w + m * inner, right + base + n * inner);
    for (int r = 1; r <= n; ++r) {
      for (int i = 0; i <= n - r; ++i) {
        double* row = w + i * inner;
        const double* next = row + inner;
        for (int j = 0; j < inner; ++j)
          row[j] = 0.5 * (row[j] + next[j]);
      }
      std::copy(w, w + inner, left + base + r * inner);
      std::copy(w + (n - r) * inner, w + (n - r + 1) * inner, right + base + (n - r) * inner);
    }
  }
}
template <int count, int n>
void split_fixed(int axis, const double* c, double* left, double* right) {
  if (axis == 0)
    split_axis<count, n, 0>(c, left, right);
  else if (axis == 1)
    split_axis<count, n, 1>(c, left, right);
  else
    split_axis<count, n, 2>(c, left, right);
}
template <int count>
void split(int n, int axis, const double* c, double* left, double* right) {
  with_degree(n, [&](auto degree) { split_fixed<count, degree>(axis, c, left, right); });
}

// Minimum and maximum of component k of a tensor with `total` values, `count` interleaved.
// Four partial minima and maxima side by side, so that their chains overlap; the values are
// finite (non-finite geometry is refused, a non-finite field deactivates its element), so the
// order does not change the result.
template <int count>
void range(const double* c, int total, int k, double& lo, double& hi) {
  double l[4] = {c[k], c[k], c[k], c[k]}, h[4] = {c[k], c[k], c[k], c[k]};
  int i = k;
  for (; i + 3 * count < total; i += 4 * count)
    for (int a = 0; a < 4; ++a)
      l[a] = std::min(l[a], c[i + a * count]), h[a] = std::max(h[a], c[i + a * count]);
  for (; i < total; i += count)
    l[0] = std::min(l[0], c[i]), h[0] = std::max(h[0], c[i]);
  lo = std::min(std::min(l[0], l[1]), std::min(l[2], l[3]));
  hi = std::max(std::max(h[0], h[1]), std::max(h[2], h[3]));
}

// Bounds of ∂/∂s_axis of each of the `count` interleaved components over the box: the
// derivative's Bernstein coefficients n (c_{i+1} − c_i) along that axis.
template <int count>
void derivative_ranges(int n, int axis, const double* c, double* lo, double* hi) {
  with_degree(n, [&](auto degree) {
    constexpr int N = degree, m = N + 1;
    const int step[3] = {count, count * m, count * m * m};
    const int stride = step[axis], s1 = step[axis == 0 ? 1 : 0], s2 = step[axis == 2 ? 1 : 2];
    for (int k = 0; k < count; ++k) {
      // One partial minimum and maximum per position along the line, so that their chains
      // overlap (finite values: the order does not change the result).
      double l[N], h[N];
      for (int i = 0; i < N; ++i)
        l[i] = std::numeric_limits<double>::infinity(), h[i] = -l[i];
      for (int a = 0; a < m; ++a)
        for (int b = 0; b < m; ++b) {
          const double* line = c + a * s1 + b * s2 + k;
          for (int i = 0; i < N; ++i) {
            const double v = N * (line[(i + 1) * stride] - line[i * stride]);
            l[i] = std::min(l[i], v), h[i] = std::max(h[i], v);
          }
        }
      lo[k] = *std::min_element(l, l + N), hi[k] = *std::max_element(h, h + N);
    }
  });
}

struct Interval {
  double lo = 0.0, hi = 0.0;
};

// One box of a subdivision: its extent in ξ. Its coefficients lie in a pool at its position in
// the stack.
struct Box {
  glm::dvec3 lo, hi;
};

// Splits the box in pool slot `slot` (just popped from the top of its stack: `components`
// geometry values per coefficient interleaved, degree gd, then the field, degree fd) in half
// along `axis`: the right half keeps the slot (it is looked at after the left one's whole
// subtree), the left one takes the next; the caller pushes both, the left on top.
template <int components>
void split_box(int gd, int fd, int axis, std::size_t slot, std::vector<double>& pool) {
  const int gm = gd + 1, fm = fd + 1, geometry = components * gm * gm * gm;
  const std::size_t size = std::size_t(geometry + fm * fm * fm);
  const std::size_t left = (slot + 1) * size;
  if (pool.size() < left + size) pool.resize(left + size);
  double* own = &pool[slot * size];
  split<components>(gd, axis, own, &pool[left], own);
  split<1>(fd, axis, own + geometry, &pool[left + geometry], own + geometry);
}

// The halves of box b along `axis`, left then right.
std::pair<Box, Box> halves(const Box& b, int axis) {
  Box left = b, right = b;
  const double mid = 0.5 * (b.lo[axis] + b.hi[axis]);
  left.hi[axis] = mid, right.lo[axis] = mid;
  return {left, right};
}

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
// rows of the slabs [outer][i][inner] (as split_axis).
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

// H(ξ) = (n₁·(x − o), n₂·(x − o), f) of the rays of one direction d, Newton's method on it and
// the hit at a solution.
struct RaySystem {
  const Element& e;
  glm::dvec3 d, n1, n2;
  double dd;  // |d|²: t = d·(x − o) / |d|², for any length of d

  RaySystem(const Element& element, glm::dvec3 dir) : e(element), d(dir), dd(glm::dot(dir, dir)) {
    ray_frame(d, n1, n2);
  }

  // H at ξ for the ray from o, and its Jacobian in ξ (rows n₁ᵀ J, n₂ᵀ J, ∇f ᵀ).
  void system(glm::dvec3 o, glm::dvec3 xi, glm::dvec3& h, glm::dmat3& jac, Sample& s) const {
    s = evaluate(e, xi);
    const glm::dvec3 r = s.x - o;
    h = glm::dvec3(glm::dot(n1, r), glm::dot(n2, r), s.f);
    // glm is column-major: jac[col][row].
    const glm::dvec3 row1 = glm::transpose(s.jacobian) * n1, row2 = glm::transpose(s.jacobian) * n2;
    for (int c = 0; c < 3; ++c)
      jac[c] = glm::dvec3(row1[c], row2[c], s.gradient[c]);
  }

  // Newton's method from xi until the next step would fall below 10⁻¹⁵ (in ξ): the step itself
  // does, or quadratic convergence predicts it (a step below 10⁻⁶ whose successor
  // ≈ |step|³ / |previous step|² would be; `previous` is the size of the step that led to xi),
  // or the steps stop shrinking below 10⁻⁹ (rounding's floor near an ill-conditioned solution)
  // — or 30 steps. `converged` says whether it stopped so, `last` is the size of its last
  // step. s is the sample at the last point (see below). False where the Jacobian is singular
  // on the way.
  bool newton(glm::dvec3 o, glm::dvec3& xi, Sample& s, bool& converged, double& last,
              double previous) const {
    converged = false;
    glm::dvec3 h;
    glm::dmat3 jac;
    for (int iter = 0; iter < 30; ++iter) {
      system(o, xi, h, jac, s);
      if (!(std::abs(glm::determinant(jac)) > 0.0)) return false;
      const glm::dvec3 step = glm::inverse(jac) * h;
      xi -= step;
      const double size = std::max({std::abs(step.x), std::abs(step.y), std::abs(step.z)});
      last = size;
      if (!(size > 1e-15) ||
          (size < 1e-6 && previous < 1.0 && size * size * size < 1e-15 * previous * previous) ||
          (size < 1e-9 && size > 0.9 * previous)) {
        // The sample moved along with the last step to first order (its error is of the order
        // of the step squared, below 10⁻¹² of the element), instead of evaluated again; the
        // derivatives are those before the step.
        s.x -= s.jacobian * step;
        s.f -= glm::dot(s.gradient, step);
        converged = true;
        return true;
      }
      previous = size;
    }
    system(o, xi, h, jac, s);
    return true;
  }

  // The hit at the solution sampled by s of the ray from o, if its depth lies in [t0, t1]:
  // ∇ₓf = J⁻ᵀ ∇ξf.
  bool hit(const RayRef& ray, const Sample& s, RayHit& out) const {
    const double t = glm::dot(d, s.x - ray.org) / dd;
    if (!(t >= ray.t0 && t <= ray.t1)) return false;
    const glm::dvec3 g = glm::transpose(glm::inverse(s.jacobian)) * s.gradient;
    out = {t, unit_normal(g, d), 0.0f};
    return true;
  }
};

// Whether ξ lies in the box [lo, hi] grown by kBoxMargin of its width (and 10⁻¹²).
bool inside(glm::dvec3 xi, glm::dvec3 lo, glm::dvec3 hi) {
  const glm::dvec3 pad = kBoxMargin * (hi - lo) + 1e-12;
  return glm::all(glm::greaterThanEqual(xi, lo - pad)) &&
         glm::all(glm::lessThanEqual(xi, hi + pad));
}

}  // namespace

Sample evaluate(const Element& e, glm::dvec3 xi) {
  Sample s;
  double x[3];
  glm::dvec3 gx[3];
  evaluate_tensor<3>(e.q, &e.geometry[0].x, xi, x, gx);
  s.x = glm::dvec3(x[0], x[1], x[2]);
  // Columns ∂x/∂ξ_k: row r of the Jacobian is the gradient of x_r.
  for (int k = 0; k < 3; ++k)
    s.jacobian[k] = glm::dvec3(gx[0][k], gx[1][k], gx[2][k]);
  if (e.field) evaluate_tensor<1>(e.p, e.field, xi, &s.f, &s.gradient);
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

namespace {

// The search from one box [lo, hi] of the reference cube for many rays of one direction d,
// given the geometry's ((x, y, z) triples, degree q) and the field's (degree p) coefficients on
// the box (the whole element, or a piece), and the margin of the field's sign tests. Hits go to
// `out` with their ray's index, per ray in increasing t, a solution found from two boxes (on
// their shared face) once.
//
// The rays share the search's boxes: the subdivision does not depend on the ray (the split axis
// comes from the box's coefficients, and the planes' derivatives do not depend on where the ray
// passes), so each box's coefficients, ranges and preconditioned system are found once for all
// the rays still in it, and each ray only takes its own tests — its planes against the box's
// ranges, the preconditioned ranges and the Krawczyk test shifted by its offsets, Newton (its
// depth range is tested on the root box).
//
// Preconditioning (as in Bernstein subdivision solvers, e.g. Mourrain & Pavone 2009): on each
// box the system's components are replaced by G = Y H, Y the inverse of H's Jacobian at the
// box's centre, whose coefficients on the box are those combinations of the components'. Near
// a solution G is close to the identity map, so its ranges bound it tightly: a box far from a
// ray's solution is excluded by them, and the Krawczyk test — with the ranges of ∂G/∂s, not
// the product of Y with H's Jacobian ranges taken apart — proves one solution in a box much
// larger than without.
void search(const Element& e, glm::dvec3 lo_box, glm::dvec3 hi_box, const double* geometry,
            const double* field, double f_margin, glm::dvec3 d, std::span<const RayRef> rays,
            AxisHits& out) {
  // The degrees the search works in: both raised to the larger one where that paid (then G's
  // coefficients are exact combinations for p ≠ q too; the lower-degree part costs more to
  // split), else the element's own. Measured (docs/benchmarks.md): raising is faster for
  // max(p, q) ≤ 4 and where the lower degree is at least half the higher (p = 6, q = 3:
  // 1.06 → 0.8–1.0 s; p = 8, q = 6: 6.7 → 3.8 s), slower for p = 8, q = 2 (3.1 → 4.2 s).
  const int high = std::max(e.p, e.q), low = std::min(e.p, e.q);
  const bool raise = low < high && (high <= 4 || 2 * low >= high);
  const int gd = raise ? high : e.q, fd = raise ? high : e.p;
  const int qm = gd + 1, pm = fd + 1;
  const int gq = qm * qm * qm, fp = pm * pm * pm;
  // A box's coefficients: the geometry's two plane components n₁·x, n₂·x interleaved (degree
  // gd), then the field (degree fd). The depth d·x is tested on the root box only (pruning; a
  // solution outside [t0, t1] is dropped where it is recorded), which saves a third of the
  // geometry's splits.
  const std::size_t box_size = std::size_t(2 * gq + fp);
  const RaySystem sys(e, d);
  const glm::dvec3 n1 = sys.n1, n2 = sys.n2;
  const double dd = sys.dd;

  // A box of the search and the rays still in it (lists[begin, end)).
  struct Entry {
    Box box;
    std::size_t begin, end;
  };
  // What each ray carries: its components (n₁, n₂, d)·o (the box's coefficients are the
  // geometry's components, the ray's subtracted in the tests), its margins, its box count.
  struct State {
    glm::dvec3 offset;
    double g_margin = 0.0, g_scale = 0.0;
    std::size_t boxes = 0;
  };
  thread_local std::vector<double> pool, combined;
  thread_local std::vector<Entry> stack;
  thread_local std::vector<std::uint32_t> lists;
  thread_local std::vector<State> state;
  thread_local std::vector<std::pair<std::uint32_t, RayHit>> found;
  pool.resize(box_size);
  combined.resize(std::size_t(3 * gq));
  stack.clear();
  lists.clear();
  found.clear();
  state.assign(rays.size(), State{});
  double depth_lo = std::numeric_limits<double>::infinity(), depth_hi = -depth_lo;
  const int eq = e.q + 1, own_gq = eq * eq * eq;
  thread_local std::vector<double> own_planes;
  own_planes.resize(std::size_t(2 * own_gq));
  glm::dvec3 box_lo(std::numeric_limits<double>::infinity()), box_hi(-box_lo);
  for (int k = 0; k < own_gq; ++k) {
    const glm::dvec3 x(geometry[3 * k], geometry[3 * k + 1], geometry[3 * k + 2]);
    own_planes[2 * k] = glm::dot(n1, x), own_planes[2 * k + 1] = glm::dot(n2, x);
    const double depth = glm::dot(d, x);
    depth_lo = std::min(depth_lo, depth), depth_hi = std::max(depth_hi, depth);
    box_lo = glm::min(box_lo, x), box_hi = glm::max(box_hi, x);
  }
  depth_lo /= dd, depth_hi /= dd;  // the same values: division by dd > 0 is monotone
  elevate(own_planes.data(), e.q, gd, 2, pool.data());
  elevate(field, e.p, fd, 1, pool.data() + 2 * gq);
  for (std::size_t r = 0; r < rays.size(); ++r) {
    const glm::dvec3 o = rays[r].org;
    State& st = state[r];
    st.offset = glm::dvec3(glm::dot(n1, o), glm::dot(n2, o), glm::dot(d, o) / dd);
    // The scale of the geometry's values seen from o, for the margins: the largest distance
    // from o to the coefficients' box (at least the largest to a coefficient).
    st.g_scale = glm::length(glm::max(glm::abs(box_lo - o), glm::abs(box_hi - o)));
    st.g_margin = kSignMargin * st.g_scale;
    // The depth range of the root box against the ray's [t0, t1].
    if (depth_hi - st.offset[2] < rays[r].t0 - st.g_margin ||
        depth_lo - st.offset[2] > rays[r].t1 + st.g_margin)
      continue;
    lists.push_back(std::uint32_t(r));
  }
  if (!lists.empty()) stack.push_back({{lo_box, hi_box}, 0, lists.size()});

  const auto record = [&](std::uint32_t r, const Sample& s) {
    RayHit h;
    if (sys.hit(rays[r], s, h)) found.push_back({r, h});
  };

  while (!stack.empty()) {
    const std::size_t slot = stack.size() - 1;
    const Entry entry = stack.back();
    const Box b = entry.box;
    stack.pop_back();  // pushed back below when it is split
    const double* c = &pool[slot * box_size];
    const double* f = c + 2 * gq;
    for (std::size_t k = entry.begin; k < entry.end; ++k)
      ++state[lists[k]].boxes;
    // The convex hull tests: the field (the same for every ray), then each ray's two planes.
    double lo[3], hi[3];
    range<1>(f, fp, 0, lo[2], hi[2]);
    if (lo[2] > f_margin || hi[2] < -f_margin) continue;
    range<2>(c, 2 * gq, 0, lo[0], hi[0]);
    range<2>(c, 2 * gq, 1, lo[1], hi[1]);
    const std::size_t in_box = lists.size();
    for (std::size_t k = entry.begin; k < entry.end; ++k) {
      const std::uint32_t r = lists[k];
      const State& st = state[r];
      const bool misses = lo[0] - st.offset[0] > st.g_margin ||
                          hi[0] - st.offset[0] < -st.g_margin ||
                          lo[1] - st.offset[1] > st.g_margin || hi[1] - st.offset[1] < -st.g_margin;
      if (!misses) lists.push_back(r);
    }
    if (lists.size() == in_box) continue;

    // The preconditioned system G = Y H on the box, in its coordinates s ∈ [0, 1]³.
    double value[3];
    glm::dvec3 gradient[3];
    evaluate_tensor<2>(gd, c, glm::dvec3(0.5), value, gradient);
    evaluate_tensor<1>(fd, f, glm::dvec3(0.5), &value[2], &gradient[2]);
    glm::dmat3 jm;  // rows: the components' gradients in s (glm: jm[col][row])
    for (int col = 0; col < 3; ++col)
      jm[col] = glm::dvec3(gradient[0][col], gradient[1][col], gradient[2][col]);
    const double norms =
        glm::length(gradient[0]) * glm::length(gradient[1]) * glm::length(gradient[2]);
    const bool preconditioned = std::abs(glm::determinant(jm)) > 1e-12 * norms;
    glm::dmat3 y(1.0);
    Interval g_range[3], g_jacobian[3][3];  // G's ranges and ∂G_row/∂s_col's
    double radius[3] = {0.0, 0.0, 0.0};
    double plane_weight[3][2] = {}, field_weight[3] = {};  // |Y_r0|, |Y_r1| and |Y_r2|
    glm::dvec3 yh(0.0);                                    // Y H(m) without the ray's offsets
    const auto scaled = [](double w, double lo, double hi) {
      return w >= 0.0 ? Interval{w * lo, w * hi} : Interval{w * hi, w * lo};
    };
    // The rounding in row r of G for a ray: its plane parts' coefficients are at most
    // |n_k·o| + g_scale in size (g_scale, the coefficients' box seen from o), its field part's
    // at most the field's magnitude, each weighed by its entry of Y (which scales with 1 / the
    // box's width: in a box 10⁻⁹ wide, rounding of 10⁻¹⁶ in x is 10⁻⁷ in G).
    const auto g_margin = [&](int row, const State& st) {
      return plane_weight[row][0] * (std::abs(st.offset[0]) * kSignMargin + st.g_margin) +
             plane_weight[row][1] * (std::abs(st.offset[1]) * kSignMargin + st.g_margin) +
             field_weight[row] * f_margin;
    };
    if (preconditioned) {
      y = glm::inverse(jm);
      yh = y * glm::dvec3(value[0], value[1], value[2]);
      for (int row = 0; row < 3; ++row) {
        plane_weight[row][0] = std::abs(y[0][row]), plane_weight[row][1] = std::abs(y[1][row]);
        field_weight[row] = std::abs(y[2][row]);
      }
      if (fd == gd) {
        // G's coefficients: each row's combination of the box's three.
        for (int k = 0; k < gq; ++k)
          for (int row = 0; row < 3; ++row)
            combined[3 * k + row] =
                y[0][row] * c[2 * k] + y[1][row] * c[2 * k + 1] + y[2][row] * f[k];
        for (int row = 0; row < 3; ++row)
          range<3>(combined.data(), 3 * gq, row, g_range[row].lo, g_range[row].hi);
      } else {
        // Degrees kept apart (not raised, above): the planes' part of each row,
        // Y_r0 n₁·x + Y_r1 n₂·x (degree q), and its field part Y_r2 f (degree p) bounded apart
        // and the bounds added.
        for (int k = 0; k < gq; ++k)
          for (int row = 0; row < 3; ++row)
            combined[3 * k + row] = y[0][row] * c[2 * k] + y[1][row] * c[2 * k + 1];
        for (int row = 0; row < 3; ++row) {
          range<3>(combined.data(), 3 * gq, row, g_range[row].lo, g_range[row].hi);
          const Interval part = scaled(y[2][row], lo[2], hi[2]);
          g_range[row].lo += part.lo, g_range[row].hi += part.hi;
        }
      }
      // G for each ray: Y (H − (n₁·o, n₂·o, 0)); its ranges exclude 0 (beyond the margins): no
      // solution in the box. Tested before G's derivatives are bounded: often no ray is left.
      std::size_t kept = in_box;
      for (std::size_t k = in_box; k < lists.size(); ++k) {
        const State& st = state[lists[k]];
        bool none = false;
        for (int row = 0; row < 3; ++row) {
          const double shift = y[0][row] * st.offset[0] + y[1][row] * st.offset[1];
          const double margin = g_margin(row, st);
          none = none || g_range[row].lo - shift > margin || g_range[row].hi - shift < -margin;
        }
        if (!none) lists[kept++] = lists[k];
      }
      lists.resize(kept);
      if (kept == in_box) continue;
      if (fd == gd) {
        for (int col = 0; col < 3; ++col) {
          double dlo[3], dhi[3];
          derivative_ranges<3>(gd, col, combined.data(), dlo, dhi);
          for (int row = 0; row < 3; ++row)
            g_jacobian[row][col] = {dlo[row], dhi[row]};
        }
      } else {
        for (int col = 0; col < 3; ++col) {
          double dlo[3], dhi[3], flo, fhi;
          derivative_ranges<3>(gd, col, combined.data(), dlo, dhi);
          derivative_ranges<1>(fd, col, f, &flo, &fhi);
          for (int row = 0; row < 3; ++row) {
            const Interval part = scaled(y[2][row], flo, fhi);
            g_jacobian[row][col] = {dlo[row] + part.lo, dhi[row] + part.hi};
          }
        }
      }
      // (I − ∂G/∂s)_row,col over the box, times the half-width ½ of B − m.
      for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 3; ++col) {
          const double identity = row == col ? 1.0 : 0.0;
          radius[row] += 0.5 * std::max(std::abs(identity - g_jacobian[row][col].lo),
                                        std::abs(identity - g_jacobian[row][col].hi));
        }
    }
    // G is one-to-one on the box when every matrix in ∂G/∂s(B) is within less than 1 of the
    // identity (row sums, the ∞-norm: all of them regular; G(a) − G(b) = M (a − b) with M's
    // rows from ∂G/∂s at points between a and b), so it has at most one solution there — a
    // weaker condition than K inside the box, which also asks the solution to keep away from
    // the box's faces.
    // (Per ray below: the rounding of G's derivative coefficients, 2n times its values', is
    // added.)
    const double contraction = 2.0 * std::max({radius[0], radius[1], radius[2]});
    const int degree = std::max(gd, fd);
    const glm::dvec3 width = b.hi - b.lo;
    const bool narrowest = std::max({width.x, width.y, width.z}) < kMinWidth;
    const std::size_t split_begin = lists.size();
    for (std::size_t k = in_box; k < split_begin; ++k) {
      const std::uint32_t r = lists[k];
      const State& st = state[r];
      bool unique = false, one_to_one = false;
      glm::dvec3 centre(0.5);
      if (preconditioned) {
        bool none = false;
        unique = true;
        double largest = 0.0;  // the largest margin of the three rows
        for (int row = 0; row < 3 && !none; ++row) {
          const double shift = y[0][row] * st.offset[0] + y[1][row] * st.offset[1];
          const double margin = g_margin(row, st);
          largest = std::max(largest, margin);
          // The Krawczyk operator K = m − G(m) + (I − ∂G/∂s(B)) (B − m): disjoint from the box
          // grown by kBoxMargin (and the rounding of G(m) and of K's radius, whose derivative
          // coefficients carry 2n times G's), no solution; inside it shrunk by that, exactly one
          // (no outward rounding in K: the margins stand in for it).
          centre[row] = 0.5 - (yh[row] - shift);
          const double klo = centre[row] - radius[row], khi = centre[row] + radius[row];
          const double pad = kBoxMargin + (1.0 + 3.0 * degree) * margin;
          if (khi < -pad || klo > 1.0 + pad) none = true;
          if (!(klo > pad && khi < 1.0 - pad)) unique = false;
        }
        if (none) continue;
        one_to_one = contraction + 6.0 * degree * largest < 1.0 - 1e-9;
      }
      // Out of budget, the boxes still pending are not split again (each gets Newton's point
      // or its centre), so that no solution that was still pending is lost.
      const bool smallest = narrowest || st.boxes > std::size_t(kMaxBoxes);
      if (unique || smallest || one_to_one) {
        // Newton from K's centre (one Newton step from the box's centre, which gives its first
        // step a predecessor), its point kept when it ends inside the box (to within the 10⁻⁹
        // margin): where K proved the solution or the box is the smallest, as it ends; where G
        // is one-to-one, only converged, with a last step far below the box's width — a root on
        // the box's face (an element's or a piece's: the shell's seams) is taken there instead
        // of at the smallest width; its neighbour finds it too, and the caster merges the two
        // (the one-to-one test's slack covers the margin's sliver).
        glm::dvec3 xi = b.lo + glm::clamp(centre, 0.0, 1.0) * width;
        const glm::dvec3 lead = glm::abs(centre - 0.5) * width;
        Sample s;
        bool converged = false;
        double last = 0.0;
        if (sys.newton(rays[r].org, xi, s, converged, last, std::max({lead.x, lead.y, lead.z})) &&
            inside(xi, b.lo, b.hi) &&
            (unique || smallest ||
             (converged && last <= 1e-6 * std::max({width.x, width.y, width.z})))) {
          record(r, s);
          continue;
        }
        if (smallest) {
          record(r, evaluate(e, 0.5 * (b.lo + b.hi)));
          continue;
        }
        // Proved but Newton left the box (rounding at its edge), or not proved: split it.
      }
      lists.push_back(r);
    }
    if (lists.size() == split_begin) continue;

    // Split along the axis along which G is furthest from linear (the widest ranges of its
    // derivatives along it; without preconditioning, the widest axis), never leaving one axis a
    // thousand times wider than the split one (every box must shrink to kMinWidth). The left
    // half is looked at next.
    const int widest = width.x >= width.y && width.x >= width.z ? 0 : width.y >= width.z ? 1 : 2;
    int axis = widest;
    if (preconditioned) {
      double score[3] = {0.0, 0.0, 0.0};
      for (int col = 0; col < 3; ++col)
        for (int row = 0; row < 3; ++row)
          score[col] += g_jacobian[row][col].hi - g_jacobian[row][col].lo;
      axis = score[0] >= score[1] && score[0] >= score[2] ? 0 : score[1] >= score[2] ? 1 : 2;
      if (width[axis] < 1e-3 * width[widest]) axis = widest;
    }
    split_box<2>(gd, fd, axis, slot, pool);
    const auto [lb, rb] = halves(b, axis);
    stack.push_back({rb, split_begin, lists.size()});
    stack.push_back({lb, split_begin, lists.size()});
  }

  // Per ray in increasing t; a solution found from two boxes (on their shared face) once.
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first < b.first : a.second.t < b.second.t;
  });
  for (std::size_t i = 0; i < found.size(); ++i) {
    const std::uint32_t r = found[i].first;
    if (i > 0 && found[i - 1].first == r &&
        found[i].second.t - found[i - 1].second.t <= 1e-12 * state[r].g_scale)
      continue;
    out.push_back({rays[r].index, found[i].second});
  }
}

}  // namespace

void intersect(const Element& e, glm::dvec3 o, glm::dvec3 d, double t0, double t1,
               std::vector<RayHit>& hits) {
  // The search with one ray (the Embree path's callback, any direction).
  thread_local AxisHits out;
  out.clear();
  const RayRef ray{0, o, t0, t1};
  search(e, glm::dvec3(0.0), glm::dvec3(1.0), &e.geometry[0].x, e.field, field_margin(e), d,
         std::span(&ray, 1), out);
  hits.insert(hits.end(), out.hits().begin(), out.hits().end());
}

Pieces::Pieces(const Element& e, double width) {
  const int qm = e.q + 1, pm = e.p + 1;
  gq_ = qm * qm * qm, fp_ = pm * pm * pm;
  const std::size_t size = std::size_t(3 * gq_ + fp_);
  field_margin_ = field_margin(e);
  const double margin = field_margin_;
  // Depth first over boxes as in the search; a box's coefficients at its stack position.
  std::vector<Box> stack{{glm::dvec3(0.0), glm::dvec3(1.0)}};
  std::vector<double> pool(size);
  for (int m = 0; m < gq_; ++m)
    for (int a = 0; a < 3; ++a)
      pool[3 * m + a] = e.geometry[m][a];
  std::copy(e.field, e.field + fp_, pool.begin() + 3 * gq_);
  while (!stack.empty()) {
    const std::size_t slot = stack.size() - 1;
    const Box b = stack.back();
    stack.pop_back();
    const double* c = &pool[slot * size];
    double lo, hi;
    range<1>(c + 3 * gq_, fp_, 0, lo, hi);
    if (lo > margin || hi < -margin) continue;  // no point of the box is on the isosurface
    const glm::dvec3 w = b.hi - b.lo;
    const int axis = w.x >= w.y && w.x >= w.z ? 0 : w.y >= w.z ? 1 : 2;
    if (w[axis] <= width) {
      Piece piece{b.lo, b.hi, glm::dvec3(c[0], c[1], c[2]), glm::dvec3(c[0], c[1], c[2])};
      for (int m = 0; m < gq_; ++m) {  // the geometry's convex hull
        const glm::dvec3 x(c[3 * m], c[3 * m + 1], c[3 * m + 2]);
        piece.world_lo = glm::min(piece.world_lo, x), piece.world_hi = glm::max(piece.world_hi, x);
      }
      pieces_.push_back(piece);
      coefficients_.insert(coefficients_.end(), c, c + size);
      continue;
    }
    split_box<3>(e.q, e.p, axis, slot, pool);
    const auto [lb, rb] = halves(b, axis);
    stack.push_back(rb);
    stack.push_back(lb);
  }
}

void Pieces::intersect(const Element& e, std::size_t k, std::span<const RayRef> rays, glm::dvec3 d,
                       AxisHits& hits) const {
  const double* c = &coefficients_[k * std::size_t(3 * gq_ + fp_)];
  search(e, pieces_[k].lo, pieces_[k].hi, c, c + 3 * gq_, field_margin_, d, rays, hits);
}

}  // namespace ldimesh::curved

#include "curved_element.hpp"
#include "curved_tensor.hpp"

#include "../bernstein/basis.hpp"
#include "../bernstein/conversion.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <type_traits>
#include <utility>

#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh::curved {
namespace {

// Boxes narrower than this (in ξ, along every axis) are not split again: a solution there that
// the Krawczyk test could not prove (a tangent ray, a root on a box face) is taken at Newton's
// point, or at the box centre when Newton leaves the box.
constexpr double kMinWidth = 1e-9;
// Bound on the boxes one ray–element search looks at (a field that is zero up to rounding over
// a region — a plateau at the isovalue — would otherwise be split down to kMinWidth everywhere).
constexpr int kMaxBoxes = 4096;
// The Krawczyk inclusion keeps this margin, relative to the box (kSignMargin).
constexpr double kBoxMargin = 1e-9;

// Whether the box coordinate s lies in [0, 1] grown by kBoxMargin (and 10⁻¹² in ξ, the box
// `width` wide).
bool inside(const glm::dvec3& s, const glm::dvec3& width) {
  for (int k = 0; k < 3; ++k) {
    const double pad = kBoxMargin + 1e-12 / width[k];
    if (!(s[k] >= -pad && s[k] <= 1.0 + pad)) return false;
  }
  return true;
}

// A sample of a search box's tensor (components n₁·x, n₂·x, f, d·x / |d|²): values and
// derivatives along the box's s.
struct BoxSample {
  Quad q[4];
};

// The ray's depth and the unit normal ∇ₓf / |∇ₓf| at a sample: with u = (n₁·x, n₂·x, d·x / |d|²)
// and M = ∂u/∂s, ∇_u f = M⁻ᵀ ∇_s f and ∇ₓf = n₁ ∇_u f₀ + n₂ ∇_u f₁ + d / |d|² ∇_u f₂ (n₁, n₂, d
// orthogonal, n₁ and n₂ of unit length).
bool box_hit(const BoxSample& s, const RayRef& ray, double offset, glm::dvec3 d, double dd,
             glm::dvec3 n1, glm::dvec3 n2, RayHit& out) {
  const double t = s.q[0][3] - offset;
  if (!(t >= ray.t0 && t <= ray.t1)) return false;
  glm::dmat3 mt;  // Mᵀ (glm: mt[col][row]; row k: ∂/∂s_k of u)
  for (int k = 0; k < 3; ++k)
    mt[0][k] = s.q[k + 1][0], mt[1][k] = s.q[k + 1][1], mt[2][k] = s.q[k + 1][3];
  const glm::dvec3 gradient(s.q[1][2], s.q[2][2], s.q[3][2]);
  const glm::dvec3 gu = glm::inverse(mt) * gradient;
  out = {t, unit_normal(n1 * gu.x + n2 * gu.y + d * (gu.z / dd), d), 0.0f};
  return true;
}

// Newton's method on H(s) = (n₁·x − n₁·o, n₂·x − n₂·o, f) in the coordinates s of a box
// `width` wide (its tensor c), from s, until the next step would fall below 10⁻¹⁵ (in ξ): the
// step itself does, or quadratic convergence predicts it (a step below 10⁻⁶ whose successor
// ≈ |step|³ / |previous step|² would be; `previous` is the size of the step that led to s), or
// the steps stop shrinking below 10⁻⁹ (rounding's floor near an ill-conditioned solution) — or
// 30 steps. `converged` says whether it stopped so, `last` is the size of its last step. The
// sample is at the last point (see below). False where the Jacobian is singular on the way.
template <int N>
[[gnu::always_inline]] inline bool newton(const Quad* c, const glm::dvec3& width,
                                          const glm::dvec3& offset, glm::dvec3& s,
                                          BoxSample& sample, bool& converged, double& last,
                                          double previous) {
  converged = false;
  for (int iter = 0; iter < 30; ++iter) {
    evaluate_quads<N>(c, s, sample.q);
    const glm::dvec3 h(sample.q[0][0] - offset.x, sample.q[0][1] - offset.y, sample.q[0][2]);
    glm::dmat3 jac;  // rows: H's components' gradients in s (glm: jac[col][row])
    for (int col = 0; col < 3; ++col)
      jac[col] = glm::dvec3(sample.q[col + 1][0], sample.q[col + 1][1], sample.q[col + 1][2]);
    if (!(std::abs(glm::determinant(jac)) > 0.0)) return false;
    const glm::dvec3 step = glm::inverse(jac) * h;
    s -= step;
    const glm::dvec3 moved = glm::abs(step) * width;  // in ξ
    const double size = std::max({moved.x, moved.y, moved.z});
    last = size;
    if (!(size > 1e-15) ||
        (size < 1e-6 && previous < 1.0 && size * size * size < 1e-15 * previous * previous) ||
        (size < 1e-9 && size > 0.9 * previous)) {
      // The sample moved along with the last step to first order (its error is of the order of
      // the step squared, below 10⁻¹² of the element), instead of evaluated again; the
      // derivatives are those before the step.
      sample.q[0] -= sample.q[1] * step.x + sample.q[2] * step.y + sample.q[3] * step.z;
      converged = true;
      return true;
    }
    previous = size;
  }
  evaluate_quads<N>(c, s, sample.q);
  return true;
}

// What the search needs besides the element: its box in ξ, the field's sign margin, the rays'
// direction, the rays and where their hits go.
struct SearchTask {
  const double* root;  // the box's coefficients: (x, y, z, f) quads, degree N
  glm::dvec3 lo_box, hi_box;
  double f_margin;
  glm::dvec3 d;
  std::span<const RayRef> rays;
  AxisHits* out;
};

// A box of the search and the rays still in it (lists[begin, end)).
struct SearchEntry {
  Box box;
  std::size_t begin, end;
};

// What each ray carries: its components (n₁, n₂, d / |d|²)·o (the box's coefficients are the
// element's components, the ray's subtracted in the tests), its margins, its box count.
struct SearchRay {
  glm::dvec3 offset;
  double g_margin = 0.0, g_scale = 0.0;
  double t_margin = 0.0;  // the depth's (in t, length / |d|)
  std::size_t boxes = 0;
};

// The rays' frame: their direction d, n₁ and n₂ across it, |d|², and the field's sign margin.
struct SearchFrame {
  glm::dvec3 d, n1, n2;
  double dd;  // t = d·(x − o) / |d|², for any length of d
  double f_margin;
};

// The preconditioned system G = Y H on a box, in its coordinates s ∈ [0, 1]³ (Y the identity
// where H's Jacobian at the centre is singular).
struct BoxSystem {
  bool preconditioned = false;
  glm::dmat3 y{1.0};
  Quad g_lo{}, g_hi{};                                   // G's ranges (lane: row)
  Quad dg_lo[3] = {}, dg_hi[3] = {};                     // ∂G/∂s_col's ranges (lane: row)
  double radius[3] = {0.0, 0.0, 0.0};                    // K's half-widths
  double plane_weight[3][2] = {}, field_weight[3] = {};  // |Y_r0|, |Y_r1| and |Y_r2|
  glm::dvec3 yh{0.0};                                    // Y H(m) without the ray's offsets

  // Row r of G for a ray is row r without it, less this.
  [[gnu::always_inline]] double shift(int row, const SearchRay& st) const {
    return y[0][row] * st.offset[0] + y[1][row] * st.offset[1];
  }
  // The rounding in row r of G for a ray: its plane parts' coefficients are at most
  // |n_k·o| + g_scale in size (g_scale, the coefficients' box seen from o), its field part's
  // at most the field's magnitude, each weighed by its entry of Y (which scales with 1 / the
  // box's width: in a box 10⁻⁹ wide, rounding of 10⁻¹⁶ in x is 10⁻⁷ in G).
  [[gnu::always_inline]] double margin(int row, const SearchRay& st, double f_margin) const {
    return plane_weight[row][0] * (std::abs(st.offset[0]) * kSignMargin + st.g_margin) +
           plane_weight[row][1] * (std::abs(st.offset[1]) * kSignMargin + st.g_margin) +
           field_weight[row] * f_margin;
  }
  // G for the ray, Y (H − (n₁·o, n₂·o, 0)): its ranges exclude 0 (beyond the margins), no
  // solution in the box.
  [[gnu::always_inline]] bool excludes(const SearchRay& st, double f_margin) const {
    bool none = false;
    for (int row = 0; row < 3; ++row) {
      const double s = shift(row, st), m = margin(row, st, f_margin);
      none = none || g_lo[row] - s > m || g_hi[row] - s < -m;
    }
    return none;
  }
};

// The root box's coefficients in the rays' frame (into `pool`), and each ray's state.
template <int N>
[[gnu::always_inline]] inline void start_search(const SearchTask& task, const SearchFrame& f,
                                                Quads& pool, std::vector<SearchRay>& state,
                                                std::vector<std::uint32_t>& lists) {
  constexpr int m = N + 1, size = m * m * m;
  const glm::dvec3 d = f.d;
  glm::dvec3 box_lo(std::numeric_limits<double>::infinity()), box_hi(-box_lo);
  for (int k = 0; k < size; ++k) {
    Quad q;
    load_quad(task.root + 4 * k, q);
    const glm::dvec3 x(q[0], q[1], q[2]);
    pool[k] = Quad{glm::dot(f.n1, x), glm::dot(f.n2, x), q[3], glm::dot(d, x) / f.dd};
    box_lo = glm::min(box_lo, x), box_hi = glm::max(box_hi, x);
  }
  for (std::size_t r = 0; r < task.rays.size(); ++r) {
    const glm::dvec3 o = task.rays[r].org;
    SearchRay& st = state[r];
    st.offset = glm::dvec3(glm::dot(f.n1, o), glm::dot(f.n2, o), glm::dot(d, o) / f.dd);
    // The scale of the geometry's values seen from o, for the margins: the largest distance
    // from o to the coefficients' box (at least the largest to a coefficient).
    st.g_scale = glm::length(glm::max(glm::abs(box_lo - o), glm::abs(box_hi - o)));
    st.g_margin = kSignMargin * st.g_scale;
    // The depth's coefficients d·x / |d|² round with their size, d·o / |d|² plus the geometry
    // seen from o over |d|.
    st.t_margin = kSignMargin * (st.g_scale / std::sqrt(f.dd) + std::abs(st.offset[2]));
    lists.push_back(std::uint32_t(r));
  }
}

// Y, G's ranges and the weights of its rounding on the box of coefficients c (its centre's
// sample `mid`), G's coefficients into `combined`; nothing where H's Jacobian at the centre is
// singular.
template <int N, bool wide>
[[gnu::always_inline]] inline void precondition(const Quad* c, const BoxSample& mid,
                                                Quads& combined, BoxSystem& g) {
  constexpr int m = N + 1, size = m * m * m;
  glm::dmat3 jm;  // rows: the components' gradients in s (glm: jm[col][row])
  for (int col = 0; col < 3; ++col)
    jm[col] = glm::dvec3(mid.q[col + 1][0], mid.q[col + 1][1], mid.q[col + 1][2]);
  double norms = 1.0;  // the product of the components' gradients' lengths
  for (int row = 0; row < 3; ++row)
    norms *= glm::length(glm::dvec3(jm[0][row], jm[1][row], jm[2][row]));
  g.preconditioned = std::abs(glm::determinant(jm)) > 1e-12 * norms;
  if (!g.preconditioned) return;
  const glm::dmat3 y = g.y = glm::inverse(jm);
  g.yh = y * glm::dvec3(mid.q[0][0], mid.q[0][1], mid.q[0][2]);
  for (int row = 0; row < 3; ++row) {
    g.plane_weight[row][0] = std::abs(y[0][row]), g.plane_weight[row][1] = std::abs(y[1][row]);
    g.field_weight[row] = std::abs(y[2][row]);
  }
  // G's coefficients: each row's combination of the box's three components (lane: row).
  const Quad y0{y[0][0], y[0][1], y[0][2], 0.0}, y1{y[1][0], y[1][1], y[1][2], 0.0},
      y2{y[2][0], y[2][1], y[2][2], 0.0};
  for (int k = 0; k < size; ++k)
    combined[k] = y0 * c[k][0] + y1 * c[k][1] + y2 * c[k][2];
  range_quads<N, wide>(combined.data(), g.g_lo, g.g_hi);
}

// The ranges of G's derivatives and K's half-widths: (I − ∂G/∂s)_row,col over the box, times
// the half-width ½ of B − m.
template <int N, bool wide>
[[gnu::always_inline]] inline void bound_derivatives(Quads& combined, BoxSystem& g) {
  for (int col = 0; col < 3; ++col)
    derivative_range_quads<N, wide>(col, combined.data(), g.dg_lo[col], g.dg_hi[col]);
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) {
      const double identity = row == col ? 1.0 : 0.0;
      g.radius[row] += 0.5 * std::max(std::abs(identity - g.dg_lo[col][row]),
                                      std::abs(identity - g.dg_hi[col][row]));
    }
}

// What a box tells one ray.
enum class BoxOutcome { done, split };

// One ray in the box b of coefficients c (its system g, its centre's sample mid): no solution
// by the Krawczyk test, a solution taken (into `found`, proved unique, in the smallest box, or
// where G is one-to-one and Newton converged), or the box to be split.
template <int N>
[[gnu::always_inline]] inline BoxOutcome solve_ray_in_box(
    const Quad* c, const Box& b, const BoxSystem& g, const BoxSample& mid, double contraction,
    const SearchFrame& f, std::uint32_t r, const RayRef& ray, const SearchRay& st,
    std::vector<std::pair<std::uint32_t, RayHit>>& found) {
  const glm::dvec3 width = b.hi - b.lo;
  const double widest_width = std::max({width.x, width.y, width.z});
  bool unique = false, one_to_one = false;
  glm::dvec3 centre(0.5);
  if (g.preconditioned) {
    bool none = false;
    unique = true;
    double largest = 0.0;  // the largest margin of the three rows
    for (int row = 0; row < 3 && !none; ++row) {
      const double margin = g.margin(row, st, f.f_margin);
      largest = std::max(largest, margin);
      // The Krawczyk operator K = m − G(m) + (I − ∂G/∂s(B)) (B − m): disjoint from the box
      // grown by kBoxMargin (and the rounding of G(m) and of K's radius, whose derivative
      // coefficients carry 2n times G's), no solution; inside it shrunk by that, exactly one
      // (no outward rounding in K: the margins stand in for it).
      centre[row] = 0.5 - (g.yh[row] - g.shift(row, st));
      const double klo = centre[row] - g.radius[row], khi = centre[row] + g.radius[row];
      const double pad = kBoxMargin + (1.0 + 3.0 * N) * margin;
      if (khi < -pad || klo > 1.0 + pad) none = true;
      if (!(klo > pad && khi < 1.0 - pad)) unique = false;
    }
    if (none) return BoxOutcome::done;
    one_to_one = contraction + 6.0 * N * largest < 1.0 - 1e-9;
  }
  // Out of budget, the boxes still pending are not split again (each gets Newton's point
  // or its centre), so that no solution that was still pending is lost.
  const bool smallest = widest_width < kMinWidth || st.boxes > std::size_t(kMaxBoxes);
  if (!(unique || smallest || one_to_one)) return BoxOutcome::split;
  // Newton from K's centre (one Newton step from the box's centre, which gives its first
  // step a predecessor), its point kept when it ends inside the box (to within the 10⁻⁹
  // margin): where K proved the solution or the box is the smallest, as it ends; where G
  // is one-to-one, only converged, with a last step far below the box's width — a root on
  // the box's face (an element's or a piece's: the shell's seams) is taken there instead
  // of at the smallest width; its neighbour finds it too, and the caster merges the two
  // (the one-to-one test's slack covers the margin's sliver).
  glm::dvec3 s = glm::clamp(centre, 0.0, 1.0);
  const glm::dvec3 lead = glm::abs(centre - 0.5) * width;
  BoxSample sample;
  bool converged = false;
  double last = 0.0;
  RayHit hit;
  if (newton<N>(c, width, st.offset, s, sample, converged, last,
                std::max({lead.x, lead.y, lead.z})) &&
      inside(s, width) && (unique || smallest || (converged && last <= 1e-6 * widest_width))) {
    if (box_hit(sample, ray, st.offset[2], f.d, f.dd, f.n1, f.n2, hit)) found.push_back({r, hit});
    return BoxOutcome::done;
  }
  if (smallest) {
    if (box_hit(mid, ray, st.offset[2], f.d, f.dd, f.n1, f.n2, hit)) found.push_back({r, hit});
    return BoxOutcome::done;
  }
  // Proved but Newton left the box (rounding at its edge), or not proved: split it.
  return BoxOutcome::split;
}

// The axis to split box b along: the one along which G is furthest from linear (the widest
// ranges of its derivatives along it; without preconditioning, the widest axis), never leaving
// one axis a thousand times wider than the split one (every box must shrink to kMinWidth).
inline int split_axis(const Box& b, const BoxSystem& g) {
  const glm::dvec3 width = b.hi - b.lo;
  const int widest = width.x >= width.y && width.x >= width.z ? 0 : width.y >= width.z ? 1 : 2;
  if (!g.preconditioned) return widest;
  double score[3] = {0.0, 0.0, 0.0};
  for (int col = 0; col < 3; ++col)
    for (int row = 0; row < 3; ++row)
      score[col] += g.dg_hi[col][row] - g.dg_lo[col][row];
  const int axis = score[0] >= score[1] && score[0] >= score[2] ? 0 : score[1] >= score[2] ? 1 : 2;
  return width[axis] < 1e-3 * width[widest] ? widest : axis;
}

// The hits per ray in increasing t to `out`; a solution found from two boxes (on their shared
// face) once.
inline void emit_hits(std::vector<std::pair<std::uint32_t, RayHit>>& found,
                      const std::vector<SearchRay>& state, std::span<const RayRef> rays,
                      AxisHits& out) {
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

// The search from one box [lo, hi] of the reference cube for many rays of one direction d,
// given the element's coefficients on the box (the whole element, or a piece) as quads of
// degree N — geometry and field raised to the same degree: the preconditioned system's
// coefficients are then exact combinations of the components' — and the margin of the field's
// sign tests. Hits go to `out` with their ray's index, per ray in increasing t, a solution found
// from two boxes (on their shared face) once.
//
// The rays share the search's boxes: the subdivision does not depend on the ray (the split axis
// comes from the box's coefficients, and the planes' derivatives do not depend on where the ray
// passes), so each box's coefficients, ranges and preconditioned system are found once for all
// the rays still in it, and each ray only takes its own tests — its planes and depth against the
// box's ranges, the preconditioned ranges and the Krawczyk test shifted by its offsets, Newton.
//
// Preconditioning (as in Bernstein subdivision solvers, e.g. Mourrain & Pavone 2009): on each
// box the system's components are replaced by G = Y H, Y the inverse of H's Jacobian at the
// box's centre, whose coefficients on the box are those combinations of the components'. Near
// a solution G is close to the identity map, so its ranges bound it tightly: a box far from a
// ray's solution is excluded by them, and the Krawczyk test — with the ranges of ∂G/∂s, not
// the product of Y with H's Jacobian ranges taken apart — proves one solution in a box much
// larger than without.
template <int N, bool wide>
[[gnu::always_inline]] inline void search_body(const SearchTask& task) {
  constexpr int m = N + 1, size = m * m * m;
  const std::span<const RayRef> rays = task.rays;
  SearchFrame f{task.d, {}, {}, glm::dot(task.d, task.d), task.f_margin};
  ray_frame(f.d, f.n1, f.n2);
  thread_local Quads pool, combined;
  thread_local std::vector<SearchEntry> stack;
  thread_local std::vector<std::uint32_t> lists;
  thread_local std::vector<SearchRay> state;
  thread_local std::vector<std::pair<std::uint32_t, RayHit>> found;
  pool.resize(size);
  combined.resize(size);
  stack.clear();
  lists.clear();
  found.clear();
  state.assign(rays.size(), SearchRay{});
  start_search<N>(task, f, pool, state, lists);
  if (!lists.empty()) stack.push_back({{task.lo_box, task.hi_box}, 0, lists.size()});

  while (!stack.empty()) {
    const std::size_t slot = stack.size() - 1;
    const SearchEntry entry = stack.back();
    const Box b = entry.box;
    stack.pop_back();  // pushed back below when it is split
    Quad* c = &pool[slot * size];
    for (std::size_t k = entry.begin; k < entry.end; ++k)
      ++state[lists[k]].boxes;
    // The convex hull tests: the field (the same for every ray), then each ray's two planes
    // and its depth range [t0, t1].
    Quad lo, hi;
    range_quads<N, wide>(c, lo, hi);
    if (lo[2] > f.f_margin || hi[2] < -f.f_margin) continue;
    const std::size_t in_box = lists.size();
    for (std::size_t k = entry.begin; k < entry.end; ++k) {
      const std::uint32_t r = lists[k];
      const SearchRay& st = state[r];
      const bool misses =
          lo[0] - st.offset[0] > st.g_margin || hi[0] - st.offset[0] < -st.g_margin ||
          lo[1] - st.offset[1] > st.g_margin || hi[1] - st.offset[1] < -st.g_margin ||
          hi[3] - st.offset[2] < rays[r].t0 - st.t_margin ||
          lo[3] - st.offset[2] > rays[r].t1 + st.t_margin;
      if (!misses) lists.push_back(r);
    }
    if (lists.size() == in_box) continue;

    // The preconditioned system on the box; the rays whose G excludes 0 leave, before G's
    // derivatives are bounded: often no ray is left.
    BoxSample mid;
    evaluate_quads<N>(c, glm::dvec3(0.5), mid.q);
    BoxSystem g;
    precondition<N, wide>(c, mid, combined, g);
    if (g.preconditioned) {
      std::size_t kept = in_box;
      for (std::size_t k = in_box; k < lists.size(); ++k)
        if (!g.excludes(state[lists[k]], f.f_margin)) lists[kept++] = lists[k];
      lists.resize(kept);
      if (kept == in_box) continue;
      bound_derivatives<N, wide>(combined, g);
    }
    // G is one-to-one on the box when every matrix in ∂G/∂s(B) is within less than 1 of the
    // identity (row sums, the ∞-norm: all of them regular; G(a) − G(b) = M (a − b) with M's
    // rows from ∂G/∂s at points between a and b), so it has at most one solution there — a
    // weaker condition than K inside the box, which also asks the solution to keep away from
    // the box's faces. (Per ray: the rounding of G's derivative coefficients, 2n times its
    // values', is added.)
    const double contraction = 2.0 * std::max({g.radius[0], g.radius[1], g.radius[2]});
    const std::size_t split_begin = lists.size();
    for (std::size_t k = in_box; k < split_begin; ++k) {
      const std::uint32_t r = lists[k];
      if (solve_ray_in_box<N>(c, b, g, mid, contraction, f, r, rays[r], state[r], found) ==
          BoxOutcome::split)
        lists.push_back(r);
    }
    if (lists.size() == split_begin) continue;

    // The left half is looked at next: the right one keeps the slot (it is looked at after the
    // left one's whole subtree), the left one takes the next.
    const int axis = split_axis(b, g);
    if (pool.size() < (slot + 2) * size) pool.resize((slot + 2) * size);
    c = &pool[slot * size];
    split_quads<N>(axis, c, c + size);
    const auto [lb, rb] = halves(b, axis);
    stack.push_back({rb, split_begin, lists.size()});
    stack.push_back({lb, split_begin, lists.size()});
  }
  emit_hits(found, state, rays, *task.out);
}

// The kernels' copies: one per degree, and on x86-64 one compiled for AVX2 beside the baseline
// one (the same operations, so the same bits), taken where the processor has it. Kernel::run<N>
// (always inlined) is the work.
template <class Kernel, int N, class Task>
void run_baseline(const Task& task) {
  Kernel::template run<N, false>(task);
}
#if defined(__x86_64__)
template <class Kernel, int N, class Task>
[[gnu::target("avx2")]] void run_avx2(const Task& task) {
  Kernel::template run<N, true>(task);
}
#endif

bool processor_has_avx2() {
#if defined(__x86_64__)
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}
std::atomic<bool> use_avx2{processor_has_avx2()};

template <class Kernel, class Task>
void run(int n, const Task& task) {
  const bool avx2 = use_avx2.load(std::memory_order_relaxed);
  bernstein::with_order(n, [&](auto degree) {
#if defined(__x86_64__)
    if (avx2) return run_avx2<Kernel, degree>(task);
#endif
    run_baseline<Kernel, degree>(task);
  });
}

struct Search {
  template <int N, bool wide>
  [[gnu::always_inline]] static void run(const SearchTask& task) {
    search_body<N, wide>(task);
  }
};
void search(int n, const SearchTask& task) {
  run<Search>(n, task);
}

// The element's geometry and field as (x, y, z, f) quads of degree max(p, q) (the lower one
// raised) in `out`.
int element_quads(const Element& e, std::vector<double>& out) {
  const int n = std::max(e.p, e.q), nm = n + 1, size = nm * nm * nm;
  thread_local std::vector<double> geometry, field;
  geometry.resize(std::size_t(3 * size));
  field.resize(std::size_t(size));
  elevate(&e.geometry[0].x, e.q, n, 3, geometry.data());
  elevate(e.field, e.p, n, 1, field.data());
  out.resize(std::size_t(4 * size));
  for (int k = 0; k < size; ++k) {
    std::copy(&geometry[3 * k], &geometry[3 * k] + 3, &out[4 * k]);
    out[4 * k + 3] = field[k];
  }
  return n;
}

// The pieces of an element: its quads (degree N) split depth first, as in the search, down to
// `width`, where the field's range holds the isovalue.
struct PiecesTask {
  const double* root;
  double width, margin;
  std::vector<Piece>* pieces;
  std::vector<double>* coefficients;
};
struct SplitIntoPieces {
  template <int N, bool wide>
  [[gnu::always_inline]] static void run(const PiecesTask& task) {
    constexpr int size = (N + 1) * (N + 1) * (N + 1);
    std::vector<Box> stack{{glm::dvec3(0.0), glm::dvec3(1.0)}};
    Quads pool;  // a box's coefficients at its stack position
    pool.resize(std::size_t(size));
    for (int k = 0; k < size; ++k)
      load_quad(task.root + 4 * k, pool[k]);
    while (!stack.empty()) {
      const std::size_t slot = stack.size() - 1;
      const Box b = stack.back();
      stack.pop_back();
      Quad lo, hi;
      range_quads<N, wide>(&pool[slot * size], lo, hi);
      if (lo[3] > task.margin || hi[3] < -task.margin) continue;  // no point on the isosurface
      const glm::dvec3 w = b.hi - b.lo;
      const int axis = w.x >= w.y && w.x >= w.z ? 0 : w.y >= w.z ? 1 : 2;
      if (w[axis] <= task.width) {
        // The geometry's convex hull: the box's (x, y, z) ranges.
        task.pieces->push_back(
            {b.lo, b.hi, glm::dvec3(lo[0], lo[1], lo[2]), glm::dvec3(hi[0], hi[1], hi[2])});
        const std::size_t at = task.coefficients->size();
        task.coefficients->resize(at + std::size_t(4 * size));
        std::memcpy(&(*task.coefficients)[at], &pool[slot * size], sizeof(Quad) * size);
        continue;
      }
      if (pool.size() < (slot + 2) * size) pool.resize((slot + 2) * size);
      Quad* c = &pool[slot * size];
      split_quads<N>(axis, c, c + size);
      const auto [lb, rb] = halves(b, axis);
      stack.push_back(rb);
      stack.push_back(lb);
    }
  }
};

}  // namespace

bool prefer_avx2(bool prefer) {
  use_avx2 = prefer && processor_has_avx2();
  return use_avx2;
}

void intersect(const Element& e, glm::dvec3 o, glm::dvec3 d, double t0, double t1,
               std::vector<RayHit>& hits) {
  // The search with one ray (the Embree path's callback, any direction).
  thread_local AxisHits out;
  thread_local std::vector<double> quads;
  out.clear();
  const int n = element_quads(e, quads);
  const RayRef ray{0, o, t0, t1};
  search(n, {quads.data(), glm::dvec3(0.0), glm::dvec3(1.0), field_margin(e), d, std::span(&ray, 1),
             &out});
  hits.insert(hits.end(), out.hits().begin(), out.hits().end());
}

Pieces::Pieces(const Element& e, double width) {
  std::vector<double> root;
  degree_ = element_quads(e, root);
  const int nm = degree_ + 1;
  size_ = nm * nm * nm;
  field_margin_ = field_margin(e);
  run<SplitIntoPieces>(degree_,
                       PiecesTask{root.data(), width, field_margin_, &pieces_, &coefficients_});
}

void Pieces::intersect(std::size_t k, std::span<const RayRef> rays, glm::dvec3 d,
                       AxisHits& hits) const {
  search(degree_, {&coefficients_[k * std::size_t(4 * size_)], pieces_[k].lo, pieces_[k].hi,
                   field_margin_, d, rays, &hits});
}

}  // namespace ldimesh::curved

// The hexahedral family's coherent caster of axis-parallel rays: object order over the pixels of
// each active element, the polynomial along a row of pixel rays staged (hex_internal.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <optional>
#include <vector>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "../axis_bins.hpp"
#include "hex_internal.hpp"

namespace ldimesh::hex {
namespace {

// ---------------------------------------------------------------------------------------------
// The coherent caster of axis-parallel rays

// Coefficients this close to zero count as zero in the sign tests (far below any field's
// values, far above underflow).
constexpr double kTinyCoefficient = 1e-250;

// Whether values v[i·si + j·sj + l] (i < ni, j < nj, l < nl) all have the strict sign of
// the first, none near underflow (nor NaN); stops at the first that differs.
[[gnu::always_inline]] inline bool one_sign(const double* v, int ni, int nj, int si, int sj,
                                            int nl) {
  const double sign = v[0] > 0.0 ? 1.0 : -1.0;
  for (int i = 0; i < ni; ++i)
    for (int j = 0; j < nj; ++j)
      for (int l = 0; l < nl; ++l)
        if (!(sign * v[i * si + j * sj + l] > kTinyCoefficient)) return false;
  return true;
}

// B_i^P and dB_i^P/dx at one coordinate: the basis of a reference axis a segment does not move
// along, kept by the staged restriction for the gradient at its hits.
struct PointBasis {
  double value[kMaxNodes] = {}, derivative[kMaxNodes] = {};
};

// The polynomial along axis rays through one element, stage by stage (contract_x, _y, _z),
// each stage kept while the segment's coordinates it depends on do not change: over a row of
// pixels only the last stage is redone. The same arithmetic as restrict_to_segment, so the
// same coefficients, to the bit. Where ξ is fixed along the ray, the gradient at a root reuses
// the ξ stage and contracts the rest with the 1-D bases and derivatives at the point: (p + 1)²
// work instead of the full tensor evaluation's (p + 1)³.
template <int P>
class StagedRestriction {
 public:
  explicit StagedRestriction(const double* c) : c_(c) {}

  // Standard Bernstein coefficients along the segment a → b; returns the degree, or −1 when
  // a stage's values all have one strict sign: the bases that follow are nonnegative and sum to
  // one, so every coefficient of the polynomial has that sign, and it has no root (nor any
  // coefficient that is exactly zero: the values are far above underflow).
  [[gnu::always_inline]] int restrict(glm::dvec3 a, glm::dvec3 b, double* f) {
    if (!x_valid_ || a.x != ax_ || b.x != bx_) {
      axis_basis(0, a.x, b.x, basis_x_);
      contract_x<P>(c_, basis_x_, x_);
      ax_ = a.x, bx_ = b.x;
      x_valid_ = true;
      y_valid_ = dx_valid_ = false;
      constexpr int n = P + 1;
      x_uniform_ =
          one_sign(&x_.g[0][0][0], n, n, kMaxNodes * kMaxNodes, kMaxNodes, basis_x_.degree + 1);
    }
    if (x_uniform_) return -1;
    if (!y_valid_ || a.y != ay_ || b.y != by_) {
      axis_basis(1, a.y, b.y, basis_y_);
      contract_y<P>(x_, basis_x_.degree, basis_y_, y_);
      ay_ = a.y, by_ = b.y;
      y_valid_ = true;
      y_uniform_ = one_sign(&y_.h[0][0], P + 1, 1, 2 * kMaxHexOrder + 1, 0,
                            basis_x_.degree + basis_y_.degree + 1);
    }
    if (y_uniform_) return -1;
    if (!z_valid_ || a.z != az_ || b.z != bz_) {
      axis_basis(2, a.z, b.z, basis_z_);
      az_ = a.z, bz_ = b.z;
      z_valid_ = true;
    }
    a_ = a, b_ = b;
    const int degree = contract_z_scaled<P>(y_, basis_x_.degree + basis_y_.degree, basis_z_, f);
    // Scaled and standard coefficients differ by positive factors: one strict sign in the
    // scaled ones (far above underflow) means no root, and the divisions can wait.
    if (degree > 0 && one_sign(f, 1, 1, 0, 0, degree + 1)) return -1;
    scaled_to_standard(degree, f);
    return degree;
  }

  // ∇ξ at parameter s of the last restrict()'s segment; false where the segment moves along ξ
  // (then evaluate the tensor).
  bool gradient(double s, glm::dvec3& g) {
    if (a_.x != b_.x) return false;
    // G_kj = Σ_i c_ijk B_i(ξ) and its ξ-derivative are the ξ stage itself where ξ is fixed along
    // the ray (kept over the row).
    // The hit's reference point, as evaluate_tensor would be given it, and the 1-D bases and
    // their derivatives there (those of a fixed axis from the restriction).
    const glm::dvec3 q = a_ + s * (b_ - a_);
    const PointBasis& y = point_at(1, a_.y == b_.y, q.y);
    const PointBasis& z = point_at(2, a_.z == b_.z, q.z);
    if (!dx_valid_) {
      AxisBasis d;
      derivative_basis(fixed_[0], d);
      contract_x<P>(c_, d, dx_);
      dx_valid_ = true;
    }
    constexpr int n = P + 1;
    g = glm::dvec3(0.0);
    for (int k = 0; k < n; ++k) {
      double sx = 0.0, sy = 0.0, sz = 0.0;
      for (int j = 0; j < n; ++j) {
        const double v = x_.g[k][j][0], d = dx_.g[k][j][0];
        sx += d * y.value[j];
        sy += v * y.derivative[j];
        sz += v * y.value[j];
      }
      g.x += sx * z.value[k];
      g.y += sy * z.value[k];
      g.z += sz * z.derivative[k];
    }
    return true;
  }

 private:
  // The basis of reference axis r along the segment xa → xb; where the axis is fixed, with its
  // derivative kept in fixed_[r] for the gradient.
  [[gnu::always_inline]] void axis_basis(int r, double xa, double xb, AxisBasis& out) {
    if (xa != xb) {
      segment_basis<P>(xa, xb, out);
      return;
    }
    bernstein_basis<P>(xa, fixed_[r].value, fixed_[r].derivative);
    out.degree = 0;
    for (int i = 0; i <= P; ++i)
      out.b[i][0] = fixed_[r].value[i];
  }

  // The point basis of axis r at the hit: the restriction's where the axis is fixed, else
  // computed at x.
  const PointBasis& point_at(int r, bool fixed, double x) {
    if (fixed) return fixed_[r];
    bernstein_basis<P>(x, at_hit_[r].value, at_hit_[r].derivative);
    return at_hit_[r];
  }

  static void derivative_basis(const PointBasis& at, AxisBasis& out) {
    out.degree = 0;
    for (int i = 0; i <= P; ++i)
      out.b[i][0] = at.derivative[i];
  }

  const double* c_;
  bool x_uniform_ = false, y_uniform_ = false;
  AxisBasis basis_x_, basis_y_, basis_z_;
  // The point bases of the fixed axes at the segment, and of the moving ones at a hit.
  PointBasis fixed_[3], at_hit_[3];
  StageX x_, dx_;
  StageY y_;
  double ax_ = 0, bx_ = 0, ay_ = 0, by_ = 0, az_ = 0, bz_ = 0;
  bool x_valid_ = false, y_valid_ = false, z_valid_ = false, dx_valid_ = false;
  glm::dvec3 a_{0.0}, b_{0.0};
};

// A root of one pixel's polynomial along a line of an element's pixels (pixel q of the line):
// known exactly (s), or bracketed by [s0, s1] with the polynomial's coefficients there, to be
// converged.
template <int P>
struct LineRoot {
  LineRoot() {}  // left uninitialised: filled where it is appended
  int q;
  bool exact;
  double s0, s1, s;
  double c[P + 1];
};

template <int P>
std::vector<LineRoot<P>>& line_roots() {
  thread_local std::vector<LineRoot<P>> roots;
  return roots;
}

// Converges the bracketed roots, four lanes at a time (converge_lanes: the same bits as one by
// one).
template <int P>
void converge_roots(std::vector<LineRoot<P>>& roots) {
  constexpr int kLanes = 4;
  const auto solve = [&]<int L>(std::integral_constant<int, L>, LineRoot<P>* const* lane) {
    const double* c[L];
    double tol[L], u[L];
    for (int l = 0; l < L; ++l)
      c[l] = lane[l]->c, tol[l] = piece_tolerance(lane[l]->s0, lane[l]->s1);
    converge_lanes<P, L>(c, tol, u);
    for (int l = 0; l < L; ++l)
      lane[l]->s = segment_point(lane[l]->s0, lane[l]->s1, u[l]);
  };
  LineRoot<P>* lane[kLanes];
  int filled = 0;
  for (LineRoot<P>& root : roots) {
    if (root.exact) continue;
    lane[filled++] = &root;
    if (filled == kLanes) solve(std::integral_constant<int, kLanes>{}, lane), filled = 0;
  }
  for (int l = 0; l < filled; ++l)
    solve(std::integral_constant<int, 1>{}, lane + l);
}

// Object order for the pixel rays of axis views: each active element loops over the pixels its
// box covers, each pixel's ray clipped to the element exactly as intersect_element clips it,
// the polynomial along it from the staged restriction (rows of pixels share its first stages),
// the roots by the same subdivision. Rays of other queries (single points) find their elements
// through the bins. Both give the roots of the Embree binding, to the bit, for affine elements;
// curved ones are searched piece by piece here and whole there: the same roots to rounding.
class HexAxisCaster final : public AxisCaster {
 public:
  explicit HexAxisCaster(Activation active) : active_(std::move(active)) {}

  std::size_t primitive_count() const override { return active_.elements.size(); }
  std::uint64_t nonfinite_values() const override { return active_.nonfinite; }

  void prepare(int axis) const override {
    std::call_once(bins_once_[axis], [&] {
      std::vector<AxisBox> boxes(active_.elements.size());
      for (std::size_t e = 0; e < boxes.size(); ++e)
        boxes[e] = {active_.elements[e].lo, active_.elements[e].hi};
      bins_[axis] = make_axis_bins(boxes, axis);
    });
    std::call_once(pieces_once_, [&] {  // the curved elements' pieces, for every axis
      pieces_.resize(active_.elements.size());
      const double width = 0.25;
      // Isolated: a thread waiting in call_once must not take a task that waits on it.
      tbb::this_task_arena::isolate([&] {
        tbb::parallel_for(std::size_t(0), active_.elements.size(), [&](std::size_t k) {
          if (active_.elements[k].curved != ActiveElement::kAffine)
            pieces_[k].emplace(active_.curved_element(k), width);
        });
      });
    });
  }

  void cast(const AxisRays& rays, AxisHits& out) const override {
    if (active_.elements.empty() || rays.rays.empty()) return;
    const int axis = rays.axis;
    prepare(axis);
    const AxisBins& bins = bins_[axis];
    std::vector<RayHit> hits;
    // The pixel loops below take whole rows (never given otherwise: prefers_column_tasks).
    if (!rays.lattice || rays.width() != rays.lattice->width) {
      for (std::size_t k = 0; k < rays.rays.size(); ++k) {
        const AxisRay& ray = rays.rays[k];
        if (!(ray.t0 <= ray.t1)) continue;
        const std::size_t bin = bins.at(ray.org);
        hits.clear();
        with_order(active_.order, [&](auto p) {
          for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
            const std::uint32_t e = bins.entries[m] & AxisBins::kIndex;
            intersect_active<p>(active_, e, ray.org, rays.dir, ray.t0, ray.t1, hits);
          }
        });
        for (const RayHit& h : hits)
          out.push_back({std::uint32_t(k), h});
      }
      return;
    }
    // The rectangle the rays cover, in bins; each element once, from the first of its bins in
    // the rectangle.
    double lo_b = INFINITY, hi_b = -INFINITY, lo_c = INFINITY, hi_c = -INFINITY;
    for (const AxisRay& ray : rays.rays) {
      lo_b = std::min(lo_b, ray.org[bins.b]), hi_b = std::max(hi_b, ray.org[bins.b]);
      lo_c = std::min(lo_c, ray.org[bins.c]), hi_c = std::max(hi_c, ray.org[bins.c]);
    }
    Scratch scratch;
    scratch.read_lattice(rays);
    visit_rectangle(bins, lo_b, hi_b, lo_c, hi_c,
                    [&](std::uint32_t e) { cast_element(e, rays, out, scratch); });
  }

 private:
  // What the separable path of cast_element_order needs of a lattice query, found once per
  // query, and what it keeps per line of an element's pixels (reused from element to element).
  struct Scratch {
    // Whether the query's rays form a regular lattice: every ray (t0 ≤ t1) of column i and
    // row r of the query starts at column_org[i] along the view's u axis, row_org[r] along v and
    // depth_org along the rays, with one range [t0, t1].
    bool regular = false;
    double depth_org = 0.0, t0 = 0.0, t1 = 0.0;
    std::vector<double> column_org, row_org;
    void read_lattice(const AxisRays& rays) {
      const View& view = *rays.lattice;
      const int ua = exact_axis(view.u), va = exact_axis(view.v), width = view.width;
      const int rows = int(rays.rays.size() / std::size_t(width));
      column_org.resize(std::size_t(width));
      row_org.resize(std::size_t(rows));
      for (int i = 0; i < width; ++i)
        column_org[i] = rays.rays[i].org[ua];
      for (int r = 0; r < rows; ++r)
        row_org[r] = rays.rays[std::size_t(r) * std::size_t(width)].org[va];
      regular = ua >= 0 && va >= 0;
      bool first = true;
      for (std::size_t k = 0; k < rays.rays.size() && regular; ++k) {
        const AxisRay& ray = rays.rays[k];
        if (!(ray.t0 <= ray.t1)) continue;
        if (first) depth_org = ray.org[rays.axis], t0 = ray.t0, t1 = ray.t1, first = false;
        regular = ray.org[ua] == column_org[k % width] && ray.org[va] == row_org[k / width] &&
                  ray.org[rays.axis] == depth_org && ray.t0 == t0 && ray.t1 == t1;
      }
    }
    // Per line of the element's pixels: whether its rays are inside the element along the
    // reference axis its image axis maps to, and the basis there.
    struct Line {
      bool inside;
      PointBasis basis;
    };
    std::vector<Line> outer, inner;
    std::vector<double> inner_values, h;  // n rows of one value per inner pixel
    std::vector<int> candidates;          // the inner pixels that may have a root
    std::vector<curved::RayRef> batch;    // the pixel rays through a curved element's piece
  };

  // One element's pixels in a lattice query: the rectangle of pixels its box covers, which image
  // axis the loops take outside, and where the hits go.
  struct ElementPixels {
    const AxisRays& rays;
    const View& view;
    const ActiveElement& el;
    AxisHits& out;
    int ua, va, wa, rows;
    int i0 = 0, i1 = -1, j0 = 0, j1 = -1;
    bool columns_outer = false;
    int outer0 = 0, outer1 = -1, inner0 = 0, inner1 = -1;
    glm::dmat3 to_world_gradient{1.0};

    ElementPixels(const AxisRays& r, const ActiveElement& element, AxisHits& hits)
        : rays(r),
          view(*r.lattice),
          el(element),
          out(hits),
          ua(exact_axis(view.u)),
          va(exact_axis(view.v)),
          wa(r.axis),
          rows(int(r.rays.size() / std::size_t(view.width))) {}

    // The pixels whose centres lie in the box [lo, hi] (with a margin far above rounding: the
    // exact tests come later), in this query's rows, as [i0, i1] × [j0, j1]; false if none.
    bool cover(glm::dvec3 lo, glm::dvec3 hi) {
      const auto range = [&](int axis, double sign, int count, int& first, int& last) {
        const double x0 = (lo[axis] - view.origin[axis]) / (view.spacing * sign),
                     x1 = (hi[axis] - view.origin[axis]) / (view.spacing * sign);
        first = int(std::max(0.0, std::ceil(std::min(x0, x1) - 0.5 - 1e-6)));
        last = int(std::min(double(count - 1), std::floor(std::max(x0, x1) - 0.5 + 1e-6)));
      };
      range(ua, view.u[ua], view.width, i0, i1);
      range(va, view.v[va], view.height, j0, j1);
      j0 = std::max(j0, rays.row_begin);
      j1 = std::min(j1, rays.row_begin + rows - 1);
      return i0 <= i1 && j0 <= j1;
    }
    // The image axis whose reference axis is the lower of the two across the ray (ru, rv) goes
    // in the outer loop, so that the first stage of the restriction is kept along the inner one.
    void orient(int ru, int rv) {
      columns_outer = ru >= 0 && ru < 3 && rv >= 0 && rv < 3 && ru < rv;
      outer0 = columns_outer ? i0 : j0, outer1 = columns_outer ? i1 : j1;
      inner0 = columns_outer ? j0 : i0, inner1 = columns_outer ? j1 : i1;
      to_world_gradient = glm::transpose(el.to_reference);
    }
    [[gnu::always_inline]] std::size_t index(int i, int j) const {
      return std::size_t(j - rays.row_begin) * std::size_t(view.width) + std::size_t(i);
    }
    [[gnu::always_inline]] std::size_t pixel(int outer, int inner) const {
      return columns_outer ? index(outer, inner) : index(inner, outer);
    }
    // The hit at parameter s of pixel k's clipped stretch [t0, t1], with reference gradient g.
    [[gnu::always_inline]] void hit_at(std::size_t k, double s, double t0, double t1,
                                       glm::dvec3 g) const {
      out.push_back(
          {std::uint32_t(k),
           {segment_point(t0, t1, s), unit_normal(to_world_gradient * g, rays.dir), 0.0f}});
    }
  };

  // The pixels of the lattice query `rays` whose centres element e's box covers,
  // in the order that keeps the staged restriction's first stages: rows of the image axis
  // whose world axis maps to the lower of the two reference axes across the ray.
  void cast_element(std::uint32_t e, const AxisRays& rays, AxisHits& out, Scratch& scratch) const {
    with_order(active_.order, [&](auto p) { cast_element_order<p>(e, rays, out, scratch); });
  }

  template <int P>
  void cast_element_order(std::uint32_t e, const AxisRays& rays, AxisHits& out,
                          Scratch& scratch) const {
    ElementPixels px(rays, active_.elements[e], out);
    if (!px.cover(px.el.lo, px.el.hi)) return;  // an affine element lies in its box
    if (px.el.curved != ActiveElement::kAffine) return cast_curved(e, px, scratch);

    // The reference axis each world axis maps to (−1: none, 3: several).
    const glm::dmat3& m = px.el.to_reference;
    const auto reference_of = [&](int world) {
      int r = -1;
      for (int k = 0; k < 3; ++k)
        if (m[world][k] != 0.0) r = r < 0 ? k : 3;
      return r;
    };
    const int ru = reference_of(px.ua), rv = reference_of(px.va), rw = reference_of(px.wa);
    px.orient(ru, rv);
    const double* c = active_.coefficients_of(e);
    const bool separable = ru >= 0 && ru < 3 && rv >= 0 && rv < 3 && rw >= 0 && rw < 3 &&
                           ru != rv && ru != rw && rv != rw;
    if (!separable || !scratch.regular) return cast_pixels<P>(px, c);
    cast_separable<P>(px, c, AxisSplit{std::min(ru, rv), std::max(ru, rv), rw}, scratch);
  }

  // A curved element: each piece that may hold the isosurface, with the pixel rays of its box
  // at once (they share the search's boxes).
  void cast_curved(std::uint32_t e, ElementPixels& px, Scratch& scratch) const {
    std::vector<curved::RayRef>& batch = scratch.batch;
    const curved::Pieces& pieces = *pieces_[e];
    for (std::size_t piece = 0; piece < pieces.pieces().size(); ++piece) {
      const curved::Piece& box = pieces.pieces()[piece];
      if (!px.cover(box.world_lo, box.world_hi)) continue;
      batch.clear();
      for (int j = px.j0; j <= px.j1; ++j)
        for (int i = px.i0; i <= px.i1; ++i) {
          const std::size_t k = px.index(i, j);
          const AxisRay& ray = px.rays.rays[k];
          if (ray.t0 <= ray.t1) batch.push_back({std::uint32_t(k), ray.org, ray.t0, ray.t1});
        }
      if (!batch.empty()) pieces.intersect(piece, batch, px.rays.dir, px.out);
    }
  }

  // An affine element's pixels each on its own, as intersect_element does it (the clip, the
  // restriction and the roots), with the staged restriction keeping the stages that rows of
  // pixels share.
  template <int P>
  void cast_pixels(const ElementPixels& px, const double* c) const {
    const AxisRays& rays = px.rays;
    // The roots of f[0..n] along the clipped stretch [t0, t1] of pixel k's ray, with the
    // reference gradient at parameter s from `gradient`.
    const auto emit = [&]<int n>(std::integral_constant<int, n>, std::size_t k, const double* f,
                                 double t0, double t1, auto gradient) {
      bernstein_roots<n>(f, [&](double s) { px.hit_at(k, s, t0, t1, gradient(s)); });
    };
    StagedRestriction<P> staged(c);
    const auto cast_pixel = [&](std::size_t k) {
      const AxisRay& ray = rays.rays[k];
      double t0 = ray.t0, t1 = ray.t1;
      glm::dvec3 a, b;
      if (!clip_to_element(px.el, ray.org, rays.dir, t0, t1, a, b)) return;
      const auto tensor_gradient = [&](double s) {
        return evaluate_tensor<P>(c, a + s * (b - a)).gradient;
      };
      double f[kMaxRayDegree + 1] = {};  // zeroed: not every degree writes all of it
      if (AxisSplit axes; axis_parallel(a, b, axes)) {
        restrict_axis_parallel<P>(c, axes, a, b, f);
        emit(std::integral_constant<int, P>{}, k, f, t0, t1, tensor_gradient);
        return;
      }
      const int degree = staged.restrict(a, b, f);
      if (degree <= 0) return;  // constant along the ray, or no root possible
      with_degree<P>(degree, [&](auto n) {
        if constexpr (n > 0)
          emit(n, k, f, t0, t1, [&](double s) {
            glm::dvec3 g;
            if (!staged.gradient(s, g)) g = tensor_gradient(s);
            return g;
          });
      });
    };
    for (int outer = px.outer0; outer <= px.outer1; ++outer)
      for (int inner = px.inner0; inner <= px.inner1; ++inner)
        if (const std::size_t k = px.pixel(outer, inner); rays.rays[k].t0 <= rays.rays[k].t1)
          cast_pixel(k);
  }

  // The segment every pixel of a separable element shares: its reference coordinates along the
  // ray at its ends (a_w, b_w), its stretch [t0, t1], its matrix.
  struct SharedSegment {
    double t0, t1, a_w, b_w;
    SegmentMatrix matrix;
  };

  // An element whose edges lie along the world axes (each world axis maps to one reference
  // axis) in a regular lattice: every pixel's segment is parallel to reference axis rw, and
  // the clip separates. A pixel's reference coordinate across the ray depends on its column
  // alone along ru and on its row alone along rv (the other terms of the product are exact
  // zeros); its stretch along the ray on neither. So the clip is done once per column, row
  // and element, the bases once per column and row, the u contraction once per outer line
  // and the segment's matrix once: the same operations as restrict_axis_parallel on each
  // pixel, so the same bits.
  template <int P>
  void cast_separable(const ElementPixels& px, const double* c, const AxisSplit& axes,
                      Scratch& scratch) const {
    const glm::dmat3& m = px.el.to_reference;
    const glm::dvec3 rd = m * px.rays.dir;
    const int rw = axes.w;
    const auto origin_of = [&](int i, int j) {  // the ray origin of pixel (i, j), as a ray has it
      glm::dvec3 org;
      org[px.ua] = scratch.column_org[i];
      org[px.va] = scratch.row_org[j - px.rays.row_begin];
      org[px.wa] = scratch.depth_org;
      return m * (org - px.el.origin);
    };
    const glm::dvec3 ro0 = origin_of(px.i0, px.j0);
    const double inv = 1.0 / rd[rw];
    double ta = (0.0 - ro0[rw]) * inv, tb = (1.0 - ro0[rw]) * inv;
    if (ta > tb) std::swap(ta, tb);
    SharedSegment seg;
    seg.t0 = std::max(scratch.t0, ta), seg.t1 = std::min(scratch.t1, tb);
    if (!(seg.t0 < seg.t1)) return;
    seg.a_w = std::clamp(ro0[rw] + seg.t0 * rd[rw], 0.0, 1.0);
    seg.b_w = std::clamp(ro0[rw] + seg.t1 * rd[rw], 0.0, 1.0);
    segment_matrix<P>(seg.a_w, seg.b_w, seg.matrix);
    const auto fill = [&](std::vector<Scratch::Line>& lines, int r, int lo, int hi, bool outer) {
      lines.resize(std::size_t(hi - lo + 1));
      for (int q = lo; q <= hi; ++q) {
        const double x = (outer == px.columns_outer ? origin_of(q, px.j0) : origin_of(px.i0, q))[r];
        Scratch::Line& line = lines[q - lo];
        line.inside = !(x < 0.0 || x > 1.0);
        bernstein_basis<P>(std::clamp(x + seg.t0 * rd[r], 0.0, 1.0), line.basis.value,
                           line.basis.derivative);
      }
    };
    fill(scratch.outer, axes.u, px.outer0, px.outer1, true);
    fill(scratch.inner, axes.v, px.inner0, px.inner1, false);

    constexpr int n = P + 1;
    const int count = px.inner1 - px.inner0 + 1;
    // The inner bases' values as rows (B_j at every inner pixel), so that a line's polynomials
    // are computed with the pixels in the vector lanes.
    scratch.inner_values.resize(std::size_t(n) * count);
    scratch.h.resize(std::size_t(n) * count);
    scratch.candidates.resize(std::size_t(count));
    for (int j = 0; j < n; ++j)
      for (int q = 0; q < count; ++q)
        scratch.inner_values[std::size_t(j) * count + q] = scratch.inner[q].basis.value[j];
    for (int outer = px.outer0; outer <= px.outer1; ++outer)
      if (scratch.outer[outer - px.outer0].inside) cast_line<P>(px, c, axes, seg, outer, scratch);
  }

  // The pixels of one outer line of a separable element (cast_separable).
  template <int P>
  [[gnu::always_inline]] void cast_line(const ElementPixels& px, const double* c,
                                        const AxisSplit& axes, const SharedSegment& seg, int outer,
                                        Scratch& scratch) const {
    constexpr int n = P + 1;
    const int count = px.inner1 - px.inner0 + 1;
    const std::size_t inner_step = px.columns_outer ? std::size_t(px.view.width) : 1;
    const Scratch::Line& o = scratch.outer[outer - px.outer0];
    FixedStage g, dg;
    contract_fixed_u<P>(c, axes, o.basis.value, g);
    // One strict sign over the line: the bases that follow are nonnegative and sum to one,
    // so no pixel of the line has a root.
    if (one_sign(&g[0][0], n, 1, kMaxNodes, 0, n)) return;
    // The v contraction of every pixel of the line, h[l][q] = Σ_j g[j][l] · B_j(x_v(q)), in
    // the order contract_fixed_v takes (the same bits); then the pixels whose h does not
    // have one strict sign, without a branch on it.
    double* h = scratch.h.data();
    const double* bv = scratch.inner_values.data();
    for (int l = 0; l < n; ++l) {
      double* hl = h + std::size_t(l) * count;
      std::fill(hl, hl + count, 0.0);
      for (int j = 0; j < n; ++j) {
        const double gjl = g[j][l], *bj = bv + std::size_t(j) * count;
        for (int q = 0; q < count; ++q)
          hl[q] += gjl * bj[q];
      }
    }
    int candidates = 0;
    std::size_t k = px.pixel(outer, px.inner0);
    for (int q = 0; q < count; ++q, k += inner_step) {
      double lo = h[q], hi = h[q];
      for (int l = 1; l < n; ++l)
        lo = std::min(lo, h[std::size_t(l) * count + q]),
        hi = std::max(hi, h[std::size_t(l) * count + q]);
      const bool keep = scratch.inner[q].inside && px.rays.rays[k].t0 <= px.rays.rays[k].t1 &&
                        !(lo > kTinyCoefficient || hi < -kTinyCoefficient);
      scratch.candidates[candidates] = q;
      candidates += keep;
    }
    // Every candidate's roots isolated first, then converged four at a time (their chains of
    // divisions are independent and overlap, where one root after the other each waits on its
    // own), then appended in the order found: pixel by pixel, along each ray — the same hits,
    // to the bit, as emit on each pixel.
    std::vector<LineRoot<P>>& roots = line_roots<P>();
    roots.clear();
    for (int m = 0; m < candidates; ++m) {
      const int q = scratch.candidates[m];
      double hq[kMaxNodes], f[kMaxNodes];
      for (int l = 0; l < n; ++l)
        hq[l] = h[std::size_t(l) * count + q];
      along_segment<P>(hq, seg.matrix, f);
      isolate_roots<P>(
          f,
          [&](double s) {
            LineRoot<P>& root = roots.emplace_back();
            root.q = q, root.exact = true, root.s = s;
          },
          [&](const double* piece, double s0, double s1) {
            LineRoot<P>& root = roots.emplace_back();
            root.q = q, root.exact = false, root.s0 = s0, root.s1 = s1;
            std::copy(piece, piece + P + 1, root.c);
          });
    }
    converge_roots<P>(roots);
    bool dg_valid = false;
    for (const LineRoot<P>& root : roots) {
      const int q = root.q;
      const PointBasis& bq = scratch.inner[q].basis;
      // ∂/∂w from h, ∂/∂v from g with B_j'(x_v), ∂/∂u from the u contraction with B_i'(x_u)
      // (once per line, at its first hit), all at the hit's x_w.
      if (!dg_valid) {
        contract_fixed_u<P>(c, axes, o.basis.derivative, dg);
        dg_valid = true;
      }
      const double s = root.s;
      double bw[kMaxNodes], dbw[kMaxNodes];
      bernstein_basis<P>(seg.a_w + s * (seg.b_w - seg.a_w), bw, dbw);
      double gu = 0.0, gv = 0.0, gw = 0.0;  // in registers: the axes are known at run time
      for (int l = 0; l < n; ++l) {
        double du = 0.0, dv = 0.0;
        for (int j = 0; j < n; ++j) {
          du += dg[j][l] * bq.value[j];
          dv += g[j][l] * bq.derivative[j];
        }
        gu += du * bw[l];
        gv += dv * bw[l];
        gw += h[std::size_t(l) * count + q] * dbw[l];
      }
      glm::dvec3 grad;
      grad[axes.u] = gu, grad[axes.v] = gv, grad[axes.w] = gw;
      px.hit_at(px.pixel(outer, px.inner0 + q), s, seg.t0, seg.t1, grad);
    }
  }

  Activation active_;
  mutable std::array<AxisBins, 3> bins_;
  mutable std::array<std::once_flag, 3> bins_once_;
  // A curved element's pieces (the pixel rays share the search's first levels): boxes of a
  // quarter of the reference cube's width per axis (the fastest width measured, and an eighth takes
  // 8× the memory: docs/history/benchmarks-log.md, "Curved elements"), only those where the field
  // allows the isovalue; the pixel rays through a piece are searched together (they share its
  // boxes).
  mutable std::vector<std::optional<curved::Pieces>> pieces_;
  mutable std::once_flag pieces_once_;
};

}  // namespace

std::unique_ptr<AxisCaster> make_axis_caster(Activation active) {
  return std::make_unique<HexAxisCaster>(std::move(active));
}

}  // namespace ldimesh::hex

#include "straight_tets.hpp"

#include <mutex>

#include "../axis_bins.hpp"
#include "../bernstein/conversion.hpp"
#include "../bernstein/roots.hpp"

namespace ldimesh::cells {
namespace {

// Barycentric coordinates below −kInside still count as inside: the segments of two
// tetrahedra that share a face overlap by that much instead of leaving a gap of rounding
// between them, where a root would be in neither (a root found by both is merged by the caster).
constexpr double kInside = 1e-12;

// A tetrahedron's Bernstein–Bézier coefficients of degree m ≤ P in a dense array: c_α at
// slot(α₁, α₂, α₃) (α₀ = m − α₁ − α₂ − α₃).
template <int P>
constexpr int slot(int a, int b, int c) {
  return a + (P + 1) * (b + (P + 1) * c);
}

// One de Casteljau step at barycentric point `l`, in place: degree m → m − 1,
// c'_β = Σ_i λ_i c_{β+e_i}. In increasing order, each coefficient is read before it is written.
template <int P>
[[gnu::always_inline]] inline void de_casteljau_step(double* c, int m, const double* l) {
  for (int z = 0; z < m; ++z)
    for (int y = 0; y + z < m; ++y)
      for (int x = 0; x + y + z < m; ++x) {
        const int k = slot<P>(x, y, z);
        c[k] =
            l[0] * c[k] + l[1] * c[k + 1] + l[2] * c[k + (P + 1)] + l[3] * c[k + (P + 1) * (P + 1)];
      }
}

// Every root of tetrahedron `tet`'s field along ray o + t·d, t ∈ [t0, t1], passed to `out`: the
// ray's segment [ua, ub] in the tetrahedron (barycentric coordinates ≥ −kInside, each linear in
// the local parameter u); the field on it is the polynomial whose Bernstein coefficients on
// [ua, ub] are the blossom of the tetrahedron's Bernstein–Bézier form,
// b_k = c(λ(ua)^{p−k}, λ(ub)^k) (a chain of de Casteljau steps at λ(ua), then k steps at λ(ub));
// roots by bernstein_roots. The normal from the gradient: de Casteljau down to degree 1 at the
// hit, ∂f/∂λ_i = p d_i, mapped to the world.
template <int P, class Out>
void straight_tet_hits(const StraightTets& all, const StraightTet& tet, glm::dvec3 o, glm::dvec3 d,
                       double t0, double t1, Out&& out) {
  // From the ray's point nearest v0 (t = s), so that the rounding of the barycentric
  // coordinates scales with the tetrahedron, not with the ray's origin: the segments of two
  // tetrahedra that share a face then meet to within kInside. Local parameter u = t − s.
  const double s = glm::dot(tet.v0 - o, d) / glm::dot(d, d);
  const glm::dvec3 a = tet.to_barycentric * (o + s * d - tet.v0), b = tet.to_barycentric * d;
  const double alpha[4] = {1.0 - a.x - a.y - a.z, a.x, a.y, a.z};
  const double beta[4] = {-(b.x + b.y + b.z), b.x, b.y, b.z};
  double ua = t0 - s, ub = t1 - s;
  for (int i = 0; i < 4; ++i) {
    if (beta[i] == 0.0) {
      if (alpha[i] < -kInside) return;
      continue;
    }
    const double u = (-kInside - alpha[i]) / beta[i];
    if (beta[i] > 0.0)
      ua = std::max(ua, u);
    else
      ub = std::min(ub, u);
  }
  if (!(ua < ub)) return;  // missed, or a single point (a grazed vertex or edge)
  const std::vector<int>& slots = all.slots;
  // The slots up to the last one the simplex uses, (0, 0, P); those outside it stay 0.
  constexpr int kUsed = P * (P + 1) * (P + 1) + 1;
  const double* coefficients = all.values.data() + tet.values;
  double form[kUsed] = {};
  for (std::size_t j = 0; j < slots.size(); ++j)
    form[slots[j]] = coefficients[j];
  double la[4], lb[4];
  for (int i = 0; i < 4; ++i)
    la[i] = alpha[i] + beta[i] * ua, lb[i] = alpha[i] + beta[i] * ub;
  // chain[j]: the form after j steps at λ(ua), of degree P − j; b_k is chain[P − k] after k
  // steps at λ(ub).
  double chain[P + 1][kUsed];
  std::copy(form, form + kUsed, chain[0]);
  for (int j = 1; j <= P; ++j) {
    std::copy(chain[j - 1], chain[j - 1] + kUsed, chain[j]);
    de_casteljau_step<P>(chain[j], P - j + 1, la);
  }
  double c[P + 1];
  c[0] = chain[P][0];
  for (int k = 1; k <= P; ++k) {
    double* w = chain[P - k];  // not needed again: stepped in place
    for (int m = k; m > 0; --m)
      de_casteljau_step<P>(w, m, lb);
    c[k] = w[0];
  }
  bernstein::bernstein_roots<P>(c, [&](double root) {
    const double u = segment_point(ua, ub, root);
    double l[4];
    for (int i = 0; i < 4; ++i)
      l[i] = alpha[i] + beta[i] * u;
    double w[kUsed];
    std::copy(form, form + kUsed, w);
    for (int m = P; m > 1; --m)
      de_casteljau_step<P>(w, m, l);
    // Degree 1: f = Σ λ_i d_i, d_0 = w[0], d_1..3 at the unit steps.
    const double d0 = w[0];
    const glm::dvec3 g(w[slot<P>(1, 0, 0)] - d0, w[slot<P>(0, 1, 0)] - d0,
                       w[slot<P>(0, 0, 1)] - d0);
    out(RayHit{s + u, unit_normal(double(P) * (glm::transpose(tet.to_barycentric) * g), d), 0.0f});
  });
}

// straight_tet_hits with the order as a constant.
template <class Out>
void hits_of(const StraightTets& all, const StraightTet& tet, glm::dvec3 o, glm::dvec3 d, double t0,
             double t1, Out&& out) {
  bernstein::with_order(all.cell->order, [&](auto p) {
    constexpr int P = p;
    if constexpr (P >= 1) straight_tet_hits<P>(all, tet, o, d, t0, t1, out);
  });
}

class StraightTetBinding final : public GeometryBinding {
 public:
  StraightTetBinding(RTCDevice device, StraightTets tets)
      : tets_(std::move(tets)),
        geometry_(device, tets_.tets.size(), this, &StraightTetBinding::bounds,
                  &StraightTetBinding::intersect) {}
  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return tets_.tets.size(); }
  std::uint64_t nonfinite_values() const override { return tets_.nonfinite; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const StraightTetBinding*>(args->geometryUserPtr);
    const StraightTet& t = self->tets_.tets[args->primID];
    write_padded_bounds(t.lo, t.hi, args->bounds_o);
  }
  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const StraightTetBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    hits_of(self->tets_, self->tets_.tets[args->primID], q->org, q->dir, q->t_min, q->t_max,
            [&](const RayHit& hit) { q->hits->push_back(hit); });
  }

  StraightTets tets_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

class StraightTetAxisCaster final : public AxisCaster {
 public:
  explicit StraightTetAxisCaster(StraightTets tets)
      : tets_(std::move(tets)), boxes_(tets_.tets.size()) {
    tbb::parallel_for(std::size_t(0), tets_.tets.size(), [&](std::size_t e) {
      boxes_[e] = {tets_.tets[e].lo, tets_.tets[e].hi};
    });
  }
  void prepare(int axis) const override {
    std::call_once(once_[axis], [&] { bins_[axis] = make_axis_bins(boxes_, axis); });
  }
  void cast(const AxisRays& rays, AxisHits& out) const override {
    if (tets_.tets.empty() || rays.rays.empty()) return;
    prepare(rays.axis);
    const AxisBins& bins = bins_[rays.axis];
    bernstein::with_order(tets_.cell->order, [&](auto p) {
      constexpr int P = p;
      if constexpr (P >= 1) {
        if (rays.lattice && rays.width() > 0)
          cast_lattice<P>(rays, bins, out);
        else
          cast_rays<P>(rays, bins, out);
      }
    });
  }
  std::size_t primitive_count() const override { return tets_.tets.size(); }
  std::uint64_t nonfinite_values() const override { return tets_.nonfinite; }

 private:
  template <int P>
  void cast_rays(const AxisRays& rays, const AxisBins& bins, AxisHits& out) const {
    for (std::size_t k = 0; k < rays.rays.size(); ++k) {
      const AxisRay& ray = rays.rays[k];
      if (!(ray.t0 <= ray.t1)) continue;
      const std::size_t bin = bins.at(ray.org);
      for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m)
        straight_tet_hits<P>(tets_, tets_.tets[bins.entries[m] & AxisBins::kIndex], ray.org,
                             rays.dir, ray.t0, ray.t1, [&](const RayHit& hit) {
                               out.push_back({std::uint32_t(k), hit});
                             });
    }
  }
  // Object order over a rectangle of an axis view's pixels: each tetrahedron whose box meets
  // the rectangle (from the first of its bins there, so once) tests the pixel centres in its
  // box (and 10⁻⁶ pixel; the segment test decides).
  template <int P>
  void cast_lattice(const AxisRays& rays, const AxisBins& bins, AxisHits& out) const {
    const View& view = *rays.lattice;
    const int w = rays.width();
    const int h = int((rays.rays.size() + std::size_t(w) - 1) / std::size_t(w));
    const int i0 = rays.column_begin, j0 = rays.row_begin;
    const glm::dvec3 a = view.point(i0, j0, 0.0), b = view.point(i0 + w, j0 + h, 0.0);
    const double lo_b = std::min(a[bins.b], b[bins.b]), hi_b = std::max(a[bins.b], b[bins.b]);
    const double lo_c = std::min(a[bins.c], b[bins.c]), hi_c = std::max(a[bins.c], b[bins.c]);
    const double inv = 1.0 / view.spacing;
    visit_rectangle(bins, lo_b, hi_b, lo_c, hi_c, [&](std::uint32_t e) {
      const StraightTet& tet = tets_.tets[e];
      const glm::dvec3 p = view.origin;
      const double x0 = std::min(glm::dot(tet.lo - p, view.u), glm::dot(tet.hi - p, view.u)),
                   x1 = std::max(glm::dot(tet.lo - p, view.u), glm::dot(tet.hi - p, view.u));
      const double y0 = std::min(glm::dot(tet.lo - p, view.v), glm::dot(tet.hi - p, view.v)),
                   y1 = std::max(glm::dot(tet.lo - p, view.v), glm::dot(tet.hi - p, view.v));
      constexpr double pad = 1e-6;
      const auto [ia, ib] = pixel_range(x0, x1, inv, pad, i0, i0 + w - 1);
      const auto [ja, jb] = pixel_range(y0, y1, inv, pad, j0, j0 + h - 1);
      for (int j = ja; j <= jb; ++j)
        for (int i = ia; i <= ib; ++i) {
          const std::size_t k = std::size_t(j - j0) * std::size_t(w) + std::size_t(i - i0);
          if (k >= rays.rays.size()) continue;
          const AxisRay& ray = rays.rays[k];
          if (!(ray.t0 <= ray.t1)) continue;
          straight_tet_hits<P>(tets_, tet, ray.org, rays.dir, ray.t0, ray.t1,
                               [&](const RayHit& hit) {
                                 out.push_back({std::uint32_t(k), hit});
                               });
        }
    });
  }

  StraightTets tets_;
  std::vector<AxisBox> boxes_;
  mutable std::once_flag once_[3];
  mutable AxisBins bins_[3];
};

}  // namespace

std::unique_ptr<GeometryBinding> bind_straight_tets(RTCDevice device, StraightTets tets) {
  return std::make_unique<StraightTetBinding>(device, std::move(tets));
}

std::unique_ptr<AxisCaster> bind_axis_straight_tets(StraightTets tets) {
  return std::make_unique<StraightTetAxisCaster>(std::move(tets));
}

}  // namespace ldimesh::cells

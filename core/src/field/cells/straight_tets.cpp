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
constexpr int kMaxTetNodes = (kMaxHexOrder + 1) * (kMaxHexOrder + 2) * (kMaxHexOrder + 3) / 6;

// The (p + 1) × (p + 1) matrix from a polynomial's values at s = k/p, k = 0..p, to its
// Bernstein coefficients on [0, 1] (row-major), for p = 1..kMaxHexOrder.
const std::vector<double>& samples_to_bernstein(int p) {
  static std::once_flag once[kMaxHexOrder + 1];
  static std::vector<double> matrix[kMaxHexOrder + 1];
  std::call_once(once[p], [p] {
    const int n = p + 1;
    // E[k][i] = B_i^p(k/p), inverted by Gauss–Jordan elimination (small, well conditioned).
    std::vector<double> e(std::size_t(n) * n), inv(std::size_t(n) * n, 0.0);
    for (int k = 0; k < n; ++k)
      for (int i = 0; i < n; ++i) {
        const double s = double(k) / p;
        e[std::size_t(k) * n + i] = kBinomial[p][i] * std::pow(s, i) * std::pow(1.0 - s, p - i);
      }
    for (int i = 0; i < n; ++i)
      inv[std::size_t(i) * n + i] = 1.0;
    for (int col = 0; col < n; ++col) {
      int pivot = col;
      for (int r = col + 1; r < n; ++r)
        if (std::abs(e[std::size_t(r) * n + col]) > std::abs(e[std::size_t(pivot) * n + col]))
          pivot = r;
      for (int k = 0; k < n; ++k) {
        std::swap(e[std::size_t(col) * n + k], e[std::size_t(pivot) * n + k]);
        std::swap(inv[std::size_t(col) * n + k], inv[std::size_t(pivot) * n + k]);
      }
      const double d = e[std::size_t(col) * n + col];
      for (int k = 0; k < n; ++k)
        e[std::size_t(col) * n + k] /= d, inv[std::size_t(col) * n + k] /= d;
      for (int r = 0; r < n; ++r) {
        const double f = e[std::size_t(r) * n + col];
        if (r == col || f == 0.0) continue;
        for (int k = 0; k < n; ++k) {
          e[std::size_t(r) * n + k] -= f * e[std::size_t(col) * n + k];
          inv[std::size_t(r) * n + k] -= f * inv[std::size_t(col) * n + k];
        }
      }
    }
    matrix[p] = std::move(inv);
  });
  return matrix[p];
}

// The field minus the isovalue at reference point r of tetrahedron `f` (its N nodal values).
double field_at(const ReferenceCell& cell, const double* f, glm::dvec3 r, double* phi) {
  shape_functions(cell, r, phi);
  double s = 0.0;
  for (std::size_t i = 0; i < cell.nodes.size(); ++i)
    s += phi[i] * f[i];
  return s;
}

// Every root of tetrahedron `tet`'s field along ray o + t·d, t ∈ [t0, t1], appended to `out`:
// the ray's segment in the tetrahedron (barycentric coordinates ≥ −kInside, each linear in t),
// the field's samples at p + 1 equispaced points of it, their Bernstein coefficients, the roots
// isolated and converged (bernstein_roots); normals from the field's gradient (central
// differences of the polynomial in the reference coordinates, mapped to the world).
template <int P, class Out>
void straight_tet_hits(const StraightTets& all, const StraightTet& tet, glm::dvec3 o, glm::dvec3 d,
                       double t0, double t1, Out&& out) {
  const glm::dvec3 a = tet.to_barycentric * (o - tet.v0), b = tet.to_barycentric * d;
  const double alpha[4] = {1.0 - a.x - a.y - a.z, a.x, a.y, a.z};
  const double beta[4] = {-(b.x + b.y + b.z), b.x, b.y, b.z};
  double ta = t0, tb = t1;
  for (int i = 0; i < 4; ++i) {
    if (beta[i] == 0.0) {
      if (alpha[i] < -kInside) return;
      continue;
    }
    const double t = (-kInside - alpha[i]) / beta[i];
    if (beta[i] > 0.0)
      ta = std::max(ta, t);
    else
      tb = std::min(tb, t);
  }
  if (!(ta < tb)) return;  // missed, or a single point (a grazed vertex or edge)
  const ReferenceCell& cell = *all.cell;
  const double* f = all.values.data() + tet.values;
  double phi[kMaxTetNodes];
  double samples[P + 1], c[P + 1];
  for (int k = 0; k <= P; ++k) {
    const double t = k == P ? tb : ta + (tb - ta) * (double(k) / P);
    samples[k] = field_at(cell, f, a + t * b, phi);
  }
  const double* m = samples_to_bernstein(P).data();
  for (int i = 0; i <= P; ++i) {
    double s = 0.0;
    for (int k = 0; k <= P; ++k)
      s += m[i * (P + 1) + k] * samples[k];
    c[i] = s;
  }
  bernstein::bernstein_roots<P>(c, [&](double s) {
    const double t = segment_point(ta, tb, s);
    const glm::dvec3 r = a + t * b;
    // The gradient in the reference coordinates, then in the world: ∇ₓf = (∂λ/∂x)ᵀ ∇_λ f.
    constexpr double h = 1e-6;
    glm::dvec3 g;
    for (int axis = 0; axis < 3; ++axis) {
      glm::dvec3 e(0.0);
      e[axis] = h;
      g[axis] = (field_at(cell, f, r + e, phi) - field_at(cell, f, r - e, phi)) / (2.0 * h);
    }
    out(RayHit{t, unit_normal(glm::transpose(tet.to_barycentric) * g, d), 0.0f});
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

class StraightTetAxisBinding final : public AxisBinding {
 public:
  explicit StraightTetAxisBinding(StraightTets tets)
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
    const int qb0 = bins.bin_b(lo_b), qb1 = bins.bin_b(hi_b);
    const int qc0 = bins.bin_c(lo_c), qc1 = bins.bin_c(hi_c);
    const double inv = 1.0 / view.spacing;
    const auto first = [](double x, int lo, int hi) {
      return int(std::clamp(std::ceil(x), double(lo), double(hi + 1)));
    };
    const auto last = [](double x, int lo, int hi) {
      return int(std::clamp(std::floor(x), double(lo - 1), double(hi)));
    };
    for (int cc = qc0; cc <= qc1; ++cc)
      for (int bb = qb0; bb <= qb1; ++bb) {
        const std::size_t bin = bins.bin(bb, cc);
        for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
          const std::uint32_t entry = bins.entries[m];
          if (!AxisBins::first_in(entry, bb, cc, qb0, qc0)) continue;
          const StraightTet& tet = tets_.tets[entry & AxisBins::kIndex];
          const glm::dvec3 p = view.origin;
          const double x0 = std::min(glm::dot(tet.lo - p, view.u), glm::dot(tet.hi - p, view.u)),
                       x1 = std::max(glm::dot(tet.lo - p, view.u), glm::dot(tet.hi - p, view.u));
          const double y0 = std::min(glm::dot(tet.lo - p, view.v), glm::dot(tet.hi - p, view.v)),
                       y1 = std::max(glm::dot(tet.lo - p, view.v), glm::dot(tet.hi - p, view.v));
          constexpr double pad = 1e-6;
          const int ia = first(x0 * inv - 0.5 - pad, i0, i0 + w - 1),
                    ib = last(x1 * inv - 0.5 + pad, i0, i0 + w - 1);
          const int ja = first(y0 * inv - 0.5 - pad, j0, j0 + h - 1),
                    jb = last(y1 * inv - 0.5 + pad, j0, j0 + h - 1);
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
        }
      }
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

std::unique_ptr<AxisBinding> bind_axis_straight_tets(StraightTets tets) {
  return std::make_unique<StraightTetAxisBinding>(std::move(tets));
}

}  // namespace ldimesh::cells

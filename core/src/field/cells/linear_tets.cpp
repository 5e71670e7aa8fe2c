#include "linear_tets.hpp"

#include <algorithm>
#include <cmath>
#include <mutex>

namespace ldimesh::cells {
namespace {

// The hit of ray o + t·d, t ∈ [t0, t1], with tetrahedron `tet`: the ray's crossing of the plane
// f = 0 where that lies in the tetrahedron (barycentric coordinates ≥ −10⁻¹², a crossing on a
// shared face or edge found by each tetrahedron there and merged by the caster). A ray in the
// plane (g·d = 0) has no isolated root. Both casters call this, so they give the same bits.
inline bool tet_hit(const LinearTet& tet, glm::dvec3 o, glm::dvec3 d, double t0, double t1,
                    RayHit& out) {
  const double gd = glm::dot(tet.g, d);
  if (gd == 0.0) return false;
  const double t = -(tet.f0 + glm::dot(tet.g, o - tet.v0)) / gd;
  if (!(t >= t0 && t <= t1)) return false;
  const glm::dvec3 l = tet.to_barycentric * (o + t * d - tet.v0);
  constexpr double eps = 1e-12;
  if (!(l.x >= -eps && l.y >= -eps && l.z >= -eps && l.x + l.y + l.z <= 1.0 + eps)) return false;
  out = {t, unit_normal(tet.g, d), 0.0f};
  return true;
}

class LinearTetBinding final : public GeometryBinding {
 public:
  LinearTetBinding(RTCDevice device, std::vector<LinearTet> tets, std::uint64_t nonfinite)
      : tets_(std::move(tets)),
        nonfinite_(nonfinite),
        geometry_(device, tets_.size(), this, &LinearTetBinding::bounds,
                  &LinearTetBinding::intersect) {}
  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return tets_.size(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const LinearTetBinding*>(args->geometryUserPtr);
    const LinearTet& t = self->tets_[args->primID];
    write_padded_bounds(t.lo, t.hi, args->bounds_o);
  }
  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const LinearTetBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    RayHit hit;
    if (tet_hit(self->tets_[args->primID], q->org, q->dir, q->t_min, q->t_max, hit))
      q->hits->push_back(hit);
  }

  std::vector<LinearTet> tets_;
  std::uint64_t nonfinite_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

// The tetrahedra binned across one ray axis: a uniform grid over the two other world axes (b, c),
// bins about as wide as the median tetrahedron, each tetrahedron in every bin its box touches. A
// ray lies in one bin, so it meets each tetrahedron there once.
struct Bins {
  int b = 0, c = 1, nb = 1, nc = 1;
  double lo_b = 0.0, lo_c = 0.0, size_b = 1.0, size_c = 1.0;
  std::vector<std::uint32_t> first, tets;  // CSR, b fastest
  int bin(double x, double lo, double size, int n) const {
    const double k = std::floor((x - lo) / size);
    return k < 0.0 ? 0 : k >= n ? n - 1 : int(k);
  }
  std::size_t at(glm::dvec3 p) const {
    return std::size_t(bin(p[b], lo_b, size_b, nb)) +
           std::size_t(nb) * std::size_t(bin(p[c], lo_c, size_c, nc));
  }
};

Bins make_bins(const std::vector<LinearTet>& tets, int axis) {
  Bins bins;
  bins.b = axis == 0 ? 1 : 0;
  bins.c = axis == 2 ? 1 : 2;
  const std::size_t n = tets.size();
  double lo_b = INFINITY, hi_b = -INFINITY, lo_c = INFINITY, hi_c = -INFINITY;
  std::vector<double> wb(n), wc(n);
  for (std::size_t e = 0; e < n; ++e) {
    lo_b = std::min(lo_b, tets[e].lo[bins.b]), hi_b = std::max(hi_b, tets[e].hi[bins.b]);
    lo_c = std::min(lo_c, tets[e].lo[bins.c]), hi_c = std::max(hi_c, tets[e].hi[bins.c]);
    wb[e] = tets[e].hi[bins.b] - tets[e].lo[bins.b];
    wc[e] = tets[e].hi[bins.c] - tets[e].lo[bins.c];
  }
  if (n > 0) {
    std::nth_element(wb.begin(), wb.begin() + n / 2, wb.end());
    std::nth_element(wc.begin(), wc.begin() + n / 2, wc.end());
    const auto layout = [](double lo, double hi, double median, double& size, int& count) {
      const double extent = std::max(hi - lo, 1e-300);
      count = int(std::clamp(std::ceil(extent / std::max(median, extent / 4096.0)), 1.0, 4096.0));
      size = extent / count;
    };
    bins.lo_b = lo_b, bins.lo_c = lo_c;
    double median_b = wb[n / 2], median_c = wc[n / 2];
    // Coarser bins while the entries (each tetrahedron in every bin its box touches) would
    // exceed 16 per tetrahedron: a graded mesh's large tetrahedra would otherwise fill
    // millions of bins each.
    for (;;) {
      layout(lo_b, hi_b, median_b, bins.size_b, bins.nb);
      layout(lo_c, hi_c, median_c, bins.size_c, bins.nc);
      std::size_t entries = 0;
      for (std::size_t e = 0; e < n; ++e) {
        const LinearTet& t = tets[e];
        entries += std::size_t(bins.bin(t.hi[bins.b], bins.lo_b, bins.size_b, bins.nb) -
                               bins.bin(t.lo[bins.b], bins.lo_b, bins.size_b, bins.nb) + 1) *
                   std::size_t(bins.bin(t.hi[bins.c], bins.lo_c, bins.size_c, bins.nc) -
                               bins.bin(t.lo[bins.c], bins.lo_c, bins.size_c, bins.nc) + 1);
      }
      if (entries <= 16 * n + 1024 || (bins.nb == 1 && bins.nc == 1)) break;
      median_b = 2.0 * std::max(median_b, bins.size_b);
      median_c = 2.0 * std::max(median_c, bins.size_c);
    }
  }
  const std::size_t cells = std::size_t(bins.nb) * std::size_t(bins.nc);
  bins.first.assign(cells + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::uint32_t> next;
    if (pass == 1) {
      for (std::size_t k = 0; k < cells; ++k)
        bins.first[k + 1] += bins.first[k];
      bins.tets.resize(bins.first[cells]);
      next.assign(bins.first.begin(), bins.first.end() - 1);
    }
    for (std::size_t e = 0; e < n; ++e) {
      const LinearTet& t = tets[e];
      const int b0 = bins.bin(t.lo[bins.b], bins.lo_b, bins.size_b, bins.nb),
                b1 = bins.bin(t.hi[bins.b], bins.lo_b, bins.size_b, bins.nb);
      const int c0 = bins.bin(t.lo[bins.c], bins.lo_c, bins.size_c, bins.nc),
                c1 = bins.bin(t.hi[bins.c], bins.lo_c, bins.size_c, bins.nc);
      for (int cc = c0; cc <= c1; ++cc)
        for (int bb = b0; bb <= b1; ++bb) {
          const std::size_t k = std::size_t(bb) + std::size_t(bins.nb) * std::size_t(cc);
          if (pass == 0)
            ++bins.first[k + 1];
          else
            bins.tets[next[k]++] = std::uint32_t(e);
        }
    }
  }
  return bins;
}

class LinearTetAxisBinding final : public AxisBinding {
 public:
  LinearTetAxisBinding(std::vector<LinearTet> tets, std::uint64_t nonfinite)
      : tets_(std::move(tets)), nonfinite_(nonfinite) {}
  void prepare(int axis) const override {
    std::call_once(once_[axis], [&] { bins_[axis] = make_bins(tets_, axis); });
  }
  void cast(const AxisRays& rays, AxisHits& out) const override {
    if (tets_.empty() || rays.rays.empty()) return;
    prepare(rays.axis);
    const Bins& bins = bins_[rays.axis];
    if (rays.lattice && rays.width() > 0) {
      cast_lattice(rays, bins, out);
      return;
    }
    for (std::size_t k = 0; k < rays.rays.size(); ++k) {
      const AxisRay& ray = rays.rays[k];
      if (!(ray.t0 <= ray.t1)) continue;
      const std::size_t bin = bins.at(ray.org);
      for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
        RayHit hit;
        if (tet_hit(tets_[bins.tets[m]], ray.org, rays.dir, ray.t0, ray.t1, hit))
          out.push_back({std::uint32_t(k), hit});
      }
    }
  }
  std::size_t primitive_count() const override { return tets_.size(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  // Object order over a rectangle of an axis view's pixels: each tetrahedron whose box meets the
  // rectangle (from the first of its bins there, so once) tests the pixel centres its box
  // covers (to 10⁻⁶ pixel; the test itself decides) — a few pixels per tetrahedron instead of
  // every tetrahedron of a bin per ray. The same pairs of ray and
  // tetrahedron that hold a hit as the per-ray loop, through the same tet_hit.
  void cast_lattice(const AxisRays& rays, const Bins& bins, AxisHits& out) const {
    const View& view = *rays.lattice;
    const int w = rays.width();
    const int h = int((rays.rays.size() + std::size_t(w) - 1) / std::size_t(w));
    const int i0 = rays.column_begin, j0 = rays.row_begin;
    // The rectangle in world coordinates along the bins' axes (pixel edges).
    const glm::dvec3 a = view.point(i0, j0, 0.0), b = view.point(i0 + w, j0 + h, 0.0);
    const double lo_b = std::min(a[bins.b], b[bins.b]), hi_b = std::max(a[bins.b], b[bins.b]);
    const double lo_c = std::min(a[bins.c], b[bins.c]), hi_c = std::max(a[bins.c], b[bins.c]);
    const int qb0 = bins.bin(lo_b, bins.lo_b, bins.size_b, bins.nb),
              qb1 = bins.bin(hi_b, bins.lo_b, bins.size_b, bins.nb);
    const int qc0 = bins.bin(lo_c, bins.lo_c, bins.size_c, bins.nc),
              qc1 = bins.bin(hi_c, bins.lo_c, bins.size_c, bins.nc);
    const double inv = 1.0 / view.spacing;
    for (int cc = qc0; cc <= qc1; ++cc)
      for (int bb = qb0; bb <= qb1; ++bb) {
        const std::size_t bin = std::size_t(bb) + std::size_t(bins.nb) * std::size_t(cc);
        for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
          const LinearTet& tet = tets_[bins.tets[m]];
          if (std::max(bins.bin(tet.lo[bins.b], bins.lo_b, bins.size_b, bins.nb), qb0) != bb ||
              std::max(bins.bin(tet.lo[bins.c], bins.lo_c, bins.size_c, bins.nc), qc0) != cc)
            continue;
          // The tetrahedron's box in image coordinates (u, v are axes: exact).
          const glm::dvec3 p = view.origin;
          const double x0 = std::min(glm::dot(tet.lo - p, view.u), glm::dot(tet.hi - p, view.u)),
                       x1 = std::max(glm::dot(tet.lo - p, view.u), glm::dot(tet.hi - p, view.u));
          const double y0 = std::min(glm::dot(tet.lo - p, view.v), glm::dot(tet.hi - p, view.v)),
                       y1 = std::max(glm::dot(tet.lo - p, view.v), glm::dot(tet.hi - p, view.v));
          // The pixel centres in the box grown by 10⁻⁶ pixel (a hit the test accepts lies in
          // the box to 10⁻¹² of the tetrahedron's size).
          constexpr double pad = 1e-6;
          // Clamped as doubles to the rectangle before the conversion (a far-away box's pixel
          // numbers would not fit an int).
          const auto first = [](double x, int lo, int hi) {
            return int(std::clamp(std::ceil(x), double(lo), double(hi + 1)));
          };
          const auto last = [](double x, int lo, int hi) {
            return int(std::clamp(std::floor(x), double(lo - 1), double(hi)));
          };
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
              RayHit hit;
              if (tet_hit(tet, ray.org, rays.dir, ray.t0, ray.t1, hit))
                out.push_back({std::uint32_t(k), hit});
            }
        }
      }
  }

  std::vector<LinearTet> tets_;
  std::uint64_t nonfinite_;
  mutable std::once_flag once_[3];
  mutable Bins bins_[3];
};

}  // namespace

std::unique_ptr<GeometryBinding> bind_linear_tets(RTCDevice device, std::vector<LinearTet> tets,
                                                  std::uint64_t nonfinite) {
  return std::make_unique<LinearTetBinding>(device, std::move(tets), nonfinite);
}

std::unique_ptr<AxisBinding> bind_axis_linear_tets(std::vector<LinearTet> tets,
                                                   std::uint64_t nonfinite) {
  return std::make_unique<LinearTetAxisBinding>(std::move(tets), nonfinite);
}

bool linear_tet_is_valid(const double* v) {
  const glm::dvec3 v0(v[0], v[1], v[2]);
  glm::dmat3 edges;
  double lengths = 1.0;
  for (int i = 1; i < 4; ++i) {
    edges[i - 1] = glm::dvec3(v[3 * i], v[3 * i + 1], v[3 * i + 2]) - v0;
    lengths *= glm::length(edges[i - 1]);
  }
  // Stricter than the sub-hexahedra's own check (HexElementSource: 10⁻¹⁰ of their Jacobian's
  // columns), so that a tetrahedron accepted here never fails when its sub-hexahedra are built
  // later (a colour field, a lookup).
  return std::abs(glm::determinant(edges)) > 1e-8 * lengths;
}

}  // namespace ldimesh::cells

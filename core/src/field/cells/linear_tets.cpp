#include "linear_tets.hpp"

#include "../axis_bins.hpp"

#include <algorithm>
#include <cmath>
#include <mutex>

namespace ldimesh::cells {
namespace {

// What a hit of tetrahedron `tet` with rays of direction d shares: g·d, d·d and the normal.
// False for rays in the plane f = 0 (g·d = 0): they have no isolated root.
struct TetDirection {
  double gd = 0.0, dd = 0.0;
  glm::vec3 normal{0.0f};
};
inline bool tet_direction(const LinearTet& tet, glm::dvec3 d, TetDirection& out) {
  out.gd = glm::dot(tet.g, d);
  if (out.gd == 0.0) return false;
  out.dd = glm::dot(d, d);
  out.normal = unit_normal(tet.g, d);
  return true;
}

// The hit of ray o + t·d, t ∈ [t0, t1], with tetrahedron `tet` (`dir` from tet_direction): the
// ray's crossing of the plane f = 0 where that lies in the tetrahedron (barycentric coordinates
// ≥ −10⁻¹², a crossing on a shared face or edge found by each tetrahedron there and merged by
// the caster). The crossing is taken from the ray's point nearest v0, so that its rounding
// scales with the tetrahedron, not with the ray's origin (set_crossing's margin counts on it).
// Both casters call this, so they give the same bits.
inline bool tet_hit(const LinearTet& tet, const TetDirection& dir, glm::dvec3 o, glm::dvec3 d,
                    double t0, double t1, RayHit& out) {
  const double s = glm::dot(tet.v0 - o, d) / dir.dd;
  const glm::dvec3 near = o + s * d - tet.v0;
  const double ds = -(tet.f0 + glm::dot(tet.g, near)) / dir.gd;
  const double t = s + ds;
  if (!(t >= t0 && t <= t1)) return false;
  const glm::dvec3 l = tet.to_barycentric * (near + ds * d);
  constexpr double eps = 1e-12;
  if (!(l.x >= -eps && l.y >= -eps && l.z >= -eps && l.x + l.y + l.z <= 1.0 + eps)) return false;
  out = {t, dir.normal, 0.0f};
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
    write_padded_bounds(t.lo(), t.hi(), args->bounds_o);
  }
  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const LinearTetBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    const LinearTet& tet = self->tets_[args->primID];
    TetDirection dir;
    RayHit hit;
    if (tet_direction(tet, q->dir, dir) &&
        tet_hit(tet, dir, q->org, q->dir, q->t_min, q->t_max, hit))
      q->hits->push_back(hit);
  }

  std::vector<LinearTet> tets_;
  std::uint64_t nonfinite_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

class LinearTetAxisCaster final : public AxisCaster {
 public:
  LinearTetAxisCaster(std::vector<LinearTet> tets, std::uint64_t nonfinite)
      : tets_(std::move(tets)), boxes_(tets_.size()), nonfinite_(nonfinite) {
    tbb::parallel_for(std::size_t(0), tets_.size(), [&](std::size_t e) {
      boxes_[e] = {tets_[e].lo(), tets_[e].hi()};
    });
  }
  void prepare(int axis) const override {
    std::call_once(once_[axis], [&] { bins_[axis] = make_axis_bins(boxes_, axis); });
  }
  void cast(const AxisRays& rays, AxisHits& out) const override {
    if (tets_.empty() || rays.rays.empty()) return;
    prepare(rays.axis);
    const AxisBins& bins = bins_[rays.axis];
    if (rays.lattice && rays.width() > 0) {
      cast_lattice(rays, bins, out);
      return;
    }
    for (std::size_t k = 0; k < rays.rays.size(); ++k) {
      const AxisRay& ray = rays.rays[k];
      if (!(ray.t0 <= ray.t1)) continue;
      const std::size_t bin = bins.at(ray.org);
      for (std::uint32_t m = bins.first[bin]; m < bins.first[bin + 1]; ++m) {
        const LinearTet& tet = tets_[bins.entries[m] & AxisBins::kIndex];
        TetDirection dir;
        RayHit hit;
        if (tet_direction(tet, rays.dir, dir) &&
            tet_hit(tet, dir, ray.org, rays.dir, ray.t0, ray.t1, hit))
          out.push_back({std::uint32_t(k), hit});
      }
    }
  }
  std::size_t primitive_count() const override { return tets_.size(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  // Object order over a rectangle of an axis view's pixels: each tetrahedron whose box meets the
  // rectangle (from the first of its bins there, so once) tests, row by row, the pixel centres
  // its crossing polygon grown by its margin covers (and 10⁻⁶ pixel; the test itself decides) —
  // little more than the pixels it hits, instead of every tetrahedron of a bin per ray. The same
  // pairs of ray and tetrahedron that hold a hit as the per-ray loop, through the same tet_hit.
  void cast_lattice(const AxisRays& rays, const AxisBins& bins, AxisHits& out) const {
    const View& view = *rays.lattice;
    const int w = rays.width();
    const int h = int((rays.rays.size() + std::size_t(w) - 1) / std::size_t(w));
    const int i0 = rays.column_begin, j0 = rays.row_begin;
    // The rectangle in world coordinates along the bins' axes (pixel edges).
    const glm::dvec3 a = view.point(i0, j0, 0.0), b = view.point(i0 + w, j0 + h, 0.0);
    const double lo_b = std::min(a[bins.b], b[bins.b]), hi_b = std::max(a[bins.b], b[bins.b]);
    const double lo_c = std::min(a[bins.c], b[bins.c]), hi_c = std::max(a[bins.c], b[bins.c]);
    const double inv = 1.0 / view.spacing;
    // The tetrahedra a few entries ahead are fetched while one is tested (each is read once per
    // view, in the mesh's order: a cache miss per tetrahedron otherwise).
    const auto ahead = [&](std::uint32_t e) {
      const char* next = reinterpret_cast<const char*>(&tets_[e]);
      for (std::size_t line = 0; line < sizeof(LinearTet); line += 64)
        __builtin_prefetch(next + line);
    };
    visit_rectangle(
        bins, lo_b, hi_b, lo_c, hi_c,
        [&](std::uint32_t e) {
          const LinearTet& tet = tets_[e];
          // The tetrahedron's box in image coordinates (u, v are axes: exact).
          const glm::dvec3 p = view.origin, lo = tet.lo(), hi = tet.hi();
          const double x0 = std::min(glm::dot(lo - p, view.u), glm::dot(hi - p, view.u)),
                       x1 = std::max(glm::dot(lo - p, view.u), glm::dot(hi - p, view.u));
          const double y0 = std::min(glm::dot(lo - p, view.v), glm::dot(hi - p, view.v)),
                       y1 = std::max(glm::dot(lo - p, view.v), glm::dot(hi - p, view.v));
          // The pixel centres in the box grown by 10⁻⁶ pixel (a hit the test accepts lies in
          // the box to 10⁻¹² of the tetrahedron's size).
          constexpr double pad = 1e-6;
          const auto [ia, ib] = pixel_range(x0, x1, inv, pad, i0, i0 + w - 1);
          const auto [ja, jb] = pixel_range(y0, y1, inv, pad, j0, j0 + h - 1);
          if (ia > ib || ja > jb) return;
          TetDirection dir;
          if (!tet_direction(tet, rays.dir, dir)) return;
          // The crossing polygon's corners in pixel coordinates (pixel centres at integers) and
          // its margin: in each row, the columns of the polygon's slice over the row ± margin.
          double cx[4], cy[4];
          for (int k = 0; k < tet.corners; ++k) {
            const glm::dvec3 c(tet.corner[k][0], tet.corner[k][1], tet.corner[k][2]);
            cx[k] = glm::dot(c - p, view.u) * inv - 0.5;
            cy[k] = glm::dot(c - p, view.v) * inv - 0.5;
          }
          const double grow = double(tet.margin) * inv + pad;
          for (int j = ja; j <= jb; ++j) {
            const double band_lo = j - grow, band_hi = j + grow;
            double xl = INFINITY, xr = -INFINITY;
            for (int a = 0; a < tet.corners; ++a) {
              if (cy[a] >= band_lo && cy[a] <= band_hi)
                xl = std::min(xl, cx[a]), xr = std::max(xr, cx[a]);
              for (int b = a + 1; b < tet.corners; ++b) {
                // The segment's part within the band: its ends there.
                const double ya = cy[a], yb = cy[b];
                if (ya == yb || std::max(ya, yb) < band_lo || std::min(ya, yb) > band_hi) continue;
                for (const double y : {std::clamp(band_lo, std::min(ya, yb), std::max(ya, yb)),
                                       std::clamp(band_hi, std::min(ya, yb), std::max(ya, yb))}) {
                  const double x = cx[a] + (cx[b] - cx[a]) * ((y - ya) / (yb - ya));
                  xl = std::min(xl, x), xr = std::max(xr, x);
                }
              }
            }
            if (!(xl <= xr)) continue;
            const auto [ra, rb] = integer_range(xl - grow, xr + grow, i0, i0 + w - 1);
            for (int i = std::max(ia, ra); i <= std::min(ib, rb); ++i) {
              const std::size_t k = std::size_t(j - j0) * std::size_t(w) + std::size_t(i - i0);
              if (k >= rays.rays.size()) continue;
              const AxisRay& ray = rays.rays[k];
              if (!(ray.t0 <= ray.t1)) continue;
              RayHit hit;
              if (tet_hit(tet, dir, ray.org, rays.dir, ray.t0, ray.t1, hit))
                out.push_back({std::uint32_t(k), hit});
            }
          }
        },
        ahead);
  }

  std::vector<LinearTet> tets_;
  std::vector<AxisBox> boxes_;
  std::uint64_t nonfinite_;
  mutable std::once_flag once_[3];
  mutable AxisBins bins_[3];
};

}  // namespace

std::unique_ptr<GeometryBinding> bind_linear_tets(RTCDevice device, std::vector<LinearTet> tets,
                                                  std::uint64_t nonfinite) {
  return std::make_unique<LinearTetBinding>(device, std::move(tets), nonfinite);
}

std::unique_ptr<AxisCaster> bind_axis_linear_tets(std::vector<LinearTet> tets,
                                                  std::uint64_t nonfinite) {
  return std::make_unique<LinearTetAxisCaster>(std::move(tets), nonfinite);
}

void set_crossing(LinearTet& tet, const double* v, const double* f) {
  glm::dvec3 p[4];
  glm::dvec3 box_lo(INFINITY), box_hi(-INFINITY);
  double f_max = 0.0;
  for (int i = 0; i < 4; ++i) {
    p[i] = glm::dvec3(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    box_lo = glm::min(box_lo, p[i]), box_hi = glm::max(box_hi, p[i]);
    f_max = std::max(f_max, std::abs(f[i]));
  }
  constexpr int kEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  // The corners: the edges' sign changes and the vertices on the plane.
  glm::dvec3 corner[4];
  int corners = 0;
  for (int i = 0; i < 4; ++i)
    if (f[i] == 0.0) corner[corners++] = p[i];
  for (const auto& e : kEdges) {
    const double fa = f[e[0]], fb = f[e[1]];
    if ((fa < 0.0 && fb > 0.0) || (fa > 0.0 && fb < 0.0))
      if (corners < 4) corner[corners++] = p[e[0]] + (fa / (fa - fb)) * (p[e[1]] - p[e[0]]);
  }
  if (corners == 0) {  // not straddling 0: the whole tetrahedron (the caller's rule)
    for (int i = 0; i < 4; ++i)
      corner[i] = p[i];
    corners = 4;
  }
  // An accepted hit lies, up to tet_hit's rounding (a few ulps of the tetrahedron's size,
  // coordinates and values), within delta of the tetrahedron and where |f| ≤ eps: generous
  // bounds of both. Such a point is within delta of a point of the tetrahedron where
  // |f| ≤ eps + |g| delta, and those points span the convex hull of the vertices and edge points
  // below (where |f| = that bound); each is within `reach` of a corner, so the polygon grown by
  // reach + delta holds them all (and by the tetrahedron's size + delta: it holds the corners).
  const double size = glm::length(box_hi - box_lo);
  double coords = 0.0;
  for (int a = 0; a < 3; ++a)
    coords = std::max({coords, std::abs(box_lo[a]), std::abs(box_hi[a])});
  const double gradient = glm::length(tet.g);
  const double delta = 1e-9 * (size + coords);
  const double eps = 1e-9 * (f_max + gradient * (size + coords)) + gradient * delta;
  double reach2 = 0.0;  // squared
  const auto near = [&](glm::dvec3 x) {
    double d2 = INFINITY;
    for (int k = 0; k < corners; ++k) {
      const glm::dvec3 r = x - corner[k];
      d2 = std::min(d2, glm::dot(r, r));
    }
    reach2 = std::max(reach2, d2);
  };
  for (int i = 0; i < 4; ++i)
    if (std::abs(f[i]) <= eps) near(p[i]);
  for (const auto& e : kEdges)
    for (const double level : {-eps, eps}) {
      const double fa = f[e[0]] - level, fb = f[e[1]] - level;
      if ((fa < 0.0 && fb > 0.0) || (fa > 0.0 && fb < 0.0))
        near(p[e[0]] + (fa / (fa - fb)) * (p[e[1]] - p[e[0]]));
    }
  double margin = std::min(std::sqrt(reach2) * (1.0 + 1e-12) + delta, size + delta);
  // The corners kept as floats: the margin grows by how far each moved, and is rounded up.
  double moved = 0.0;
  tet.corners = corners;
  for (int k = 0; k < corners; ++k) {
    glm::dvec3 rounded;
    for (int a = 0; a < 3; ++a)
      rounded[a] = tet.corner[k][a] = float(corner[k][a]);
    moved = std::max(moved, glm::length(rounded - corner[k]));
  }
  margin = (margin + moved) * (1.0 + 1e-12);
  tet.margin = float(margin);
  if (double(tet.margin) < margin) tet.margin = std::nextafter(tet.margin, INFINITY);
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

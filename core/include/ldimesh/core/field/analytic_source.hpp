// Analytic fields as ray-caster sources: the domain is split into bricks; bricks whose interval
// enclosure contains the isovalue become Embree user primitives; the intersect callback isolates
// every root along the ray inside the brick with interval bisection and converges on each with
// safeguarded Newton steps (after Knoll et al. 2009; no fixed-step sampling, so features thinner
// than a brick or a step are never skipped).
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include "ldimesh/core/field/field_source.hpp"
#include "ldimesh/core/field/interval.hpp"
#include "ldimesh/core/field/jet.hpp"

namespace ldimesh {

// Everything about a root search that does not depend on the field type.
struct RootSearchTolerances {
  double min_width;  // stop bisecting intervals without a sign change below this length
  double converged;  // Newton/bisection stops when the bracket is shorter than this
};

namespace analytic_detail {

template <class Field>
double value(const Field& f, glm::dvec3 p) {
  return f(p.x, p.y, p.z);
}

template <class Field>
glm::dvec3 gradient(const Field& f, glm::dvec3 p) {
  using J = Jet<double, 3>;
  J x(p.x, {1.0, 0.0, 0.0}), y(p.y, {0.0, 1.0, 0.0}), z(p.z, {0.0, 0.0, 1.0});
  J r = f(x, y, z);
  return {r.d[0], r.d[1], r.d[2]};
}

// Enclosure of f over a box: the natural interval extension intersected with the mean value
// form f(c) + ∇f(box)·(box − c), which is much tighter on small boxes.
template <class Field>
Interval enclose(const Field& f, glm::dvec3 lo, glm::dvec3 hi) {
  using J = Jet<Interval, 3>;
  J x(Interval(lo.x, hi.x), {Interval(1.0), Interval(0.0), Interval(0.0)});
  J y(Interval(lo.y, hi.y), {Interval(0.0), Interval(1.0), Interval(0.0)});
  J z(Interval(lo.z, hi.z), {Interval(0.0), Interval(0.0), Interval(1.0)});
  J r = f(x, y, z);
  glm::dvec3 c = 0.5 * (lo + hi), h = 0.5 * (hi - lo);
  Interval mv(value(f, c));
  mv += r.d[0] * Interval(-h.x, h.x);
  mv += r.d[1] * Interval(-h.y, h.y);
  mv += r.d[2] * Interval(-h.z, h.z);
  return intersect(r.v, mv);
}

// Value and derivative of t ↦ f(o + t·d) enclosed over [ta, tb].
template <class Field>
Jet<Interval, 1> enclose_on_ray(const Field& f, glm::dvec3 o, glm::dvec3 d, double ta, double tb) {
  using J = Jet<Interval, 1>;
  Interval t(ta, tb);
  J x(Interval(o.x) + d.x * t, {Interval(d.x)});
  J y(Interval(o.y) + d.y * t, {Interval(d.y)});
  J z(Interval(o.z) + d.z * t, {Interval(d.z)});
  return f(x, y, z);
}

template <class Field>
Jet<double, 1> eval_on_ray(const Field& f, glm::dvec3 o, glm::dvec3 d, double t) {
  using J = Jet<double, 1>;
  J x(o.x + t * d.x, {d.x}), y(o.y + t * d.y, {d.y}), z(o.z + t * d.z, {d.z});
  return f(x, y, z);
}

// Converges on the single root in [a, b], where g = f − iso changes sign, with Newton steps that
// fall back to bisection whenever they leave the bracket.
template <class Field>
double converge(const Field& f, double iso, glm::dvec3 o, glm::dvec3 d, double a, double b,
                double ga, double gb, double tol) {
  if (gb == 0.0) return b;  // exactly at the end: return it exactly (the half-open rule needs it)
  double t = a - ga * (b - a) / (gb - ga);  // regula falsi start
  if (!(t > a && t < b)) t = 0.5 * (a + b);
  for (int iter = 0; iter < 64 && b - a > tol; ++iter) {
    Jet<double, 1> g = eval_on_ray(f, o, d, t);
    double gt = g.v - iso;
    if (gt == 0.0) return t;
    if (positive(gt) == positive(ga)) {
      a = t;
      ga = gt;
    } else {
      b = t;
    }
    double next = t - gt / g.d[0];
    if (!(next > a && next < b)) next = 0.5 * (a + b);
    if (std::abs(next - t) < tol) return next;
    t = next;
  }
  return t;
}

// Appends every root of f(o + t d) = iso with t in [t0, t1] to `hits` (unsorted).
template <class Field>
void find_roots(const Field& f, double iso, glm::dvec3 o, glm::dvec3 d, double t0, double t1,
                const RootSearchTolerances& tol, std::vector<RayHit>& hits) {
  struct Segment {
    double ta, tb, ga, gb;
  };
  // The hit at t with its unit normal.
  auto report = [&](double t) {
    hits.push_back({t, unit_normal(gradient(f, o + t * d), d), 0.0f});
  };
  Segment stack[128];
  int top = 0;
  stack[top++] = {t0, t1, value(f, o + t0 * d) - iso, value(f, o + t1 * d) - iso};
  // A root exactly at the start belongs to this segment (the caster's half-open rule drops one
  // exactly at a shared end); zero counts as positive below, so it is not found twice.
  if (stack[0].ga == 0.0) report(t0);
  while (top > 0) {
    const Segment s = stack[--top];
    const double w = s.tb - s.ta;
    const Jet<Interval, 1> e = enclose_on_ray(f, o, d, s.ta, s.tb);
    const Interval slope = e.d[0];
    // Mean value forms anchored at both ends bound g on the segment as well.
    const double rise = w * std::max(slope.hi, 0.0), fall = w * std::min(slope.lo, 0.0);
    const double lo = std::max({e.v.lo - iso, s.ga + fall, s.gb - rise});
    const double hi = std::min({e.v.hi - iso, s.ga + rise, s.gb - fall});
    if (lo > 0.0 || hi < 0.0) continue;
    const bool sign_change = positive(s.ga) != positive(s.gb);
    const bool monotone = slope.lo > 0.0 || slope.hi < 0.0;
    if (monotone || w < tol.min_width || top + 2 > int(std::size(stack))) {
      // Monotone: a sign change means exactly one root, none otherwise. Tiny: a sign change
      // means at least one root; a touching double root without sign change is dropped.
      if (sign_change) {
        report(converge(f, iso, o, d, s.ta, s.tb, s.ga, s.gb, tol.converged));
      }
      continue;
    }
    const double tm = 0.5 * (s.ta + s.tb);
    const double gm = value(f, o + tm * d) - iso;
    stack[top++] = {tm, s.tb, gm, s.gb};  // right half later, so hits come out in order
    stack[top++] = {s.ta, tm, s.ga, gm};
  }
}

// Clips the ray to the ball of radius R around the origin; returns false if it misses.
inline bool clip_to_ball(glm::dvec3 o, glm::dvec3 d, double R, double& t0, double& t1) {
  double b = glm::dot(o, d), c = glm::dot(o, o) - R * R;
  double disc = b * b - c;  // d is a unit vector
  if (disc <= 0.0) return false;
  double s = std::sqrt(disc);
  t0 = std::max(t0, -b - s);
  t1 = std::min(t1, -b + s);
  return t0 < t1;
}

}  // namespace analytic_detail

template <class Field>
class AnalyticBinding final : public GeometryBinding {
 public:
  struct Brick {
    glm::dvec3 lo, hi;
  };

  AnalyticBinding(RTCDevice device, const Field& field, double isovalue, double clip_radius,
                  RootSearchTolerances tol, std::vector<Brick> bricks)
      : field_(field),
        iso_(isovalue),
        clip_radius_(clip_radius),
        tol_(tol),
        bricks_(std::move(bricks)),
        geometry_(device, bricks_.size(), this, &AnalyticBinding::bounds,
                  &AnalyticBinding::intersect) {}

  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return bricks_.size(); }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const AnalyticBinding*>(args->geometryUserPtr);
    const Brick& b = self->bricks_[args->primID];
    write_padded_bounds(b.lo, b.hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const AnalyticBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    const Brick& b = self->bricks_[args->primID];
    double t0 = q->t_min, t1 = q->t_max;
    if (!clip_ray_to_box(q->org, q->dir, b.lo, b.hi, t0, t1)) return;
    if (self->clip_radius_ > 0.0 &&
        !analytic_detail::clip_to_ball(q->org, q->dir, self->clip_radius_, t0, t1))
      return;
    analytic_detail::find_roots(self->field_, self->iso_, q->org, q->dir, t0, t1, self->tol_,
                                *q->hits);
  }

  Field field_;
  double iso_;
  double clip_radius_;
  RootSearchTolerances tol_;
  std::vector<Brick> bricks_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

// An analytic field over a box, optionally clipped to the ball of radius clip_radius around the
// origin (0 = no clipping), split into bricks_per_axis³ bricks for culling.
template <class Field>
class AnalyticSource final : public FieldSource {
 public:
  AnalyticSource(Field field, Box domain, double clip_radius = 0.0, int bricks_per_axis = 32)
      : field_(field),
        domain_(domain),
        clip_radius_(clip_radius),
        bricks_per_axis_(bricks_per_axis) {
    if (!domain.is_valid()) throw std::invalid_argument("analytic source: empty domain box");
    if (bricks_per_axis < 1) throw std::invalid_argument("analytic source: bricks_per_axis < 1");
  }

  Box bounds() const override { return domain_; }
  const Field& field() const { return field_; }

  std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const override {
    using Brick = typename AnalyticBinding<Field>::Brick;
    const int n = bricks_per_axis_;
    // Brick faces come from one formula so that neighbours share them exactly.
    auto face = [&](int axis, int i) {
      return i == n ? domain_.hi[axis]
                    : domain_.lo[axis] + (domain_.hi[axis] - domain_.lo[axis]) * i / n;
    };
    std::vector<Brick> active;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          Brick b{{face(0, i), face(1, j), face(2, k)},
                  {face(0, i + 1), face(1, j + 1), face(2, k + 1)}};
          if (clip_radius_ > 0.0) {
            glm::dvec3 nearest = glm::clamp(glm::dvec3(0.0), b.lo, b.hi);
            if (glm::dot(nearest, nearest) > clip_radius_ * clip_radius_) continue;
          }
          if (analytic_detail::enclose(field_, b.lo, b.hi).contains(isovalue)) active.push_back(b);
        }
    const double scale = domain_.diagonal();
    RootSearchTolerances tol{1e-9 * scale, 1e-13 * scale};
    return std::make_unique<AnalyticBinding<Field>>(device, field_, isovalue, clip_radius_, tol,
                                                    std::move(active));
  }

 private:
  Field field_;
  Box domain_;
  double clip_radius_;
  int bricks_per_axis_;
};

}  // namespace ldimesh

#include "ldimesh/core/field/surfaces.hpp"

#include <array>
#include <stdexcept>
#include <string>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"

namespace ldimesh {
namespace {

Box cube(double h) {
  return {{-h, -h, -h}, {h, h, h}};
}

template <class Field>
std::unique_ptr<FieldSource> make(const SurfaceInfo& s, int bricks) {
  return std::make_unique<AnalyticSource<Field>>(Field{}, s.domain, s.clip_radius, bricks);
}

template <class Field>
double field(const glm::dvec3& p, glm::dvec3& gradient) {
  using J = Jet<double, 3>;
  const J f = Field{}(J(p.x, {1.0, 0.0, 0.0}), J(p.y, {0.0, 1.0, 0.0}), J(p.z, {0.0, 0.0, 1.0}));
  gradient = {f.d[0], f.d[1], f.d[2]};
  return f.v;
}

const std::array<SurfaceInfo, 6> kSurfaces{{
    {"sphere", "x^2 + y^2 + z^2 = 1", cube(1.25), 1.0, 0.0, &make<fields::Sphere>,
     &field<fields::Sphere>},
    {"torus",
     "(x^2 + y^2 + z^2 + R^2 - a^2)^2 - 4 R^2 (x^2 + y^2) = 0, R = 1, a = 0.4",
     {{-1.5, -1.5, -0.5}, {1.5, 1.5, 0.5}},
     0.0,
     0.0,
     &make<fields::Torus>,
     &field<fields::Torus>},
    {"barth",
     "4 (p^2 x^2 - y^2)(p^2 y^2 - z^2)(p^2 z^2 - x^2) - (1 + 2p)(x^2 + y^2 + z^2 - 1)^2 = 0, "
     "p = golden ratio, clipped to the ball of radius 2",
     cube(2.0), 0.0, 2.0, &make<fields::BarthSextic>, &field<fields::BarthSextic>},
    {"klein",
     "(x^2+y^2+z^2+2y-1)((x^2+y^2+z^2-2y-1)^2 - 8z^2) + 16xz(x^2+y^2+z^2-2y-1) = 0",
     {{-3.25, -2.75, -4.0}, {3.25, 3.25, 4.0}},
     0.0,
     0.0,
     &make<fields::KleinBottle>,
     &field<fields::KleinBottle>},
    {"marschner-lobb",
     "(1 - sin(pi z/2) + a (1 + cos(2 pi fM cos(pi r/2)))) / (2 (1 + a)) = 0.5, "
     "r = sqrt(x^2 + y^2), fM = 6, a = 0.25",
     cube(1.0), 0.5, 0.0, &make<fields::MarschnerLobb>, &field<fields::MarschnerLobb>},
    {"slices", "x^2 + y^2 + z^2 + sin(5x + 15y + 6z) - 1 = 0", cube(1.5), 0.0, 0.0,
     &make<fields::Slices>, &field<fields::Slices>},
}};

}  // namespace

std::span<const SurfaceInfo> builtin_surfaces() {
  return kSurfaces;
}

const SurfaceInfo* find_surface(std::string_view name) {
  for (const SurfaceInfo& s : kSurfaces)
    if (s.name == name) return &s;
  return nullptr;
}

std::unique_ptr<FieldSource> make_surface_source(std::string_view name, int bricks_per_axis) {
  const SurfaceInfo* s = find_surface(name);
  if (!s) throw std::invalid_argument("unknown surface '" + std::string(name) + "'");
  return s->make_source(*s, bricks_per_axis);
}

}  // namespace ldimesh

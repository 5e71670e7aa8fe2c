#include "ldimesh/core/base/view.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace ldimesh {

View make_view(const Box& domain, glm::dvec3 direction, int resolution) {
  if (resolution < 1) throw std::invalid_argument("view resolution must be at least 1");
  if (!domain.is_valid()) throw std::invalid_argument("view domain box is empty");
  const double len = glm::length(direction);
  if (!(len > 0.0) || !std::isfinite(len)) throw std::invalid_argument("view direction is zero");

  View view;
  view.dir = direction / len;
  // Axis directions get fixed frames so that axis views are exact (no rounding in u, v).
  const glm::dvec3 ex{1, 0, 0}, ey{0, 1, 0}, ez{0, 0, 1};
  if (view.dir == ex || view.dir == -ex) {
    view.u = ey;
  } else if (view.dir == ey || view.dir == -ey) {
    view.u = ez;
  } else if (view.dir == ez || view.dir == -ez) {
    view.u = ex;
  } else {
    const glm::dvec3 a = glm::abs(view.dir);
    const glm::dvec3 helper = (a.x <= a.y && a.x <= a.z) ? ex : (a.y <= a.z ? ey : ez);
    view.u = glm::normalize(glm::cross(helper, view.dir));
  }
  view.v = glm::cross(view.dir, view.u);  // u × v = dir

  glm::dvec3 lo(INFINITY), hi(-INFINITY);  // box corners in (u, v, depth) coordinates
  for (int c = 0; c < 8; ++c) {
    const glm::dvec3 p{c & 1 ? domain.hi.x : domain.lo.x, c & 2 ? domain.hi.y : domain.lo.y,
                       c & 4 ? domain.hi.z : domain.lo.z};
    const glm::dvec3 q{glm::dot(p, view.u), glm::dot(p, view.v), glm::dot(p, view.dir)};
    lo = glm::min(lo, q);
    hi = glm::max(hi, q);
  }
  const double eu = hi.x - lo.x, ev = hi.y - lo.y;
  view.spacing = std::max(eu, ev) / resolution;
  view.width = std::max(1, int(std::ceil(eu / view.spacing - 1e-9)));
  view.height = std::max(1, int(std::ceil(ev / view.spacing - 1e-9)));
  view.origin = lo.x * view.u + lo.y * view.v + lo.z * view.dir;
  view.depth_extent = hi.z - lo.z;
  return view;
}

std::vector<View> make_axis_views(const Box& domain, int resolution, std::string_view axes) {
  std::vector<View> views;
  std::string seen;
  for (char c : axes) {
    if (c != 'x' && c != 'y' && c != 'z')
      throw std::invalid_argument(std::string("unknown view axis '") + c + "' (use x, y, z)");
    if (seen.find(c) != std::string::npos)
      throw std::invalid_argument(std::string("view axis '") + c + "' given twice");
    seen += c;
    const glm::dvec3 dir{c == 'x', c == 'y', c == 'z'};
    views.push_back(make_view(domain, dir, resolution));
  }
  return views;
}

}  // namespace ldimesh

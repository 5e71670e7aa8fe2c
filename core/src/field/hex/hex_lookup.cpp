#include "ldimesh/core/field/hex_lookup.hpp"

#include "curved_element.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace ldimesh {
namespace {

// Points at most this far outside every element's cube (in ξ) take the nearest one's polynomial.
constexpr double kReach = 1e-3;
// The hinted element is taken without a search for points this far inside it (in ξ).
constexpr double kInterior = 1e-7;
// The grid has at most this many cells per axis, and about one element per cell.
constexpr int kMaxCells = 256;

Box element_box(const HexElementSource& source, std::size_t e) {
  Box box{glm::dvec3(std::numeric_limits<double>::infinity()),
          glm::dvec3(-std::numeric_limits<double>::infinity())};
  if (source.is_curved(e)) {
    // The convex hull property: the geometry's Bernstein coefficients hold the element.
    for (const glm::dvec3& c : source.curved_geometry(e)) {
      box.lo = glm::min(box.lo, c);
      box.hi = glm::max(box.hi, c);
    }
    return box;
  }
  const double* corners = source.corners_of(e);
  for (int c = 0; c < 8; ++c) {
    const glm::dvec3 x(corners[3 * c], corners[3 * c + 1], corners[3 * c + 2]);
    box.lo = glm::min(box.lo, x);
    box.hi = glm::max(box.hi, x);
  }
  return box;
}

// How far ξ lies outside the reference cube [0, 1]³ (negative inside: minus the distance to the
// nearest face; +∞ for NaN).
double miss(glm::dvec3 xi) {
  double m = -std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(xi[a])) return std::numeric_limits<double>::infinity();
    m = std::max({m, -xi[a], xi[a] - 1.0});
  }
  return m;
}

}  // namespace

HexFieldLookup::HexFieldLookup(std::span<const HexElementSource* const> sources) {
  std::vector<Box> boxes;
  bounds_ = {glm::dvec3(std::numeric_limits<double>::infinity()),
             glm::dvec3(-std::numeric_limits<double>::infinity())};
  for (const HexElementSource* source : sources) {
    const HexBlock& block = source->block();
    const std::size_t n = std::size_t(block.order + 1) * (block.order + 1) * (block.order + 1);
    for (std::size_t e = 0; e < block.element_count; ++e) {
      elements_.push_back({source, e, bernstein_.size(), block.order});
      bernstein_.resize(bernstein_.size() + n);
      source->element_bernstein(e,
                                std::span<double>(&bernstein_[elements_.back().coefficients], n));
      Box box = element_box(*source, e);
      bounds_.lo = glm::min(bounds_.lo, box.lo);
      bounds_.hi = glm::max(bounds_.hi, box.hi);
      boxes.push_back(box);
    }
  }
  if (elements_.empty()) throw std::invalid_argument("hex lookup: no elements");

  // About one element per cell, the cells as cubic as the bounds allow.
  const glm::dvec3 extent = glm::max(bounds_.hi - bounds_.lo, glm::dvec3(1e-300));
  const double volume = extent.x * extent.y * extent.z;
  const double side = std::max(std::cbrt(volume / double(elements_.size())), 1e-300);
  for (int a = 0; a < 3; ++a) {
    dims_[a] = int(std::clamp(std::ceil(extent[a] / side), 1.0, double(kMaxCells)));
    cell_size_[a] = extent[a] / dims_[a];
  }
  // Each element in every cell its box overlaps, widened by the reach of the extrapolation (a
  // step of kReach along each ξ moves a point of a map of degree q at most q·kReach of the
  // box's extent along each axis) and a little more for rounding.
  const std::size_t cells = std::size_t(dims_.x) * dims_.y * dims_.z;
  std::vector<std::uint32_t> count(cells + 1, 0);
  std::vector<std::pair<glm::ivec3, glm::ivec3>> ranges(elements_.size());
  boxes_.resize(elements_.size());
  for (std::size_t e = 0; e < elements_.size(); ++e) {
    const HexElementSource& source = *elements_[e].source;
    const int degree = source.is_curved(elements_[e].index) ? source.geometry_degree() : 1;
    const glm::dvec3 pad = 3.0 * degree * kReach * (boxes[e].hi - boxes[e].lo) + 1e-12 * extent;
    boxes_[e] = {boxes[e].lo - pad, boxes[e].hi + pad};
    const glm::dvec3 lo = (boxes_[e].lo - bounds_.lo) / cell_size_,
                     hi = (boxes_[e].hi - bounds_.lo) / cell_size_;
    glm::ivec3 a, b;
    for (int k = 0; k < 3; ++k) {
      a[k] = clamped_floor(lo[k], 0, dims_[k] - 1);
      b[k] = clamped_floor(hi[k], 0, dims_[k] - 1);
    }
    ranges[e] = {a, b};
    for (int z = a.z; z <= b.z; ++z)
      for (int y = a.y; y <= b.y; ++y)
        for (int x = a.x; x <= b.x; ++x)
          ++count[std::size_t(x) + dims_.x * (std::size_t(y) + std::size_t(dims_.y) * z) + 1];
  }
  for (std::size_t c = 0; c < cells; ++c)
    count[c + 1] += count[c];
  begin_ = count;
  items_.resize(begin_.back());
  for (std::size_t e = 0; e < elements_.size(); ++e) {
    const auto& [a, b] = ranges[e];
    for (int z = a.z; z <= b.z; ++z)
      for (int y = a.y; y <= b.y; ++y)
        for (int x = a.x; x <= b.x; ++x)
          items_[count[std::size_t(x) + dims_.x * (std::size_t(y) + std::size_t(dims_.y) * z)]++] =
              std::uint32_t(e);
  }
}

bool HexFieldLookup::sample(glm::dvec3 world, PolynomialSample& out) const {
  Hint hint;
  return sample(world, out, hint);
}

std::size_t HexFieldLookup::locate(glm::dvec3 world, Hint& hint, glm::dvec3& xi_out,
                                   double reach) const {
  const std::size_t none = elements_.size();
  if (!std::isfinite(world.x) || !std::isfinite(world.y) || !std::isfinite(world.z)) return none;
  const auto inside_box = [&](std::size_t e) {
    return glm::all(glm::greaterThanEqual(world, boxes_[e].lo)) &&
           glm::all(glm::lessThanEqual(world, boxes_[e].hi));
  };
  const auto reference = [&](std::size_t e) {
    return elements_[e].source->to_reference(elements_[e].index, world);
  };
  // The hinted element first. Well inside it (10⁻⁷ from its faces in ξ) the point lies in no
  // other element of a mesh whose elements do not overlap, and the search below takes such an
  // element as soon as it meets one: the same answer, whatever the hint.
  if (hint.element < elements_.size() && inside_box(hint.element)) {
    const glm::dvec3 xi = reference(hint.element);
    if (miss(xi) <= -kInterior) {
      xi_out = xi;
      return hint.element;
    }
  }
  glm::ivec3 c;
  for (int a = 0; a < 3; ++a) {
    const double u = (world[a] - bounds_.lo[a]) / cell_size_[a];
    // Well outside every element's box, or not a number.
    if (!(u >= -1.0 && u <= dims_[a] + 1.0)) return none;
    c[a] = clamped_floor(u, 0, dims_[a] - 1);
  }
  const std::size_t cell =
      std::size_t(c.x) + dims_.x * (std::size_t(c.y) + std::size_t(dims_.y) * c.z);
  // The first element the point lies well inside, else the one it misses least (on a face two
  // elements share, the one it is deeper in; the first of equals).
  std::size_t best = none;
  glm::dvec3 best_xi(0.0);
  double best_miss = std::nextafter(reach, 1.0);
  for (std::uint32_t k = begin_[cell]; k < begin_[cell + 1]; ++k) {
    const std::size_t e = items_[k];
    if (!inside_box(e)) continue;  // its inverse map is not worth computing
    const glm::dvec3 xi = reference(e);
    const double m = miss(xi);
    if (m < best_miss) {
      best = e;
      best_xi = xi;
      best_miss = m;
      if (m <= -kInterior) break;
    }
  }
  if (best == none) return none;
  hint.element = best;
  xi_out = best_xi;
  return best;
}

bool HexFieldLookup::sample(glm::dvec3 world, PolynomialSample& out, Hint& hint) const {
  glm::dvec3 xi;
  const std::size_t e = locate(world, hint, xi, kReach);
  return e < elements_.size() && evaluate(e, xi, out);
}

bool HexFieldLookup::value(glm::dvec3 world, double& out, Hint& hint, bool extrapolate) const {
  glm::dvec3 xi;
  // Without extrapolation: points in an element, up to the inverse map's rounding.
  const std::size_t e = locate(world, hint, xi, extrapolate ? kReach : 1e-9);
  if (e == elements_.size()) return false;
  const Element& el = elements_[e];
  const std::size_t n = std::size_t(el.order + 1) * (el.order + 1) * (el.order + 1);
  out = evaluate_bernstein(el.order, std::span<const double>(&bernstein_[el.coefficients], n), xi)
            .value;
  return std::isfinite(out);
}

std::function<double(const glm::dvec3&, glm::dvec3&)> HexFieldLookup::field() const {
  return [this](const glm::dvec3& p, glm::dvec3& gradient) {
    thread_local Hint hint;  // each thread's last element first: a projection's points move little
    PolynomialSample s;
    if (!sample(p, s, hint)) {
      gradient = glm::dvec3(std::numeric_limits<double>::quiet_NaN());
      return std::numeric_limits<double>::quiet_NaN();
    }
    gradient = s.gradient;
    return s.value;
  };
}

bool HexFieldLookup::evaluate(std::size_t element, glm::dvec3 xi, PolynomialSample& out) const {
  const Element& e = elements_[element];
  const std::size_t n = std::size_t(e.order + 1) * (e.order + 1) * (e.order + 1);
  const PolynomialSample s =
      evaluate_bernstein(e.order, std::span<const double>(&bernstein_[e.coefficients], n), xi);
  glm::dmat3 jacobian;  // columns ∂x/∂ξ_k
  if (e.source->is_curved(e.index)) {
    const curved::Element ce{e.order, e.source->geometry_degree(), nullptr,
                             e.source->curved_geometry(e.index).data()};
    jacobian = curved::evaluate(ce, xi).jacobian;
  } else {
    const glm::dvec3 o = e.source->to_world(e.index, glm::dvec3(0.0));
    for (int a = 0; a < 3; ++a) {
      glm::dvec3 unit(0.0);
      unit[a] = 1.0;
      jacobian[a] = e.source->to_world(e.index, unit) - o;
    }
  }
  const double det = glm::determinant(jacobian);
  if (!(std::abs(det) > 0.0) || !std::isfinite(det)) return false;
  out.value = s.value;
  out.gradient = glm::inverse(glm::transpose(jacobian)) * s.gradient;
  return std::isfinite(out.value) && std::isfinite(out.gradient.x) &&
         std::isfinite(out.gradient.y) && std::isfinite(out.gradient.z);
}

}  // namespace ldimesh

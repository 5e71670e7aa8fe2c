// The hexahedral family's internals shared by its Embree binding (hex_source.cpp) and its
// coherent axis caster (hex_axis.cpp): the active elements of a bind and the intersection of a
// ray with one of them, over the Bernstein toolkit (field/bernstein/).
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "../bernstein/basis.hpp"
#include "../bernstein/conversion.hpp"
#include "../bernstein/roots.hpp"
#include "../bernstein/segment.hpp"
#include "curved_element.hpp"
#include "ldimesh/core/field/axis_caster.hpp"
#include "ldimesh/core/field/field_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh::hex {

using namespace ldimesh::bernstein;

inline int nodes_per_element(int order) {
  return (order + 1) * (order + 1) * (order + 1);
}

inline void check_order(int order) {
  if (order < 1 || order > kMaxHexOrder)
    throw std::invalid_argument("hex source: order " + std::to_string(order) + " outside 1.." +
                                std::to_string(kMaxHexOrder));
}

// Enums cast from a host code's integers may hold anything; they index tables here.
inline void check_node_set(NodeSet nodes) {
  if (nodes != NodeSet::gauss_lobatto_legendre && nodes != NodeSet::gauss_legendre &&
      nodes != NodeSet::equispaced)
    throw std::invalid_argument("hex source: unknown node set " + std::to_string(int(nodes)));
}

// ---------------------------------------------------------------------------------------------
// The active elements of a bind: those whose coefficient range holds the isovalue.

// What the casters need of one active element.
struct ActiveElement {
  glm::dvec3 origin;               // corner 0 (affine elements)
  glm::dmat3 to_reference;         // inverse of the affine frame's axes (affine elements)
  glm::dvec3 lo, hi;               // axis-aligned bounds
  std::uint32_t curved = kAffine;  // a curved element's index in Activation::geometry
  static constexpr std::uint32_t kAffine = ~std::uint32_t(0);
};

struct Activation {
  int order = 1;
  std::size_t values_per_element = 0;
  std::vector<ActiveElement> elements;
  std::vector<double> coefficients;  // iso subtracted, values_per_element per active element
  std::uint64_t nonfinite = 0;
  // The curved active elements' geometry in Bernstein form, points_per_element each.
  int geometry_degree = 1;
  std::size_t points_per_element = 0;
  std::vector<glm::dvec3> geometry;
  const double* coefficients_of(std::size_t k) const {
    return &coefficients[k * values_per_element];
  }
  // Active element k as the curved intersection takes it (k must be curved).
  curved::Element curved_element(std::size_t k) const {
    return {order, geometry_degree, coefficients_of(k),
            &geometry[std::size_t(elements[k].curved) * points_per_element]};
  }
};

// The ray o + t·d clipped to affine element e: false if it misses, else [t0, t1] narrowed to
// the stretch inside and its ends a, b in reference coordinates. Both casters clip with it.
inline bool clip_to_element(const ActiveElement& e, glm::dvec3 org, glm::dvec3 dir, double& t0,
                            double& t1, glm::dvec3& a, glm::dvec3& b) {
  const glm::dvec3 ro = e.to_reference * (org - e.origin), rd = e.to_reference * dir;
  if (!clip_ray_to_box(ro, rd, glm::dvec3(0.0), glm::dvec3(1.0), t0, t1)) return false;
  a = glm::clamp(ro + t0 * rd, 0.0, 1.0), b = glm::clamp(ro + t1 * rd, 0.0, 1.0);
  return true;
}

// Every root in [t_min, t_max] of the ray o + t·d in element e (coefficients c), appended to
// `hits` with its normal: the ray in reference coordinates, clipped to the unit cube, the
// polynomial along the clipped segment, its roots by Bernstein subdivision. Both casters call
// this for a ray through an element (the coherent one where it has no shortcut).
template <int P>
void intersect_element(const ActiveElement& e, const double* c, glm::dvec3 org, glm::dvec3 dir,
                       double t_min, double t_max, std::vector<RayHit>& hits) {
  double t0 = t_min, t1 = t_max;
  glm::dvec3 a, b;
  if (!clip_to_element(e, org, dir, t0, t1, a, b)) return;

  double f[kMaxRayDegree + 1];
  const int degree = restrict_to_segment<P>(c, a, b, f);
  const glm::dmat3 to_world_gradient = glm::transpose(e.to_reference);  // ∇x f = A⁻ᵀ ∇ξ f
  with_degree<P>(degree, [&](auto n) {
    if constexpr (n > 0)  // else constant along the ray: no crossing
      bernstein_roots<n>(f, [&](double s) {
        const glm::dvec3 g = to_world_gradient * evaluate_tensor<P>(c, a + s * (b - a)).gradient;
        hits.push_back({segment_point(t0, t1, s), unit_normal(g, dir), 0.0f});
      });
  });
}

// The roots of active element k along a ray, whichever its geometry.
template <int P>
void intersect_active(const Activation& act, std::size_t k, glm::dvec3 org, glm::dvec3 dir,
                      double t_min, double t_max, std::vector<RayHit>& hits) {
  const ActiveElement& el = act.elements[k];
  if (el.curved != ActiveElement::kAffine)
    curved::intersect(act.curved_element(k), org, dir, t_min, t_max, hits);
  else
    intersect_element<P>(el, act.coefficients_of(k), org, dir, t_min, t_max, hits);
}

// The coherent caster of axis-parallel rays over the active elements (hex_axis.cpp).
std::unique_ptr<AxisCaster> make_axis_caster(Activation active);

}  // namespace ldimesh::hex

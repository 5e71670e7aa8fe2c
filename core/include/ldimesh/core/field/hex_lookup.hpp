// The piecewise-polynomial field of high-order hexahedra at world points: which element holds a
// point (a uniform grid over the elements' boxes, then each candidate's inverse map), and the
// field's value and world gradient there. It measures a mesh against the data's own isosurface
// — the polynomials', not an approximation of them (`ldimesh distance --vtu`, bench/evaluate's
// high-order section).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/field/hex_source.hpp"

namespace ldimesh {

class HexFieldLookup {
 public:
  // The elements of `sources` (they must outlive the lookup; their current values are read
  // here, once). Each element's box is its geometry's Bernstein hull (the corners of an affine
  // element), which holds the whole element. Throws std::invalid_argument without elements.
  explicit HexFieldLookup(std::span<const HexElementSource* const> sources);

  // The field and its world gradient ∇ₓf = J⁻ᵀ ∇ξf at `world`, from the first element (in
  // source and element order) whose reference cube holds the point at least 10⁻⁷ from its
  // faces (in ξ), else from the element the point misses least: the one it is deeper in on a
  // face two elements share, the nearest one — extrapolated — for a point at most 10⁻³
  // outside every element (so that a projection onto an isosurface that meets the mesh's
  // boundary converges). False beyond that, or where an element's inverse map does not
  // converge or its Jacobian is singular. Reentrant.
  bool sample(glm::dvec3 world, PolynomialSample& out) const;
  // The same, trying the element of `hint` first and leaving the element used there: a caller
  // whose points move little (a projection's steps) skips the search. The answer is the one
  // without a hint (the hinted element is taken only for points well inside it, which no other
  // element holds in a mesh whose elements do not overlap). Start from Hint{}.
  struct Hint {
    std::size_t element = ~std::size_t(0);
  };
  bool sample(glm::dvec3 world, PolynomialSample& out, Hint& hint) const;
  // The field's value alone, from the element sample() takes (false where it has none, or the
  // value is not finite): the colour of a hit (ScalarProbe), which needs no gradient. Without
  // `extrapolate`, only from an element that holds the point (within 10⁻⁹ in ξ).
  bool value(glm::dvec3 world, double& out, Hint& hint, bool extrapolate = true) const;

  // sample() as a field for ImplicitSurface (core/metrics/distance.hpp): the value, or NaN
  // (and a NaN gradient) where there is none; each calling thread keeps its own hint. The
  // lookup must outlive it.
  std::function<double(const glm::dvec3&, glm::dvec3&)> field() const;

  Box bounds() const { return bounds_; }
  std::size_t element_count() const { return elements_.size(); }

 private:
  bool evaluate(std::size_t element, glm::dvec3 xi, PolynomialSample& out) const;
  // The element sample() takes for `world` (missed by at most `reach` in ξ) and the point's
  // reference coordinates in it (`hint` updated); element_count() where there is none.
  std::size_t locate(glm::dvec3 world, Hint& hint, glm::dvec3& xi, double reach) const;

  struct Element {
    const HexElementSource* source;
    std::size_t index;         // in its source
    std::size_t coefficients;  // offset into bernstein_
    int order;
  };
  std::vector<Element> elements_;
  std::vector<Box> boxes_;         // per element, widened by the extrapolation's reach
  std::vector<double> bernstein_;  // the field's coefficients, element after element
  Box bounds_;
  // The grid: dims_ cells over bounds_, cell c's elements in items_[begin_[c] .. begin_[c + 1]).
  glm::ivec3 dims_{1};
  glm::dvec3 cell_size_{1.0};
  std::vector<std::uint32_t> begin_, items_;
};

}  // namespace ldimesh

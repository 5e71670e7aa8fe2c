// All intersections of a ray with the isosurface of a curved (non-affine) hexahedral element:
// geometry x(ξ) and field f(ξ) both tensor-product polynomials in Bernstein form on the
// reference cube [0, 1]³ (degrees q and p per axis). Internal to the element source.
//
// A hit is a solution ξ of the system H(ξ) = (n₁·(x(ξ) − o), n₂·(x(ξ) − o), f(ξ)) = 0, with
// n₁, n₂ ⊥ d (the ray is the intersection of two planes), and its depth t = d·(x(ξ) − o) / |d|².
// The reference cube is subdivided. On each box the system is preconditioned, G = Y H with Y the
// inverse of H's Jacobian at the box's centre; a box is dropped when one component's or one of
// G's Bernstein ranges has one strict sign (the convex hull property: no zero there), its depth
// range misses [t0, t1], or the Krawczyk operator of G misses it; a box that the operator maps
// into itself, or on which G is one-to-one (∂G/∂s within 1 of the identity) and Newton's method
// converges inside, holds exactly that one solution; otherwise the box is split in half along
// the axis along which G is furthest from linear. docs/method.md ("Curved elements") gives the
// guarantees and tolerances.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "ldimesh/core/field/axis_caster.hpp"

namespace ldimesh::curved {

// The Bernstein coefficients of one element, (n + 1)³ per tensor, index i + (n+1)(j + (n+1)k)
// along ξ, η, ζ; geometry as (x, y, z) per coefficient.
struct Element {
  int p = 1;                             // the field's degree per axis
  int q = 1;                             // the geometry's degree per axis
  const double* field = nullptr;         // (p + 1)³, isovalue subtracted
  const glm::dvec3* geometry = nullptr;  // (q + 1)³
};

// A ray o + t·d of a batch (their common d given beside), t ∈ [t0, t1] (closed), and the index
// its hits are reported with.
struct RayRef {
  std::uint32_t index = 0;
  glm::dvec3 org{0.0};
  double t0 = 0.0, t1 = 0.0;
};

// The search runs in a copy compiled for AVX2 where the processor has it (x86-64), else in the
// baseline one; both do the same operations in the same order, so they give the same bits.
// prefer_avx2(false) switches to the baseline copy (for tests; not while a search runs),
// prefer_avx2(true) back. Returns whether the AVX2 copy is used now.
bool prefer_avx2(bool prefer);

// Appends every hit of the ray o + t·d (d of any length), t ∈ [t0, t1] (closed), with element e to
// `hits`, in increasing t, with the unit normal ∇ₓf/|∇ₓf| (towards −d where the gradient vanishes).
void intersect(const Element& e, glm::dvec3 o, glm::dvec3 d, double t0, double t1,
               std::vector<RayHit>& hits);

// The boxes of an element's reference cube, down to a width, on which the field's Bernstein
// coefficients do not rule out the isovalue, with the geometry's and the field's coefficients
// on each: the first levels of the search, the same for every ray, found once per element.
// A ray meets the isosurface only in the pieces; roots on a face two pieces share come from
// both (the caster merges them).
struct Piece {
  glm::dvec3 lo, hi;              // in ξ
  glm::dvec3 world_lo, world_hi;  // the axis-aligned box around its geometry
};
class Pieces {
 public:
  Pieces(const Element& e, double width);
  const std::vector<Piece>& pieces() const { return pieces_; }
  // intersect() for the part of the element in piece k, for many rays of one direction at once
  // (the pixel rays through the piece): the search's boxes, their coefficients and their
  // Jacobians are shared by the rays, each ray's hits the same as its own search's (up to
  // rounding in the planes' offsets), reported with its index, per ray in increasing t. The
  // pieces hold all they need of the element.
  void intersect(std::size_t k, std::span<const RayRef> rays, glm::dvec3 d, AxisHits& hits) const;

 private:
  int degree_ = 1;             // max(p, q): the lower of the two raised to it
  int size_ = 0;               // (degree_ + 1)³
  double field_margin_ = 0.0;  // the sign tests' margin, from the whole element's field
  std::vector<Piece> pieces_;
  std::vector<double> coefficients_;  // per piece: size_ quads (x, y, z, f)
};

// x(ξ), the Jacobian ∂x/∂ξ (columns ∂x/∂ξ_k) and f(ξ), ∇ξf at a reference point (f and
// ∇ξf zero where the element has no field).
struct Sample {
  glm::dvec3 x{0.0};
  glm::dmat3 jacobian{0.0};
  double f = 0.0;
  glm::dvec3 gradient{0.0};
};
Sample evaluate(const Element& e, glm::dvec3 xi);

// The reference point ξ where x(ξ) = world, by Newton's method from the element's centre;
// false when it does not converge (the point is far outside the element, or the map folds).
bool invert(const Element& e, glm::dvec3 world, glm::dvec3& xi);

}  // namespace ldimesh::curved

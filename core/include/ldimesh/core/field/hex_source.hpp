// High-order hexahedral elements (DG, spectral-element and FEM data) as ray-caster sources.
//
// Each element's nodal (Lagrange) values are converted to tensor-product Bernstein coefficients.
// By the convex hull property of the Bernstein basis the coefficients bound the element's values,
// so only elements whose coefficient range contains the isovalue become Embree primitives. Along a
// ray the polynomial restricted to an element is univariate of degree 3p; its Bernstein
// coefficients are computed exactly and its roots are isolated by subdivision with sign-variation
// counting (Descartes' rule of signs in the Bernstein basis: Lane & Riesenfeld 1981, Mørken &
// Reimers 2007), then converged with Newton steps safeguarded by bisection. No fixed step: a root
// is never skipped, however close to its neighbours.
//
// Geometry: 8 corners per element (the trilinear map; parallelepipeds keep the affine fast path)
// or nodes of its own order q (HexBlock::geometry_order, curved elements: their intersection
// subdivides the reference cube and converges by Newton on (ξ, t), docs/method.md); nodes in
// lexicographic or VTK Lagrange order. The constructor refuses an inverted or degenerate element
// (std::invalid_argument naming it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "ldimesh/core/field/blocks.hpp"
#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh {

// A polynomial's value and gradient at one point.
struct PolynomialSample {
  double value = 0.0;
  glm::dvec3 gradient{0.0};
};

// The p + 1 node positions of `nodes` for order p, increasing, on the reference interval [0, 1]
// (the usual [−1, 1] nodes mapped by x ↦ (x + 1)/2). Throws std::invalid_argument unless
// 1 ≤ order ≤ kMaxHexOrder.
std::vector<double> node_positions(int order, NodeSet nodes);

// The position of node (i, j, k) (0..order along ξ, η, ζ) of an element of `order` in VTK's
// Lagrange hexahedron order (VTK_LAGRANGE_HEXAHEDRON, as deal.II's DataOut writes high-order
// cells): the corners (0,0,0), (p,0,0), (p,p,0), (0,p,0), then the same at ζ = p; the edges'
// interior nodes (along ξ at η = 0, along η at ξ = p, along ξ at η = p, along η at ξ = 0 — at
// ζ = 0, then at ζ = p — then along ζ at (0,0), (p,0), (p,p), (0,p)), each in increasing
// parameter; the faces' interior nodes (ξ = 0, ξ = p with η fastest; η = 0, η = p with ξ
// fastest; ζ = 0, ζ = p with ξ fastest); then the interior, ξ fastest. Throws
// std::invalid_argument for an order outside 1..kMaxHexOrder or a node outside the element.
std::size_t vtk_lagrange_index(int i, int j, int k, int order);

// Converts the (p + 1)³ nodal values of one element (layout as in HexBlock) into the (p + 1)³
// tensor-product Bernstein coefficients on [0, 1]³ of the same polynomial, same layout. Both
// spans must hold exactly (p + 1)³ values and must not overlap; throws std::invalid_argument
// otherwise or for an order outside 1..kMaxHexOrder. Reentrant.
void lagrange_to_bernstein(int order, NodeSet nodes, std::span<const double> nodal,
                           std::span<double> bernstein);

// Value and reference-space gradient (∂/∂ξ, ∂/∂η, ∂/∂ζ) at `reference` of the polynomial with
// the (p + 1)³ tensor-product Bernstein coefficients `bernstein`. Any reference point works;
// the element is [0, 1]³. Throws std::invalid_argument for a wrong span size or order.
PolynomialSample evaluate_bernstein(int order, std::span<const double> bernstein,
                                    glm::dvec3 reference);

// A block of high-order hexahedra as a ray-caster source. Roots that lie on a face shared by two
// elements are found by both and merged by the caster; data discontinuous across faces (DG) is
// intersected element by element.
class HexElementSource final : public FieldSource {
 public:
  // Checks the block, converts each element's geometry and computes its bounds. Throws
  // std::invalid_argument for an order or geometry order outside its range, an unknown node set
  // or scalar type, no elements, a null array, an element stride below (p + 1)³, and for the
  // first element (named by index) with a non-finite geometry node or that is degenerate or
  // inverted (an affine one of zero volume; a curved one whose Jacobian determinant vanishes or
  // changes sign). Elements whose map is not affine (trilinear or of geometry order q) are
  // intersected by the curved search (docs/method.md). The corners or geometry nodes are read
  // here only: the source keeps what it needs of them (every element's 8 corners, 24 doubles,
  // and a curved element's geometry in Bernstein form), shared with the sources made from it.
  // The value arrays must outlive the source and may change: every bind() reads them.
  explicit HexElementSource(const HexBlock& block) : HexElementSource(block, false) {}
  // The same for elements whose top face (ζ = 1) is collapsed to one point when `top_collapsed`
  // (pyramids, as CellElementSource gives them: cell_source.hpp): the Jacobian determinant may
  // vanish on that face, and only there.
  HexElementSource(const HexBlock& block, bool top_collapsed);
  // A source over `block`, whose geometry is that of `prepared`'s block, with its own values
  // (the adaptor's snapshot of a block at each due step): the geometry as `prepared` prepared
  // it (its Bernstein form, bounds and checks, for curved elements most of the constructor's
  // time) is shared, not copied; `block`'s geometry arrays are not read (they may be null),
  // only its layout: throws std::invalid_argument where the order, node set, ordering, element
  // count or geometry order differ, or for a null value array or an element stride below
  // (p + 1)³.
  HexElementSource(const HexElementSource& prepared, const HexBlock& block);
  // The same, over a copy of only some elements' values (the adaptor's snapshot of what a cast
  // reads): `held` has a flag per element and must mark at least the elements
  // needed_elements() names for every isovalue bound; the values of the others may be anything,
  // bind() and bind_axis() do not read them (the colour field, bind_scalar, is read whole). It
  // casts what a source over all values casts. Also throws std::invalid_argument for a mask of
  // the wrong size.
  HexElementSource(const HexElementSource& prepared, const HexBlock& block,
                   std::vector<std::uint8_t> held);

  // The axis-aligned box around all elements.
  Box bounds() const override;
  // Reads the current values, converts every element to Bernstein form (in parallel) and keeps
  // the elements whose coefficient range contains `isovalue`. The binding holds its own copy of
  // their coefficients: it does not read the solver's arrays after bind() returns.
  //
  // Non-finite values (NaN, ±Inf): an element with such a nodal value produces no hits (it is
  // left out of the scene); the other elements are unaffected. The binding's
  // nonfinite_values() is the number of non-finite nodal values over all elements (the
  // (p + 1)³ values of each; padding up to element_stride is not read).
  std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const override;
  // The same active elements for rays parallel to an axis: object order over the pixels each
  // element covers (the same roots as bind()).
  std::unique_ptr<AxisCaster> bind_axis(double isovalue) const override;
  // The block's colour field (HexBlock::colour): its nodal values read now, each hit's value from
  // the element that holds it (HexFieldLookup); null without one.
  std::unique_ptr<ScalarProbe> bind_scalar() const override;

  // Threads: see field_source.hpp; to_reference and element_bernstein are const and reentrant.

  // Per element: whether bind() or bind_axis() for one of `isovalues` keeps it or finds a NaN
  // or ±Inf among its values. Reads the values in place and converts every element to
  // Bernstein form (as bind() does), on all cores.
  std::vector<std::uint8_t> needed_elements(std::span<const double> isovalues) const;
  // The held mask (empty: every element's values are there).
  std::span<const std::uint8_t> held() const {
    return held_ ? std::span<const std::uint8_t>(*held_) : std::span<const std::uint8_t>();
  }

  // The block as given, with element_stride 0 replaced by (p + 1)³.
  const HexBlock& block() const { return block_; }
  // Reference coordinates in element `element` of the world point `world` (inside the element
  // iff all three lie in [0, 1]). `element` must be below block().element_count.
  // For a curved element: by Newton's method from the element's centre; NaN where it does not
  // converge (a point far outside the element).
  glm::dvec3 to_reference(std::size_t element, glm::dvec3 world) const;
  // The world point of reference point `reference` of element `element` (below
  // block().element_count, not checked).
  glm::dvec3 to_world(std::size_t element, glm::dvec3 reference) const;
  // The Bernstein coefficients of element `element` from the current values (see
  // lagrange_to_bernstein; `out` holds exactly (p + 1)³ values, else std::invalid_argument;
  // `element` must be below block().element_count, not checked). Minimum and maximum bound the
  // element's values; bind() culls with them. A non-finite nodal value makes some
  // coefficients non-finite.
  void element_bernstein(std::size_t element, std::span<double> out) const;

  // The 8 corners × (x, y, z) of element `element` (the geometry's vertices when the block gives
  // geometry nodes).
  const double* corners_of(std::size_t element) const;
  // Whether element `element` is curved (its map from the reference cube is not affine).
  bool is_curved(std::size_t element) const { return geometry_->curved_of[element] != kNotCurved; }
  // The geometry's degree per axis: geometry_order, or 1 for a block of corners.
  int geometry_degree() const { return geometry_degree_; }
  // The Bernstein coefficients of a curved element's geometry, (q + 1)³ points in the values'
  // layout (empty for an affine element).
  std::span<const glm::dvec3> curved_geometry(std::size_t element) const;

 private:
  static constexpr std::uint32_t kNotCurved = ~std::uint32_t(0);
  void check_jacobian(std::size_t element, const std::vector<glm::dvec3>& x,
                      bool top_collapsed) const;

  HexBlock block_;
  Box bounds_;
  int geometry_degree_ = 1;
  // The geometry as prepared by the constructor, shared by the sources made from this one.
  struct Prepared {
    std::vector<double> corners;           // 24 per element: the block's, or the vertices
    std::vector<glm::dvec3> curved;        // (q + 1)³ per curved element, Bernstein form
    std::vector<std::uint32_t> curved_of;  // per element: its index among the curved ones
  };
  std::shared_ptr<const Prepared> geometry_;
  std::shared_ptr<const std::vector<std::uint8_t>> held_;  // null: every element's values
};

}  // namespace ldimesh

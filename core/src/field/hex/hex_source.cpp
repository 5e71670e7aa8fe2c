#include "ldimesh/core/field/hex_source.hpp"

#include "../colour_block.hpp"
#include "hex_internal.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "ldimesh/core/field/hex_lookup.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace ldimesh {

using namespace ldimesh::hex;

namespace {

// Copies the (p + 1)³ = n nodal values of `element` as doubles into `nodal`; returns how many
// are NaN or ±Inf.
// vtk_lagrange_index without the checks.
std::size_t vtk_index(int i, int j, int k, int p) {
  const bool ib = i == 0 || i == p, jb = j == 0 || j == p, kb = k == 0 || k == p;
  const int bounds = int(ib) + int(jb) + int(kb), e = p - 1;
  if (bounds == 3) return std::size_t((j == 0 ? (i == p) : (i == p ? 2 : 3)) + (k == p ? 4 : 0));
  if (bounds == 2) {
    int edge, t;
    if (!ib)
      edge = (j == 0 ? 0 : 2) + (k == p ? 4 : 0), t = i;
    else if (!jb)
      edge = (i == 0 ? 3 : 1) + (k == p ? 4 : 0), t = j;
    else
      edge = 8 + (i == 0 ? (j == 0 ? 0 : 3) : (j == 0 ? 1 : 2)), t = k;
    return std::size_t(8 + edge * e + t - 1);
  }
  if (bounds == 1) {
    int face, a, b;
    if (ib)
      face = i == 0 ? 0 : 1, a = j, b = k;
    else if (jb)
      face = j == 0 ? 2 : 3, a = i, b = k;
    else
      face = k == 0 ? 4 : 5, a = i, b = j;
    return std::size_t(8 + 12 * e + face * e * e + (a - 1) + e * (b - 1));
  }
  return std::size_t(8 + 12 * e + 6 * e * e + (i - 1) + e * ((j - 1) + e * (k - 1)));
}

// For each order, the position in the solver's array of the element's lexicographic node m.
const std::vector<std::uint16_t>& node_permutation(int order, NodeOrdering ordering) {
  static const auto tables = [] {
    std::array<std::array<std::vector<std::uint16_t>, 2>, kMaxHexOrder + 1> t;
    for (int p = 1; p <= kMaxHexOrder; ++p)
      for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
          for (int i = 0; i <= p; ++i) {
            t[p][0].push_back(std::uint16_t(i + (p + 1) * (j + (p + 1) * k)));
            t[p][1].push_back(std::uint16_t(vtk_index(i, j, k, p)));
          }
    return t;
  }();
  return tables[order][ordering == NodeOrdering::vtk_lagrange ? 1 : 0];
}

std::size_t read_nodal(const HexBlock& block, std::size_t element, std::size_t n, double* nodal) {
  const std::size_t first = element * block.element_stride;
  // One branch per element on the scalar type and the ordering, none per value.
  const auto read = [&](const auto* values) {
    if (block.ordering == NodeOrdering::lexicographic) {
      std::copy_n(values + first, n, nodal);
      return;
    }
    const std::vector<std::uint16_t>& at = node_permutation(block.order, block.ordering);
    for (std::size_t m = 0; m < n; ++m)
      nodal[m] = double(values[first + at[m]]);
  };
  if (block.type == ScalarType::float32)
    read(static_cast<const float*>(block.values));
  else
    read(static_cast<const double*>(block.values));
  std::size_t nonfinite = 0;
  for (std::size_t i = 0; i < n; ++i)
    nonfinite += !std::isfinite(nodal[i]);
  return nonfinite;
}

// ---------------------------------------------------------------------------------------------
// Element geometry

// x = origin + axes · ξ for ξ ∈ [0, 1]³ (axes' columns are the edges from corner 0).
struct AffineFrame {
  glm::dvec3 origin;
  glm::dmat3 axes;
};

glm::dvec3 corner(const double* corners, int c) {
  return {corners[3 * c], corners[3 * c + 1], corners[3 * c + 2]};
}

AffineFrame frame_of(const double* corners) {
  const glm::dvec3 o = corner(corners, 0);
  return {o, glm::dmat3(corner(corners, 1) - o, corner(corners, 2) - o, corner(corners, 4) - o)};
}

// The axis-aligned box around the parallelepiped.
Box bounding_box(const AffineFrame& f) {
  Box box{f.origin, f.origin};
  for (int edge = 0; edge < 3; ++edge) {
    box.lo += glm::min(f.axes[edge], 0.0);
    box.hi += glm::max(f.axes[edge], 0.0);
  }
  return box;
}

// ---------------------------------------------------------------------------------------------
// The Embree binding

class HexBinding final : public GeometryBinding {
 public:
  HexBinding(RTCDevice device, Activation active)
      : active_(std::move(active)),
        geometry_(device, active_.elements.size(), this, &HexBinding::bounds,
                  &HexBinding::intersect) {}

  RTCGeometry geometry() const override { return geometry_.get(); }
  std::size_t primitive_count() const override { return active_.elements.size(); }
  std::uint64_t nonfinite_values() const override { return active_.nonfinite; }

 private:
  static void bounds(const RTCBoundsFunctionArguments* args) {
    const auto* self = static_cast<const HexBinding*>(args->geometryUserPtr);
    const ActiveElement& e = self->active_.elements[args->primID];
    write_padded_bounds(e.lo, e.hi, args->bounds_o);
  }

  static void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* self = static_cast<const HexBinding*>(args->geometryUserPtr);
    auto* q = reinterpret_cast<RayQuery*>(args->context);
    const Activation& act = self->active_;
    with_order(act.order, [&](auto p) {
      intersect_active<p>(act, args->primID, q->org, q->dir, q->t_min, q->t_max, *q->hits);
    });
  }

  Activation active_;
  UserGeometry geometry_;  // last: its callbacks read the members above
};

}  // namespace

std::size_t vtk_lagrange_index(int i, int j, int k, int order) {
  check_order(order);
  if (std::min({i, j, k}) < 0 || std::max({i, j, k}) > order)
    throw std::invalid_argument("vtk_lagrange_index: node (" + std::to_string(i) + ", " +
                                std::to_string(j) + ", " + std::to_string(k) +
                                ") outside an element of order " + std::to_string(order));
  return vtk_index(i, j, k, order);
}

std::vector<double> node_positions(int order, NodeSet nodes) {
  check_order(order);
  check_node_set(nodes);
  std::vector<double> x = nodes_on_symmetric_interval(order, nodes);
  for (double& v : x)
    v = 0.5 * (v + 1.0);
  return x;
}

void lagrange_to_bernstein(int order, NodeSet nodes, std::span<const double> nodal,
                           std::span<double> bernstein) {
  check_order(order);
  check_node_set(nodes);
  const std::size_t n = nodes_per_element(order);
  if (nodal.size() != n || bernstein.size() != n)
    throw std::invalid_argument("lagrange_to_bernstein: spans must hold (order + 1)^3 values");
  if (std::less<const double*>()(nodal.data(), bernstein.data() + n) &&
      std::less<const double*>()(bernstein.data(), nodal.data() + n))
    throw std::invalid_argument("lagrange_to_bernstein: the spans overlap");
  convert_element(order, conversion_matrix(order, nodes), nodal.data(), bernstein.data());
}

PolynomialSample evaluate_bernstein(int order, std::span<const double> bernstein,
                                    glm::dvec3 reference) {
  check_order(order);
  if (bernstein.size() != std::size_t(nodes_per_element(order)))
    throw std::invalid_argument("evaluate_bernstein: span must hold (order + 1)^3 values");
  return with_order(order, [&](auto p) { return evaluate_tensor<p>(bernstein.data(), reference); });
}

namespace {

// The value and colour arrays' element types.
void check_scalar_types(const HexBlock& block) {
  const auto known = [](ScalarType t) {
    return t == ScalarType::float32 || t == ScalarType::float64;
  };
  if (!known(block.type)) throw std::invalid_argument("hex source: unknown scalar type");
  if (block.colour && !known(block.colour_type))
    throw std::invalid_argument("hex source: unknown scalar type of the colour field");
}

}  // namespace

HexElementSource::HexElementSource(const HexBlock& block, bool top_collapsed) : block_(block) {
  check_order(block.order);
  check_node_set(block.nodes);
  const std::size_t n = nodes_per_element(block.order);
  const int q = block.geometry_order;
  if (block.element_count == 0) throw std::invalid_argument("hex source: no elements");
  if (q < 0 || q > kMaxHexOrder)
    throw std::invalid_argument("hex source: geometry order " + std::to_string(q) + " outside 0.." +
                                std::to_string(kMaxHexOrder));
  if (q > 0 && !block.geometry) throw std::invalid_argument("hex source: null geometry array");
  if (q == 0 && !block.corners) throw std::invalid_argument("hex source: null corner array");
  if (!block.values) throw std::invalid_argument("hex source: null value array");
  if (block.ordering != NodeOrdering::lexicographic && block.ordering != NodeOrdering::vtk_lagrange)
    throw std::invalid_argument("hex source: unknown node ordering");
  check_scalar_types(block);
  if (block_.element_stride == 0) block_.element_stride = n;
  if (block_.element_stride < n)
    throw std::invalid_argument("hex source: element stride " +
                                std::to_string(block_.element_stride) +
                                " below (order + 1)^3 = " + std::to_string(n));

  // Each element's geometry in Bernstein form (degree q, or 1 for corners: a trilinear map's
  // Bernstein coefficients are its corners); affine ones keep the parallelepiped path, the
  // others are kept for the curved intersection.
  geometry_degree_ = q > 0 ? q : 1;
  const int gm = geometry_degree_ + 1;
  const std::size_t gn = std::size_t(gm) * gm * gm;
  const auto prepared = std::make_shared<Prepared>();
  geometry_ = prepared;
  prepared->corners.resize(24 * block.element_count);
  prepared->curved_of.assign(block.element_count, kNotCurved);
  std::vector<glm::dvec3> x(gn);
  std::vector<double> nodal(gn), bernstein(gn);
  constexpr double inf = std::numeric_limits<double>::infinity();
  bounds_ = {glm::dvec3(inf), glm::dvec3(-inf)};
  const auto vertex = [&](int c) {
    return std::size_t((c & 1) * geometry_degree_) +
           std::size_t(gm) * (std::size_t(((c >> 1) & 1) * geometry_degree_) +
                              std::size_t(gm) * std::size_t(((c >> 2) & 1) * geometry_degree_));
  };
  for (std::size_t e = 0; e < block.element_count; ++e) {
    if (q > 0) {
      const double* nodes = block.geometry + 3 * gn * e;
      const std::vector<std::uint16_t>& at = node_permutation(q, block.ordering);
      for (int axis = 0; axis < 3; ++axis) {
        for (std::size_t m = 0; m < gn; ++m)
          nodal[m] = nodes[3 * at[m] + axis];
        convert_element(q, conversion_matrix(q, block.nodes), nodal.data(), bernstein.data());
        for (std::size_t m = 0; m < gn; ++m)
          x[m][axis] = bernstein[m];
      }
      for (int c = 0; c < 8; ++c)
        for (int axis = 0; axis < 3; ++axis)
          prepared->corners[24 * e + 3 * c + axis] = x[vertex(c)][axis];
    } else {
      std::copy_n(block.corners + 24 * e, 24, &prepared->corners[24 * e]);
      for (int c = 0; c < 8; ++c)
        x[c] = corner(block.corners + 24 * e, c);
    }
    for (const glm::dvec3& v : x)
      if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
        throw std::invalid_argument("hex source: element " + std::to_string(e) +
                                    " has a non-finite geometry node");
    const AffineFrame f = frame_of(corners_of(e));
    const glm::dvec3 e1 = f.axes[0], e2 = f.axes[1], e3 = f.axes[2];
    const double size = glm::length(e1) + glm::length(e2) + glm::length(e3);
    bool affine = true;
    for (int k = 0; k < gm && affine; ++k)
      for (int j = 0; j < gm && affine; ++j)
        for (int i = 0; i < gm && affine; ++i) {
          const glm::dvec3 a = f.origin + (double(i) / geometry_degree_) * e1 +
                               (double(j) / geometry_degree_) * e2 +
                               (double(k) / geometry_degree_) * e3;
          affine = glm::length(x[i + gm * (j + gm * k)] - a) <= 1e-9 * size;
        }
    Box box;
    if (affine) {
      if (!(std::abs(glm::determinant(f.axes)) >
            1e-12 * glm::length(e1) * glm::length(e2) * glm::length(e3)))
        throw std::invalid_argument("hex source: element " + std::to_string(e) +
                                    " is degenerate (zero volume)");
      box = bounding_box(f);
    } else {
      check_jacobian(e, x, top_collapsed);
      prepared->curved_of[e] = std::uint32_t(prepared->curved.size() / gn);
      prepared->curved.insert(prepared->curved.end(), x.begin(), x.end());
      box = {x[0], x[0]};
      for (const glm::dvec3& v : x)  // the convex hull property
        box.lo = glm::min(box.lo, v), box.hi = glm::max(box.hi, v);
    }
    bounds_.lo = glm::min(bounds_.lo, box.lo);
    bounds_.hi = glm::max(bounds_.hi, box.hi);
  }
}

HexElementSource::HexElementSource(const HexElementSource& prepared, const HexBlock& block)
    : block_(block),
      bounds_(prepared.bounds_),
      geometry_degree_(prepared.geometry_degree_),
      geometry_(prepared.geometry_) {
  const HexBlock& p = prepared.block_;
  if (block.order != p.order || block.nodes != p.nodes || block.ordering != p.ordering ||
      block.element_count != p.element_count || block.geometry_order != p.geometry_order)
    throw std::invalid_argument(
        "hex source: the block's layout (order, node set, ordering, element count, geometry "
        "order) differs from the prepared source's");
  if (!block.values) throw std::invalid_argument("hex source: null value array");
  check_scalar_types(block);
  const std::size_t n = nodes_per_element(block.order);
  if (block_.element_stride == 0) block_.element_stride = n;
  if (block_.element_stride < n)
    throw std::invalid_argument("hex source: element stride " +
                                std::to_string(block_.element_stride) +
                                " below (order + 1)^3 = " + std::to_string(n));
}

HexElementSource::HexElementSource(const HexElementSource& prepared, const HexBlock& block,
                                   std::vector<std::uint8_t> held)
    : HexElementSource(prepared, block) {
  if (held.size() != block_.element_count)
    throw std::invalid_argument("hex source: " + std::to_string(held.size()) +
                                " element flags for " + std::to_string(block_.element_count) +
                                " elements");
  held_ = std::make_shared<const std::vector<std::uint8_t>>(std::move(held));
}

namespace {

// Calls range(e, lo, hi) with the least and greatest Bernstein coefficient of every element e of
// `source` whose values it holds (HexElementSource::held) and that has no non-finite nodal
// value, in parallel, converting each element; returns how many non-finite nodal values the
// others have.
template <class Range>
std::uint64_t coefficient_ranges(const HexElementSource& source, Range range) {
  const HexBlock& block = source.block();
  const int p = block.order;
  const std::size_t n = nodes_per_element(p);
  const std::span<const std::uint8_t> held = source.held();
  const ConversionMatrix& matrix = conversion_matrix(p, block.nodes);
  std::atomic<std::uint64_t> nonfinite{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, block.element_count, 64),
                    [&](const tbb::blocked_range<std::size_t>& elements) {
                      double nodal[kMaxElementValues], b[kMaxElementValues];
                      std::uint64_t bad = 0;
                      for (std::size_t e = elements.begin(); e != elements.end(); ++e) {
                        if (!held.empty() && !held[e]) continue;
                        if (const std::size_t k = read_nodal(block, e, n, nodal); k > 0) {
                          bad += k;
                          continue;
                        }
                        convert_element(p, matrix, nodal, b);
                        const auto [lo, hi] = std::minmax_element(b, b + n);
                        range(e, *lo, *hi);
                      }
                      if (bad > 0) nonfinite.fetch_add(bad, std::memory_order_relaxed);
                    });
  return nonfinite.load();
}

}  // namespace

std::vector<std::uint8_t> HexElementSource::needed_elements(
    std::span<const double> isovalues) const {
  // The elements bind() keeps for one of the isovalues, and those it leaves out for a NaN or
  // ±Inf value (flagged first, then cleared where the range comes).
  std::vector<std::uint8_t> needed(block_.element_count, 1);
  for (std::size_t e = 0; e < needed.size(); ++e)
    if (held_ && !(*held_)[e]) needed[e] = 0;
  coefficient_ranges(*this, [&](std::size_t e, double lo, double hi) {
    needed[e] = std::any_of(isovalues.begin(), isovalues.end(),
                            [&](double iso) { return lo <= iso && iso <= hi; });
  });
  return needed;
}

namespace {

// The colour field of an element block: a source over the colour's nodal values with the block's
// prepared geometry, and a lookup of the element that holds a point (its values read when
// bound, as bind() reads the isovalue's field).
class HexScalarProbe final : public ScalarProbe {
 public:
  HexScalarProbe(const HexElementSource& prepared, const HexBlock& colour)
      : source_(prepared, colour), sources_{&source_}, lookup_(sources_) {}
  HexScalarProbe(const HexScalarProbe&) = delete;  // the lookup points at source_
  HexScalarProbe& operator=(const HexScalarProbe&) = delete;
  double at(glm::dvec3 p) const override { return value(p, false); }
  double near(glm::dvec3 p) const override { return value(p, true); }

 private:
  double value(glm::dvec3 p, bool extrapolate) const {
    // Each thread's last element first: a row of pixels' hits lie in few elements. The hint
    // cannot change the answer (HexFieldLookup::sample).
    thread_local HexFieldLookup::Hint hint;
    double v = 0.0;
    return lookup_.value(p, v, hint, extrapolate) ? v : std::numeric_limits<double>::quiet_NaN();
  }

  HexElementSource source_;
  std::array<const HexElementSource*, 1> sources_;
  HexFieldLookup lookup_;
};

}  // namespace

std::unique_ptr<ScalarProbe> HexElementSource::bind_scalar() const {
  if (!block_.colour) return nullptr;
  return std::make_unique<HexScalarProbe>(*this, colour_as_values(block_));
}

// A curved element's Jacobian determinant has one strict sign (either: a mirrored element is
// fine) at the (q + 2)³ points of a uniform lattice of its reference cube; zero or a change of
// sign there means a folded (inverted) or degenerate element. A necessary condition, checked
// where the solver's mesh generator would have gone wrong.
void HexElementSource::check_jacobian(std::size_t element, const std::vector<glm::dvec3>& x,
                                      bool top_collapsed) const {
  // The Jacobian at the lattice by sum factorization over the geometry's Bernstein form: the
  // 1-D basis and its derivative at the lattice's coordinates, then one axis contracted at a
  // time (O(q⁴) per element instead of a full evaluation per point).
  const int q = geometry_degree_, m = q + 1, points = q + 2;
  std::vector<double> basis(std::size_t(points) * m), derivative(std::size_t(points) * m);
  for (int a = 0; a < points; ++a) {
    const double t = double(a) / (points - 1);
    // B_{i,n}(t) for n = q − 1 (the derivative's basis) and n = q.
    std::vector<double> lower(m, 0.0), upper(m, 0.0);
    upper[0] = 1.0;
    for (int n = 1; n <= q; ++n) {
      if (n == q) lower = upper;  // degree q − 1
      for (int i = n; i >= 0; --i)
        upper[i] = (i > 0 ? t * upper[i - 1] : 0.0) + (i < n ? (1.0 - t) * upper[i] : 0.0);
    }
    for (int i = 0; i < m; ++i) {
      basis[a * m + i] = upper[i];
      // d/dt B_{i,q} = q (B_{i−1,q−1} − B_{i,q−1})
      derivative[a * m + i] = q * ((i > 0 ? lower[i - 1] : 0.0) - (i < q ? lower[i] : 0.0));
    }
  }
  // Contract ξ: value and ∂ξ per (point a, coefficient j, k).
  const std::size_t mm = std::size_t(m) * m;
  std::vector<glm::dvec3> v1(points * mm), d1(points * mm);
  for (int a = 0; a < points; ++a)
    for (std::size_t jk = 0; jk < mm; ++jk) {
      glm::dvec3 v(0.0), d(0.0);
      for (int i = 0; i < m; ++i) {
        v += basis[a * m + i] * x[i + m * jk];
        d += derivative[a * m + i] * x[i + m * jk];
      }
      v1[a * mm + jk] = v;
      d1[a * mm + jk] = d;
    }
  // Contract η: value, ∂ξ and ∂η per (a, b, coefficient k).
  const std::size_t pp = std::size_t(points) * points;
  std::vector<glm::dvec3> v2(pp * m), dx2(pp * m), dy2(pp * m);
  for (int b = 0; b < points; ++b)
    for (int a = 0; a < points; ++a)
      for (int k = 0; k < m; ++k) {
        glm::dvec3 v(0.0), dx(0.0), dy(0.0);
        for (int j = 0; j < m; ++j) {
          const std::size_t from = a * mm + j + std::size_t(m) * k;
          v += basis[b * m + j] * v1[from];
          dx += basis[b * m + j] * d1[from];
          dy += derivative[b * m + j] * v1[from];
        }
        const std::size_t to = (a + std::size_t(points) * b) * m + k;
        v2[to] = v;
        dx2[to] = dx;
        dy2[to] = dy;
      }
  // Contract ζ at each lattice point, in the order of the lattice (ξ fastest), and test.
  int sign = 0;
  for (int c = 0; c < points - (top_collapsed ? 1 : 0); ++c)
    for (int b = 0; b < points; ++b)
      for (int a = 0; a < points; ++a) {
        glm::dmat3 jac(0.0);
        const std::size_t from = (a + std::size_t(points) * b) * m;
        for (int k = 0; k < m; ++k) {
          jac[0] += basis[c * m + k] * dx2[from + k];
          jac[1] += basis[c * m + k] * dy2[from + k];
          jac[2] += derivative[c * m + k] * v2[from + k];
        }
        // Relative to the columns' lengths, as the affine test: thin elements are fine.
        const double det = glm::determinant(jac),
                     tol = 1e-10 * glm::length(jac[0]) * glm::length(jac[1]) * glm::length(jac[2]);
        const int s = det > tol ? 1 : det < -tol ? -1 : 0;
        if (s == 0 || (sign != 0 && s != sign)) {
          const glm::dvec3 xi(double(a) / (points - 1), double(b) / (points - 1),
                              double(c) / (points - 1));
          throw std::invalid_argument(
              "hex source: element " + std::to_string(element) +
              " is inverted or degenerate (its Jacobian determinant vanishes or changes sign "
              "near reference point (" +
              std::to_string(xi.x) + ", " + std::to_string(xi.y) + ", " + std::to_string(xi.z) +
              "))");
        }
        sign = s;
      }
}

Box HexElementSource::bounds() const {
  return bounds_;
}

const double* HexElementSource::corners_of(std::size_t element) const {
  return &geometry_->corners[24 * element];
}

std::span<const glm::dvec3> HexElementSource::curved_geometry(std::size_t element) const {
  const std::uint32_t k = geometry_->curved_of[element];
  if (k == kNotCurved) return {};
  const std::size_t gn =
      std::size_t(geometry_degree_ + 1) * (geometry_degree_ + 1) * (geometry_degree_ + 1);
  return {&geometry_->curved[k * gn], gn};
}

glm::dvec3 HexElementSource::to_world(std::size_t element, glm::dvec3 reference) const {
  if (is_curved(element)) {
    const curved::Element ce{block_.order, geometry_degree_, nullptr,
                             curved_geometry(element).data()};
    return curved::evaluate(ce, reference).x;
  }
  const AffineFrame f = frame_of(corners_of(element));
  return f.origin + f.axes * reference;
}

glm::dvec3 HexElementSource::to_reference(std::size_t element, glm::dvec3 world) const {
  if (is_curved(element)) {
    const curved::Element ce{block_.order, geometry_degree_, nullptr,
                             curved_geometry(element).data()};
    glm::dvec3 xi;
    return curved::invert(ce, world, xi) ? xi
                                         : glm::dvec3(std::numeric_limits<double>::quiet_NaN());
  }
  const AffineFrame f = frame_of(corners_of(element));
  return glm::inverse(f.axes) * (world - f.origin);
}

void HexElementSource::element_bernstein(std::size_t element, std::span<double> out) const {
  const int p = block_.order;
  const std::size_t n = nodes_per_element(p);
  if (out.size() != n)
    throw std::invalid_argument("element_bernstein: span must hold (order + 1)^3 values");
  double nodal[kMaxElementValues];
  read_nodal(block_, element, n, nodal);
  convert_element(p, conversion_matrix(p, block_.nodes), nodal, out.data());
}

namespace {

// The elements of `source` whose Bernstein coefficient range holds `isovalue`, with their
// coefficients (iso subtracted) and frames, in element order (the same for any thread count).
Activation activate(const HexElementSource& source, double isovalue) {
  const HexBlock& block = source.block();
  const int p = block.order;
  const std::size_t n = nodes_per_element(p);
  const std::size_t count = block.element_count;

  // Pass 1: which elements may hold the isosurface (convex hull of the Bernstein coefficients).
  // Flags only, so memory does not grow with the block. An element with a non-finite nodal
  // value has no polynomial to intersect: it is left out.
  std::vector<std::uint8_t> active(count, 0);
  const std::uint64_t nonfinite = coefficient_ranges(
      source,
      [&](std::size_t e, double lo, double hi) { active[e] = lo <= isovalue && isovalue <= hi; });
  std::vector<std::size_t> kept;
  for (std::size_t e = 0; e < count; ++e)
    if (active[e]) kept.push_back(e);

  // Pass 2: the kept elements' coefficients (converted again: usually few are kept) and frames.
  Activation out;
  out.order = p;
  out.values_per_element = n;
  out.nonfinite = nonfinite;
  out.elements.resize(kept.size());
  out.coefficients.resize(kept.size() * n);
  // The curved ones' geometry, numbered in element order.
  out.geometry_degree = source.geometry_degree();
  out.points_per_element =
      std::size_t(out.geometry_degree + 1) * (out.geometry_degree + 1) * (out.geometry_degree + 1);
  std::size_t curved = 0;
  for (std::size_t k = 0; k < kept.size(); ++k)
    if (source.is_curved(kept[k])) out.elements[k].curved = std::uint32_t(curved++);
  out.geometry.resize(curved * out.points_per_element);
  tbb::parallel_for(std::size_t(0), kept.size(), [&](std::size_t k) {
    const std::size_t e = kept[k];
    const std::span<double> b(&out.coefficients[k * n], n);
    source.element_bernstein(e, b);
    for (double& v : b)
      v -= isovalue;
    ActiveElement& el = out.elements[k];
    if (el.curved != ActiveElement::kAffine) {
      const std::span<const glm::dvec3> x = source.curved_geometry(e);
      std::copy(x.begin(), x.end(), &out.geometry[el.curved * out.points_per_element]);
      el.origin = glm::dvec3(0.0);
      el.to_reference = glm::dmat3(1.0);
      el.lo = el.hi = x[0];
      for (const glm::dvec3& v : x)  // the convex hull property
        el.lo = glm::min(el.lo, v), el.hi = glm::max(el.hi, v);
      return;
    }
    const AffineFrame f = frame_of(source.corners_of(e));
    el.origin = f.origin;
    el.to_reference = glm::inverse(f.axes);
    const Box box = bounding_box(f);
    el.lo = box.lo;
    el.hi = box.hi;
  });
  return out;
}

}  // namespace

std::unique_ptr<GeometryBinding> HexElementSource::bind(RTCDevice device, double isovalue) const {
  return std::make_unique<HexBinding>(device, activate(*this, isovalue));
}

std::unique_ptr<AxisCaster> HexElementSource::bind_axis(double isovalue) const {
  return make_axis_caster(activate(*this, isovalue));
}

}  // namespace ldimesh

#include "ldimesh/core/field/hex_source.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <span>
#include <string>

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include "../test_helpers.hpp"
#include "ldimesh/core/base/view.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

constexpr NodeSet kNodeSets[] = {NodeSet::gauss_lobatto_legendre, NodeSet::gauss_legendre,
                                 NodeSet::equispaced};

std::string describe(int order, NodeSet nodes) {
  const char* names[] = {"GLL", "GL", "equispaced"};
  return "order " + std::to_string(order) + " " + names[int(nodes)];
}

int values_per_element(int order) {
  return (order + 1) * (order + 1) * (order + 1);
}

// Corners (HexBlock layout) of an nx × ny × nz tiling of the box [lo, hi], mapped by the affine
// x ↦ map·x: every element is the same sheared, rotated parallelepiped.
std::vector<double> tiled_corners(glm::ivec3 n, glm::dvec3 lo, glm::dvec3 hi,
                                  const glm::dmat3& map) {
  std::vector<double> corners;
  for (int k = 0; k < n.z; ++k)
    for (int j = 0; j < n.y; ++j)
      for (int i = 0; i < n.x; ++i)
        for (int c = 0; c < 8; ++c) {
          const glm::dvec3 cell(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
          const glm::dvec3 x = map * (lo + (hi - lo) * cell / glm::dvec3(n));
          corners.insert(corners.end(), {x.x, x.y, x.z});
        }
  return corners;
}

// World point of reference point r in the element with these corners (trilinear blend, so it
// does not rely on the source's affine assumption).
glm::dvec3 trilinear(const double* corners, glm::dvec3 r) {
  glm::dvec3 x(0.0);
  for (int c = 0; c < 8; ++c) {
    const double w =
        ((c & 1) ? r.x : 1 - r.x) * ((c & 2) ? r.y : 1 - r.y) * ((c & 4) ? r.z : 1 - r.z);
    x += w * glm::dvec3(corners[3 * c], corners[3 * c + 1], corners[3 * c + 2]);
  }
  return x;
}

// Nodal values f(x) at the world positions of every element's nodes.
template <class Field>
std::vector<double> sample_nodes(int order, NodeSet nodes, const std::vector<double>& corners,
                                 Field f) {
  const std::vector<double> x = node_positions(order, nodes);
  std::vector<double> values;
  for (std::size_t e = 0; e < corners.size() / 24; ++e)
    for (int k = 0; k <= order; ++k)
      for (int j = 0; j <= order; ++j)
        for (int i = 0; i <= order; ++i)
          values.push_back(f(trilinear(&corners[24 * e], {x[i], x[j], x[k]})));
  return values;
}

HexBlock make_block(int order, NodeSet nodes, const std::vector<double>& corners,
                    const std::vector<double>& values) {
  return {order, nodes, corners.size() / 24, corners.data(), values.data(), ScalarType::float64};
}

// The nodal interpolant of one element at reference point r, straight from the Lagrange basis
// on `x` (node positions on [0, 1]): an evaluation independent of the Bernstein path.
double lagrange_value(const std::vector<double>& x, const double* nodal, glm::dvec3 r) {
  const int n = int(x.size());
  double l[3][9];
  for (int axis = 0; axis < 3; ++axis)
    for (int i = 0; i < n; ++i) {
      l[axis][i] = 1.0;
      for (int m = 0; m < n; ++m)
        if (m != i) l[axis][i] *= (r[axis] - x[m]) / (x[i] - x[m]);
    }
  double sum = 0.0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j) {
      double row = 0.0;
      for (int i = 0; i < n; ++i)
        row += nodal[i + n * (j + n * k)] * l[0][i];
      sum += row * l[1][j] * l[2][k];
    }
  return sum;
}

// A skewed frame: rotation by 25° about (1, 2, 2)/3 times a shear.
glm::dmat3 skew_map() {
  const glm::dvec3 a = glm::normalize(glm::dvec3(1, 2, 2));
  const double c = std::cos(0.436), s = std::sin(0.436);
  const glm::dmat3 cross(0, a.z, -a.y, -a.z, 0, a.x, a.y, -a.x, 0);  // columns of [a]×
  const glm::dmat3 rotation = glm::dmat3(c) + s * cross + (1 - c) * glm::outerProduct(a, a);
  const glm::dmat3 shear(1.0, 0.0, 0.0, 0.18, 1.0, 0.0, -0.12, 0.1, 1.0);  // column-major
  return rotation * shear;
}

const Box kSphereBox{{-1.25, -1.25, -1.25}, {1.25, 1.25, 1.25}};

using testing::axis_and_oblique_views;

// Legendre P_n(x) and P'_n(x) on (−1, 1), by the three-term recurrence.
glm::dvec2 legendre(int n, double x) {
  double p0 = 1.0, p1 = x;
  for (int k = 1; k < n; ++k) {
    const double p2 = ((2 * k + 1) * x * p1 - k * p0) / (k + 1);
    p0 = p1;
    p1 = p2;
  }
  return {p1, n * (x * p1 - p0) / (x * x - 1.0)};
}

TEST(HexElementSource, NodePositionsAreTheQuadratureRules) {
  // Closed forms on [0, 1]: GLL p = 4 has ±√(3/7) and GL p = 2 has ±√(3/5) on [−1, 1].
  const double a = 0.5 * std::sqrt(3.0 / 7.0), b = 0.5 * std::sqrt(3.0 / 5.0);
  const std::vector<double> gll_expected{0.0, 0.5 - a, 0.5, 0.5 + a, 1.0};
  const std::vector<double> gl_expected{0.5 - b, 0.5, 0.5 + b};
  const std::vector<double> gll = node_positions(4, NodeSet::gauss_lobatto_legendre);
  const std::vector<double> gl = node_positions(2, NodeSet::gauss_legendre);
  for (int i = 0; i < 5; ++i)
    EXPECT_NEAR(gll[i], gll_expected[i], 1e-15);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(gl[i], gl_expected[i], 1e-15);
  EXPECT_EQ(node_positions(4, NodeSet::equispaced),
            (std::vector<double>{0.0, 0.25, 0.5, 0.75, 1.0}));
  // For every order: GL nodes are the p + 1 distinct roots of P_{p+1}, GLL nodes the ends and
  // the p − 1 roots of P'_p.
  for (int order = 1; order <= kMaxHexOrder; ++order) {
    const std::vector<double> g = node_positions(order, NodeSet::gauss_legendre);
    const std::vector<double> l = node_positions(order, NodeSet::gauss_lobatto_legendre);
    ASSERT_EQ(g.size(), std::size_t(order + 1));
    ASSERT_EQ(l.size(), std::size_t(order + 1));
    EXPECT_EQ(l.front(), 0.0);
    EXPECT_EQ(l.back(), 1.0);
    for (int i = 0; i <= order; ++i)
      EXPECT_NEAR(legendre(order + 1, 2 * g[i] - 1)[0], 0.0, 1e-13) << order << " " << i;
    for (int i = 1; i < order; ++i)
      EXPECT_NEAR(legendre(order, 2 * l[i] - 1)[1], 0.0, 1e-12) << order << " " << i;
    for (int i = 1; i <= order; ++i) {
      EXPECT_GT(g[i] - g[i - 1], 0.02);
      EXPECT_GT(l[i] - l[i - 1], 0.02);
    }
  }
  EXPECT_THROW(node_positions(0, NodeSet::equispaced), std::invalid_argument);
}

TEST(HexElementSource, SphereFromQuadraticNodalValuesIsExact) {
  // |x|² is a quadratic, exactly represented for p ≥ 2 on affine elements, so the isosurface at
  // 1 is the unit sphere up to rounding for every order and node set.
  // Skewed elements (rays cross all three reference axes: degree 3p along a ray) and
  // axis-aligned ones (axis views move along one reference axis only: degree p).
  for (const glm::dmat3& map : {skew_map(), glm::dmat3(1.0)}) {
    const glm::dmat3 inverse_rows = glm::transpose(glm::inverse(map));
    for (int a = 0; a < 3; ++a)  // the skewed tiling still contains the sphere
      ASSERT_LT(glm::length(inverse_rows[a]), 1.2);
    const std::vector<double> corners = tiled_corners({4, 4, 4}, kSphereBox.lo, kSphereBox.hi, map);
    for (int order = 2; order <= kMaxHexOrder; ++order)
      for (NodeSet nodes : kNodeSets) {
        SCOPED_TRACE(describe(order, nodes) +
                     (map == glm::dmat3(1.0) ? ", axis-aligned" : ", skewed"));
        const std::vector<double> values =
            sample_nodes(order, nodes, corners, [](glm::dvec3 x) { return glm::dot(x, x); });
        const HexElementSource source(make_block(order, nodes, corners, values));
        const RayCaster caster(source, 1.0);
        EXPECT_EQ(caster.primitive_count(), 56u);  // the 8 corner elements miss the sphere
        for (const View& view : axis_and_oblique_views(source.bounds(), 24)) {
          const testing::SphereRays rays =
              testing::expect_sphere_hits(caster.cast(view), 1.0, 1e-6);
          EXPECT_GT(rays.through, 60);
          EXPECT_GT(rays.outside, 50);
        }
      }
  }
}

// ---------------------------------------------------------------------------------------------
// Reference roots by brute force: a dense scan of each element's Lagrange interpolant.

// Roots along o + t·d, t ∈ [0, t_max], of the field of `source` (nodal values `values`, default
// layout) minus `iso`: sign changes on 2000 steps per element segment, refined by bisection.
// nullopt when the scan cannot be trusted for this ray: two roots within a few steps, a
// near-tangency, or a root at an element face.
std::optional<std::vector<double>> dense_scan_roots(const HexElementSource& source,
                                                    const std::vector<double>& values, double iso,
                                                    glm::dvec3 o, glm::dvec3 d, double t_max) {
  const HexBlock& block = source.block();
  const std::vector<double> x = node_positions(block.order, block.nodes);
  const int per_element = values_per_element(block.order);
  std::vector<double> roots;
  constexpr int kSteps = 2000;
  std::vector<double> g(kSteps + 1);
  for (std::size_t e = 0; e < block.element_count; ++e) {
    const glm::dvec3 ro = source.to_reference(e, o), rd = source.to_reference(e, o + d) - ro;
    double t0 = 0.0, t1 = t_max;
    for (int a = 0; a < 3; ++a) {
      if (rd[a] == 0.0) {
        if (ro[a] < 0.0 || ro[a] > 1.0) t1 = -1.0;
        continue;
      }
      const double ta = -ro[a] / rd[a], tb = (1.0 - ro[a]) / rd[a];
      t0 = std::max(t0, std::min(ta, tb));
      t1 = std::min(t1, std::max(ta, tb));
    }
    if (!(t0 < t1)) continue;
    const double* nodal = &values[e * per_element];
    auto field = [&](double t) { return lagrange_value(x, nodal, ro + t * rd) - iso; };
    auto step_t = [&](double k) { return t0 + (t1 - t0) * k / kSteps; };
    double scale = 0.0;
    for (int k = 0; k <= kSteps; ++k) {
      g[k] = field(step_t(k));
      scale = std::max(scale, std::abs(g[k]));
    }
    int last_root_step = -100;
    for (int k = 0; k <= kSteps; ++k) {
      if (k < kSteps && positive(g[k]) != positive(g[k + 1])) {
        if (k - last_root_step <= 3) return std::nullopt;  // two roots within a few steps
        last_root_step = k;
        double a = step_t(k), b = step_t(k + 1);
        const bool left_positive = positive(g[k]);
        for (int iter = 0; iter < 80; ++iter) {
          const double m = 0.5 * (a + b);
          (positive(field(m)) == left_positive ? a : b) = m;
        }
        const double root = 0.5 * (a + b);
        if (std::min(root - t0, t1 - root) < 1e-9 * (t1 - t0)) return std::nullopt;  // at a face
        roots.push_back(root);
      }
      // A local minimum of |g| without a sign change may hide two roots between steps, or be
      // a near-tangency: look closer.
      const int lo = std::max(k - 1, 0), hi = std::min(k + 1, kSteps);
      if (std::abs(g[k]) > std::abs(g[lo]) || std::abs(g[k]) > std::abs(g[hi])) continue;
      if (positive(g[lo]) != positive(g[k]) || positive(g[hi]) != positive(g[k])) continue;
      for (int f = 0; f <= 200; ++f) {
        const double v = field(step_t(lo + (hi - lo) * f / 200.0));
        if (positive(v) != positive(g[k]) || std::abs(v) < 1e-6 * scale) return std::nullopt;
      }
    }
  }
  std::sort(roots.begin(), roots.end());
  return roots;
}

// Casts `rays_per_view` random rays of views along each of `directions` and checks their hits
// against the dense scan; returns how many rays were checked and how many roots they had.
struct ScanComparison {
  int rays_checked = 0;
  int roots_checked = 0;
};
ScanComparison expect_hits_match_dense_scan(const HexElementSource& source,
                                            const std::vector<double>& values, double iso,
                                            std::span<const glm::dvec3> directions,
                                            int rays_per_view, std::mt19937& rng) {
  const RayCaster caster(source, iso);
  ScanComparison result;
  for (const glm::dvec3& dir : directions) {
    const View view = make_view(source.bounds(), dir, 32);
    std::uniform_real_distribution<double> ux(0.0, view.width), uy(0.0, view.height);
    std::vector<glm::dvec2> points(rays_per_view);
    for (glm::dvec2& p : points)
      p = {ux(rng), uy(rng)};
    const RayHitList hits = caster.cast_points(view, points);
    for (std::size_t r = 0; r < points.size(); ++r) {
      const glm::dvec3 o = view.point(points[r].x, points[r].y, 0.0);
      const auto expected = dense_scan_roots(source, values, iso, o, view.dir, view.depth_extent);
      if (!expected) continue;
      ++result.rays_checked;
      const std::uint32_t begin = hits.offsets[r], count = hits.offsets[r + 1] - begin;
      EXPECT_EQ(count, expected->size()) << "ray " << r;
      if (count != expected->size()) continue;
      for (std::uint32_t h = 0; h < count; ++h)
        EXPECT_NEAR(hits.depth[begin + h], (*expected)[h], 1e-7) << "ray " << r << " hit " << h;
      result.roots_checked += int(count);
    }
  }
  return result;
}

TEST(HexElementSource, RandomPolynomialRootsMatchADenseScan) {
  // Random nodal values: wiggly DG polynomials, discontinuous across faces, several roots per
  // element along many rays. Small domain so float depths resolve 1e-7.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const std::vector<double> corners =
      tiled_corners({2, 2, 1}, {0.0, 0.0, 0.0}, {0.9, 0.9, 0.45}, skew_map());
  for (int order : {1, 3, 5, 8})
    for (NodeSet nodes : kNodeSets) {
      SCOPED_TRACE(describe(order, nodes));
      std::vector<double> values(4 * values_per_element(order));
      for (double& v : values)
        v = uniform(rng);
      const HexElementSource source(make_block(order, nodes, corners, values));
      const glm::dvec3 directions[] = {{0.31, -0.52, 0.79}, {-0.9, 0.2, 0.35}, {0.1, 0.95, -0.3}};
      const ScanComparison checked =
          expect_hits_match_dense_scan(source, values, 0.1, directions, 50, rng);
      EXPECT_GT(checked.rays_checked, 120);  // few rays are skipped as ambiguous
      EXPECT_GT(checked.roots_checked, order == 1 ? 30 : 100);
    }
}

// Nodal values of x plus three random waves of `amplitude` (random directions and phases from
// `rng`): only the elements near a level x = c can hold the isosurface of c.
std::vector<double> wavy_ramp(int order, NodeSet nodes, const std::vector<double>& corners,
                              double amplitude, std::mt19937& rng) {
  std::uniform_real_distribution<double> wave(-4.0, 4.0);
  glm::dvec3 k[3];
  double phase[3];
  for (int w = 0; w < 3; ++w)
    k[w] = {wave(rng), wave(rng), wave(rng)}, phase[w] = wave(rng);
  return sample_nodes(order, nodes, corners, [&](glm::dvec3 x) {
    double v = x.x;
    for (int w = 0; w < 3; ++w)
      v += amplitude * std::sin(glm::dot(k[w], x) + phase[w]);
    return v;
  });
}

TEST(HexElementSource, CullingNeverDropsAnElementThatHoldsARoot) {
  // Random smooth fields: a ramp in x plus random waves, so that only elements near x = 0.5
  // can hold the isosurface. (On rough data such as random nodal values the Bernstein
  // coefficients bound the element only loosely, and little is culled.)
  std::mt19937 rng(11);
  const std::vector<double> corners =
      tiled_corners({4, 4, 4}, {0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}, skew_map());
  const double iso = 0.5;
  for (int order : {3, 6})
    for (NodeSet nodes : kNodeSets) {
      SCOPED_TRACE(describe(order, nodes));
      const std::vector<double> values = wavy_ramp(order, nodes, corners, 0.03, rng);
      const HexElementSource source(make_block(order, nodes, corners, values));
      const std::vector<double> x = node_positions(order, nodes);
      const int n = values_per_element(order);
      std::vector<double> b(n);
      std::size_t culled = 0;
      for (std::size_t e = 0; e < 64; ++e) {
        source.element_bernstein(e, b);
        const double lo = *std::min_element(b.begin(), b.end());
        const double hi = *std::max_element(b.begin(), b.end());
        const bool holds_iso = lo <= iso && iso <= hi;
        culled += !holds_iso;
        // The Bernstein form is the nodal interpolant, and its coefficients bound it.
        const double* nodal = &values[e * n];
        for (int k = 0; k < 15; ++k)
          for (int j = 0; j < 15; ++j)
            for (int i = 0; i < 15; ++i) {
              const glm::dvec3 r = glm::dvec3(i, j, k) / 14.0;
              const double v = lagrange_value(x, nodal, r);
              if ((i + j + k) % 7 == 0) {
                ASSERT_NEAR(evaluate_bernstein(order, b, r).value, v, 1e-12);
              }
              ASSERT_GE(v, lo - 1e-12);
              ASSERT_LE(v, hi + 1e-12);
              if (!holds_iso) {
                ASSERT_EQ(positive(v - iso), positive(lo - iso)) << "element " << e;
              }
            }
      }
      EXPECT_GE(culled, 24u);
      const RayCaster caster(source, iso);
      EXPECT_EQ(caster.primitive_count(), 64 - culled);
      // Across the ramp, so that most rays cross the surface.
      const glm::dvec3 directions[] = {{1.0, 0.1, 0.05}, {0.8, -0.4, 0.3}};
      const ScanComparison checked =
          expect_hits_match_dense_scan(source, values, iso, directions, 40, rng);
      EXPECT_GT(checked.roots_checked, 25);
    }
}

TEST(HexElementSource, ACopyOfTheNeededElementsCastsWhatAllValuesCast) {
  // What the adaptor's snapshot does: copy the values of the elements needed_elements names and
  // cast them with the mask, the other elements' values NaN. A ramp in x with waves (two
  // isovalues: two bands of elements), and non-finite values in elements far from the surface
  // and on it.
  std::mt19937 rng(3);
  const std::vector<double> corners =
      tiled_corners({6, 4, 4}, {0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}, skew_map());
  const std::size_t elements = corners.size() / 24;
  const std::vector<double> isovalues{0.3, 0.7};
  for (int order : {2, 4, 7})
    for (NodeSet nodes : kNodeSets) {
      SCOPED_TRACE(describe(order, nodes));
      std::vector<double> values = wavy_ramp(order, nodes, corners, 0.02, rng);
      const int n = values_per_element(order);
      values[0 * std::size_t(n) + 1] = kNaN;  // x < 1/6: far from both surfaces
      values[3 * std::size_t(n) + 2] = kInf;  // x in [0.5, 0.67]: near 0.7
      const HexElementSource source(make_block(order, nodes, corners, values));
      const std::vector<std::uint8_t> needed = source.needed_elements(isovalues);
      ASSERT_EQ(needed.size(), elements);
      // The elements bind() keeps for either isovalue, and those with a non-finite value.
      std::vector<double> b(n);
      for (std::size_t e = 0; e < elements; ++e) {
        source.element_bernstein(e, b);
        const auto [lo, hi] = std::minmax_element(b.begin(), b.end());
        bool kept = !std::all_of(b.begin(), b.end(), [](double v) { return std::isfinite(v); });
        for (const double iso : isovalues)
          kept = kept || (*lo <= iso && iso <= *hi);
        ASSERT_EQ(bool(needed[e]), kept) << "element " << e;
      }
      const std::size_t held = std::size_t(std::count(needed.begin(), needed.end(), 1));
      EXPECT_LE(held, elements * 3 / 4);  // the copy leaves much out
      for (const bool wild : {false, true}) {
        // The other elements' values NaN, or anything; the geometry not given (shared).
        std::vector<double> copy(values.size(), kNaN);
        std::uniform_real_distribution<double> any(-2.0, 2.0);
        if (wild)
          for (double& v : copy)
            v = any(rng);
        for (std::size_t e = 0; e < elements; ++e)
          if (needed[e]) std::copy_n(&values[e * n], n, &copy[e * n]);
        HexBlock copied = make_block(order, nodes, corners, copy);
        copied.corners = nullptr;
        const HexElementSource part(source, copied, needed);
        for (const double iso : isovalues) {
          const RayCaster a(source, iso), c(part, iso);
          EXPECT_EQ(a.nonfinite_values(), 2u);
          EXPECT_EQ(c.nonfinite_values(), a.nonfinite_values());
          EXPECT_EQ(c.primitive_count(), a.primitive_count());
          SCOPED_TRACE("isovalue " + std::to_string(iso));
          EXPECT_GT(testing::expect_same_casts(a, c, axis_and_oblique_views(source.bounds(), 40)),
                    1000u);
        }
        EXPECT_THROW(HexElementSource(source, copied, std::vector<std::uint8_t>(elements - 1, 1)),
                     std::invalid_argument);
      }
    }
}

TEST(HexElementSource, BernsteinConversionChecksItsSpans) {
  const int n = values_per_element(2);
  std::vector<double> nodal(2 * n, 1.0), out(n);
  EXPECT_NO_THROW(
      lagrange_to_bernstein(2, NodeSet::gauss_lobatto_legendre, std::span(nodal).first(n), out));
  for (double b : out)
    EXPECT_NEAR(b, 1.0, 1e-14);  // a constant's coefficients are the constant
  EXPECT_THROW(
      lagrange_to_bernstein(2, NodeSet::gauss_lobatto_legendre, std::span(nodal).first(n - 1), out),
      std::invalid_argument);
  // In place, or shifted by one value: the output would overwrite nodal values not yet read.
  for (std::size_t shift : {0, 1})
    EXPECT_THROW(
        lagrange_to_bernstein(2, NodeSet::gauss_lobatto_legendre, std::span(nodal).first(n),
                              std::span(nodal).subspan(shift, n)),
        std::invalid_argument)
        << shift;
  // Adjacent, not overlapping.
  EXPECT_NO_THROW(lagrange_to_bernstein(2, NodeSet::gauss_lobatto_legendre,
                                        std::span(nodal).first(n), std::span(nodal).subspan(n)));
}

TEST(HexElementSource, Float32ValuesWithAStrideReadTheSameField) {
  const int order = 4, n = values_per_element(order);
  const NodeSet nodes = NodeSet::gauss_legendre;
  const std::vector<double> corners =
      tiled_corners({3, 3, 3}, kSphereBox.lo, kSphereBox.hi, skew_map());
  const std::vector<double> exact =
      sample_nodes(order, nodes, corners, [](glm::dvec3 x) { return glm::dot(x, x); });
  const std::size_t elements = corners.size() / 24, stride = n + 7;
  // The solver's float array has 7 unused values after each element; NaN, so reading them
  // would show.
  std::vector<float> strided(elements * stride, std::numeric_limits<float>::quiet_NaN());
  std::vector<double> rounded(exact.size());
  for (std::size_t e = 0; e < elements; ++e)
    for (int v = 0; v < n; ++v) {
      strided[e * stride + v] = float(exact[e * n + v]);
      rounded[e * n + v] = double(strided[e * stride + v]);
    }
  HexBlock block{order, nodes, elements, corners.data(), strided.data(), ScalarType::float32,
                 stride};
  const HexElementSource from_float(block);
  const HexElementSource from_rounded(make_block(order, nodes, corners, rounded));
  const HexElementSource from_exact(make_block(order, nodes, corners, exact));
  const View view = make_view(from_exact.bounds(), {0.3, -0.5, 0.8}, 32);
  const Ldi a = RayCaster(from_float, 1.0).cast(view);
  const Ldi b = RayCaster(from_rounded, 1.0).cast(view);
  const Ldi c = RayCaster(from_exact, 1.0).cast(view);
  // The same numbers in float or double give bit-identical hits.
  EXPECT_EQ(a.offsets, b.offsets);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_EQ(a.normal, b.normal);
  // And float rounding of the values moves the surface by about 1e-7.
  ASSERT_EQ(a.offsets, c.offsets);
  EXPECT_GT(a.sample_count(), 200u);
  for (std::size_t s = 0; s < a.sample_count(); ++s)
    EXPECT_NEAR(a.depth[s], c.depth[s], 1e-5);
}

TEST(HexElementSource, InvalidBlocksAreRejected) {
  const std::vector<double> corners =
      tiled_corners({2, 1, 1}, {0.0, 0.0, 0.0}, {2.0, 1.0, 1.0}, glm::dmat3(1.0));
  const std::vector<double> values(2 * values_per_element(kMaxHexOrder), 0.0);
  const HexBlock good = make_block(2, NodeSet::gauss_lobatto_legendre, corners, values);
  EXPECT_NO_THROW(HexElementSource{good});
  auto rejects = [&](HexBlock block, const char* needle) {
    try {
      HexElementSource source(block);
      ADD_FAILURE() << "accepted a block that should throw (" << needle << ")";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  HexBlock b = good;
  b.order = 0;
  rejects(b, "order 0");
  b.order = kMaxHexOrder + 1;
  rejects(b, "order 9");
  b = good;
  b.element_count = 0;
  rejects(b, "no elements");
  b = good;
  b.corners = nullptr;
  rejects(b, "null corner");
  b = good;
  b.values = nullptr;
  rejects(b, "null value");
  b = good;
  b.element_stride = 26;
  rejects(b, "stride");

  // Element 1 with one corner pulled out is a trilinear, not affine, hexahedron: accepted
  // (curved_hex_test.cpp); pulled through the opposite face it folds over.
  std::vector<double> bent = corners;
  bent[24 + 3 * 7 + 2] += 0.1;
  EXPECT_TRUE(
      HexElementSource(make_block(2, NodeSet::gauss_lobatto_legendre, bent, values)).is_curved(1));
  std::vector<double> folded = corners;
  folded[24 + 3 * 7 + 2] = 2.0 * folded[24 + 3 * 0 + 2] - folded[24 + 3 * 7 + 2];
  rejects(make_block(2, NodeSet::gauss_lobatto_legendre, folded, values),
          "element 1 is inverted or degenerate");
  // Element 0 flattened to zero height.
  std::vector<double> flat = corners;
  for (int c = 4; c < 8; ++c)
    flat[3 * c + 2] = 0.0;
  rejects(make_block(2, NodeSet::gauss_lobatto_legendre, flat, values), "element 0 is degenerate");
}

// ---------------------------------------------------------------------------------------------
// Non-finite values

// Whether the reference point r lies in the unit cube grown by `pad` (pad < 0 shrinks it).
bool in_unit_cube(glm::dvec3 r, double pad) {
  for (int a = 0; a < 3; ++a)
    if (!(r[a] > -pad && r[a] < 1.0 + pad)) return false;
  return true;
}

// Casts a sphere field over `corners` and the same field with a NaN, a +Inf and a −Inf nodal
// value in three elements the sphere crosses: rays that miss those elements get bit-identical
// hits, the others lose exactly the hits inside them.
void expect_only_nonfinite_elements_lose_hits(int order, NodeSet nodes,
                                              const std::vector<double>& corners) {
  const int n = values_per_element(order);
  const std::vector<double> clean_values =
      sample_nodes(order, nodes, corners, [](glm::dvec3 x) { return glm::dot(x, x); });
  std::vector<double> values = clean_values;
  const std::size_t bad[] = {20, 17, 5};
  values[bad[0] * n + 5] = kNaN;
  values[bad[1] * n + n / 2] = kInf;
  values[bad[2] * n + n - 1] = -kInf;
  const HexElementSource clean(make_block(order, nodes, corners, clean_values));
  const HexElementSource dirty(make_block(order, nodes, corners, values));
  const RayCaster clean_caster(clean, 1.0), dirty_caster(dirty, 1.0);
  EXPECT_EQ(clean_caster.nonfinite_values(), 0u);
  EXPECT_EQ(dirty_caster.nonfinite_values(), 3u);
  EXPECT_EQ(clean_caster.primitive_count(), 56u);
  EXPECT_EQ(dirty_caster.primitive_count(), 53u);

  int untouched = 0, touched = 0, dropped = 0;
  for (const View& view : axis_and_oblique_views(clean.bounds(), 48)) {
    const Ldi a = clean_caster.cast(view), b = dirty_caster.cast(view);
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i) {
        const std::size_t p = std::size_t(j) * view.width + i;
        const glm::dvec3 o = view.pixel_point(i, j, 0.0);
        bool touches = false;
        for (std::size_t e : bad) {
          const glm::dvec3 ro = clean.to_reference(e, o),
                           rd = clean.to_reference(e, o + view.dir) - ro;
          double t0 = 0.0, t1 = view.depth_extent;
          touches =
              touches || clip_ray_to_box(ro, rd, glm::dvec3(-1e-6), glm::dvec3(1.0 + 1e-6), t0, t1);
        }
        if (!touches) {  // the same hits, bit for bit
          ++untouched;
          ASSERT_EQ(a.count(p), b.count(p)) << "pixel " << i << "," << j;
          for (std::uint32_t s = 0; s < a.count(p); ++s) {
            ASSERT_EQ(a.depth[a.begin(p) + s], b.depth[b.begin(p) + s]);
            ASSERT_EQ(a.normal[a.begin(p) + s], b.normal[b.begin(p) + s]);
          }
          continue;
        }
        ++touched;
        auto found_in = [](const Ldi& ldi, std::size_t pixel, float depth) {
          for (std::uint32_t s = ldi.begin(pixel); s < ldi.end(pixel); ++s)
            if (std::abs(ldi.depth[s] - depth) < 1e-6) return true;
          return false;
        };
        auto where = [&](float depth, double pad) {
          bool in = false;
          for (std::size_t e : bad)
            in = in || in_unit_cube(clean.to_reference(e, view.pixel_point(i, j, depth)), pad);
          return in;
        };
        for (std::uint32_t s = b.begin(p); s < b.end(p); ++s) {
          ASSERT_FALSE(where(b.depth[s], -1e-6)) << "hit in a non-finite element";
          ASSERT_TRUE(found_in(a, p, b.depth[s])) << "pixel " << i << "," << j;
        }
        for (std::uint32_t s = a.begin(p); s < a.end(p); ++s) {
          if (where(a.depth[s], -1e-6)) {
            ++dropped;
          } else if (!where(a.depth[s], 1e-6)) {
            ASSERT_TRUE(found_in(b, p, a.depth[s])) << "pixel " << i << "," << j;
          }
        }
      }
  }
  EXPECT_GT(untouched, 3000);
  EXPECT_GT(touched, 300);
  EXPECT_GT(dropped, 100);  // the three elements did hold surface
}

TEST(HexElementSource, ElementsWithNonFiniteValuesProduceNoHitsAndAreCounted) {
  const int order = 3;
  const std::vector<double> corners =
      tiled_corners({4, 4, 4}, kSphereBox.lo, kSphereBox.hi, skew_map());
  for (NodeSet nodes : kNodeSets) {
    SCOPED_TRACE(describe(order, nodes));
    expect_only_nonfinite_elements_lose_hits(order, nodes, corners);
  }
}

TEST(HexElementSource, AllNonFiniteElementsHaveNoHits) {
  const int order = 2, n = values_per_element(order);
  const std::vector<double> corners =
      tiled_corners({2, 2, 2}, kSphereBox.lo, kSphereBox.hi, glm::dmat3(1.0));
  for (const double v : {kNaN, kInf, -kInf}) {
    // float32 with a stride: the padding after each element is not read, so not counted.
    const std::size_t stride = n + 3;
    const std::vector<float> values(8 * stride, float(v));
    const HexBlock block{order,         NodeSet::equispaced, 8,     corners.data(),
                         values.data(), ScalarType::float32, stride};
    const HexElementSource source(block);
    const RayCaster caster(source, 1.0);
    EXPECT_EQ(caster.nonfinite_values(), 8u * n);
    EXPECT_EQ(caster.primitive_count(), 0u);
    for (const View& view : axis_and_oblique_views(source.bounds(), 16))
      EXPECT_EQ(caster.cast(view).sample_count(), 0u);
  }
}

TEST(HexElementSource, RayCasterSumsNonFiniteCountsOverBlocks) {
  const int order = 3, n = values_per_element(order);
  const NodeSet nodes = NodeSet::gauss_legendre;
  const std::vector<double> corners =
      tiled_corners({4, 4, 4}, kSphereBox.lo, kSphereBox.hi, glm::dmat3(1.0));
  std::vector<double> values =
      sample_nodes(order, nodes, corners, [](glm::dvec3 x) { return glm::dot(x, x); });
  // Two blocks of 32 elements each over the same arrays.
  HexBlock first = make_block(order, nodes, corners, values), second = first;
  first.element_count = second.element_count = 32;
  second.corners = corners.data() + 32 * 24;
  second.values = values.data() + 32 * n;
  const HexElementSource a(first), b(second);
  const std::array<const FieldSource*, 2> both{&a, &b};
  EXPECT_EQ(RayCaster(both, 1.0).nonfinite_values(), 0u);
  values[3] = kNaN;
  values[21 * n + 7] = kInf;
  values[21 * n + 8] = kNaN;  // two in one element count twice
  values[40 * n + 1] = -kInf;
  EXPECT_EQ(RayCaster(a, 1.0).nonfinite_values(), 3u);
  EXPECT_EQ(RayCaster(b, 1.0).nonfinite_values(), 1u);
  EXPECT_EQ(RayCaster(both, 1.0).nonfinite_values(), 4u);
}

TEST(HexElementSource, ThreadCountDoesNotChangeTheLdi) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const int order = 5;
  const std::vector<double> corners =
      tiled_corners({3, 3, 2}, {0.0, 0.0, 0.0}, {1.5, 1.5, 1.0}, skew_map());
  std::vector<double> values(18 * values_per_element(order));
  for (double& v : values)
    v = uniform(rng);
  const HexElementSource source(
      make_block(order, NodeSet::gauss_lobatto_legendre, corners, values));
  const View view = make_view(source.bounds(), {0.4, 0.7, -0.6}, 48);
  auto cast_in_arena = [&](int threads) {
    tbb::task_arena arena(threads);
    return arena.execute([&] { return RayCaster(source, 0.2).cast(view); });
  };
  const Ldi one = cast_in_arena(1), many = cast_in_arena(8);
  EXPECT_GT(one.sample_count(), 2000u);
  EXPECT_EQ(one.offsets, many.offsets);
  EXPECT_EQ(one.depth, many.depth);
  EXPECT_EQ(one.normal, many.normal);
}

}  // namespace
}  // namespace ldimesh

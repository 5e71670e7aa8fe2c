// The field of high-order hexahedra at world points, and distances to its exact isosurface.
#include "ldimesh/core/field/hex_lookup.hpp"

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "ldimesh/core/metrics/distance.hpp"

#include "curved_meshes.hpp"

namespace ldimesh {
namespace {

using test::curved_mesh;
using test::CurvedMesh;
using test::kBox;
using test::shell_mesh;

// At random points of kBox (which the mesh fills), the lookup's value and gradient are
// `field`'s and `gradient`'s.
template <class Field, class Gradient>
void expect_field_in_box(const HexFieldLookup& lookup, Field field, Gradient gradient) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int i = 0; i < 2000; ++i) {
    const glm::dvec3 x =
        kBox.lo + (kBox.hi - kBox.lo) * glm::dvec3(unit(rng), unit(rng), unit(rng));
    PolynomialSample s;
    ASSERT_TRUE(lookup.sample(x, s));
    EXPECT_NEAR(s.value, field(x), 1e-12);
    EXPECT_NEAR(glm::length(s.gradient - gradient(x)), 0.0, 1e-9);
  }
}

// A field each mesh represents exactly (f ∘ x of the elements' degree), so the lookup must
// return it and its gradient to rounding, wherever the point lies among the elements.
TEST(HexFieldLookup, ValuesAndGradientsAreTheFieldsOwn) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  {
    // Curved shell 0.5 ≤ r ≤ 1, geometry q = 2, field r² (degree 4 = p in ξ).
    const CurvedMesh m = shell_mesh(2, 2, 4, 2, NodeSet::gauss_lobatto_legendre, 0.5, 1.0,
                                    [](glm::dvec3 x) { return glm::dot(x, x); });
    const HexElementSource source(m.block);
    const HexElementSource* sources[] = {&source};
    const HexFieldLookup lookup(sources);
    EXPECT_EQ(lookup.element_count(), m.block.element_count);
    // Points of the elements (the geometry of degree 2 is not the sphere's: its outer faces
    // lie within it between the nodes).
    // Some on the elements' faces, where two elements hold the point: the hint (the previous
    // point's element) must not change the answer.
    std::uniform_int_distribution<std::size_t> element(0, m.block.element_count - 1);
    HexFieldLookup::Hint hint;
    for (int i = 0; i < 2000; ++i) {
      glm::dvec3 xi(unit(rng), unit(rng), unit(rng));
      if (i % 4 == 0) xi[i % 3] = double(i % 8 < 4);
      const glm::dvec3 x = source.to_world(element(rng), xi);
      PolynomialSample s, h;
      ASSERT_TRUE(lookup.sample(x, s)) << "r " << glm::length(x);
      EXPECT_NEAR(s.value, glm::dot(x, x), 1e-12);
      EXPECT_NEAR(glm::length(s.gradient - 2.0 * x), 0.0, 1e-9);
      ASSERT_TRUE(lookup.sample(x, h, hint));
      EXPECT_EQ(s.value, h.value);
      EXPECT_EQ(s.gradient, h.gradient);
    }
    // Inside the hole, beyond the outer sphere, far away: no element holds the point.
    PolynomialSample s;
    for (const glm::dvec3& x : {glm::dvec3(0.0), glm::dvec3(0.3, 0.1, 0.0),
                                glm::dvec3(0.0, 1.05, 0.0), glm::dvec3(5.0, 5.0, 5.0)})
      EXPECT_FALSE(lookup.sample(x, s)) << x.x << ", " << x.y << ", " << x.z;
  }
  {
    // Distorted box, 3³ elements, q = 2, p = 3, a linear field; the faces of the box stay planes.
    const auto plane = [](glm::dvec3 x) { return x.x + 2.0 * x.y - x.z; };
    const CurvedMesh m = curved_mesh(3, 3, 2, NodeSet::equispaced, 0.08, plane);
    const HexElementSource source(m.block);
    const HexElementSource* sources[] = {&source};
    const HexFieldLookup lookup(sources);
    expect_field_in_box(lookup, plane, [](glm::dvec3) { return glm::dvec3(1.0, 2.0, -1.0); });
    // Just beyond a face (3·10⁻⁴ of an element in ξ): extrapolated, still the field; further
    // (3 %): outside.
    const glm::dvec3 mid = 0.5 * (kBox.lo + kBox.hi);
    const double element = (kBox.hi.x - kBox.lo.x) / 3.0;
    PolynomialSample s;
    const glm::dvec3 near(kBox.hi.x + 3e-4 * element, mid.y, mid.z);
    ASSERT_TRUE(lookup.sample(near, s));
    EXPECT_NEAR(s.value, plane(near), 1e-12);
    EXPECT_FALSE(lookup.sample({kBox.hi.x + 0.03 * element, mid.y, mid.z}, s));
  }
  {
    // Sheared parallelepipeds (affine, J neither diagonal nor symmetric: J⁻ᵀ is not J⁻¹), two
    // side by side, a quadratic field at GLL nodes of order 2.
    const glm::dvec3 o(0.1, -0.2, 0.3), a(0.5, 0.1, 0.0), b(0.2, 0.4, -0.1), c(-0.1, 0.15, 0.6);
    std::vector<double> corners;
    for (int e = 0; e < 2; ++e)
      for (int k = 0; k < 8; ++k) {
        const glm::dvec3 x =
            o + double(e + (k & 1)) * a + double((k >> 1) & 1) * b + double((k >> 2) & 1) * c;
        corners.insert(corners.end(), {x.x, x.y, x.z});
      }
    const auto quadratic = [](glm::dvec3 x) { return x.x * x.x + 3.0 * x.y * x.z - x.z; };
    std::vector<double> values(2 * 27, 0.0);
    HexBlock block;
    block.order = 2;
    block.nodes = NodeSet::gauss_lobatto_legendre;
    block.element_count = 2;
    block.corners = corners.data();
    block.values = values.data();
    const std::vector<double> nodes = node_positions(2, block.nodes);
    {
      const HexElementSource geometry(block);
      std::size_t v = 0;
      for (std::size_t e = 0; e < 2; ++e)
        for (int k = 0; k < 3; ++k)
          for (int j = 0; j < 3; ++j)
            for (int i = 0; i < 3; ++i)
              values[v++] = quadratic(geometry.to_world(e, {nodes[i], nodes[j], nodes[k]}));
    }
    const HexElementSource source(block);
    EXPECT_FALSE(source.is_curved(0));
    const HexElementSource* sources[] = {&source};
    const HexFieldLookup lookup(sources);
    for (int i = 0; i < 1000; ++i) {
      const glm::dvec3 x = o + 2.0 * unit(rng) * a + unit(rng) * b + unit(rng) * c;
      PolynomialSample s;
      ASSERT_TRUE(lookup.sample(x, s));
      EXPECT_NEAR(s.value, quadratic(x), 1e-12);
      EXPECT_NEAR(glm::length(s.gradient - glm::dvec3(2.0 * x.x, 3.0 * x.z, 3.0 * x.y - 1.0)), 0.0,
                  1e-9);
    }
  }
  {
    // Straight (affine) elements: the same box undistorted, a quadratic field.
    const auto quadratic = [](glm::dvec3 x) { return x.x * x.x + x.y * x.z; };
    const CurvedMesh m = curved_mesh(3, 2, 1, NodeSet::gauss_lobatto_legendre, 0.0, quadratic);
    const HexElementSource source(m.block);
    EXPECT_FALSE(source.is_curved(0));
    const HexElementSource* sources[] = {&source};
    const HexFieldLookup lookup(sources);
    expect_field_in_box(lookup, quadratic,
                        [](glm::dvec3 x) { return glm::dvec3(2.0 * x.x, x.z, x.y); });
  }
}

// A latitude–longitude sphere whose vertices sit at radius 0.75 (1 + 0.02 sin(3θ) cos(2φ)):
// its distances to the isosurface r² = 0.72² of the curved shell's field (through the lookup)
// are its distances to the sphere of radius 0.72 (the analytic field r²).
TEST(HexFieldLookup, DistanceToTheShellsIsosurfaceIsTheSpheres) {
  const CurvedMesh m = shell_mesh(3, 2, 4, 2, NodeSet::equispaced, 0.5, 1.0,
                                  [](glm::dvec3 x) { return glm::dot(x, x); });
  const HexElementSource source(m.block);
  const HexElementSource* sources[] = {&source};
  const HexFieldLookup lookup(sources);

  Mesh sphere;
  const int rings = 24, segments = 48;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const double theta = M_PI * i / rings, phi = 2.0 * M_PI * j / segments;
      const double r = 0.75 * (1.0 + 0.02 * std::sin(3.0 * theta) * std::cos(2.0 * phi));
      sphere.positions.emplace_back(r * std::sin(theta) * std::cos(phi),
                                    r * std::sin(theta) * std::sin(phi), r * std::cos(theta));
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const std::uint32_t a = i * segments + j, b = i * segments + (j + 1) % segments;
      sphere.triangles.insert(sphere.triangles.end(),
                              {a, a + segments, b, b, a + segments, b + segments});
    }
  sphere.triangle_view.assign(sphere.triangles.size() / 3, 0);

  const ImplicitSurface polynomial{"shell", lookup.field(), lookup.bounds()};
  const ImplicitSurface analytic{"r²",
                                 [](const glm::dvec3& p, glm::dvec3& gradient) {
                                   gradient = 2.0 * p;
                                   return glm::dot(p, p);
                                 },
                                 lookup.bounds()};
  const double iso = 0.72 * 0.72;
  const SurfaceDistance d = surface_distance(sphere, polynomial, iso);
  {
    // The threads' hints do not change the figures: the same bits on one thread.
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    const SurfaceDistance serial = surface_distance(sphere, polynomial, iso);
    EXPECT_EQ(serial.forward.mean, d.forward.mean);
    EXPECT_EQ(serial.forward.max, d.forward.max);
  }
  const SurfaceDistance e = surface_distance(sphere, analytic, iso);
  EXPECT_EQ(d.not_converged, 0u);
  EXPECT_EQ(d.outside_clip, 0u);
  EXPECT_EQ(d.forward.samples.total(), e.forward.samples.total());
  EXPECT_NEAR(d.forward.mean, e.forward.mean, 1e-9);
  EXPECT_NEAR(d.forward.max, e.forward.max, 1e-9);
  // 0.02 · 0.75 at most (the vertices' bumps) plus 0.03 (the radii): the figure is not trivial.
  EXPECT_GT(d.forward.mean, 0.02);
  EXPECT_LT(d.forward.max, 0.03 + 0.0151);

  // The field is not defined inside the hole: a mesh there is not measured.
  Mesh inner = sphere;
  for (glm::vec3& p : inner.positions)
    p *= 0.3f;
  const SurfaceDistance h = surface_distance(inner, polynomial, iso);
  EXPECT_EQ(h.forward.samples.total(), 0u);
  EXPECT_EQ(h.not_converged, d.forward.samples.total());
}

}  // namespace
}  // namespace ldimesh

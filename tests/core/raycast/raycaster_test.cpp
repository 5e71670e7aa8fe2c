#include "ldimesh/core/raycast/raycaster.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include "../test_helpers.hpp"
#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"

namespace ldimesh {
namespace {

const Box kSphereBox{{-1.25, -1.25, -1.25}, {1.25, 1.25, 1.25}};

// Two spheres, radius 1 and 0.7: f = (r² − 1)(r² − 0.49) = 0.
struct ConcentricSpheres {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    const T r2 = sqr(x) + sqr(y) + sqr(z);
    return (r2 - 1.0) * (r2 - 0.49);
  }
};

// f = (r² − 1)² = ε² gives the shell 1 − ε ≤ r² ≤ 1 + ε, far thinner than a brick.
struct SquaredSphere {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    return sqr(sqr(x) + sqr(y) + sqr(z) - 1.0);
  }
};

// 64 roots along every ray in z: sin(32π(z + 1)) = 0.5 on z ∈ [−1, 1].
struct Layers64 {
  template <class T>
  T operator()(const T&, const T&, const T& z) const {
    using std::sin;
    return sin((32.0 * std::numbers::pi) * (z + 1.0));
  }
};

using testing::axis_and_oblique_views;
using testing::sphere_crossing;
using testing::SphereCrossing;

TEST(RayCaster, SphereHitsLieOnTheSphere) {
  const AnalyticSource<fields::Sphere> source(fields::Sphere{}, kSphereBox);
  const RayCaster caster(source, 1.0);
  for (const View& view : axis_and_oblique_views(kSphereBox, 48)) {
    const testing::SphereRays rays = testing::expect_sphere_hits(caster.cast(view), 1.0, 1e-5);
    EXPECT_GT(rays.through, 500);
    EXPECT_GT(rays.outside, 100);
  }
}

TEST(RayCaster, TwoConcentricSpheresGiveFourHits) {
  const AnalyticSource<ConcentricSpheres> source(ConcentricSpheres{}, kSphereBox);
  const RayCaster caster(source, 0.0);
  const View view = make_view(kSphereBox, {0.2, 0.1, 1.0}, 64);
  const Ldi ldi = caster.cast(view);
  int four = 0;
  for (int j = 0; j < view.height; ++j)
    for (int i = 0; i < view.width; ++i) {
      const SphereCrossing outer = sphere_crossing(view, i, j, 1.0, 1e-6);
      const SphereCrossing inner = sphere_crossing(view, i, j, 0.7, 1e-6);
      if (outer.grazing || inner.grazing) continue;
      const std::size_t p = std::size_t(j) * view.width + i;
      ASSERT_EQ(ldi.count(p), std::uint32_t(outer.count + inner.count));
      if (inner.count == 0) continue;
      ++four;
      const float* d = &ldi.depth[ldi.begin(p)];
      EXPECT_NEAR(d[0], outer.t0, 1e-5);
      EXPECT_NEAR(d[1], inner.t0, 1e-5);
      EXPECT_NEAR(d[2], inner.t1, 1e-5);
      EXPECT_NEAR(d[3], outer.t1, 1e-5);
    }
  EXPECT_GT(four, 500);
}

TEST(RayCaster, ShellThinnerThanABrickIsNeverMissed) {
  // Shell of thickness ≈ 2e-4 against bricks of 2.5 / 8 = 0.31.
  const double eps = 2e-4;
  const AnalyticSource<SquaredSphere> source(SquaredSphere{}, kSphereBox, 0.0, 8);
  const RayCaster caster(source, eps * eps);
  const double r_in = std::sqrt(1 - eps), r_out = std::sqrt(1 + eps);
  ASSERT_LT(r_out - r_in, 1e-3 * (2.5 / 8));
  for (const View& view : axis_and_oblique_views(kSphereBox, 40)) {
    const Ldi ldi = caster.cast(view);
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i) {
        const SphereCrossing outer = sphere_crossing(view, i, j, r_out, 1e-6);
        const SphereCrossing inner = sphere_crossing(view, i, j, r_in, 1e-6);
        if (outer.grazing || inner.grazing) continue;
        const std::size_t p = std::size_t(j) * view.width + i;
        ASSERT_EQ(ldi.count(p), std::uint32_t(outer.count + inner.count))
            << "pixel " << i << "," << j;
      }
  }
}

TEST(RayCaster, SixtyFourLayersAlongEveryRay) {
  const Box box{{-1, -1, -1}, {1, 1, 1}};
  const AnalyticSource<Layers64> source(Layers64{}, box, 0.0, 4);
  const RayCaster caster(source, 0.5);
  const Ldi ldi = caster.cast(make_view(box, {0, 0, 1}, 8));
  for (std::size_t p = 0; p < ldi.pixel_count(); ++p) {
    ASSERT_EQ(ldi.count(p), 64u);
    for (std::uint32_t k = 0; k < 64; ++k) {
      const double phase = (k % 2 == 0 ? 1.0 / 6 : 5.0 / 6) + 2.0 * (k / 2);  // in units of π
      EXPECT_NEAR(ldi.depth[ldi.begin(p) + k], phase / 32.0, 1e-5);
    }
  }
}

TEST(RayCaster, RaysBetweenPixelCentresMatchTheSphere) {
  const AnalyticSource<fields::Sphere> source(fields::Sphere{}, kSphereBox);
  const RayCaster caster(source, 1.0);
  const View view = make_view(kSphereBox, {0, 0, 1}, 16);
  const std::vector<glm::dvec2> points{{8.0, 8.0}, {0.25, 0.25}, {3.75, 9.5}};
  const RayHitList hits = caster.cast_points(view, points);
  ASSERT_EQ(hits.offsets.size(), points.size() + 1);
  EXPECT_EQ(hits.offsets[1] - hits.offsets[0], 2u);  // through the centre: depth 0.25 and 2.25
  EXPECT_NEAR(hits.depth[0], 0.25, 1e-6);
  EXPECT_NEAR(hits.depth[1], 2.25, 1e-6);
  EXPECT_EQ(hits.offsets[2] - hits.offsets[1], 0u);  // the corner misses
}

// A depth range per ray keeps exactly the hits of the whole ray that lie in it, for rays on
// brick faces and edges (even positions) as well.
TEST(RayCaster, DepthRangesKeepTheWholeRaysHitsInside) {
  const Box box{{-1, -1, -1}, {1, 1, 1}};
  const AnalyticSource<Layers64> source(Layers64{}, box, 0.0, 4);
  const RayCaster caster(source, 0.5);
  const View view = make_view(box, {0, 0, 1}, 8);
  const std::vector<glm::dvec2> points{{4.0, 4.0}, {2.5, 6.0}, {0.3, 7.9}, {6.0, 2.0}};
  const RayHitList whole = caster.cast_points(view, points);
  const std::vector<glm::dvec2> ranges{{0.30, 0.50}, {0.0, INFINITY}, {1.7, 1.2}, {0.625, 0.875}};
  const RayHitList part = caster.cast_points(view, points, nullptr, ranges);
  ASSERT_EQ(part.offsets.size(), points.size() + 1);
  for (std::size_t k = 0; k < points.size(); ++k) {
    std::vector<float> expected;
    for (std::uint32_t s = whole.offsets[k]; s < whole.offsets[k + 1]; ++s)
      if (whole.depth[s] >= ranges[k].x - 1e-6 && whole.depth[s] <= ranges[k].y + 1e-6)
        expected.push_back(whole.depth[s]);
    const std::vector<float> got(part.depth.begin() + part.offsets[k],
                                 part.depth.begin() + part.offsets[k + 1]);
    ASSERT_EQ(got.size(), expected.size()) << "ray " << k;
    for (std::size_t i = 0; i < got.size(); ++i)
      EXPECT_NEAR(got[i], expected[i], 1e-6) << "ray " << k << ", hit " << i;
  }
  EXPECT_EQ(part.offsets[1] - part.offsets[0], 6u);   // 64 layers in depth 2: 6 in [0.3, 0.5]
  EXPECT_EQ(part.offsets[2] - part.offsets[1], 64u);  // the whole ray
  EXPECT_EQ(part.offsets[3] - part.offsets[2], 0u);   // an empty range
  EXPECT_EQ(part.offsets[4] - part.offsets[3], 8u);
  EXPECT_THROW(caster.cast_points(view, points, nullptr, std::span(ranges).first(2)),
               std::invalid_argument);
}

TEST(RayCaster, BuiltinSurfacesProduceHits) {
  for (const SurfaceInfo& s : builtin_surfaces()) {
    const auto source = make_surface_source(s.name, 16);
    const RayCaster caster(*source, s.isovalue);
    EXPECT_GT(caster.primitive_count(), 0u) << s.name;
    std::size_t samples = 0;
    for (const View& view : make_axis_views(s.domain, 32))
      samples += caster.cast(view).sample_count();
    EXPECT_GT(samples, 300u) << s.name;
  }
  EXPECT_THROW(make_surface_source("no-such-surface"), std::invalid_argument);
}

// A failing Embree call is reported with Embree's own message, once.
TEST(EmbreeDevice, AFailureCarriesEmbreesMessage) {
  RTCDevice device = make_embree_device();
  EXPECT_EQ(embree_failure(device, "nothing"), "");
  RTCGeometry geometry = rtcNewGeometry(device, RTCGeometryType(9999));  // no such type
  EXPECT_EQ(geometry, nullptr);
  const std::string failure = embree_failure(device, "making a geometry");
  const std::string head = "Embree: making a geometry failed: ";
  EXPECT_EQ(failure.rfind(head, 0), 0u) << failure;
  EXPECT_NE(failure.find(" (RTCError "), std::string::npos) << failure;
  EXPECT_GT(failure.find(" (RTCError "), head.size()) << "no message of Embree's: " << failure;
  EXPECT_EQ(embree_failure(device, "nothing again"), "");  // reported once
  rtcReleaseDevice(device);
}

}  // namespace
}  // namespace ldimesh

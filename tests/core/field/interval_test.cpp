#include "ldimesh/core/field/interval.hpp"

#include <random>

#include <gtest/gtest.h>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"

namespace ldimesh {
namespace {

// Every value a field takes at points of a box lies in its interval enclosure over the box.
template <class Field>
void expect_enclosures_hold(const Field& f, double half_width) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pos(-1.5, 1.5), unit(0.0, 1.0), size(0.0, half_width);
  for (int trial = 0; trial < 300; ++trial) {
    const glm::dvec3 c{pos(rng), pos(rng), pos(rng)}, h{size(rng), size(rng), size(rng)};
    const Interval range = analytic_detail::enclose(f, c - h, c + h);
    for (int k = 0; k < 20; ++k) {
      const glm::dvec3 p = c - h + 2.0 * h * glm::dvec3(unit(rng), unit(rng), unit(rng));
      const double v = f(p.x, p.y, p.z);
      const double slack = 1e-12 * (1.0 + std::abs(v));
      ASSERT_GE(v, range.lo - slack) << "trial " << trial;
      ASSERT_LE(v, range.hi + slack) << "trial " << trial;
    }
  }
}

TEST(Interval, EnclosesEveryBuiltinFieldOverBoxes) {
  expect_enclosures_hold(fields::Sphere{}, 0.3);
  expect_enclosures_hold(fields::Torus{}, 0.3);
  expect_enclosures_hold(fields::BarthSextic{}, 0.3);
  expect_enclosures_hold(fields::KleinBottle{}, 0.3);
  expect_enclosures_hold(fields::MarschnerLobb{}, 0.3);
  expect_enclosures_hold(fields::Slices{}, 0.3);
}

TEST(Interval, CosineFindsInteriorExtrema) {
  const Interval c = cos(Interval(-0.5, 0.5));
  EXPECT_DOUBLE_EQ(c.hi, 1.0);
  EXPECT_NEAR(c.lo, std::cos(0.5), 1e-15);
  const Interval s = sin(Interval(1.0, 2.0));  // contains π/2
  EXPECT_DOUBLE_EQ(s.hi, 1.0);
  EXPECT_EQ(cos(Interval(0.0, 7.0)).lo, -1.0);
}

TEST(Interval, SquareOfStraddlingIntervalIsNonNegative) {
  const Interval s = sqr(Interval(-2.0, 1.0));
  EXPECT_EQ(s.lo, 0.0);
  EXPECT_EQ(s.hi, 4.0);
  const Interval p = Interval(-2.0, 1.0) * Interval(-2.0, 1.0);
  EXPECT_EQ(p.lo, -2.0);  // plain product cannot know both factors are the same
}

TEST(Jet, GradientMatchesFiniteDifferences) {
  const fields::BarthSextic f;
  const glm::dvec3 p{0.3, -0.7, 1.1};
  const glm::dvec3 g = analytic_detail::gradient(f, p);
  const double h = 1e-6;
  for (int a = 0; a < 3; ++a) {
    glm::dvec3 e(0.0);
    e[a] = h;
    const double fd =
        (f((p + e).x, (p + e).y, (p + e).z) - f((p - e).x, (p - e).y, (p - e).z)) / (2 * h);
    EXPECT_NEAR(g[a], fd, 1e-5 * (1.0 + std::abs(fd)));
  }
}

}  // namespace
}  // namespace ldimesh

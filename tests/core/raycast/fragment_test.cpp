#include "ldimesh/core/raycast/fragment.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

const View kView = make_view({{0, 0, 0}, {1, 1, 1}}, {0, 0, 1}, 4);

LdiFragment fragment(std::vector<std::uint32_t> pixels, std::vector<std::uint32_t> counts,
                     std::vector<float> depth) {
  LdiFragment f = make_empty_fragment(kView, 2);
  f.pixels = std::move(pixels);
  f.counts = std::move(counts);
  f.depth = std::move(depth);
  f.normal.assign(f.depth.size(), {0, 0, -1});
  return f;
}

TEST(Fragment, LdiRoundTripKeepsEverySample) {
  const auto source = make_surface_source("torus");
  const RayCaster caster(*source, 0.0);
  const View view = make_view(source->bounds(), {0.2, 0.3, 1.0}, 48);
  const Ldi ldi = caster.cast(view);
  const LdiFragment f = fragment_from_ldi(ldi, 1);
  ASSERT_TRUE(validate_fragment(f)) << validate_fragment(f).message();
  EXPECT_EQ(f.view, 1u);
  EXPECT_LT(f.pixels.size(), ldi.pixel_count());  // only non-empty pixels are listed
  const Ldi back = ldi_from_fragment(f, view);
  EXPECT_EQ(back.offsets, ldi.offsets);
  EXPECT_EQ(back.depth, ldi.depth);
  EXPECT_THROW(ldi_from_fragment(f, kView), std::invalid_argument);
}

TEST(Fragment, MergeConcatenatesSortsAndDropsDuplicates) {
  // Pixel 5 gets 0.3 from a and the next float above it from b: closer than the tolerance, one
  // is dropped. Pixel 9 gets two samples 1e-5 apart: farther than the tolerance, both stay.
  const float near_duplicate = std::nextafter(0.3f, 1.0f);
  ASSERT_NE(near_duplicate, 0.3f);
  ASSERT_LT(double(near_duplicate) - double(0.3f), 1e-6);
  const LdiFragment a = fragment({1, 5, 9}, {2, 1, 1}, {0.1f, 0.5f, 0.3f, 0.7f + 1e-5f});
  const LdiFragment b = fragment({0, 5, 9}, {1, 2, 1}, {0.2f, 0.1f, near_duplicate, 0.7f});
  const std::vector<LdiFragment> ab{a, b}, ba{b, a};
  const LdiFragment m = merge_fragments(ab, 1e-6);
  ASSERT_TRUE(validate_fragment(m)) << validate_fragment(m).message();
  EXPECT_EQ(m.pixels, (std::vector<std::uint32_t>{0, 1, 5, 9}));
  EXPECT_EQ(m.counts, (std::vector<std::uint32_t>{1, 2, 2, 2}));
  EXPECT_EQ(m.depth, (std::vector<float>{0.2f, 0.1f, 0.5f, 0.1f, 0.3f, 0.7f, 0.7f + 1e-5f}));
  const LdiFragment n = merge_fragments(ba, 1e-6);  // order of fragments does not matter
  EXPECT_EQ(n.depth, m.depth);
  EXPECT_EQ(n.pixels, m.pixels);
  // Empty fragments merge to nothing; fragments of different views are refused.
  const std::vector<LdiFragment> empties{make_empty_fragment(kView, 2),
                                         make_empty_fragment(kView, 2)};
  EXPECT_EQ(merge_fragments(empties, 1e-6).sample_count(), 0u);
  LdiFragment other = a;
  other.view = 3;
  const std::vector<LdiFragment> mixed{a, other};
  EXPECT_THROW(merge_fragments(mixed, 1e-6), std::invalid_argument);
}

TEST(Fragment, ValidationNamesTheBrokenInvariant) {
  EXPECT_TRUE(validate_fragment(fragment({1, 5}, {2, 1}, {0.1f, 0.5f, 0.3f})));
  EXPECT_FALSE(validate_fragment(fragment({5, 1}, {1, 2}, {0.1f, 0.5f, 0.3f})));   // not increasing
  EXPECT_FALSE(validate_fragment(fragment({1, 16}, {2, 1}, {0.1f, 0.5f, 0.3f})));  // out of range
  EXPECT_FALSE(validate_fragment(fragment({1, 5}, {2, 0}, {0.1f, 0.5f})));         // empty pixel
  EXPECT_FALSE(validate_fragment(fragment({1, 5}, {2, 2}, {0.1f, 0.5f, 0.3f})));   // sum
  EXPECT_FALSE(validate_fragment(fragment({1}, {2}, {0.5f, 0.1f})));               // unsorted
  const Status s = validate_fragment(fragment({1, 5}, {2, 2}, {0.1f, 0.5f, 0.3f}));
  EXPECT_NE(s.message().find("counts"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace ldimesh

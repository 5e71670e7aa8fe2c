#include "ldimesh/core/raycast/fragment.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

const View kView = make_view({{0, 0, 0}, {1, 1, 1}}, {0, 0, 1}, 4);
const glm::vec3 kDir(kView.dir);

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

TEST(Fragment, CombiningConcatenatesSortsAndCollapsesDuplicates) {
  // Pixel 5 gets 0.3 from a and the next float above it from b: closer than the tolerance, one
  // is dropped. Pixel 9 gets two samples 1e-5 apart: farther than the tolerance, both stay.
  const float near_duplicate = std::nextafter(0.3f, 1.0f);
  ASSERT_NE(near_duplicate, 0.3f);
  ASSERT_LT(double(near_duplicate) - double(0.3f), 1e-6);
  const LdiFragment a = fragment({1, 5, 9}, {2, 1, 1}, {0.1f, 0.5f, 0.3f, 0.7f + 1e-5f});
  const LdiFragment b = fragment({0, 5, 9}, {1, 2, 1}, {0.2f, 0.1f, near_duplicate, 0.7f});
  const std::vector<LdiFragment> ab{a, b}, ba{b, a};
  const LdiFragment m = combine_fragments(ab, 1e-6, kDir);
  ASSERT_TRUE(validate_fragment(m)) << validate_fragment(m).message();
  EXPECT_EQ(m.pixels, (std::vector<std::uint32_t>{0, 1, 5, 9}));
  EXPECT_EQ(m.counts, (std::vector<std::uint32_t>{1, 2, 2, 2}));
  EXPECT_EQ(m.depth, (std::vector<float>{0.2f, 0.1f, 0.5f, 0.1f, 0.3f, 0.7f, 0.7f + 1e-5f}));
  const LdiFragment n = combine_fragments(ba, 1e-6, kDir);  // order of fragments does not matter
  EXPECT_EQ(n.depth, m.depth);
  EXPECT_EQ(n.pixels, m.pixels);
  // Empty fragments merge to nothing; fragments of different views are refused.
  const std::vector<LdiFragment> empties{make_empty_fragment(kView, 2),
                                         make_empty_fragment(kView, 2)};
  EXPECT_EQ(combine_fragments(empties, 1e-6, kDir).sample_count(), 0u);
  LdiFragment other = a;
  other.view = 3;
  const std::vector<LdiFragment> mixed{a, other};
  EXPECT_THROW(combine_fragments(mixed, 1e-6, kDir), std::invalid_argument);
}

// A root on a face two cells share, found by both with their own gradients (a C⁰ field: they
// differ): merging fragments of two blocks or ranks keeps the hit that one caster keeps of the
// same two (kept_before: the normal facing the viewer most), not the smaller depth, whichever
// fragment holds which, and whatever the rounding that orders their depths.
TEST(Fragment, CombiningKeepsTheDuplicateOneCasterKeeps) {
  LdiFragment a = fragment({5}, {1}, {0.3f});
  LdiFragment b = fragment({5}, {1}, {std::nextafter(0.3f, 0.0f)});
  a.normal = {glm::normalize(glm::vec3(0.2f, 0.0f, -1.0f))};  // faces the viewer (dir +z) most
  b.normal = {glm::normalize(glm::vec3(0.0f, 0.6f, -0.8f))};
  for (const bool swapped : {false, true}) {
    const std::vector<LdiFragment> pair =
        swapped ? std::vector<LdiFragment>{b, a} : std::vector<LdiFragment>{a, b};
    const LdiFragment m = combine_fragments(pair, 1e-6, kDir);
    ASSERT_EQ(m.depth.size(), 1u);
    EXPECT_EQ(m.depth[0], 0.3f);
    EXPECT_EQ(m.normal[0], a.normal[0]);
  }
  std::vector<RayHit> hits{{double(b.depth[0]), b.normal[0], 0.0f},
                           {double(a.depth[0]), a.normal[0], 0.0f}};
  const std::size_t kept = collapse_duplicate_hits(
      std::span<RayHit>(hits), 1e-6, kDir,
      [](const RayHit& x, const RayHit& y) { return x.t < y.t; },
      [](const RayHit& h) { return h.t; }, [](const RayHit& h) { return h.normal; });
  ASSERT_EQ(kept, 1u);
  EXPECT_EQ(hits[0].normal, a.normal[0]);
  // Without a tolerance both stay, by depth.
  const std::vector<LdiFragment> pair{a, b};
  EXPECT_EQ(combine_fragments(pair, 0.0, kDir).depth,
            (std::vector<float>{std::nextafter(0.3f, 0.0f), 0.3f}));
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

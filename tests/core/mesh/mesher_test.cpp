#include "ldimesh/core/mesh/mesher.hpp"

#include <gtest/gtest.h>

namespace ldimesh {
namespace {

// A z view over the unit square with W × H pixels of spacing 1 / max(W, H).
View square_view(int res) {
  return make_view(Box{{0, 0, 0}, {1, 1, 1}}, {0, 0, 1}, res);
}

// An LDI whose pixels hold the given depths (all facing the viewer: normal −z).
Ldi ldi_from_layers(const View& view, const std::vector<std::vector<float>>& per_pixel) {
  Ldi ldi = make_empty_ldi(view);
  for (std::size_t p = 0; p < per_pixel.size(); ++p) {
    for (float d : per_pixel[p]) {
      ldi.depth.push_back(d);
      ldi.normal.push_back({0, 0, -1});
    }
    ldi.offsets[p + 1] = std::uint32_t(ldi.depth.size());
  }
  return ldi;
}

TEST(Mesher, EmptyAndSingleSampleLdisGiveNoQuads) {
  const View view = square_view(4);
  EXPECT_TRUE(build_quads(make_empty_ldi(view)).empty());
  std::vector<std::vector<float>> one(view.pixel_count());
  one[5] = {0.5f};
  EXPECT_TRUE(build_quads(ldi_from_layers(view, one)).empty());
  // A 1 × 1 image has no neighbours at all.
  const View tiny = square_view(1);
  EXPECT_TRUE(build_quads(ldi_from_layers(tiny, {{0.5f}})).empty());
}

TEST(Mesher, FlatSamplesFormOneQuadPerPixelSquare) {
  const View view = square_view(3);
  std::vector<std::vector<float>> flat(view.pixel_count(), std::vector<float>{0.25f});
  const std::vector<std::uint32_t> quads = build_quads(ldi_from_layers(view, flat));
  ASSERT_EQ(quads.size(), 4u * 4u);  // (3 − 1)² quads
  // Normals face −z, so the quads run counter-clockwise seen from −z: s0, top, top-right, right.
  EXPECT_EQ(std::vector<std::uint32_t>(quads.begin(), quads.begin() + 4),
            (std::vector<std::uint32_t>{0, 3, 4, 1}));
}

TEST(Mesher, SixtyFourLayersStaySeparate) {
  const View view = square_view(2);
  const float gap = float(3.0 * view.spacing);  // wider than the default rejection threshold
  std::vector<float> layers;
  for (int k = 0; k < 64; ++k)
    layers.push_back(k * gap);
  const Ldi ldi = ldi_from_layers(view, std::vector<std::vector<float>>(4, layers));
  const std::vector<std::uint32_t> quads = build_quads(ldi);
  ASSERT_EQ(quads.size(), 64u * 4u);
  for (std::size_t q = 0; q < quads.size(); q += 4)
    for (int c = 1; c < 4; ++c)
      EXPECT_EQ(ldi.depth[quads[q + c]], ldi.depth[quads[q]]);
}

TEST(Mesher, SeparateLayersAreNeverJoined) {
  // Layer A at depth 0.1 in three pixels, layer B at depth 0.6 in the fourth: no quad, since
  // the only candidate would join the two layers.
  const View view = square_view(2);
  const Ldi ldi = ldi_from_layers(view, {{0.1f}, {0.1f}, {0.1f}, {0.6f}});
  EXPECT_TRUE(build_quads(ldi).empty());
  // With both layers present everywhere, two quads, one per layer.
  const Ldi both = ldi_from_layers(view, {{0.1f, 0.6f}, {0.1f, 0.6f}, {0.1f, 0.6f}, {0.1f, 0.6f}});
  const std::vector<std::uint32_t> quads = build_quads(both);
  ASSERT_EQ(quads.size(), 8u);
  for (std::size_t q = 0; q < quads.size(); q += 4)
    for (int c = 1; c < 4; ++c)
      EXPECT_EQ(both.depth[quads[q + c]], both.depth[quads[q]]);
}

TEST(Mesher, SlopedPlaneIsMatchedThroughNormalPrediction) {
  // Plane depth = 0.2 + 1.5 x (steeper than one pixel of depth per pixel step): depth-only
  // matching would reject it at max_cost = 0.5 pixel, the normal-based prediction is exact.
  const View view = square_view(8);
  Ldi ldi = make_empty_ldi(view);
  const glm::vec3 n = glm::normalize(glm::vec3(1.5f, 0.0f, -1.0f));
  for (int j = 0; j < view.height; ++j)
    for (int i = 0; i < view.width; ++i) {
      ldi.depth.push_back(float(0.2 + 1.5 * (i + 0.5) * view.spacing));
      ldi.normal.push_back(n);
      ldi.offsets[std::size_t(j) * view.width + i + 1] = std::uint32_t(ldi.depth.size());
    }
  MatchOptions options;
  options.max_cost = 0.5;
  EXPECT_EQ(build_quads(ldi, options).size(), 4u * 7u * 7u);
}

}  // namespace
}  // namespace ldimesh

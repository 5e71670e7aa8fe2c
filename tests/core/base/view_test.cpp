#include "ldimesh/core/base/view.hpp"

#include <gtest/gtest.h>

namespace ldimesh {
namespace {

const Box kBox{{-1.0, -2.0, -0.5}, {1.0, 2.0, 0.5}};

TEST(View, AxisViewsCoverTheBoxWithSquarePixels) {
  const std::vector<View> views = make_axis_views(kBox, 64, "xyz");
  ASSERT_EQ(views.size(), 3u);
  // x view: image (y, z) = 4 × 1 → 64 × 16 pixels of 1/16.
  EXPECT_EQ(views[0].width, 64);
  EXPECT_EQ(views[0].height, 16);
  EXPECT_DOUBLE_EQ(views[0].spacing, 4.0 / 64);
  EXPECT_DOUBLE_EQ(views[0].depth_extent, 2.0);
  for (const View& v : views) {
    EXPECT_NEAR(glm::length(glm::cross(v.u, v.v) - v.dir), 0.0, 1e-15);
    // Pixel (0, 0) lies inside the box's projection at depth 0 on its entry face.
    const glm::dvec3 p = v.pixel_point(0, 0, 0.0);
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(p[a], kBox.lo[a] - 1e-12);
      EXPECT_LE(p[a], kBox.hi[a] + 1e-12);
    }
  }
}

TEST(View, AnyDirectionGivesAnOrthonormalFrameCoveringTheBox) {
  const View v = make_view(kBox, {1.0, 2.0, -3.0}, 100);
  EXPECT_NEAR(glm::length(v.dir), 1.0, 1e-15);
  EXPECT_NEAR(glm::dot(v.u, v.v), 0.0, 1e-15);
  EXPECT_NEAR(glm::dot(v.u, v.dir), 0.0, 1e-15);
  EXPECT_NEAR(glm::length(glm::cross(v.u, v.v) - v.dir), 0.0, 1e-15);
  EXPECT_EQ(std::max(v.width, v.height), 100);
  // Every box corner projects into the image and into [0, depth_extent].
  for (int c = 0; c < 8; ++c) {
    const glm::dvec3 p{c & 1 ? kBox.hi.x : kBox.lo.x, c & 2 ? kBox.hi.y : kBox.lo.y,
                       c & 4 ? kBox.hi.z : kBox.lo.z};
    const glm::dvec3 q = p - v.origin;
    EXPECT_GE(glm::dot(q, v.u) / v.spacing, -1e-9);
    EXPECT_LE(glm::dot(q, v.u) / v.spacing, v.width + 1e-9);
    EXPECT_GE(glm::dot(q, v.v) / v.spacing, -1e-9);
    EXPECT_LE(glm::dot(q, v.v) / v.spacing, v.height + 1e-9);
    EXPECT_GE(glm::dot(q, v.dir), -1e-12);
    EXPECT_LE(glm::dot(q, v.dir), v.depth_extent + 1e-12);
  }
}

TEST(View, RejectsBadInput) {
  EXPECT_THROW(make_view(kBox, {0, 0, 0}, 10), std::invalid_argument);
  EXPECT_THROW(make_view(kBox, {0, 0, 1}, 0), std::invalid_argument);
  EXPECT_THROW(make_view(Box{}, {0, 0, 1}, 10), std::invalid_argument);
  EXPECT_THROW(make_axis_views(kBox, 10, "xw"), std::invalid_argument);
  EXPECT_THROW(make_axis_views(kBox, 10, "xx"), std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

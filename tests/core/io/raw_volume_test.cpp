#include "ldimesh/core/io/raw_volume.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

class RawVolumeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = (std::filesystem::temp_directory_path() /
             ("ldimesh_raw_" + std::to_string(::getpid()) + ".raw"))
                .string();
  }
  void TearDown() override { std::filesystem::remove(path_); }
  void write(const std::vector<float>& v) {
    std::ofstream(path_, std::ios::binary)
        .write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 4));
  }
  std::string path_;
};

TEST_F(RawVolumeTest, ReadsAVolumeThatMeshesLikeTheSamplesSay) {
  const int n = 16;
  std::vector<float> v(n * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        v[(k * n + j) * n + i] = float(i);  // f = x: planes x = const
  write(v);
  RawVolume vol;
  ASSERT_TRUE(read_raw_volume(path_, {n, n, n}, ScalarType::float32, glm::dvec3(0.0),
                              glm::dvec3(0.5), vol));
  EXPECT_EQ(vol.min_value, 0.0);
  EXPECT_EQ(vol.max_value, 15.0);
  const GridSource grid(vol.block);
  EXPECT_EQ(grid.bounds().hi.x, 7.5);
  // Every ray along x crosses the plane f = 6.25 once, at x = 3.125.
  const RayCaster caster(grid, 6.25);
  const Ldi ldi = caster.cast(make_axis_views(grid.bounds(), 8, "x")[0]);
  ASSERT_EQ(ldi.sample_count(), ldi.pixel_count());
  for (float d : ldi.depth)
    EXPECT_NEAR(d, 3.125, 1e-6);
}

TEST_F(RawVolumeTest, WrongSizeMissingFileAndNaNAreErrors) {
  write(std::vector<float>(100, 1.0f));
  RawVolume vol;
  const Status size =
      read_raw_volume(path_, {4, 5, 6}, ScalarType::float32, {}, glm::dvec3(1.0), vol);
  ASSERT_FALSE(size);
  EXPECT_NE(size.message().find("400 bytes"), std::string::npos) << size.message();
  EXPECT_NE(size.message().find("480"), std::string::npos) << size.message();
  EXPECT_FALSE(read_raw_volume(path_ + ".missing", {4, 5, 5}, ScalarType::float32, {},
                               glm::dvec3(1.0), vol));
  EXPECT_FALSE(read_raw_volume(path_, {1, 10, 10}, ScalarType::float32, {}, glm::dvec3(1.0), vol));
  std::vector<float> bad(100, 1.0f);
  bad[37] = std::nanf("");
  write(bad);
  EXPECT_FALSE(read_raw_volume(path_, {4, 5, 5}, ScalarType::float32, {}, glm::dvec3(1.0), vol));
}

// Found by fuzzing (scripts/fuzz.sh raw): 2⁸·2⁴⁰·2¹⁵ = 2⁶³ float32 values fit a 64-bit count but
// their 2⁶⁵ bytes wrapped to 0, so an empty file was read as that volume.
TEST_F(RawVolumeTest, DimensionsWhoseByteCountOverflowsAreRefused) {
  write({});
  RawVolume vol;
  const std::int64_t big = std::int64_t(1) << 40;
  const Status s =
      read_raw_volume(path_, {256, big, 32768}, ScalarType::float32, {}, glm::dvec3(1.0), vol);
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("overflow"), std::string::npos) << s.message();
  // 2⁶¹ float64 values: 2⁶⁴ bytes, which wraps to exactly 0.
  const std::int64_t m = std::int64_t(1) << 20;
  const Status wide =
      read_raw_volume(path_, {m, m, 2 * m}, ScalarType::float64, {}, glm::dvec3(1.0), vol);
  ASSERT_FALSE(wide);
  EXPECT_NE(wide.message().find("overflow"), std::string::npos) << wide.message();
}

}  // namespace
}  // namespace ldimesh

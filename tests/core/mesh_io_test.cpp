#include "ldimesh/core/mesh_io.hpp"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include <gtest/gtest.h>

namespace ldimesh {
namespace {

Mesh two_faces() {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {2, 0, 0}};
  m.normals.assign(5, {0, 0, 1});
  m.quads = {0, 1, 2, 3};
  m.quad_view = {0};
  m.triangles = {1, 4, 2};
  m.triangle_view = {1};
  m.view_dirs = {{1, 0, 0}, {0, 0, 1}};
  return m;
}

class MeshIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("ldimesh_io_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::filesystem::path dir_;
};

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

TEST_F(MeshIo, PlyHasHeaderCountsAndBinaryBody) {
  ASSERT_TRUE(write_ply(path("m.ply"), two_faces()));
  const std::string bytes = slurp(path("m.ply"));
  const std::size_t end = bytes.find("end_header\n");
  ASSERT_NE(end, std::string::npos);
  const std::string header = bytes.substr(0, end);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(header.find("element vertex 5"), std::string::npos);
  EXPECT_NE(header.find("element face 2"), std::string::npos);
  EXPECT_NE(header.find("comment view 1 dir 0 0 1"), std::string::npos);
  const std::size_t body = bytes.size() - end - std::strlen("end_header\n");
  EXPECT_EQ(body, 5 * 24 + (1 + 16 + 1) + (1 + 12 + 1));
  // The triangle is the last face: count 3, indices 1 4 2, view 1.
  const char* tri = bytes.data() + bytes.size() - 14;
  std::uint32_t idx[3];
  std::memcpy(idx, tri + 1, 12);
  EXPECT_EQ(tri[0], 3);
  EXPECT_EQ(idx[1], 4u);
  EXPECT_EQ(tri[13], 1);
}

TEST_F(MeshIo, ObjHasOneBasedFacesGroupedByView) {
  ASSERT_TRUE(write_mesh(path("m.OBJ"), two_faces()));
  const std::string text = slurp(path("m.OBJ"));
  EXPECT_NE(text.find("v 2 0 0\n"), std::string::npos);
  EXPECT_NE(text.find("g view_0\nf 1//1 2//2 3//3 4//4\n"), std::string::npos);
  EXPECT_NE(text.find("g view_1\nf 2//2 5//5 3//3\n"), std::string::npos);
}

TEST_F(MeshIo, UnwritablePathsAndUnknownFormatsAreErrors) {
  const Status missing = write_ply(path("no/such/folder/m.ply"), two_faces());
  EXPECT_FALSE(missing);
  EXPECT_NE(missing.message().find("cannot write"), std::string::npos);
  const Status format = write_mesh(path("m.stl"), two_faces());
  EXPECT_FALSE(format);
  EXPECT_NE(format.message().find(".ply or .obj"), std::string::npos);
}

}  // namespace
}  // namespace ldimesh

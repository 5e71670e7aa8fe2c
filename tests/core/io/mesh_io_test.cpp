#include "ldimesh/core/io/mesh_io.hpp"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
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

TEST_F(MeshIo, MalformedMeshesAreRefusedBeforeAnyFileIsWritten) {
  Mesh bad = two_faces();
  bad.triangles[1] = 7;  // beyond the 5 vertices
  Mesh short_normals = two_faces();
  short_normals.normals.pop_back();
  for (const Mesh* m : {&bad, &short_normals})
    for (const char* name : {"bad.ply", "bad.obj"}) {
      const Status s = write_mesh(path(name), *m);
      EXPECT_EQ(s.code(), StatusCode::invalid_argument) << name;
      EXPECT_FALSE(std::filesystem::exists(path(name))) << name;
    }
  EXPECT_NE(write_ply(path("bad.ply"), bad).message().find("write_ply: "), std::string::npos);
}

TEST_F(MeshIo, MeshesWithoutViewsAreWrittenAsView0) {
  Mesh m = two_faces();
  m.quad_view.clear();
  m.triangle_view.clear();
  ASSERT_TRUE(write_ply(path("m.ply"), m));
  ASSERT_TRUE(write_obj(path("m.obj"), m));
  Mesh r;
  ASSERT_TRUE(read_ply(path("m.ply"), r));
  EXPECT_EQ(r.quad_view, std::vector<std::uint8_t>{0});
  EXPECT_EQ(r.triangle_view, std::vector<std::uint8_t>{0});
  const std::string text = slurp(path("m.obj"));
  EXPECT_NE(text.find("g view_0\nf 1//1 2//2 3//3 4//4\nf 2//2 5//5 3//3\n"), std::string::npos);
}

// ---- Reading PLY ----

TEST_F(MeshIo, PlyRoundTripsThroughReadPly) {
  const Mesh m = two_faces();
  ASSERT_TRUE(write_ply(path("m.ply"), m));
  Mesh r;
  const Status s = read_ply(path("m.ply"), r);
  ASSERT_TRUE(s) << s.message();
  EXPECT_EQ(r.positions, m.positions);
  EXPECT_EQ(r.normals, m.normals);
  EXPECT_EQ(r.quads, m.quads);
  EXPECT_EQ(r.triangles, m.triangles);
  EXPECT_EQ(r.quad_view, m.quad_view);
  EXPECT_EQ(r.triangle_view, m.triangle_view);
  EXPECT_EQ(r.view_dirs, m.view_dirs);
  // What was read writes the same bytes again.
  ASSERT_TRUE(write_ply(path("again.ply"), r));
  EXPECT_EQ(slurp(path("again.ply")), slurp(path("m.ply")));
}

// A mesh with scalars (a field to colour by) writes a float `value` per vertex and reads back the
// same; a `value` given as a list is not one (skipped), a non-finite one is an error.
TEST_F(MeshIo, ScalarsRoundTripAsThePlyValueProperty) {
  Mesh m = two_faces();
  m.scalars = {0.0f, -1.5f, 2.25f, 1e-20f, 3.0f};
  ASSERT_TRUE(write_ply(path("s.ply"), m));
  EXPECT_NE(slurp(path("s.ply")).find("property float nz\nproperty float value\n"),
            std::string::npos);
  Mesh r;
  ASSERT_TRUE(read_ply(path("s.ply"), r));
  EXPECT_EQ(r.scalars, m.scalars);
  ASSERT_TRUE(write_ply(path("s2.ply"), r));
  EXPECT_EQ(slurp(path("s2.ply")), slurp(path("s.ply")));
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\n";
  const std::string faces = "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  Mesh listed;
  ASSERT_TRUE(parse_ply(head + "property list uchar float value\n" + faces +
                            "0 0 0 1 7\n1 0 0 1 7\n0 1 0 1 7\n3 0 1 2\n",
                        listed));
  EXPECT_TRUE(listed.scalars.empty());
  Mesh bad;
  const Status s = parse_ply(
      head + "property float value\n" + faces + "0 0 0 1\n1 0 0 nan\n0 1 0 2\n3 0 1 2\n", bad);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("vertex 1: value is not finite"), std::string::npos) << s.message();
}

TEST(PlyReader, AsciiWithoutNormalsAndWithPolygons) {
  // A unit square as one pentagon-free quad, a triangle, and a pentagon (a fan of 3 triangles);
  // CRLF line ends, extra properties and an extra element are skipped.
  const std::string text =
      "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\n"
      "element vertex 6\r\nproperty double x\r\nproperty double y\r\nproperty float z\r\n"
      "property uchar red\r\n"
      "element face 3\r\nproperty list uchar int vertex_index\r\nproperty int flags\r\n"
      "element edge 1\r\nproperty int a\r\nproperty int b\r\nend_header\r\n"
      "0 0 0 255\r\n1 0 0 0\r\n1 1 0 0\r\n0 1 0 0\r\n2 0 0 0\r\n2 1 0.5 0\r\n"
      "4 0 1 2 3 7\r\n3 1 4 2 0\r\n5 0 1 4 5 3 -1\r\n"
      "0 1\r\n";
  Mesh m;
  const Status s = parse_ply(text, m);
  ASSERT_TRUE(s) << s.message();
  ASSERT_EQ(m.vertex_count(), 6u);
  EXPECT_EQ(m.positions[5], glm::vec3(2, 1, 0.5f));
  EXPECT_EQ(m.quads, (std::vector<std::uint32_t>{0, 1, 2, 3}));
  EXPECT_EQ(m.triangles, (std::vector<std::uint32_t>{1, 4, 2, 0, 1, 4, 0, 4, 5, 0, 5, 3}));
  EXPECT_EQ(m.triangle_view, std::vector<std::uint8_t>(4, 0));
  EXPECT_EQ(m.quad_view, std::vector<std::uint8_t>(1, 0));
  // Normals from the faces: the square and the triangle face +z.
  ASSERT_EQ(m.normals.size(), 6u);
  EXPECT_NEAR(m.normals[2].z, 1.0f, 1e-6f);
  EXPECT_NEAR(glm::length(m.normals[5]), 1.0f, 1e-6f);
}

// Binary big-endian with double coordinates and int indices.
TEST(PlyReader, BinaryBigEndian) {
  std::string bytes =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\n"
      "property double y\nproperty double z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n";
  auto put = [&](auto v) {
    char b[sizeof(v)];
    std::memcpy(b, &v, sizeof(v));
    std::reverse(b, b + sizeof(v));  // the test machine is little-endian
    bytes.append(b, sizeof(v));
  };
  for (double c : {0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, -2.0, 0.25})
    put(c);
  bytes += char(3);
  for (std::int32_t i : {0, 1, 2})
    put(i);
  Mesh m;
  const Status s = parse_ply(bytes, m);
  ASSERT_TRUE(s) << s.message();
  EXPECT_EQ(m.positions[1], glm::vec3(1.5f, 0, 0));
  EXPECT_EQ(m.positions[2], glm::vec3(0, -2.0f, 0.25f));
  EXPECT_EQ(m.triangles, (std::vector<std::uint32_t>{0, 1, 2}));
}

// Every way a file can lie about itself: an error with a message, never a crash, and no mesh.
TEST(PlyReader, BadFilesAreErrors) {
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string verts = "0 0 0\n1 0 0\n0 1 0\n";
  const std::pair<std::string, std::string> cases[] = {
      {"", "not a PLY file"},
      {"solid stl\n", "not a PLY file"},
      {"ply\nformat ascii 1.0\nelement vertex 1\n", "no end_header"},
      {"ply\nelement vertex 0\nend_header\n", "no format"},
      {"ply\nformat ascii 2.0\nend_header\n", "bad format"},
      {"ply\nformat binary_middle_endian 1.0\nend_header\n", "unknown format"},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "property before any element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
       "unknown property type"},
      {"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "bad element line"},
      {"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no vertex element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n"
       "0 0\n",
       "no property z"},
      {"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
       "property float z\nend_header\n0 0 0\n",
       "too short"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty list float int vertex_indices\nend_header\n",
       "integer type"},
      {head + verts + "3 0 1 3\n", "out of range"},
      {head + verts + "3 0 -1 2\n", "out of range"},
      {head + verts + "2 0 1\n", "at least 3"},
      {head + verts + "3 0 1\n", "ends early"},
      {head + verts + "3 0 1 2\n5 5 5\n", "data after the last element"},
      {head + "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "non-finite"},
      {head + "0 0 0\n1 1e99 0\n0 1 0\n3 0 1 2\n", "non-finite"},
      {head + "0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "malformed"},
      {head + verts + "300 0 1 2\n", "malformed or out-of-range"},
  };
  for (const auto& [bytes, message] : cases) {
    Mesh m;
    const Status s = parse_ply(bytes, m);
    EXPECT_FALSE(s) << bytes;
    EXPECT_NE(s.message().find(message), std::string::npos) << s.message() << "\n" << bytes;
    EXPECT_EQ(m.vertex_count(), 0u);
  }
  Mesh ok;
  EXPECT_TRUE(parse_ply(head + verts + "3 0 1 2\n", ok));
  Mesh m;
  const Status missing = read_ply("/no/such/file.ply", m);
  EXPECT_FALSE(missing);
  EXPECT_NE(missing.message().find("cannot read '/no/such/file.ply'"), std::string::npos);
}

// Every truncation of a binary file is an error; random bit flips give an error or a mesh whose
// indices are all in range, never a crash.
TEST_F(MeshIo, TruncatedAndCorruptedBinaryPly) {
  Mesh m = two_faces();
  ASSERT_TRUE(write_ply(path("m.ply"), m));
  const std::string bytes = slurp(path("m.ply"));
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    Mesh r;
    EXPECT_FALSE(parse_ply(std::string_view(bytes).substr(0, n), r)) << n << " bytes";
  }
  std::mt19937 rng(42);
  for (int trial = 0; trial < 2000; ++trial) {
    std::string bad = bytes;
    for (int flips = 0; flips < 3; ++flips) {
      const std::size_t at = rng() % bad.size();
      bad[at] = char(bad[at] ^ (1 << (rng() % 8)));
    }
    Mesh r;
    if (!parse_ply(bad, r)) continue;
    for (std::uint32_t i : r.triangles)
      ASSERT_LT(i, r.vertex_count());
    for (std::uint32_t i : r.quads)
      ASSERT_LT(i, r.vertex_count());
    ASSERT_EQ(r.quad_view.size(), r.quad_count());
    ASSERT_EQ(r.triangle_view.size(), r.triangle_count());
    ASSERT_EQ(r.normals.size(), r.vertex_count());
  }
}

}  // namespace
}  // namespace ldimesh

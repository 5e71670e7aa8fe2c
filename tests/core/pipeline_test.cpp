#include "ldimesh/core/pipeline.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

#include <gtest/gtest.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "test_helpers.hpp"

namespace ldimesh {
namespace {

std::vector<Ldi> cast_axis_views(const FieldSource& source, double iso, int res) {
  const RayCaster caster(source, iso);
  std::vector<Ldi> ldis;
  for (const View& v : make_axis_views(source.bounds(), res))
    ldis.push_back(caster.cast(v));
  return ldis;
}

MeshingResult mesh_surface(std::string_view name, int res, double r) {
  const SurfaceInfo* s = find_surface(name);
  const auto source = make_surface_source(name);
  MeshingOptions options;
  options.r = r;
  return mesh_ldis(cast_axis_views(*source, s->isovalue, res), options);
}

double sphere_distance(glm::dvec3 p) {
  return std::abs(glm::length(p) - 1.0);
}
double torus_distance(glm::dvec3 p) {
  const fields::Torus t;
  return std::abs(std::hypot(std::hypot(p.x, p.y) - t.R, p.z) - t.a);
}

template <class Distance>
void expect_on_surface(const Mesh& mesh, Distance distance, double spacing) {
  ASSERT_GT(mesh.triangle_count(), 1000u);
  for (const glm::vec3& p : mesh.positions)
    ASSERT_LT(distance(glm::dvec3(p)), 1e-4);
  // A face that joined two layers would cut through the inside: its centroid would lie far
  // from the surface. Faces of one layer deviate by their sagitta, a small fraction of a pixel.
  for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
    const std::uint32_t* t = &mesh.triangles[3 * f];
    const glm::dvec3 c = (glm::dvec3(mesh.positions[t[0]]) + glm::dvec3(mesh.positions[t[1]]) +
                          glm::dvec3(mesh.positions[t[2]])) /
                         3.0;
    ASSERT_LT(distance(c), 0.25 * spacing) << "face " << f;
  }
}

TEST(Pipeline, SphereMeshLiesOnTheSphereAndKeepsLayersApart) {
  const int res = 64;
  const MeshingResult result = mesh_surface("sphere", res, 0.5);
  const Mesh& mesh = result.mesh;
  expect_on_surface(mesh, sphere_distance, 2.5 / res);
  // The front and back layers of each view never share a face.
  for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
    const glm::vec3 d(mesh.view_dirs[mesh.triangle_view[f]]);
    const std::uint32_t* t = &mesh.triangles[3 * f];
    const bool front = glm::dot(mesh.normals[t[0]], d) < 0;
    for (int c = 1; c < 3; ++c)
      ASSERT_EQ(glm::dot(mesh.normals[t[c]], d) < 0, front) << "face " << f;
  }
}

TEST(Pipeline, TorusMeshLiesOnTheTorus) {
  const int res = 96;
  const MeshingResult result = mesh_surface("torus", res, 0.5);
  expect_on_surface(result.mesh, torus_distance, 3.0 / res);
}

// Spheres of radius 1 and 0.9: f = (r² − 1)(r² − 0.81) = 0.
struct Concentric {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    const T r2 = sqr(x) + sqr(y) + sqr(z);
    return (r2 - 1.0) * (r2 - 0.81);
  }
};

MeshingOptions with_r(double r) {
  MeshingOptions options;
  options.r = r;
  return options;
}

TEST(Pipeline, ConcentricSpheresAreMeshedSeparately) {
  const AnalyticSource<Concentric> source(Concentric{},
                                          {{-1.25, -1.25, -1.25}, {1.25, 1.25, 1.25}});
  const Mesh mesh = mesh_ldis(cast_axis_views(source, 0.0, 64), with_r(0.0)).mesh;
  ASSERT_GT(mesh.triangle_count(), 1000u);
  for (std::size_t f = 0; f < mesh.triangle_count(); ++f) {
    const std::uint32_t* t = &mesh.triangles[3 * f];
    const bool outer = glm::length(mesh.positions[t[0]]) > 0.95f;
    for (int c = 1; c < 3; ++c)
      ASSERT_EQ(glm::length(mesh.positions[t[c]]) > 0.95f, outer) << "face " << f;
  }
}

TEST(Pipeline, WithoutTrimmingTheViewsCoverTheWholeSphere) {
  const Mesh mesh = mesh_surface("sphere", 48, 0.0).mesh;
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  int missed = 0;
  for (int k = 0; k < 400; ++k) {
    const glm::dvec3 dir = glm::normalize(glm::dvec3(g(rng), g(rng), g(rng)));
    if (!testing::ray_hits_mesh(mesh, {0, 0, 0}, dir, 0.95, 1.05)) ++missed;
  }
  EXPECT_EQ(missed, 0);
}

TEST(Pipeline, WithoutTrimmingTheViewsCoverTheWholeTorus) {
  const fields::Torus torus;
  const Mesh mesh = mesh_surface("torus", 64, 0.0).mesh;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> angle(0.0, 2 * std::numbers::pi);
  int missed = 0;
  for (int k = 0; k < 300; ++k) {
    // From a point of the tube's core circle outward through the tube wall.
    const double phi = angle(rng), theta = angle(rng);
    const glm::dvec3 core{torus.R * std::cos(phi), torus.R * std::sin(phi), 0.0};
    const glm::dvec3 out{std::cos(theta) * std::cos(phi), std::cos(theta) * std::sin(phi),
                         std::sin(theta)};
    if (!testing::ray_hits_mesh(mesh, core, out, 0.9 * torus.a, 1.1 * torus.a)) ++missed;
  }
  EXPECT_EQ(missed, 0);
}

TEST(Pipeline, LargerRKeepsFewerFaces) {
  const auto source = make_surface_source("torus");
  const std::vector<Ldi> ldis = cast_axis_views(*source, 0.0, 64);
  std::size_t previous = SIZE_MAX;
  for (double r : {0.0, 0.3, 0.5, 0.7, 1.0}) {
    const std::size_t faces = mesh_ldis(ldis, with_r(r)).mesh.face_count();
    EXPECT_LT(faces, previous) << "r = " << r;
    previous = faces;
  }
  EXPECT_GT(previous, 0u);
  EXPECT_THROW(mesh_ldis(ldis, with_r(1.5)), std::invalid_argument);
}

TEST(Pipeline, QuadOutputHasOnlyQuads) {
  const auto source = make_surface_source("sphere");
  MeshingOptions options;
  options.faces = FaceType::quads;
  const MeshingResult result = mesh_ldis(cast_axis_views(*source, 1.0, 32), options);
  EXPECT_EQ(result.mesh.triangle_count(), 0u);
  EXPECT_EQ(result.mesh.quad_count(), result.quads);
  EXPECT_GT(result.quads, 100u);
}

TEST(Pipeline, ObliqueViewsWork) {
  const auto source = make_surface_source("sphere");
  const RayCaster caster(*source, 1.0);
  std::vector<Ldi> ldis;
  for (glm::dvec3 d : {glm::dvec3(1, 1, 0), glm::dvec3(1, -1, 0.5), glm::dvec3(0.2, 0.1, -1)})
    ldis.push_back(caster.cast(make_view(source->bounds(), d, 64)));
  const Mesh mesh = mesh_ldis(ldis, {}).mesh;
  expect_on_surface(mesh, sphere_distance, 2.5 * std::sqrt(2.0) / 64);
}

TEST(Pipeline, EmptyAndOneSampleLdisGiveAnEmptyMesh) {
  const View view = make_view({{0, 0, 0}, {1, 1, 1}}, {0, 0, 1}, 4);
  Ldi one = make_empty_ldi(view);
  one.depth = {0.5f};
  one.normal = {{0, 0, -1}};
  for (std::size_t p = 6; p < one.offsets.size(); ++p)
    one.offsets[p] = 1;  // pixel 5 holds it
  for (const Ldi& ldi : {make_empty_ldi(view), one}) {
    const MeshingResult result = mesh_ldis(std::span<const Ldi>(&ldi, 1), {});
    EXPECT_EQ(result.mesh.face_count(), 0u);
    EXPECT_EQ(result.mesh.vertex_count(), 0u);
  }
  EXPECT_EQ(mesh_ldis({}, {}).mesh.face_count(), 0u);
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

TEST(Pipeline, SameFileForOneThreadAndForManyThreads) {
  const auto dir = std::filesystem::temp_directory_path() / "ldimesh_determinism";
  std::filesystem::create_directories(dir);
  auto run = [&](int threads, const std::string& name) {
    tbb::task_arena arena(threads);
    arena.execute([&] {
      const auto source = make_surface_source("barth");
      const MeshingResult result = mesh_ldis(cast_axis_views(*source, 0.0, 96), {});
      ASSERT_TRUE(write_ply((dir / name).string(), result.mesh));
    });
    return read_file(dir / name);
  };
  const std::string one = run(1, "one.ply");
  const std::string many = run(tbb::info::default_concurrency(), "many.ply");
  EXPECT_GT(one.size(), 100000u);
  EXPECT_TRUE(one == many) << "PLY files differ between 1 thread and all cores";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace ldimesh

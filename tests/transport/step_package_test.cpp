#include "ldimesh/transport/step_package.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "ldimesh/core/base/view.hpp"

namespace ldimesh {
namespace {

// A square of two triangles at height z, its vertices coloured by `colour` (none if empty).
StepSurface square(float z, std::vector<float> colour, std::size_t samples) {
  StepSurface r;
  r.mesh.positions = {{0, 0, z}, {1, 0, z}, {1, 1, z}, {0, 1, z}};
  r.mesh.normals.assign(4, {0, 0, 1});
  r.mesh.triangles = {0, 1, 2, 0, 2, 3};
  r.mesh.triangle_view = {2, 2};  // both from the z view
  r.mesh.scalars = std::move(colour);
  r.samples = samples;
  r.quads = 1;
  return r;
}

StepDescription description(std::size_t surfaces) {
  StepDescription d;
  d.step = 7;
  d.time = 0.25;
  for (std::size_t i = 0; i < surfaces; ++i)
    d.isovalues.push_back(0.1 * double(i + 1));
  d.views = make_axis_views({glm::dvec3(0.0), glm::dvec3(1.0)}, 32);
  return d;
}

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Two isosurfaces: one mesh each in the GLB, in order, the counts summed, the step described.
TEST(StepPackage, SurfacesAreJoinedInOrderAndDescribed) {
  std::vector<StepSurface> results;
  results.push_back(square(0.2f, {}, 10));
  results.push_back(square(0.7f, {}, 5));
  PackagedStep out;
  ASSERT_TRUE(package_step(description(2), std::move(results), out));
  ASSERT_EQ(out.mesh.vertex_count(), 8u);
  EXPECT_EQ(out.mesh.positions[4].z, 0.7f);
  EXPECT_EQ(out.mesh.triangles[6], 4u);  // the second surface's indices moved on
  EXPECT_EQ(out.metadata.step, 7u);
  EXPECT_EQ(out.metadata.samples, 15u);
  EXPECT_EQ(out.metadata.quads, 2u);
  EXPECT_EQ(out.metadata.triangles, 4u);
  EXPECT_EQ(out.metadata.isovalues.size(), 2u);
  EXPECT_FALSE(out.metadata.scalar);
  EXPECT_TRUE(out.metadata.surface_scalars.empty());
  EXPECT_TRUE(out.metadata.seconds.count("glb"));
  Mesh decoded;
  ASSERT_TRUE(decode_glb(out.glb, decoded));
  EXPECT_EQ(decoded.triangle_count(), 4u);
  // Without encoding: the joined mesh only.
  std::vector<StepSurface> again;
  again.push_back(square(0.2f, {}, 10));
  StepDescription plain = description(1);
  plain.encode = false;
  ASSERT_TRUE(package_step(plain, std::move(again), out));
  EXPECT_EQ(out.mesh.vertex_count(), 4u);
  EXPECT_TRUE(out.glb.empty());
}

// One colour field: the non-finite values take the field's lowest finite value on the step's
// surfaces, and the metadata names the field and its range.
TEST(StepPackage, OneFieldColoursEverySurfaceAndRepairsNonFiniteValues) {
  std::vector<StepSurface> results;
  results.push_back(square(0.2f, {2.0f, kNaN, 3.0f, 4.0f}, 1));
  results.push_back(square(0.7f, {1.5f, 2.5f, INFINITY, 3.5f}, 1));
  StepDescription d = description(2);
  d.colour_fields = {"T"};
  d.surface_field = {0, 0};
  PackagedStep out;
  ASSERT_TRUE(package_step(d, std::move(results), out));
  EXPECT_EQ(out.uncoloured, 2u);
  EXPECT_EQ(out.mesh.scalars[1], 1.5f);
  EXPECT_EQ(out.mesh.scalars[6], 1.5f);
  ASSERT_TRUE(out.metadata.scalar);
  EXPECT_EQ(out.metadata.scalar->name, "T");
  EXPECT_EQ(out.metadata.scalar->min, 1.5f);
  EXPECT_EQ(out.metadata.scalar->max, 4.0f);
  EXPECT_TRUE(out.metadata.surface_scalars.empty());
}

// Surfaces coloured by different fields, or one by none: each field its own range, per surface
// in the metadata, and a repaired value from its own field only.
TEST(StepPackage, SurfacesOfDifferentFieldsKeepTheirOwnRanges) {
  std::vector<StepSurface> results;
  results.push_back(square(0.2f, {10.0f, 20.0f, kNaN, 30.0f}, 1));
  results.push_back(square(0.5f, {}, 1));
  results.push_back(square(0.7f, {-1.0f, 0.0f, 1.0f, 2.0f}, 1));
  StepDescription d = description(3);
  d.colour_fields = {"T", "p"};
  d.surface_field = {0, -1, 1};
  PackagedStep out;
  ASSERT_TRUE(package_step(d, std::move(results), out));
  EXPECT_EQ(out.uncoloured, 1u);
  EXPECT_EQ(out.mesh.scalars[2], 10.0f);  // T's lowest, not p's
  ASSERT_EQ(out.metadata.surface_scalars.size(), 3u);
  ASSERT_TRUE(out.metadata.surface_scalars[0]);
  EXPECT_EQ(out.metadata.surface_scalars[0]->name, "T");
  EXPECT_EQ(out.metadata.surface_scalars[0]->min, 10.0f);
  EXPECT_EQ(out.metadata.surface_scalars[0]->max, 30.0f);
  EXPECT_FALSE(out.metadata.surface_scalars[1]);
  ASSERT_TRUE(out.metadata.surface_scalars[2]);
  EXPECT_EQ(out.metadata.surface_scalars[2]->name, "p");
  EXPECT_EQ(out.metadata.surface_scalars[2]->max, 2.0f);
}

}  // namespace
}  // namespace ldimesh

// Ray casting by subdomains, as MPI ranks do it, in one process: the fragments of subdomains
// that tile the domain must merge into exactly the LDI of the whole domain.
#include <memory>

#include <gtest/gtest.h>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

// The plane x = 0: every ray along x hits it exactly on the face two subdomains share.
struct PlaneX {
  template <class T>
  T operator()(const T& x, const T&, const T&) const {
    return x;
  }
};

const Box kCube{{-1, -1, -1}, {1, 1, 1}};

LdiFragment cast_tiled(const RayCaster& caster, const View& view, const Box& global, int parts) {
  std::vector<LdiFragment> fragments;
  for (const Box& box : decompose_box(global, parts))
    fragments.push_back(caster.cast_fragment(view, 0, {box, global}));
  return combine_fragments(fragments, 0.0,
                           glm::vec3(view.dir));  // no tolerance: a double hit would show
}

void expect_same(const Ldi& whole, const LdiFragment& tiled) {
  const Ldi merged = ldi_from_fragment(tiled, whole.view);
  for (std::size_t p = 0; p < whole.pixel_count(); ++p)
    ASSERT_EQ(merged.count(p), whole.count(p))
        << "pixel " << p % whole.view.width << "," << p / whole.view.width << " of a view along ("
        << whole.view.dir.x << ", " << whole.view.dir.y << ", " << whole.view.dir.z << ")";
  for (std::size_t s = 0; s < whole.sample_count(); ++s)
    ASSERT_NEAR(merged.depth[s], whole.depth[s], 1e-6);
}

TEST(Subdomain, DecompositionTilesTheBox) {
  EXPECT_EQ(block_grid(kCube, 1), (std::array<int, 3>{1, 1, 1}));
  EXPECT_EQ(block_grid(kCube, 3), (std::array<int, 3>{3, 1, 1}));
  EXPECT_EQ(block_grid(kCube, 8), (std::array<int, 3>{2, 2, 2}));
  EXPECT_EQ(block_grid({{0, 0, 0}, {1, 4, 1}}, 4), (std::array<int, 3>{1, 4, 1}));
  for (int parts : {1, 2, 3, 4, 5, 6, 8, 12}) {
    const std::vector<Box> boxes = decompose_box(kCube, parts);
    ASSERT_EQ(boxes.size(), std::size_t(parts));
    double volume = 0.0;
    for (const Box& b : boxes)
      volume += b.extent().x * b.extent().y * b.extent().z;
    EXPECT_NEAR(volume, 8.0, 1e-12);
  }
  EXPECT_THROW(decompose_box(kCube, 0), std::invalid_argument);
}

TEST(Subdomain, TiledFragmentsMergeIntoTheWholeLdi) {
  for (const char* name : {"sphere", "torus", "barth"}) {
    const SurfaceInfo* s = find_surface(name);
    const auto source = make_surface_source(name);
    const RayCaster caster(*source, s->isovalue);
    std::vector<View> views = make_axis_views(s->domain, 40);
    views.push_back(make_view(s->domain, {0.4, -0.7, 0.6}, 40));
    for (const View& view : views) {
      const Ldi whole = caster.cast(view);
      for (int parts : {2, 3, 4, 7}) {
        SCOPED_TRACE(std::string(name) + " in " + std::to_string(parts) + " parts");
        expect_same(whole, cast_tiled(caster, view, s->domain, parts));
      }
    }
  }
}

TEST(Subdomain, AHitOnASharedFaceIsProducedExactlyOnce) {
  const AnalyticSource<PlaneX> plane(PlaneX{}, kCube, 0.0, 4);
  const RayCaster caster(plane, 0.0);
  // Views along +x and −x: every hit lies exactly on x = 0, the face between the 2 halves.
  for (glm::dvec3 dir : {glm::dvec3(1, 0, 0), glm::dvec3(-1, 0, 0), glm::dvec3(1, 0.3, -0.2)}) {
    const View view = make_view(kCube, dir, 16);
    const Box left{{-1, -1, -1}, {0, 1, 1}}, right{{0, -1, -1}, {1, 1, 1}};
    const LdiFragment a = caster.cast_fragment(view, 0, {left, kCube});
    const LdiFragment b = caster.cast_fragment(view, 0, {right, kCube});
    const std::vector<LdiFragment> both{a, b};
    const LdiFragment merged = combine_fragments(both, 0.0, glm::vec3(view.dir));
    std::size_t through = 0;
    for (std::uint32_t c : merged.counts)
      ASSERT_EQ(c, 1u);
    through = merged.pixels.size();
    EXPECT_EQ(a.sample_count() + b.sample_count(), through);  // never by two
    EXPECT_GT(through, 100u);                                 // never by none
  }
  // Rays lying in the face plane (a y view with a pixel column exactly at x = 0): the upper
  // side owns them.
  const View along_y = make_view(kCube, {0, 1, 0}, 63);
  ASSERT_EQ(along_y.pixel_point(0, 31, 0.0).x + 0.0, 0.0);
  const Box left{{-1, -1, -1}, {0, 1, 1}}, right{{0, -1, -1}, {1, 1, 1}};
  RaySegment seg;
  const glm::dvec3 o = along_y.pixel_point(0, 31, 0.0);
  EXPECT_FALSE(subdomain_segment({left, kCube}, o, along_y.dir, seg));
  EXPECT_TRUE(subdomain_segment({right, kCube}, o, along_y.dir, seg));
}

TEST(Subdomain, GridBlocksWithGhostLayersTileLikeOneBlock) {
  const int n = 25;
  std::vector<double> values(std::size_t(n) * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1),
                     z = -1 + 2.0 * k / (n - 1);
        values[(std::size_t(k) * n + j) * n + i] = x * x + 1.5 * y * y + z * z + 0.3 * x * y;
      }
  GridBlock whole;
  whole.dims = {n, n, n};
  whole.values = values.data();
  whole.type = ScalarType::float64;
  whole.origin = glm::dvec3(-1.0);
  whole.spacing = glm::dvec3(2.0 / (n - 1));
  const GridSource one(whole);
  const RayCaster single(one, 0.6);
  // Ranks hold parts of the cells, each with the ghost layer above it that its last cells read.
  for (std::array<int, 3> blocks : {std::array<int, 3>{2, 1, 1}, {3, 1, 1}, {2, 2, 1}, {1, 2, 2}}) {
    SCOPED_TRACE("blocks " + std::to_string(blocks[0]) + "x" + std::to_string(blocks[1]) + "x" +
                 std::to_string(blocks[2]));
    std::vector<GridPart> parts;
    for (int k = 0; k < blocks[2]; ++k)
      for (int j = 0; j < blocks[1]; ++j)
        for (int i = 0; i < blocks[0]; ++i)
          parts.push_back(grid_part(whole, blocks, {i, j, k}));
    std::vector<std::unique_ptr<GridSource>> sources;
    std::vector<std::unique_ptr<RayCaster>> casters;
    for (const GridPart& p : parts) {
      sources.push_back(std::make_unique<GridSource>(p.block));
      casters.push_back(std::make_unique<RayCaster>(*sources.back(), 0.6));
    }
    std::vector<View> views = make_axis_views(one.bounds(), 48);
    views.push_back(make_view(one.bounds(), {0.3, 0.5, -0.8}, 48));
    for (const View& view : views) {
      std::vector<LdiFragment> fragments;
      for (std::size_t r = 0; r < parts.size(); ++r)
        fragments.push_back(casters[r]->cast_fragment(view, 0, {parts[r].owned, one.bounds()}));
      expect_same(single.cast(view), combine_fragments(fragments, 0.0, glm::vec3(view.dir)));
    }
  }
  EXPECT_THROW(grid_part(whole, {30, 1, 1}, {0, 0, 0}), std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

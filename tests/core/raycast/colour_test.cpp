// Colour by a second field (FieldSource::bind_scalar): every hit carries that field's value at
// the hit, whichever caster found it. Checked against values the test computes itself: its own
// trilinear interpolation of a grid's colour points, and, on elements, colour fields whose value
// at a hit is known exactly (a world coordinate that the element's polynomials represent, or an
// affine function of the isovalue's field, constant on the isosurface).
#include <cmath>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "../field/curved_meshes.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

constexpr RayCasterOptions kEmbree{CastPath::embree};

// Calls check(view, p, scalar) for every sample of every view's LDI, p the hit's world position
// (from the pixel centre and the stored depth). Returns the number of samples.
template <class Check>
std::size_t for_each_sample(const RayCaster& caster, const std::vector<View>& views, Check check) {
  std::size_t samples = 0;
  for (const View& view : views) {
    const Ldi ldi = caster.cast(view);
    EXPECT_EQ(ldi.scalar.size(), ldi.depth.size());
    if (ldi.scalar.size() != ldi.depth.size()) return samples;
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i) {
        const std::size_t pixel = std::size_t(j) * view.width + i;
        for (std::uint32_t s = ldi.begin(pixel); s < ldi.end(pixel); ++s) {
          check(view, view.pixel_point(i, j, ldi.depth[s]), ldi.scalar[s]);
          ++samples;
        }
      }
  }
  return samples;
}

// A grid of a sphere's field |x|² with the colour g(x) = sin 3x + y·z at its points, float32;
// uniform, or rectilinear with uneven spacing.
struct ColouredGrid {
  std::array<std::vector<double>, 3> coords;
  std::vector<double> values;
  std::vector<float> colour;
  GridBlock block;
};

ColouredGrid coloured_grid(bool rectilinear) {
  ColouredGrid g;
  const std::array<std::int64_t, 3> dims{20, 18, 16};
  for (int a = 0; a < 3; ++a)
    for (std::int64_t i = 0; i < dims[a]; ++i)
      g.coords[a].push_back(-0.95 + 0.1 * double(i) + (rectilinear ? 0.03 * std::sin(1.7 * i) : 0));
  for (std::int64_t k = 0; k < dims[2]; ++k)
    for (std::int64_t j = 0; j < dims[1]; ++j)
      for (std::int64_t i = 0; i < dims[0]; ++i) {
        const glm::dvec3 x(g.coords[0][i], g.coords[1][j], g.coords[2][k]);
        g.values.push_back(glm::dot(x, x));
        g.colour.push_back(float(std::sin(3.0 * x.x) + x.y * x.z));
      }
  g.block.dims = dims;
  g.block.values = g.values.data();
  g.block.type = ScalarType::float64;
  if (rectilinear) {
    g.block.coords = {g.coords[0].data(), g.coords[1].data(), g.coords[2].data()};
  } else {
    g.block.origin = {-0.95, -0.95, -0.95};
    g.block.spacing = glm::dvec3(0.1);
  }
  g.block.colour = g.colour.data();
  g.block.colour_type = ScalarType::float32;
  return g;
}

// The test's own trilinear interpolation of the grid's colour points at p.
double colour_at(const ColouredGrid& g, glm::dvec3 p) {
  std::array<std::size_t, 3> cell{};
  glm::dvec3 f(0.0);
  for (int a = 0; a < 3; ++a) {
    const std::vector<double>& c = g.coords[a];
    std::size_t i = 0;
    while (i + 2 < c.size() && p[a] >= c[i + 1])
      ++i;
    cell[a] = i;
    f[a] = (p[a] - c[i]) / (c[i + 1] - c[i]);
  }
  double v = 0.0;
  for (int corner = 0; corner < 8; ++corner) {
    double w = 1.0;
    std::array<std::size_t, 3> at{};
    for (int a = 0; a < 3; ++a) {
      const bool up = (corner >> a) & 1;
      w *= up ? f[a] : 1.0 - f[a];
      at[a] = cell[a] + (up ? 1 : 0);
    }
    const std::size_t nx = g.coords[0].size(), ny = g.coords[1].size();
    v += w * double(g.colour[at[0] + nx * (at[1] + ny * at[2])]);
  }
  return v;
}

TEST(Colour, GridHitsCarryTheColourFieldsInterpolant) {
  for (bool rectilinear : {false, true}) {
    const ColouredGrid g = coloured_grid(rectilinear);
    const GridSource source(g.block, 4);
    const std::vector<View> views = make_axis_views(source.bounds(), 64);
    for (const RayCasterOptions options : {RayCasterOptions{}, kEmbree}) {
      const RayCaster caster(source, 0.5, options);
      // The colour's gradient is at most about 4; the depth is a float (about 1e-7 of the
      // domain), the colour a float too.
      double worst = 0.0;
      const std::size_t samples =
          for_each_sample(caster, views, [&](const View&, glm::dvec3 p, float scalar) {
            const double err = std::abs(double(scalar) - colour_at(g, p));
            if (!(err <= worst)) worst = err;  // NaN too
          });
      EXPECT_GT(samples, 10000u);
      EXPECT_LT(worst, 4e-6) << (rectilinear ? "rectilinear" : "uniform")
                             << (options.path == CastPath::embree ? ", Embree" : ", axis casters");
    }
  }
}

TEST(Colour, WithoutAColourFieldHitsCarryNone) {
  ColouredGrid g = coloured_grid(false);
  g.block.colour = nullptr;
  const GridSource source(g.block);
  EXPECT_EQ(source.bind_scalar(), nullptr);
  const RayCaster caster(source, 0.5);
  const Ldi ldi = caster.cast(make_axis_views(source.bounds(), 32)[0]);
  EXPECT_GT(ldi.sample_count(), 0u);
  EXPECT_TRUE(ldi.scalar.empty());
}

TEST(Colour, GridPartsWithGhostLayersGiveTheWholeBlocksColours) {
  const ColouredGrid g = coloured_grid(true);
  const GridSource whole(g.block, 4);
  std::vector<GridSource> parts;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j)
      parts.emplace_back(grid_part(g.block, {2, 3, 1}, {i, j, 0}).block, 4);
  std::vector<const FieldSource*> sources;
  for (const GridSource& s : parts)
    sources.push_back(&s);
  const RayCaster one(whole, 0.5), split(sources, 0.5);
  for (const View& view : make_axis_views(whole.bounds(), 48)) {
    const Ldi a = one.cast(view), b = split.cast(view);
    ASSERT_EQ(a.sample_count(), b.sample_count());
    ASSERT_EQ(b.scalar.size(), b.sample_count());
    for (std::size_t s = 0; s < a.sample_count(); ++s) {
      ASSERT_TRUE(std::isfinite(a.scalar[s]) && std::isfinite(b.scalar[s])) << "sample " << s;
      EXPECT_NEAR(a.scalar[s], b.scalar[s], 1e-6) << "sample " << s;
    }
  }
}

// Straight and curved elements: a colour field of the world z coordinate, which a field of order
// p ≥ q represents exactly on geometry of order q (so its value at a hit is the hit's z), and one
// of 3f − 1, which is 3·iso − 1 on the isosurface f = iso.
TEST(Colour, ElementHitsCarryTheColourFieldsPolynomial) {
  struct Case {
    const char* name;
    test::CurvedMesh field, z, affine_of_field;
  };
  const auto field = [](glm::dvec3 x) { return glm::dot(x, x); };
  const auto z = [](glm::dvec3 x) { return x.z; };
  const auto three_f_minus_one = [&](glm::dvec3 x) { return 3.0 * field(x) - 1.0; };
  std::vector<Case> cases;
  cases.push_back(
      {"distorted box, p = 3, q = 2",
       test::curved_mesh(3, 3, 2, NodeSet::gauss_lobatto_legendre, 0.08, field),
       test::curved_mesh(3, 3, 2, NodeSet::gauss_lobatto_legendre, 0.08, z),
       test::curved_mesh(3, 3, 2, NodeSet::gauss_lobatto_legendre, 0.08, three_f_minus_one)});
  cases.push_back({"straight box, p = 2, q = 1",
                   test::curved_mesh(4, 2, 1, NodeSet::equispaced, 0.0, field),
                   test::curved_mesh(4, 2, 1, NodeSet::equispaced, 0.0, z),
                   test::curved_mesh(4, 2, 1, NodeSet::equispaced, 0.0, three_f_minus_one)});
  cases.push_back(
      {"shell, p = q = 3", test::shell_mesh(2, 2, 3, 3, NodeSet::gauss_legendre, 0.5, 1.0, field),
       test::shell_mesh(2, 2, 3, 3, NodeSet::gauss_legendre, 0.5, 1.0, z),
       test::shell_mesh(2, 2, 3, 3, NodeSet::gauss_legendre, 0.5, 1.0, three_f_minus_one)});
  for (const Case& c : cases) {
    const double iso = std::string(c.name).starts_with("shell") ? 0.6 : 0.1;
    for (int which = 0; which < 2; ++which) {
      HexBlock block = c.field.block;
      const test::CurvedMesh& colour = which == 0 ? c.z : c.affine_of_field;
      block.colour = colour.values.data();
      block.colour_type = ScalarType::float64;
      const HexElementSource source(block);
      const std::vector<View> views = make_axis_views(source.bounds(), 48);
      for (const RayCasterOptions options : {RayCasterOptions{}, kEmbree}) {
        const RayCaster caster(source, iso, options);
        double worst = 0.0;
        const std::size_t samples =
            for_each_sample(caster, views, [&](const View&, glm::dvec3 p, float scalar) {
              const double expected = which == 0 ? p.z : 3.0 * iso - 1.0;
              const double err = std::abs(double(scalar) - expected);
              if (!(err <= worst)) worst = err;  // NaN too
            });
        EXPECT_GT(samples, 1000u) << c.name;
        // Float depths and colours; the root's own tolerance (1e-9 of the domain) times the
        // field's gradient for 3f − 1.
        EXPECT_LT(worst, 2e-6) << c.name << (which == 0 ? ": colour z" : ": colour 3f - 1")
                               << (options.path == CastPath::embree ? ", Embree" : ", axis");
      }
    }
  }
}

TEST(Colour, AnUnknownColourTypeIsRefused) {
  test::CurvedMesh m =
      test::curved_mesh(2, 2, 1, NodeSet::equispaced, 0.0, [](glm::dvec3 x) { return x.x; });
  m.block.colour = m.values.data();
  m.block.colour_type = ScalarType(7);
  EXPECT_THROW(HexElementSource{m.block}, std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

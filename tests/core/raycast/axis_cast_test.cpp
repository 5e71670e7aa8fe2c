// The coherent axis casters against the Embree path, the reference: the same hits (count
// equal, depth within 1e-6 of the domain size, normals within 1e-5) on random blocks and
// elements, at degenerate spots (isovalues at node values, rays exactly on grid lines and
// element faces), for whole views, subdomain fragments and single rays with depth ranges.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

constexpr RayCasterOptions kEmbree{CastPath::embree};

// The six axis views of `box`; with `pixel` > 0, pixels of that size instead of `resolution`
// along the longer side (a dyadic size makes the rays through dyadic coordinates exact).
std::vector<View> signed_axis_views(const Box& box, int resolution, double pixel = 0.0) {
  std::vector<View> views;
  for (int a = 0; a < 3; ++a)
    for (double sign : {1.0, -1.0}) {
      glm::dvec3 dir(0.0);
      dir[a] = sign;
      View view = make_view(box, dir, resolution);
      if (pixel > 0.0) {
        const double eu = view.width * view.spacing, ev = view.height * view.spacing;
        view.spacing = pixel;
        view.width = int(std::ceil(eu / pixel - 1e-9));
        view.height = int(std::ceil(ev / pixel - 1e-9));
      }
      views.push_back(view);
    }
  return views;
}

// Hit lists of two casts, ray by ray: the same number of hits on every ray, depths within
// `depth_tolerance`, normals within 1e-5. Returns the number of hits compared.
std::size_t expect_same_hits(std::span<const std::uint32_t> offsets_a,
                             std::span<const float> depth_a, std::span<const glm::vec3> normal_a,
                             std::span<const std::uint32_t> offsets_b,
                             std::span<const float> depth_b, std::span<const glm::vec3> normal_b,
                             double depth_tolerance, const std::string& what) {
  EXPECT_EQ(offsets_a.size(), offsets_b.size()) << what;
  if (offsets_a.size() != offsets_b.size()) return 0;
  for (std::size_t k = 0; k + 1 < offsets_a.size(); ++k) {
    const std::uint32_t na = offsets_a[k + 1] - offsets_a[k], nb = offsets_b[k + 1] - offsets_b[k];
    if (na != nb) {
      ADD_FAILURE() << what << ": ray " << k << " has " << na << " hits, the reference " << nb;
      return 0;
    }
    for (std::uint32_t h = 0; h < na; ++h) {
      const std::uint32_t ia = offsets_a[k] + h, ib = offsets_b[k] + h;
      if (std::abs(depth_a[ia] - depth_b[ib]) > depth_tolerance ||
          glm::length(normal_a[ia] - normal_b[ib]) > 1e-5f) {
        std::string all;
        for (std::uint32_t m = 0; m < na; ++m) {
          const glm::vec3 x = normal_a[offsets_a[k] + m], y = normal_b[offsets_b[k] + m];
          all += "\n  " + std::to_string(depth_a[offsets_a[k] + m]) + " (" + std::to_string(x.x) +
                 ", " + std::to_string(x.y) + ", " + std::to_string(x.z) + ") vs " +
                 std::to_string(depth_b[offsets_b[k] + m]) + " (" + std::to_string(y.x) + ", " +
                 std::to_string(y.y) + ", " + std::to_string(y.z) + ")";
        }
        ADD_FAILURE() << what << ": ray " << k << " hit " << h << " differs:" << all;
        return 0;
      }
    }
  }
  return depth_a.size();
}

std::size_t expect_same_ldi(const Ldi& a, const Ldi& b, double tol, const std::string& what) {
  return expect_same_hits(a.offsets, a.depth, a.normal, b.offsets, b.depth, b.normal, tol, what);
}

std::size_t expect_same_list(const RayHitList& a, const RayHitList& b, double tol,
                             const std::string& what) {
  return expect_same_hits(a.offsets, a.depth, a.normal, b.offsets, b.depth, b.normal, tol, what);
}

// Casts the six axis views (pixels of size `pixel`: 1/8 makes the rays through grid lines at
// multiples of 1/4 exact) with both casters: whole LDIs, the fragments of `parts`
// subdomains, and single rays — random image positions with random depth ranges, and image
// positions exactly on the lines x = `lines[i]` of the view's image axes (when given).
// Returns the number of hits compared. Depths within 1e-6 of the diagonal, or equal with
// `same_depths` (elements: both casters restrict and solve with the same arithmetic).
std::size_t compare_casters(const FieldSource& source, double iso, double pixel,
                            const std::vector<double>& lines, std::mt19937& rng,
                            const std::string& what, bool same_depths = false) {
  const RayCaster fast(source, iso), reference(source, iso, kEmbree);
  const Box box = source.bounds();
  const double tol = same_depths ? 0.0 : 1e-6 * box.diagonal();
  std::size_t compared = 0;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (const View& view : signed_axis_views(box, 1, pixel)) {
    EXPECT_TRUE(fast.uses_axis_casters(view));
    EXPECT_FALSE(reference.uses_axis_casters(view));
    const std::string name = what + " view (" + std::to_string(view.dir.x) + ", " +
                             std::to_string(view.dir.y) + ", " + std::to_string(view.dir.z) + ")";
    compared += expect_same_ldi(fast.cast(view), reference.cast(view), tol, name);

    const Box global = box;
    std::vector<Box> parts = decompose_box(global, 3);
    {
      // A subdomain whose faces across the ray pass exactly through pixel centres (dyadic); one
      // of them may lie outside the block (pixels reach beyond it).
      const int ua = exact_axis(view.u), va = exact_axis(view.v);
      Box part = global;
      part.hi[ua] = view.point(view.width / 2 + 0.5, 0.5, 0.0)[ua];
      part.lo[va] = view.point(0.5, view.height / 3 + 0.5, 0.0)[va];
      if (part.lo[ua] > part.hi[ua]) std::swap(part.lo[ua], part.hi[ua]);
      if (part.lo[va] > part.hi[va]) std::swap(part.lo[va], part.hi[va]);
      parts.push_back(part);
    }
    for (const Box& part : parts) {
      const Subdomain sub{part, global};
      const LdiFragment a = fast.cast_fragment(view, 0, sub),
                        b = reference.cast_fragment(view, 0, sub);
      EXPECT_EQ(a.pixels, b.pixels)
          << name << " fragment of [" << part.lo.x << ", " << part.lo.y << ", " << part.lo.z
          << "] – [" << part.hi.x << ", " << part.hi.y << ", " << part.hi.z << "] in ["
          << global.lo.x << ", " << global.lo.y << ", " << global.lo.z << "] – [" << global.hi.x
          << ", " << global.hi.y << ", " << global.hi.z << "]";
      EXPECT_EQ(a.counts, b.counts) << name << " fragment";
      EXPECT_EQ(a.depth.size(), b.depth.size()) << name << " fragment";
      if (a.depth.size() == b.depth.size()) {
        std::size_t far = 0;
        for (std::size_t s = 0; s < a.depth.size(); ++s)
          far += std::abs(a.depth[s] - b.depth[s]) > tol;
        EXPECT_EQ(far, 0u) << name << " fragment";
      }
      compared += a.depth.size();
    }

    std::vector<glm::dvec2> points, ranges;
    for (int k = 0; k < 400; ++k) {
      points.push_back({unit(rng) * view.width, unit(rng) * view.height});
      const double d0 = unit(rng) * view.depth_extent, d1 = unit(rng) * view.depth_extent;
      ranges.push_back({std::min(d0, d1), std::max(d0, d1)});
    }
    // Image positions on the grid lines / element faces: x = (X − origin) / spacing, exact for
    // the dyadic coordinates and pixel sizes the callers use (checked).
    const int ua = exact_axis(view.u), va = exact_axis(view.v);
    for (double X : lines)
      for (double Y : lines) {
        const double x = (X - view.origin[ua]) / (view.spacing * view.u[ua]);
        const double y = (Y - view.origin[va]) / (view.spacing * view.v[va]);
        EXPECT_EQ(view.point(x, y, 0.0)[ua], X);
        EXPECT_EQ(view.point(x, y, 0.0)[va], Y);
        points.push_back({x, y});
        ranges.push_back({0.0, view.depth_extent});
        points.push_back({x, unit(rng) * view.height});
        ranges.push_back({0.0, view.depth_extent});
      }
    compared += expect_same_list(fast.cast_points(view, points),
                                 reference.cast_points(view, points), tol, name + " points");
    compared += expect_same_list(fast.cast_points(view, points, nullptr, ranges),
                                 reference.cast_points(view, points, nullptr, ranges), tol,
                                 name + " points with depth ranges");
    const Subdomain sub{decompose_box(global, 2)[1], global};
    compared += expect_same_list(fast.cast_points(view, points, &sub, ranges),
                                 reference.cast_points(view, points, &sub, ranges), tol,
                                 name + " points in a subdomain");
  }
  return compared;
}

// The six axis views of `source` cast on 1, 2 and 8 threads (task arenas; 8 oversubscribes
// this machine, so that threads steal each other's tasks), each with a caster of its own built
// in the arena: the same LDIs, bit for bit, and not empty.
void expect_same_ldis_for_any_thread_count(const FieldSource& source, double iso, int resolution) {
  const std::vector<View> views = signed_axis_views(source.bounds(), resolution);
  std::vector<std::vector<Ldi>> ldis;
  for (int threads : {1, 2, 8}) {
    tbb::task_arena arena(threads);
    ldis.push_back(arena.execute([&] {
      const RayCaster caster(source, iso);
      std::vector<Ldi> out;
      for (const View& view : views)
        out.push_back(caster.cast(view));
      return out;
    }));
  }
  for (std::size_t t = 1; t < ldis.size(); ++t)
    for (std::size_t v = 0; v < views.size(); ++v) {
      EXPECT_EQ(ldis[0][v].offsets, ldis[t][v].offsets) << "view " << v;
      EXPECT_EQ(ldis[0][v].depth, ldis[t][v].depth) << "view " << v;
      EXPECT_EQ(ldis[0][v].normal, ldis[t][v].normal) << "view " << v;
      EXPECT_GT(ldis[0][v].sample_count(), 100u) << "view " << v;
    }
}

// ---------------------------------------------------------------------------------------------
// Grid blocks

struct RandomGrid {
  std::vector<double> storage64;
  std::vector<float> storage32;
  std::vector<double> coords[3];
  GridBlock block;
  std::vector<double> lines;  // coordinates of some grid lines (dyadic: exact in image space)
};

// A random block: dims 5…12 per axis, ghost layers 0…2, values from `value` (NaN where it says
// so), float or double, contiguous or strided (inside a larger array), uniform or rectilinear.
template <class Value>
RandomGrid random_grid(std::mt19937& rng, bool float32, bool strided, bool rectilinear,
                       Value value) {
  RandomGrid g;
  std::uniform_int_distribution<int> dim(5, 12), ghost(0, 2);
  GridBlock& b = g.block;
  for (int a = 0; a < 3; ++a) {
    b.dims[a] = dim(rng);
    b.ghost_lo[a] = ghost(rng) % 2;
    b.ghost_hi[a] = ghost(rng);
  }
  const std::int64_t pad = strided ? 3 : 0;
  const std::array<std::int64_t, 3> alloc{b.dims[0] + pad, b.dims[1] + 1, b.dims[2]};
  b.strides = strided ? std::array<std::int64_t, 3>{1, alloc[0], alloc[0] * alloc[1]}
                      : std::array<std::int64_t, 3>{0, 0, 0};
  const std::size_t size = std::size_t(alloc[0] * alloc[1] * alloc[2]);
  g.storage64.assign(size, 0.0);
  g.storage32.assign(size, 0.0f);
  const std::array<std::int64_t, 3> s =
      strided ? b.strides : std::array<std::int64_t, 3>{1, b.dims[0], b.dims[0] * b.dims[1]};
  for (std::int64_t k = 0; k < b.dims[2]; ++k)
    for (std::int64_t j = 0; j < b.dims[1]; ++j)
      for (std::int64_t i = 0; i < b.dims[0]; ++i) {
        const double v = value(rng);
        g.storage64[i * s[0] + j * s[1] + k * s[2]] = v;
        g.storage32[i * s[0] + j * s[1] + k * s[2]] = float(v);
      }
  b.type = float32 ? ScalarType::float32 : ScalarType::float64;
  b.values = float32 ? static_cast<const void*>(g.storage32.data())
                     : static_cast<const void*>(g.storage64.data());
  // Coordinates: multiples of 1/4 (uniform spacing 0.5, or rectilinear steps of 1/4 … 1).
  b.origin = {-1.0, -0.5, 0.25};
  b.spacing = glm::dvec3(0.5);
  std::uniform_int_distribution<int> quarter(1, 4);
  for (int a = 0; a < 3; ++a) {
    double x = b.origin[a];
    for (std::int64_t i = 0; i < b.dims[a]; ++i) {
      g.coords[a].push_back(rectilinear ? x : b.origin[a] + 0.5 * double(i));
      x += 0.25 * quarter(rng);
    }
    if (rectilinear) b.coords[a] = g.coords[a].data();
  }
  for (int a = 0; a < 3; ++a)
    for (std::size_t i = 0; i < g.coords[a].size(); i += 2)
      g.lines.push_back(g.coords[a][i]);
  std::sort(g.lines.begin(), g.lines.end());
  g.lines.erase(std::unique(g.lines.begin(), g.lines.end()), g.lines.end());
  if (g.lines.size() > 6) g.lines.resize(6);
  return g;
}

TEST(AxisCast, GridBlocksGiveTheEmbreeHits) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::size_t compared = 0;
  for (int trial = 0; trial < 16; ++trial) {
    const bool float32 = trial & 1, strided = trial & 2, rectilinear = trial & 4;
    const bool with_nan = trial & 8;
    RandomGrid g = random_grid(rng, float32, strided, rectilinear, [&](std::mt19937& r) {
      const double v = uniform(r);
      return with_nan && v > 0.93 ? std::numeric_limits<double>::quiet_NaN() : v;
    });
    const GridSource source(g.block, 1 + trial % 4);
    const std::string what = "grid trial " + std::to_string(trial);
    compared += compare_casters(source, 0.1 * (trial % 5) - 0.2, 0.125, g.lines, rng, what);
  }
  EXPECT_GT(compared, 50000u);
}

TEST(AxisCast, GridIsovaluesAtNodeValuesAndRaysOnGridLines) {
  // Values of a few integer levels and the isovalue at one of them: zeros at nodes, whole faces
  // and cells at the isovalue, rays on grid lines through them — every degenerate spot.
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> level(-2, 2);
  std::size_t compared = 0;
  for (int trial = 0; trial < 8; ++trial) {
    RandomGrid g = random_grid(rng, trial & 1, trial & 2, trial & 4,
                               [&](std::mt19937& r) { return double(level(r)); });
    const GridSource source(g.block, 2 + trial % 3);
    for (double iso : {0.0, 1.0, 0.5}) {
      const std::string what =
          "levels trial " + std::to_string(trial) + " iso " + std::to_string(iso);
      compared += compare_casters(source, iso, 0.125, g.lines, rng, what);
    }
  }
  EXPECT_GT(compared, 20000u);
}

TEST(AxisCast, GridLdiIsTheSameForAnyThreadCount) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  RandomGrid g = random_grid(rng, false, false, false, [&](std::mt19937& r) { return uniform(r); });
  const GridSource source(g.block, 3);
  expect_same_ldis_for_any_thread_count(source, 0.0, 64);
}

TEST(AxisCast, GridPrimitiveAndNonFiniteCountsMatchTheEmbreeBinding) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  RandomGrid g = random_grid(rng, true, true, false, [&](std::mt19937& r) {
    const double v = uniform(r);
    return v > 0.9 ? std::numeric_limits<double>::infinity() : v;
  });
  const GridSource source(g.block, 2);
  const RayCaster fast(source, 0.3), reference(source, 0.3, kEmbree);
  EXPECT_GT(fast.nonfinite_values(), 0u);
  EXPECT_EQ(fast.nonfinite_values(), reference.nonfinite_values());
  EXPECT_GT(fast.primitive_count(), 0u);
  EXPECT_EQ(fast.primitive_count(), reference.primitive_count());
}

TEST(AxisCast, ObliqueViewsBuildTheEmbreeSceneOnFirstUse) {
  // A caster that has cast axis views (no Embree scene yet) casts an oblique view through the
  // scene it builds then: the same LDI as a caster that built it at construction.
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  RandomGrid g = random_grid(rng, false, false, false, [&](std::mt19937& r) { return uniform(r); });
  const GridSource source(g.block, 3);
  const RayCaster caster(source, 0.0), reference(source, 0.0, kEmbree);
  EXPECT_GT(caster.cast(make_view(source.bounds(), {0, 0, 1}, 32)).sample_count(), 50u);
  const double axis_only = caster.build_seconds();
  const View oblique = make_view(source.bounds(), {1.0, 0.3, -0.2}, 32);
  EXPECT_FALSE(caster.uses_axis_casters(oblique));
  const Ldi a = caster.cast(oblique), b = reference.cast(oblique);
  EXPECT_GT(caster.build_seconds(), axis_only);  // the scene was built just now
  EXPECT_EQ(a.offsets, b.offsets);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_GT(a.sample_count(), 50u);
}

// ---------------------------------------------------------------------------------------------
// High-order elements

struct RandomElements {
  std::vector<double> corners, values;
  HexBlock block;
  std::vector<double> lines;  // element face coordinates (dyadic: exact in image space)
};

// nx × ny × nz unit elements from (−1, −0.5, 0); `frame` picks each element's reference axes:
// 0 axis-aligned, 1 permuted (ξ along y, η along z, ζ along x), 2 sheared (a parallelepiped
// leaning along x). Nodal values from `value(x, y, z, rng)` at the nodes of order p.
template <class Value>
RandomElements random_elements(std::mt19937& rng, int p, NodeSet nodes, int nx, int ny, int nz,
                               int frame, Value value) {
  RandomElements r;
  const std::vector<double> x = node_positions(p, nodes);
  const int n = p + 1;
  for (int ez = 0; ez < nz; ++ez)
    for (int ey = 0; ey < ny; ++ey)
      for (int ex = 0; ex < nx; ++ex) {
        const glm::dvec3 o(-1.0 + ex, -0.5 + ey, 0.0 + ez);
        glm::dvec3 e1(1, 0, 0), e2(0, 1, 0), e3(0, 0, 1);
        if (frame == 1) e1 = {0, 1, 0}, e2 = {0, 0, 1}, e3 = {1, 0, 0};
        if (frame == 2) e3 = {0.25, 0, 1};
        // Sheared elements lean by 1/4 per layer: layer ez starts ez/4 further along x.
        const glm::dvec3 base = frame == 2 ? o + double(ez) * glm::dvec3(0.25, 0, 0) : o;
        for (int c = 0; c < 8; ++c) {
          const glm::dvec3 q =
              base + double(c & 1) * e1 + double((c >> 1) & 1) * e2 + double((c >> 2) & 1) * e3;
          r.corners.insert(r.corners.end(), {q.x, q.y, q.z});
        }
        for (int k = 0; k < n; ++k)
          for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
              const glm::dvec3 q = base + x[i] * e1 + x[j] * e2 + x[k] * e3;
              r.values.push_back(value(q.x, q.y, q.z, rng));
            }
      }
  r.block.order = p;
  r.block.nodes = nodes;
  r.block.element_count = std::size_t(nx) * ny * nz;
  r.block.corners = r.corners.data();
  r.block.values = r.values.data();
  for (int i = 0; i <= std::max({nx, ny, nz}); ++i)
    for (double o : {-1.0, -0.5, 0.0})
      r.lines.push_back(o + i);
  std::sort(r.lines.begin(), r.lines.end());
  r.lines.erase(std::unique(r.lines.begin(), r.lines.end()), r.lines.end());
  return r;
}

TEST(AxisCast, ElementsOfEveryOrderAndNodeSetGiveTheEmbreeHits) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> noise(-0.3, 0.3);
  std::size_t compared = 0;
  for (int p = 1; p <= kMaxHexOrder; ++p)
    for (NodeSet nodes :
         {NodeSet::gauss_lobatto_legendre, NodeSet::gauss_legendre, NodeSet::equispaced}) {
      const int frame = (p + int(nodes)) % 3;
      // A smooth field (continuous across faces for GLL and equispaced nodes) with noise: several
      // roots per ray, touching roots now and then.
      RandomElements r = random_elements(
          rng, p, nodes, 3, 2, 2, frame, [&](double x, double y, double z, std::mt19937& g) {
            return std::sin(2.1 * x + 0.3) * std::cos(1.7 * y) + 0.5 * std::sin(2.3 * z + x) +
                   (p > 2 ? noise(g) : 0.0);
          });
      const HexElementSource source(r.block);
      const std::string what = "p " + std::to_string(p) + " nodes " + std::to_string(int(nodes)) +
                               " frame " + std::to_string(frame);
      compared += compare_casters(source, 0.05, 0.125, r.lines, rng, what, true);
    }
  EXPECT_GT(compared, 100000u);
}

TEST(AxisCast, ElementIsovaluesAtNodeValuesAndRaysOnElementFaces) {
  // Integer nodal levels and the isovalue at one of them; rays on element faces and edges.
  std::mt19937 rng(23);
  std::uniform_int_distribution<int> level(-2, 2);
  std::size_t compared = 0;
  for (int p : {1, 2, 3, 5})
    for (int frame = 0; frame < 3; ++frame) {
      RandomElements r = random_elements(
          rng, p, NodeSet::equispaced, 2, 2, 2, frame,
          [&](double, double, double, std::mt19937& g) { return double(level(g)); });
      const HexElementSource source(r.block);
      for (double iso : {0.0, 1.0}) {
        const std::string what = "levels p " + std::to_string(p) + " frame " +
                                 std::to_string(frame) + " iso " + std::to_string(iso);
        compared += compare_casters(source, iso, 0.125, r.lines, rng, what, true);
      }
    }
  EXPECT_GT(compared, 5000u);
}

TEST(AxisCast, ElementsWithNonFiniteValuesCountAndHitAlike) {
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  RandomElements r =
      random_elements(rng, 3, NodeSet::gauss_legendre, 3, 2, 2, 0,
                      [&](double x, double y, double z, std::mt19937& g) {
                        const double v = x * x + y * y + z * z - 1.2;
                        return unit(g) > 0.995 ? std::numeric_limits<double>::quiet_NaN() : v;
                      });
  const HexElementSource source(r.block);
  const RayCaster fast(source, 0.0), reference(source, 0.0, kEmbree);
  EXPECT_GT(fast.nonfinite_values(), 0u);
  EXPECT_EQ(fast.nonfinite_values(), reference.nonfinite_values());
  EXPECT_EQ(fast.primitive_count(), reference.primitive_count());
  EXPECT_GT(compare_casters(source, 0.0, 0.125, r.lines, rng, "nonfinite elements", true), 1000u);
}

TEST(AxisCast, ElementLdiIsTheSameForAnyThreadCount) {
  std::mt19937 rng(31);
  RandomElements r = random_elements(rng, 4, NodeSet::gauss_lobatto_legendre, 4, 3, 2, 0,
                                     [](double x, double y, double z, std::mt19937&) {
                                       return std::sin(3 * x) + std::cos(2 * y) * z;
                                     });
  const HexElementSource source(r.block);
  expect_same_ldis_for_any_thread_count(source, 0.2, 96);
}

}  // namespace
}  // namespace ldimesh

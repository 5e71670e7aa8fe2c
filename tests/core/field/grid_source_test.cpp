#include "ldimesh/core/field/grid_source.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <set>

#include <gtest/gtest.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include "../test_helpers.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

// Point values of f on an n³ grid over [lo, hi]³, x fastest.
template <class T, class F>
std::vector<T> sample(int n, double lo, double hi, F f) {
  std::vector<T> v(std::size_t(n) * n * n);
  const double h = (hi - lo) / (n - 1);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        v[(std::size_t(k) * n + j) * n + i] = T(f(lo + i * h, lo + j * h, lo + k * h));
  return v;
}

double sphere_field(double x, double y, double z) {
  return x * x + y * y + z * z;
}
// Smooth but wiggly: several roots per ray at isovalue 0.
double wavy_field(double x, double y, double z) {
  return std::sin(3.1 * x + 0.4) * std::cos(2.3 * y - 0.2) + 0.6 * std::sin(2.7 * z + 1.9 * x) -
         0.1;
}

GridBlock uniform_block(const void* values, ScalarType type, int n, double lo, double hi) {
  GridBlock b;
  b.dims = {n, n, n};
  b.values = values;
  b.type = type;
  b.origin = glm::dvec3(lo);
  b.spacing = glm::dvec3((hi - lo) / (n - 1));
  return b;
}

// The trilinear interpolant of `grid` at p (p inside the owned region).
double interpolate(const GridSource& grid, glm::dvec3 p) {
  std::array<std::int64_t, 3> c;
  glm::dvec3 w;
  for (int a = 0; a < 3; ++a) {
    std::int64_t i = grid.first_cell()[a];
    while (i < grid.last_cell()[a] && grid.coordinate(a, i + 1) <= p[a])
      ++i;
    c[a] = i;
    w[a] = (p[a] - grid.coordinate(a, i)) / (grid.coordinate(a, i + 1) - grid.coordinate(a, i));
  }
  double v = 0.0;
  for (int n = 0; n < 8; ++n) {
    const int x = n & 1, y = (n >> 1) & 1, z = (n >> 2) & 1;
    v += (x ? w.x : 1 - w.x) * (y ? w.y : 1 - w.y) * (z ? w.z : 1 - w.z) *
         grid.value(c[0] + x, c[1] + y, c[2] + z);
  }
  return v;
}

using testing::axis_and_oblique_views;

// A contiguous float64 block of 33 points along x split in two along x: A owns points 0…15 and
// reads point 16 as a ghost; B owns 16…32 and reads point 15 as a ghost. Both read the same
// array in place (offset pointer, full strides), uniform or rectilinear as `whole` is.
std::pair<GridBlock, GridBlock> split_along_x(const GridBlock& whole) {
  const std::int64_t n = whole.dims[0];
  GridBlock a = whole, b = whole;
  a.dims[0] = 17;
  a.ghost_hi[0] = 1;
  a.strides = {1, n, n * whole.dims[1]};
  b.dims[0] = n - 15;
  b.ghost_lo[0] = 1;
  b.strides = a.strides;
  b.values = static_cast<const double*>(whole.values) + 15;
  if (whole.coords[0])
    b.coords[0] = whole.coords[0] + 15;
  else
    b.origin.x = whole.origin.x + 15 * whole.spacing.x;
  return {a, b};
}

TEST(GridSource, HitsLieOnTheTrilinearSurface) {
  for (int n : {32, 64}) {
    const std::vector<float> values = sample<float>(n, -1.25, 1.25, sphere_field);
    const GridSource grid(uniform_block(values.data(), ScalarType::float32, n, -1.25, 1.25));
    const RayCaster caster(grid, 1.0);
    const auto [mn, mx] = std::minmax_element(values.begin(), values.end());
    const double range = *mx - *mn;
    std::size_t hits = 0;
    for (const View& view : axis_and_oblique_views(grid.bounds(), 48)) {
      const Ldi ldi = caster.cast(view);
      hits += ldi.sample_count();
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          const std::size_t p = std::size_t(j) * view.width + i;
          for (std::uint32_t s = ldi.begin(p); s < ldi.end(p); ++s) {
            // The stored depth is a float: allow for its rounding along the gradient (≤ 2.5).
            const glm::dvec3 x = view.pixel_point(i, j, ldi.depth[s]);
            ASSERT_LT(std::abs(interpolate(grid, x) - 1.0), 1e-5 * range + 2.5 * 2.4e-7)
                << "n " << n;
            // And close to the sphere the grid samples (trilinear error ~ h²).
            ASSERT_NEAR(glm::length(x), 1.0, 0.01);
          }
        }
    }
    EXPECT_GT(hits, 4000u);
  }
}

// Roots of the trilinear interpolant along o + t d, found by brute force: every cell near the
// ray is clipped and its interpolant scanned densely, sign changes refined by bisection.
std::vector<double> brute_force_roots(const GridSource& grid, glm::dvec3 o, glm::dvec3 d,
                                      double iso, double t_max, double h, bool& ambiguous) {
  std::set<std::array<std::int64_t, 3>> cells;
  const auto first = grid.first_cell(), last = grid.last_cell();
  for (double t = 0.0; t <= t_max; t += h / 8) {
    const glm::dvec3 p = o + t * d;
    std::array<std::int64_t, 3> c;
    for (int a = 0; a < 3; ++a)
      c[a] = std::int64_t(std::floor((p[a] - grid.coordinate(a, 0)) / h));
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const std::array<std::int64_t, 3> n{c[0] + dx, c[1] + dy, c[2] + dz};
          bool ok = true;
          for (int a = 0; a < 3; ++a)
            ok = ok && n[a] >= first[a] && n[a] <= last[a];
          if (ok) cells.insert(n);
        }
  }
  std::vector<double> roots;
  ambiguous = false;
  for (const auto& c : cells) {
    glm::dvec3 lo, hi;
    for (int a = 0; a < 3; ++a)
      lo[a] = grid.coordinate(a, c[a]), hi[a] = grid.coordinate(a, c[a] + 1);
    double t0 = 0.0, t1 = t_max;
    if (!clip_ray_to_box(o, d, lo, hi, t0, t1)) continue;
    auto f = [&](double t) {
      const glm::dvec3 w = glm::clamp((o + t * d - lo) / (hi - lo), 0.0, 1.0);
      double v = 0.0;
      for (int n = 0; n < 8; ++n) {
        const int x = n & 1, y = (n >> 1) & 1, z = (n >> 2) & 1;
        v += (x ? w.x : 1 - w.x) * (y ? w.y : 1 - w.y) * (z ? w.z : 1 - w.z) *
             grid.value(c[0] + x, c[1] + y, c[2] + z);
      }
      return v - iso;
    };
    const int steps = 200;
    double ta = t0, fa = f(t0);
    int last_change = -10;
    for (int k = 1; k <= steps; ++k) {
      const double tb = t0 + (t1 - t0) * k / steps, fb = f(tb);
      if ((fa >= 0) != (fb >= 0)) {
        if (k - last_change < 3) ambiguous = true;
        last_change = k;
        double a = ta, b = tb, ga = fa;
        for (int it = 0; it < 80; ++it) {
          const double m = 0.5 * (a + b), gm = f(m);
          if ((gm >= 0) == (ga >= 0))
            a = m, ga = gm;
          else
            b = m;
        }
        roots.push_back(0.5 * (a + b));
      }
      if (std::abs(fb) < 1e-9) ambiguous = true;  // grazing or exactly on a face
      ta = tb, fa = fb;
    }
  }
  std::sort(roots.begin(), roots.end());
  std::vector<double> merged;
  for (double r : roots)
    if (merged.empty() || r - merged.back() > 1e-9) merged.push_back(r);
  return merged;
}

// Casts `count` rays of `view` through random image positions and compares each one that the
// dense scan finds unambiguous with it (hit count, depths within 1e-6). Adds the rays compared
// and the roots they hold to `compared` and `roots`.
void expect_brute_force_hits(const RayCaster& caster, const GridSource& grid, const View& view,
                             double h, int count, std::mt19937& rng, int& compared, int& roots) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<glm::dvec2> points(count);
  for (auto& p : points)
    p = {unit(rng) * view.width, unit(rng) * view.height};
  const RayHitList hits = caster.cast_points(view, points);
  for (std::size_t k = 0; k < points.size(); ++k) {
    bool ambiguous = false;
    const glm::dvec3 o = view.point(points[k].x, points[k].y, 0.0);
    const std::vector<double> expected =
        brute_force_roots(grid, o, view.dir, 0.0, view.depth_extent, h, ambiguous);
    if (ambiguous) continue;
    ++compared;
    roots += int(expected.size());
    ASSERT_EQ(hits.offsets[k + 1] - hits.offsets[k], expected.size())
        << "view (" << view.dir.x << ", " << view.dir.y << ", " << view.dir.z << ") ray " << k;
    for (std::size_t r = 0; r < expected.size(); ++r)
      ASSERT_NEAR(hits.depth[hits.offsets[k] + r], expected[r], 1e-6);
  }
}

TEST(GridSource, RandomRaysMatchABruteForceCellSolver) {
  // Embree: 10 000 rays of 100 random directions. The coherent caster: 4 800 rays along ±x, ±y
  // and ±z.
  const int n = 24;
  const std::vector<double> values = sample<double>(n, -1.0, 1.0, wavy_field);
  const GridSource grid(uniform_block(values.data(), ScalarType::float64, n, -1.0, 1.0));
  const RayCaster caster(grid, 0.0);
  const double h = 2.0 / (n - 1);
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  int compared = 0, roots = 0;
  for (int v = 0; v < 100; ++v) {
    const View view = make_view(grid.bounds(), {normal(rng), normal(rng), normal(rng)}, 64);
    ASSERT_FALSE(caster.uses_axis_casters(view));
    expect_brute_force_hits(caster, grid, view, h, 100, rng, compared, roots);
  }
  EXPECT_GT(compared, 9800);
  EXPECT_GT(roots, 5000);  // most rays cross the surface: the comparison is not vacuous
  compared = roots = 0;
  for (int a = 0; a < 3; ++a)
    for (double sign : {1.0, -1.0}) {
      glm::dvec3 dir(0.0);
      dir[a] = sign;
      const View view = make_view(grid.bounds(), dir, 64);
      ASSERT_TRUE(caster.uses_axis_casters(view));
      expect_brute_force_hits(caster, grid, view, h, 800, rng, compared, roots);
    }
  EXPECT_GT(compared, 4500);
  EXPECT_GT(roots, 4000);
}

TEST(GridSource, TwoBlocksWithGhostLayersGiveTheSameHitsAsOneBlock) {
  const int n = 33;
  const std::vector<double> values = sample<double>(n, -1.0, 1.0, [](double x, double y, double z) {
    return sphere_field(x - 0.07, y + 0.03, z);  // the surface crosses the blocks' interface
  });
  std::vector<double> coords(n);
  for (int i = 0; i < n; ++i)
    coords[i] = -1.0 + 2.0 * i / (n - 1);
  GridBlock whole;
  whole.dims = {n, n, n};
  whole.values = values.data();
  whole.type = ScalarType::float64;
  whole.coords = {coords.data(), coords.data(), coords.data()};
  const auto [a, b] = split_along_x(whole);
  const GridSource one(whole), block_a(a), block_b(b);
  EXPECT_EQ(block_a.bounds().hi.x, coords[16]);
  EXPECT_EQ(block_b.bounds().lo.x, coords[16]);
  const RayCaster single(one, 0.5);
  const std::array<const FieldSource*, 2> pair{&block_a, &block_b};
  const RayCaster split(pair, 0.5);
  std::size_t samples = 0;
  for (const View& view : axis_and_oblique_views(one.bounds(), 64)) {
    const Ldi x = single.cast(view), y = split.cast(view);
    ASSERT_EQ(x.offsets, y.offsets);
    for (std::size_t s = 0; s < x.sample_count(); ++s)
      ASSERT_NEAR(x.depth[s], y.depth[s], 1e-6);
    samples += x.sample_count();
  }
  EXPECT_GT(samples, 5000u);
  // Either block alone misses the other's half: the ghost cells add nothing of their own.
  const RayCaster only_a(block_a, 0.5);
  const View vx = make_axis_views(one.bounds(), 64, "x")[0];
  EXPECT_LT(only_a.cast(vx).sample_count(), single.cast(vx).sample_count());
}

TEST(GridSource, FloatStridedAndRectilinearInputsReadTheSameField) {
  const int n = 20;
  const std::vector<double> dense = sample<double>(n, -1.25, 1.25, sphere_field);
  // z fastest instead of x fastest, padded rows: strides {n·(n+3), n+3, 1}.
  std::vector<float> transposed(std::size_t(n) * n * (n + 3), -99.0f);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        transposed[std::size_t(i) * n * (n + 3) + std::size_t(j) * (n + 3) + k] =
            float(dense[(std::size_t(k) * n + j) * n + i]);
  GridBlock strided = uniform_block(transposed.data(), ScalarType::float32, n, -1.25, 1.25);
  strided.strides = {std::int64_t(n) * (n + 3), n + 3, 1};
  std::vector<double> coords(n);
  for (int i = 0; i < n; ++i)
    coords[i] = -1.25 + 2.5 * i / (n - 1);
  GridBlock rect;
  rect.dims = {n, n, n};
  rect.values = dense.data();
  rect.type = ScalarType::float64;
  rect.coords = {coords.data(), coords.data(), coords.data()};
  const GridSource a(uniform_block(dense.data(), ScalarType::float64, n, -1.25, 1.25)), b(strided),
      c(rect);
  const RayCaster ca(a, 1.0), cb(b, 1.0), cc(c, 1.0);
  for (const View& view : axis_and_oblique_views(a.bounds(), 40)) {
    const Ldi la = ca.cast(view), lb = cb.cast(view), lc = cc.cast(view);
    ASSERT_EQ(la.offsets, lb.offsets);
    ASSERT_EQ(la.offsets, lc.offsets);
    for (std::size_t s = 0; s < la.sample_count(); ++s) {
      EXPECT_NEAR(la.depth[s], lb.depth[s], 1e-6);
      EXPECT_NEAR(la.depth[s], lc.depth[s], 1e-6);
      // The normals too: the uniform grid's shortcut for the blended central differences
      // (CellNormals) and the rectilinear grid's general form agree up to rounding.
      EXPECT_LT(glm::length(la.normal[s] - lb.normal[s]), 1e-5f) << "sample " << s;
      EXPECT_LT(glm::length(la.normal[s] - lc.normal[s]), 1e-5f) << "sample " << s;
    }
  }
}

TEST(GridSource, NonUniformRectilinearHitsLieOnItsInterpolant) {
  const int n = 24;
  std::vector<double> coords(n);
  for (int i = 0; i < n; ++i)
    coords[i] = 1.3 * std::sinh(2.0 * (double(i) / (n - 1) - 0.5)) / std::sinh(1.0);
  std::vector<double> values(std::size_t(n) * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        values[(std::size_t(k) * n + j) * n + i] = sphere_field(coords[i], coords[j], coords[k]);
  GridBlock block;
  block.dims = {n, n, n};
  block.values = values.data();
  block.type = ScalarType::float64;
  block.coords = {coords.data(), coords.data(), coords.data()};
  const GridSource grid(block);
  const RayCaster caster(grid, 1.0);
  std::size_t hits = 0;
  for (const View& view : axis_and_oblique_views(grid.bounds(), 40)) {
    const Ldi ldi = caster.cast(view);
    hits += ldi.sample_count();
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i)
        for (std::uint32_t s = ldi.begin(std::size_t(j) * view.width + i);
             s < ldi.end(std::size_t(j) * view.width + i); ++s)
          ASSERT_NEAR(interpolate(grid, view.pixel_point(i, j, ldi.depth[s])), 1.0, 1e-5);
  }
  EXPECT_GT(hits, 2000u);
}

TEST(GridSource, SameLdiForOneThreadAndManyThreads) {
  const int n = 48;
  const std::vector<float> values = sample<float>(n, -1.0, 1.0, wavy_field);
  const GridSource grid(uniform_block(values.data(), ScalarType::float32, n, -1.0, 1.0));
  auto cast = [&](int threads) {
    Ldi ldi;
    tbb::task_arena(threads).execute([&] {
      ldi = RayCaster(grid, 0.0).cast(make_view(grid.bounds(), {1, 2, 3}, 96));
    });
    return ldi;
  };
  const Ldi one = cast(1), many = cast(tbb::info::default_concurrency());
  EXPECT_GT(one.sample_count(), 5000u);
  EXPECT_EQ(one.offsets, many.offsets);
  EXPECT_EQ(one.depth, many.depth);
  EXPECT_TRUE(one.normal == many.normal);
}

TEST(GridSource, RejectsBadBlocks) {
  const std::vector<float> v(64, 0.0f);
  GridBlock ok = uniform_block(v.data(), ScalarType::float32, 4, 0.0, 1.0);
  EXPECT_NO_THROW(GridSource{ok});
  GridBlock b = ok;
  b.values = nullptr;
  EXPECT_THROW(GridSource{b}, std::invalid_argument);
  b = ok;
  b.dims = {1, 4, 4};
  EXPECT_THROW(GridSource{b}, std::invalid_argument);
  b = ok;
  b.spacing.y = 0.0;
  EXPECT_THROW(GridSource{b}, std::invalid_argument);
  b = ok;
  b.ghost_lo = {2, 0, 0};
  b.ghost_hi = {2, 0, 0};
  EXPECT_THROW(GridSource{b}, std::invalid_argument);
  const std::vector<double> decreasing{0.0, 1.0, 0.5, 2.0};
  b = ok;
  b.coords = {decreasing.data(), decreasing.data(), decreasing.data()};
  EXPECT_THROW(GridSource{b}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Non-finite values

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

using Index3 = std::array<std::int64_t, 3>;

// The owned cells of `grid` (lower corner indices) with a corner among `points`.
std::vector<Index3> cells_with_corner_among(const GridSource& grid,
                                            const std::vector<Index3>& points) {
  std::set<Index3> cells;
  for (const Index3& p : points)
    for (int n = 0; n < 8; ++n) {
      const Index3 c{p[0] - (n & 1), p[1] - ((n >> 1) & 1), p[2] - ((n >> 2) & 1)};
      bool owned = true;
      for (int a = 0; a < 3; ++a)
        owned = owned && c[a] >= grid.first_cell()[a] && c[a] <= grid.last_cell()[a];
      if (owned) cells.insert(c);
    }
  return {cells.begin(), cells.end()};
}

// The box of cell c grown by `pad` on every side (pad < 0 shrinks it).
Box cell_box(const GridSource& grid, const Index3& c, double pad) {
  Box box;
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = grid.coordinate(a, c[a]) - pad;
    box.hi[a] = grid.coordinate(a, c[a] + 1) + pad;
  }
  return box;
}

bool inside(const Box& box, glm::dvec3 x) {
  for (int a = 0; a < 3; ++a)
    if (!(x[a] > box.lo[a] && x[a] < box.hi[a])) return false;
  return true;
}

// The points one step along an axis from `points` (the normals' central differences read
// them), `points` included.
std::vector<Index3> with_axis_neighbours(const std::vector<Index3>& points) {
  std::vector<Index3> out;
  for (const Index3& p : points)
    for (int a = 0; a < 3; ++a)
      for (int d : {-1, 0, 1}) {
        Index3 q = p;
        q[a] += d;
        out.push_back(q);
      }
  return out;
}

// Compares the LDIs of the same views of a clean field and of the field with non-finite
// values in `bad` cells: rays that do not touch a bad cell get the same hits, bit-identical
// where they touch no cell of `stencil` either (the cells whose normals read a non-finite
// value: one-sided differences there, so only close to the clean normal); rays that do lose
// exactly the hits inside bad cells. Counts the rays of both kinds and the hits lost in
// `result`.
struct NonfiniteComparison {
  int untouched_rays = 0;
  int touched_rays = 0;
  int hits_dropped = 0;
  int one_sided_rays = 0;  // untouched rays through a cell of `stencil`
};
void expect_only_bad_cells_lose_hits(const GridSource& grid, const std::vector<Index3>& bad,
                                     const std::vector<Index3>& stencil, const RayCaster& clean,
                                     const RayCaster& dirty, NonfiniteComparison& result) {
  const double h = grid.coordinate(0, 1) - grid.coordinate(0, 0);
  for (const View& view : axis_and_oblique_views(grid.bounds(), 64)) {
    const Ldi a = clean.cast(view), b = dirty.cast(view);
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i) {
        const std::size_t p = std::size_t(j) * view.width + i;
        const glm::dvec3 o = view.pixel_point(i, j, 0.0);
        const auto ray_touches = [&](const std::vector<Index3>& cells) {
          for (const Index3& c : cells) {
            const Box box = cell_box(grid, c, 1e-6 * h);
            double t0 = 0.0, t1 = view.depth_extent;
            if (clip_ray_to_box(o, view.dir, box.lo, box.hi, t0, t1)) return true;
          }
          return false;
        };
        if (!ray_touches(bad)) {
          ++result.untouched_rays;
          const bool one_sided = ray_touches(stencil);
          result.one_sided_rays += one_sided;
          ASSERT_EQ(a.count(p), b.count(p)) << "pixel " << i << "," << j;
          for (std::uint32_t s = 0; s < a.count(p); ++s) {
            ASSERT_EQ(a.depth[a.begin(p) + s], b.depth[b.begin(p) + s]);
            const glm::vec3 na = a.normal[a.begin(p) + s], nb = b.normal[b.begin(p) + s];
            if (one_sided) {
              ASSERT_NEAR(glm::length(nb), 1.0f, 1e-5f);
              ASSERT_GT(glm::dot(na, nb), 0.99f) << "pixel " << i << "," << j;
            } else {
              ASSERT_EQ(na, nb);
            }
          }
          continue;
        }
        ++result.touched_rays;
        auto found_in = [](const Ldi& ldi, std::size_t pixel, float depth) {
          for (std::uint32_t s = ldi.begin(pixel); s < ldi.end(pixel); ++s)
            if (std::abs(ldi.depth[s] - depth) < 1e-6) return true;
          return false;
        };
        // No hit inside a bad cell, and none that the clean field does not have.
        for (std::uint32_t s = b.begin(p); s < b.end(p); ++s) {
          const glm::dvec3 x = view.pixel_point(i, j, b.depth[s]);
          for (const Index3& c : bad)
            ASSERT_FALSE(inside(cell_box(grid, c, -1e-6 * h), x))
                << "hit in a cell with a non-finite corner, pixel " << i << "," << j;
          ASSERT_TRUE(found_in(a, p, b.depth[s])) << "pixel " << i << "," << j;
        }
        // Every clean hit outside the bad cells is still there.
        for (std::uint32_t s = a.begin(p); s < a.end(p); ++s) {
          const glm::dvec3 x = view.pixel_point(i, j, a.depth[s]);
          bool in_bad = false, near_bad = false;
          for (const Index3& c : bad) {
            in_bad = in_bad || inside(cell_box(grid, c, -1e-6 * h), x);
            near_bad = near_bad || inside(cell_box(grid, c, 1e-6 * h), x);
          }
          if (in_bad) {
            ++result.hits_dropped;
          } else if (!near_bad) {
            ASSERT_TRUE(found_in(b, p, a.depth[s])) << "pixel " << i << "," << j;
          }
        }
      }
  }
}

// Shading normals (CellNormals): the trilinear blend of central-difference gradients at the
// cell corners, continuous across cell faces — the interpolant's own gradient jumps there, which
// shows as bands. Along a row of pixels 64 to a cell, the change of the first hit's normal
// between neighbouring pixels is as small where they straddle a cell face as within a cell, for
// both casters; the normals also follow the field's true gradient within the grid's error.
TEST(GridSource, NormalsAreContinuousAcrossCellFaces) {
  const int n = 9;  // 8 cells over [−1, 1]: 0.25 per cell
  const auto f = [](double x, double y, double z) {
    return x * x + 2.0 * y * y + z * z + 0.6 * x * y + 0.3 * std::sin(3.0 * x);
  };
  const std::vector<double> values = sample<double>(n, -1.0, 1.0, f);
  const GridSource grid(uniform_block(values.data(), ScalarType::float64, n, -1.0, 1.0), 2);
  const RayCaster axis(grid, 0.5);
  RayCasterOptions embree_only;
  embree_only.path = CastPath::embree;
  const RayCaster embree(grid, 0.5, embree_only);
  const View view = make_axis_views(grid.bounds(), 512, "z")[0];  // rows along x
  for (const RayCaster* caster : {&axis, &embree}) {
    const Ldi ldi = caster->cast(view);
    double across = 0.0, within = 0.0, smooth_error = 0.0, trilinear_error = 0.0;
    int faces = 0, insides = 0, hits = 0;
    for (int j = 200; j < 320; j += 7) {
      for (int i = 0; i + 1 < view.width; ++i) {
        const std::size_t p = std::size_t(j) * view.width + i;
        if (ldi.count(p) == 0 || ldi.count(p + 1) == 0) continue;
        const glm::dvec3 a = view.pixel_point(i, j, ldi.depth[ldi.begin(p)]);
        const glm::dvec3 b = view.pixel_point(i + 1, j, ldi.depth[ldi.begin(p + 1)]);
        const double jump =
            glm::length(glm::dvec3(ldi.normal[ldi.begin(p)] - ldi.normal[ldi.begin(p + 1)]));
        const bool straddles = std::floor((a.x + 1.0) / 0.25) != std::floor((b.x + 1.0) / 0.25);
        (straddles ? across : within) += jump;
        faces += straddles;
        insides += !straddles;
        // Against the field's exact gradient, and the interpolant's (both by differences at the
        // hit, the interpolant's inside its cell).
        const double e = 1e-7;
        const auto gradient = [&](auto&& g) {
          return glm::normalize(
              glm::dvec3{(g(a + glm::dvec3(e, 0, 0)) - g(a - glm::dvec3(e, 0, 0))),
                         (g(a + glm::dvec3(0, e, 0)) - g(a - glm::dvec3(0, e, 0))),
                         (g(a + glm::dvec3(0, 0, e)) - g(a - glm::dvec3(0, 0, e)))});
        };
        const glm::dvec3 exact = gradient([&](glm::dvec3 x) { return f(x.x, x.y, x.z); });
        const glm::dvec3 interpolant = gradient([&](glm::dvec3 x) { return interpolate(grid, x); });
        const auto angle = [&](glm::dvec3 n) {
          return std::acos(std::min(1.0, glm::dot(exact, n)));
        };
        smooth_error += angle(glm::dvec3(ldi.normal[ldi.begin(p)]));
        trilinear_error += angle(interpolant);
        ++hits;
      }
    }
    EXPECT_GT(faces, 50);
    across /= faces;
    within /= insides;
    EXPECT_GT(within, 0.0);
    // The interpolant's gradient jumps at faces by about 60 times its change within a cell.
    EXPECT_LT(across, 1.5 * within) << "across faces " << across << ", within cells " << within;
    // And they are closer to the field's true normals than the interpolant's own.
    EXPECT_LT(smooth_error, trilinear_error)
        << "mean angle " << smooth_error / hits << " against " << trilinear_error / hits;
  }
}

TEST(GridSource, CellsWithNonFiniteCornersProduceNoHitsAndAreCounted) {
  const int n = 33;  // 32 cells per axis: 4 bricks of 8 cells
  const std::vector<float> clean_values = sample<float>(n, -1.25, 1.25, sphere_field);
  std::vector<float> values = clean_values;
  // Points near the sphere (so that their cells hold surface), on brick boundaries (read by 2,
  // 4 or 8 bricks), on the last point layer and at a corner of the block.
  const std::vector<std::pair<Index3, double>> written{
      {{24, 24, 24}, kNaN}, {{29, 16, 16}, kInf}, {{16, 3, 16}, -kInf},  {{8, 16, 27}, kNaN},
      {{32, 16, 16}, kNaN}, {{0, 0, 0}, kNaN},    {{16, 24, 23}, -kInf},
  };
  std::vector<Index3> points;
  for (const auto& [p, v] : written) {
    values[(std::size_t(p[2]) * n + p[1]) * n + p[0]] = float(v);
    points.push_back(p);
  }
  const GridSource clean(uniform_block(clean_values.data(), ScalarType::float32, n, -1.25, 1.25));
  const GridSource dirty(uniform_block(values.data(), ScalarType::float32, n, -1.25, 1.25));
  const RayCaster clean_caster(clean, 1.0), dirty_caster(dirty, 1.0);
  EXPECT_EQ(clean_caster.nonfinite_values(), 0u);
  EXPECT_EQ(dirty_caster.nonfinite_values(), written.size());
  // The bricks around a non-finite point stay in the scene: their finite cells still count.
  EXPECT_EQ(dirty_caster.primitive_count(), clean_caster.primitive_count());
  NonfiniteComparison compared;
  expect_only_bad_cells_lose_hits(dirty, cells_with_corner_among(dirty, points),
                                  cells_with_corner_among(dirty, with_axis_neighbours(points)),
                                  clean_caster, dirty_caster, compared);
  EXPECT_GT(compared.untouched_rays, 10000);
  EXPECT_GT(compared.one_sided_rays, 20);
  EXPECT_GT(compared.touched_rays, 200);
  EXPECT_GT(compared.hits_dropped, 50);  // the bad cells did hold surface
}

TEST(GridSource, AllNonFiniteGridHasNoHits) {
  const int n = 17;
  for (const double v : {kNaN, kInf, -kInf}) {
    const std::vector<double> values(std::size_t(n) * n * n, v);
    const GridSource grid(uniform_block(values.data(), ScalarType::float64, n, -1.0, 1.0), 4);
    const RayCaster caster(grid, 0.5);
    EXPECT_EQ(caster.nonfinite_values(), values.size());
    EXPECT_EQ(caster.primitive_count(), 0u);
    for (const View& view : axis_and_oblique_views(grid.bounds(), 32))
      EXPECT_EQ(caster.cast(view).sample_count(), 0u);
  }
}

TEST(GridSource, NonFiniteValuesDoNotWidenBrickRanges) {
  // Finite values all above the isovalue, with −Inf and +Inf points: no brick can hold the
  // surface, so none is kept.
  const int n = 17;
  std::vector<double> values = sample<double>(n, -1.0, 1.0, sphere_field);
  values[(std::size_t(5) * n + 6) * n + 7] = -kInf;
  values[(std::size_t(12) * n + 3) * n + 9] = kInf;
  values[(std::size_t(1) * n + 14) * n + 2] = kNaN;
  const GridSource grid(uniform_block(values.data(), ScalarType::float64, n, -1.0, 1.0), 4);
  const RayCaster caster(grid, -0.5);
  EXPECT_EQ(caster.nonfinite_values(), 3u);
  EXPECT_EQ(caster.primitive_count(), 0u);
}

TEST(GridSource, HugeFiniteValuesAreNeitherCountedNorSkipped) {
  // Values near the largest double: finite, though sums of them are not.
  const int n = 17;
  const std::vector<double> unit = sample<double>(n, -1.0, 1.0, [](double x, double y, double z) {
    return sphere_field(x, y, z) < 0.5 ? -1.0 : 1.0;
  });
  std::vector<double> huge(unit.size());
  for (std::size_t p = 0; p < unit.size(); ++p)
    huge[p] = 1e308 * unit[p];
  const GridSource a(uniform_block(unit.data(), ScalarType::float64, n, -1.0, 1.0), 4);
  const GridSource b(uniform_block(huge.data(), ScalarType::float64, n, -1.0, 1.0), 4);
  const RayCaster ca(a, 0.0), cb(b, 0.0);
  EXPECT_EQ(cb.nonfinite_values(), 0u);
  EXPECT_GT(ca.primitive_count(), 0u);
  EXPECT_EQ(ca.primitive_count(), cb.primitive_count());
}

TEST(GridSource, NonFiniteCountIsExactForAnyBrickSizeAndGhostLayers) {
  // Points read by the bind: indices first_cell … last_cell + 1 per axis. Ghost layers below
  // (1) are outside that range, of the two above the first is inside it.
  const int n = 21;
  GridBlock block;
  block.dims = {n, n, n};
  block.type = ScalarType::float64;
  block.origin = glm::dvec3(-1.0);
  block.spacing = glm::dvec3(0.1);
  block.ghost_lo = {1, 1, 1};
  block.ghost_hi = {2, 2, 2};
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> index(0, n - 1), kind(0, 2);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<double> values = sample<double>(n, -1.0, 1.0, sphere_field);
    std::uint64_t expected = 0;
    for (int w = 0; w < 40; ++w) {
      const int i = index(rng), j = index(rng), k = index(rng);
      double& v = values[(std::size_t(k) * n + j) * n + i];
      if (!std::isfinite(v)) continue;  // already written
      v = kind(rng) == 0 ? kNaN : (kind(rng) == 1 ? kInf : -kInf);
      expected += i >= 1 && i <= n - 2 && j >= 1 && j <= n - 2 && k >= 1 && k <= n - 2;
    }
    block.values = values.data();
    for (int brick_cells : {1, 3, 4, 8, 32}) {
      const GridSource grid(block, brick_cells);
      ASSERT_EQ(grid.first_cell()[0], 1);
      ASSERT_EQ(grid.last_cell()[0], n - 3);
      EXPECT_EQ(RayCaster(grid, 0.5).nonfinite_values(), expected)
          << "trial " << trial << ", bricks of " << brick_cells;
    }
  }
}

TEST(GridSource, RayCasterSumsNonFiniteCountsOverBlocks) {
  // Two blocks split along x as in TwoBlocksWithGhostLayersGiveTheSameHitsAsOneBlock: A reads
  // points x = 0…16 (16 a ghost), B reads x = 16…32 (its ghost x = 15 lies below its cells).
  const int n = 33;
  std::vector<double> values = sample<double>(n, -1.0, 1.0, sphere_field);
  auto at = [&](int i, int j, int k) -> double& {
    return values[(std::size_t(k) * n + j) * n + i];
  };
  GridBlock whole = uniform_block(values.data(), ScalarType::float64, n, -1.0, 1.0);
  const auto [a, b] = split_along_x(whole);
  const GridSource block_a(a), block_b(b), one(whole);
  const std::array<const FieldSource*, 2> pair{&block_a, &block_b};
  EXPECT_EQ(RayCaster(pair, 0.5).nonfinite_values(), 0u);
  at(3, 4, 5) = kNaN;    // A only
  at(15, 9, 9) = kInf;   // A only: B's ghost below its cells is not read
  at(16, 2, 2) = -kInf;  // A's ghost and B's own point: read, and counted, by both
  at(30, 1, 7) = kNaN;   // B only
  EXPECT_EQ(RayCaster(block_a, 0.5).nonfinite_values(), 3u);
  EXPECT_EQ(RayCaster(block_b, 0.5).nonfinite_values(), 2u);
  EXPECT_EQ(RayCaster(pair, 0.5).nonfinite_values(), 5u);
  EXPECT_EQ(RayCaster(one, 0.5).nonfinite_values(), 4u);
}

// needed_bricks' definition, brick by brick: the bricks as GridSource documents them (cells
// first … last per axis, brick_cells each, x fastest; a brick reads its cells' points lo … hi + 1)
// whose points hold an isovalue between their finite minimum and maximum, or a NaN or ±Inf.
// at(i, j, k): the value of point (i, j, k).
template <class At>
std::vector<std::uint8_t> needed_by_definition(const GridBlock& block, int brick_cells,
                                               const std::vector<double>& isovalues, At at) {
  std::array<std::int64_t, 3> first{}, last{}, count{};
  for (int a = 0; a < 3; ++a) {
    first[a] = block.ghost_lo[a];
    last[a] = std::min(block.dims[a] - 1 - block.ghost_hi[a], block.dims[a] - 2);
    count[a] = (last[a] - first[a] + brick_cells) / brick_cells;
  }
  std::vector<std::uint8_t> needed(std::size_t(count[0] * count[1] * count[2]), 0);
  for (std::int64_t bz = 0; bz < count[2]; ++bz)
    for (std::int64_t by = 0; by < count[1]; ++by)
      for (std::int64_t bx = 0; bx < count[0]; ++bx) {
        const std::array<std::int64_t, 3> b{bx, by, bz};
        std::array<std::int64_t, 3> lo{}, hi{};
        for (int a = 0; a < 3; ++a) {
          lo[a] = first[a] + b[a] * brick_cells;
          hi[a] = std::min(last[a], lo[a] + brick_cells - 1) + 1;
        }
        double min = kInf, max = -kInf;
        bool nonfinite = false;
        for (std::int64_t k = lo[2]; k <= hi[2]; ++k)
          for (std::int64_t j = lo[1]; j <= hi[1]; ++j)
            for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
              const double v = at(i, j, k);
              if (!std::isfinite(v)) {
                nonfinite = true;
              } else {
                min = std::min(min, v);
                max = std::max(max, v);
              }
            }
        bool expected = nonfinite;
        for (const double iso : isovalues)
          expected = expected || (min <= iso && iso <= max);
        needed[std::size_t(bx + count[0] * (by + count[1] * bz))] = expected;
      }
  return needed;
}

// The bricks where `got` and `expected` differ, at most ten, for a failure message.
std::string differing_bricks(const std::vector<std::uint8_t>& got,
                             const std::vector<std::uint8_t>& expected) {
  std::string out;
  int shown = 0;
  for (std::size_t n = 0; n < std::min(got.size(), expected.size()) && shown < 10; ++n)
    if ((got[n] != 0) != (expected[n] != 0)) {
      out += ' ';
      out += std::to_string(n);
      out += expected[n] ? " (missed)" : " (extra)";
      ++shown;
    }
  return out;
}

TEST(GridSource, NeededBricksAreThoseABruteForceScanFinds) {
  // needed_bricks against its definition: a smooth field with noise (bricks in and out of
  // range), non-finite points at random places and at every offset within a brick's row (every
  // lane of a vector, and the rows' tails), float and double, rows in memory order (the
  // vectorized scan) and z fastest (the scalar one), several brick sizes, ghost layers.
  const int n = 23;
  const std::vector<double> isovalues{0.45, 1.7};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> noise(-0.04, 0.04);
  std::uniform_int_distribution<int> point(0, n - 1);
  std::vector<double> values = sample<double>(n, -1.1, 1.1, sphere_field);
  for (double& v : values)
    v += noise(rng);
  const double bad[] = {kNaN, kInf, -kInf};
  for (int m = 0; m < 12; ++m)
    values[(std::size_t(point(rng)) * n + point(rng)) * n + point(rng)] = bad[m % 3];
  // Row (j, k) = (3, 4): point 1 + 9b + b of brick b of 8 cells (cells from x = 1), offsets 0 …
  // 8 within its row: each lane, and the last point, which no full vector holds.
  for (int b = 0; b < 2; ++b)
    for (int offset = 0; offset <= 8; ++offset) {
      const int i = 1 + 8 * b + offset, j = 3 + 9 * b + offset % 3, k = 4 + 2 * (offset / 3);
      if (i < n && j < n && k < n) values[(std::size_t(k) * n + j) * n + i] = bad[offset % 3];
    }
  // Huge finite values, whose sum overflows: neither needed nor skipped for that.
  values[(std::size_t(20) * n + 2) * n + 2] = 1.5e308;
  values[(std::size_t(20) * n + 2) * n + 3] = 1.5e308;
  std::size_t needed_any = 0, skipped_any = 0;
  for (const ScalarType type : {ScalarType::float64, ScalarType::float32})
    for (const bool z_fastest : {false, true})
      for (const int brick_cells : {1, 3, 4, 8}) {
        SCOPED_TRACE(std::string(type == ScalarType::float32 ? "float" : "double") +
                     (z_fastest ? ", z fastest" : "") + ", bricks of " +
                     std::to_string(brick_cells));
        const auto index = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
          return z_fastest ? (std::size_t(i) * n + j) * n + k : (std::size_t(k) * n + j) * n + i;
        };
        std::vector<double> doubles(values.size());
        for (int k = 0; k < n; ++k)
          for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i)
              doubles[index(i, j, k)] = values[(std::size_t(k) * n + j) * n + i];
        // Float: 1.5e308 becomes +Inf, so the brick holding it is needed there.
        const std::vector<float> floats(doubles.begin(), doubles.end());
        GridBlock block = uniform_block(
            type == ScalarType::float64 ? (const void*)doubles.data() : (const void*)floats.data(),
            type, n, -1.1, 1.1);
        if (z_fastest) block.strides = {std::int64_t(n) * n, n, 1};
        block.ghost_lo = {1, 0, 2};
        block.ghost_hi = {2, 1, 0};
        const std::vector<std::uint8_t> needed =
            GridSource(block, brick_cells).needed_bricks(isovalues);
        const auto value_at = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
          return type == ScalarType::float64 ? doubles[index(i, j, k)]
                                             : double(floats[index(i, j, k)]);
        };
        const std::vector<std::uint8_t> expected =
            needed_by_definition(block, brick_cells, isovalues, value_at);
        ASSERT_EQ(needed.size(), expected.size());
        EXPECT_EQ(needed, expected) << "bricks:" << differing_bricks(needed, expected);
        for (const std::uint8_t e : expected)
          (e ? needed_any : skipped_any) += 1;
        // Per isovalue: bit i is the bricks needed for isovalue i alone.
        const std::vector<std::uint8_t> by_isovalue =
            GridSource(block, brick_cells).needed_bricks_by_isovalue(isovalues);
        for (std::size_t i = 0; i < isovalues.size(); ++i) {
          std::vector<std::uint8_t> bit(by_isovalue.size());
          for (std::size_t b = 0; b < bit.size(); ++b)
            bit[b] = (by_isovalue[b] >> i) & 1;
          const std::vector<std::uint8_t> alone =
              needed_by_definition(block, brick_cells, {isovalues[i]}, value_at);
          EXPECT_EQ(bit, alone) << "isovalue " << isovalues[i]
                                << ", bricks:" << differing_bricks(bit, alone);
          EXPECT_NE(alone, expected);  // each isovalue needs fewer bricks than both
        }
      }
  EXPECT_GT(needed_any, 200u);
  EXPECT_GT(skipped_any, 200u);
}

TEST(GridSource, NeededBricksOfABlockOfMoreThanEightMiPointsAreThoseABruteForceScanFinds) {
  // Above 8 Mi points needed_bricks runs in tasks on all cores (below, on the calling thread):
  // 208³ float points, rows in memory order, a few non-finite points.
  const int n = 208;
  const std::vector<double> isovalues{0.5};
  std::vector<float> values = sample<float>(n, -1.0, 1.0, wavy_field);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> point(0, n - 1);
  const float bad[] = {std::numeric_limits<float>::quiet_NaN(),
                       std::numeric_limits<float>::infinity()};
  for (int m = 0; m < 20; ++m)
    values[(std::size_t(point(rng)) * n + point(rng)) * n + point(rng)] = bad[m % 2];
  GridBlock block = uniform_block(values.data(), ScalarType::float32, n, -1.0, 1.0);
  block.ghost_lo = {1, 1, 1};
  const std::vector<std::uint8_t> needed = GridSource(block, 8).needed_bricks(isovalues);
  const std::vector<std::uint8_t> expected = needed_by_definition(
      block, 8, isovalues, [&](std::int64_t i, std::int64_t j, std::int64_t k) {
        return double(values[(std::size_t(k) * n + std::size_t(j)) * n + std::size_t(i)]);
      });
  ASSERT_EQ(needed.size(), expected.size());
  EXPECT_EQ(needed, expected) << "bricks:" << differing_bricks(needed, expected);
  const auto count = std::count(expected.begin(), expected.end(), 1);
  EXPECT_GT(count, std::ptrdiff_t(expected.size() / 10));
  EXPECT_LT(count, std::ptrdiff_t(expected.size() * 9 / 10));
}

TEST(GridSource, ACopyOfTheNeededBricksCastsWhatTheWholeBlockCasts) {
  // What the adaptor's snapshot does: copy the points of the bricks that needed_bricks names
  // (for_each_needed_run) into a buffer whose other points hold anything, and cast that with
  // the mask. Two nested spheres with ghost layers, non-finite points near the surface and far
  // from it, a colour field copied at the same points; the buffer's other points NaN or wild
  // values. Fine views (object order) and coarse ones (rays walking their columns).
  const int n = 41;
  const std::vector<double> isovalues{0.3, 0.9};
  for (const ScalarType type : {ScalarType::float64, ScalarType::float32})
    for (const int brick_cells : {3, 8}) {
      std::vector<double> values = sample<double>(n, -1.3, 1.3, sphere_field);
      const auto at = [&](int i, int j, int k) -> double& {
        return values[(std::size_t(k) * n + j) * n + i];
      };
      at(20, 20, 20) = kNaN;  // the centre, far from both spheres
      at(2, 3, 38) = kInf;    // a corner, far too
      at(31, 20, 20) = kNaN;  // next to the inner sphere (r ≈ 0.55 there)
      std::vector<float> floats(values.begin(), values.end());
      const std::vector<double> colour =
          sample<double>(n, -1.3, 1.3, [](double x, double y, double z) { return x + 2 * y - z; });
      GridBlock block = uniform_block(
          type == ScalarType::float64 ? (const void*)values.data() : (const void*)floats.data(),
          type, n, -1.3, 1.3);
      block.ghost_lo = {1, 1, 1};
      block.ghost_hi = {2, 2, 2};
      block.colour = colour.data();
      block.colour_type = ScalarType::float64;
      const GridSource whole(block, brick_cells);
      const std::vector<std::uint8_t> needed = whole.needed_bricks(isovalues);
      const std::size_t held = std::size_t(std::count(needed.begin(), needed.end(), 1));
      SCOPED_TRACE(std::to_string(held) + " of " + std::to_string(needed.size()) + " bricks, " +
                   std::to_string(brick_cells) + " cells each");
      ASSERT_GT(held, needed.size() / 10);
      ASSERT_LT(held, needed.size() * 9 / 10);  // the copy leaves much out
      for (const bool wild : {false, true}) {
        std::vector<double> copy(values.size(), kNaN);
        std::mt19937 rng(7);
        std::uniform_real_distribution<double> any(-2.0, 2.0);
        if (wild)
          for (double& v : copy)
            v = any(rng);
        std::vector<float> copy_floats(copy.begin(), copy.end());
        std::vector<double> copy_colour = copy;
        std::atomic<std::size_t> copied{0};
        whole.for_each_needed_run(
            needed, [&](std::int64_t j, std::int64_t k, std::int64_t i0, std::int64_t i1) {
              const std::size_t row = (std::size_t(k) * n + std::size_t(j)) * n;
              for (std::int64_t i = i0; i <= i1; ++i) {
                copy[row + std::size_t(i)] = values[row + std::size_t(i)];
                copy_floats[row + std::size_t(i)] = floats[row + std::size_t(i)];
                copy_colour[row + std::size_t(i)] = colour[row + std::size_t(i)];
              }
              copied += std::size_t(i1 - i0 + 1);
            });
        EXPECT_LT(copied.load(), values.size() * 9 / 10);
        GridBlock sparse = block;
        sparse.values = type == ScalarType::float64 ? (const void*)copy.data()
                                                    : (const void*)copy_floats.data();
        sparse.colour = copy_colour.data();
        const GridSource part(sparse, brick_cells, needed);
        // Far from both surfaces the copy holds nothing: its colour probe answers NaN there,
        // not what the buffer holds.
        const glm::dvec3 far(1.2, 1.2, 1.2);
        EXPECT_TRUE(std::isfinite(whole.bind_scalar()->at(far)));
        EXPECT_TRUE(std::isnan(part.bind_scalar()->at(far)));
        for (const double iso : isovalues) {
          const RayCaster a(whole, iso), b(part, iso);
          EXPECT_EQ(a.nonfinite_values(), 3u);
          EXPECT_EQ(b.nonfinite_values(), a.nonfinite_values());
          EXPECT_EQ(b.primitive_count(), a.primitive_count());
          SCOPED_TRACE("isovalue " + std::to_string(iso) + (wild ? ", wild" : ""));
          const View front = make_axis_views(whole.bounds(), 48, "z")[0];
          const Ldi coloured = a.cast(front);
          EXPECT_EQ(coloured.scalar.size(), coloured.sample_count());  // colours compared too
          std::size_t samples = 0;
          for (const int resolution : {48, 20})  // object order, and rays walking their columns
            samples += testing::expect_same_casts(
                a, b, axis_and_oblique_views(whole.bounds(), resolution));
          EXPECT_GT(samples, 2000u);
        }
      }
    }
  // A mask of the wrong size is refused.
  const std::vector<double> values = sample<double>(9, -1.0, 1.0, sphere_field);
  const GridBlock block = uniform_block(values.data(), ScalarType::float64, 9, -1.0, 1.0);
  EXPECT_THROW(GridSource(block, 4, std::vector<std::uint8_t>(3, 1)), std::invalid_argument);
  EXPECT_THROW(
      GridSource(block, 4).for_each_needed_run(std::vector<std::uint8_t>(3, 1), [](auto...) {}),
      std::invalid_argument);
}

TEST(GridSource, CubicRootsOfACellSegment) {
  double roots[3];
  // Corners −1 except +1 at (1,1,1): along the diagonal f(s) = −1 + 2s³, one root at 2^(−1/3).
  const double corner[8] = {-1, -1, -1, -1, -1, -1, -1, 1};
  ASSERT_EQ(trilinear_segment_roots(corner, {0, 0, 0}, {1, 1, 1}, roots), 1);
  EXPECT_NEAR(roots[0], std::cbrt(0.5), 1e-12);
  // f = −0.64 + 5.28x − 12xy + 8xyz is 8(s − 0.2)(s − 0.5)(s − 0.8) on the diagonal: three roots.
  const double three[8] = {-0.64, 4.64, -0.64, -7.36, -0.64, 4.64, -0.64, 0.64};
  ASSERT_EQ(trilinear_segment_roots(three, {0, 0, 0}, {1, 1, 1}, roots), 3);
  EXPECT_NEAR(roots[0], 0.2, 1e-12);
  EXPECT_NEAR(roots[1], 0.5, 1e-12);
  EXPECT_NEAR(roots[2], 0.8, 1e-12);
  // The saddle (1 − 2x)(1 − 2y) from (0, 0.9) to (1, 0.3): roots at s = 0.5 and s = 2/3.
  const double saddle[8] = {1, -1, -1, 1, 1, -1, -1, 1};
  ASSERT_EQ(trilinear_segment_roots(saddle, {0.0, 0.9, 0.5}, {1.0, 0.3, 0.5}, roots), 2);
  EXPECT_NEAR(roots[0], 0.5, 1e-12);
  EXPECT_NEAR(roots[1], 2.0 / 3.0, 1e-12);
  // A segment inside one quadrant of the saddle never crosses zero.
  ASSERT_EQ(trilinear_segment_roots(saddle, {0.0, 0.1, 0.5}, {0.4, 0.3, 0.9}, roots), 0);
}

}  // namespace
}  // namespace ldimesh

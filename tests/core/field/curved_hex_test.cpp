// Curved and general trilinear hexahedra: geometry of its own order q, intersected exactly.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "ldimesh/core/base/view.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

#include "curved_meshes.hpp"
#include "field/hex/curved_element.hpp"  // the search's copies (internal)

namespace ldimesh {
namespace {

using test::curved_mesh;
using test::CurvedMesh;
using test::kBox;
using test::mesh_of;
using test::shell_mesh;

constexpr double kPi = std::numbers::pi;
constexpr NodeSet kNodeSets[] = {NodeSet::gauss_lobatto_legendre, NodeSet::gauss_legendre,
                                 NodeSet::equispaced};

std::string describe(int p, int q, NodeSet nodes) {
  const char* names[] = {"GLL", "GL", "equispaced"};
  return "p " + std::to_string(p) + " q " + std::to_string(q) + " " + names[int(nodes)];
}

// Hits of the isosurface x = c of the field x (represented exactly by the elements): every hit
// lies on the plane, and, for a conforming mesh that fills the box (`fills_box`), every pixel
// ray that crosses the plane inside the box (away from its faces) has exactly one hit, the
// others none. Returns the number of hits checked.
std::size_t expect_plane_hits(const HexElementSource& source, double c, const std::string& what,
                              bool fills_box = true) {
  const RayCaster caster(source, c);
  std::size_t checked = 0;
  int failures = 0;
  for (const glm::dvec3 dir : {glm::dvec3(1, 0, 0), glm::dvec3(-1, 0, 0),
                               glm::dvec3(0.3, -0.5, 0.8), glm::dvec3(-0.6, 0.2, -0.5)}) {
    const View view = make_view(source.bounds(), dir, 40);
    const Ldi ldi = caster.cast(view);
    const double margin = 1e-6;
    for (int j = 0; j < view.height; ++j)
      for (int i = 0; i < view.width; ++i) {
        const std::size_t pixel = std::size_t(j) * view.width + i;
        const glm::dvec3 o = view.pixel_point(i, j, 0.0);
        const double t = (c - o.x) / view.dir.x;
        const glm::dvec3 crossing = o + t * view.dir;
        bool inside = true, near_face = false;
        for (int a = 0; a < 3; ++a) {
          inside = inside && crossing[a] > kBox.lo[a] && crossing[a] < kBox.hi[a];
          near_face = near_face || std::abs(crossing[a] - kBox.lo[a]) < margin ||
                      std::abs(crossing[a] - kBox.hi[a]) < margin;
        }
        if (near_face) continue;
        const std::uint32_t count = ldi.offsets[pixel + 1] - ldi.offsets[pixel];
        if (!fills_box) {
          EXPECT_LE(count, 1u) << what;
          inside = count > 0;
        }
        EXPECT_EQ(count, inside ? 1u : 0u) << what << " view (" << dir.x << ", " << dir.y << ", "
                                           << dir.z << ") pixel " << i << ", " << j;
        if (count != (inside ? 1u : 0u) && ++failures > 5) return checked;  // enough said
        if (count != 1) continue;
        const glm::dvec3 hit = view.pixel_point(i, j, ldi.depth[ldi.offsets[pixel]]);
        EXPECT_NEAR(hit.x, c, 2e-6) << what;
        // The field's gradient is e_x: the normal faces against the ray's x direction... or
        // along it; either way it is ±e_x.
        EXPECT_NEAR(std::abs(ldi.normal[ldi.offsets[pixel]].x), 1.0, 1e-5) << what;
        ++checked;
      }
  }
  return checked;
}

TEST(CurvedHex, TheFieldXOnCurvedElementsCutsThePlaneExactly) {
  // p = q with one node set: the field's nodes are the geometry's, so the field is the
  // element's x coordinate and its isosurface the plane x = c, however curved the elements.
  // Gauss–Legendre geometry nodes lie inside the elements: neighbours' faces then differ (the
  // mesh is not conforming), so only the hits' positions are checked there, not the coverage.
  for (int q : {1, 2, 3, 5})
    for (NodeSet nodes : kNodeSets) {
      const CurvedMesh m = curved_mesh(3, q, q, nodes, 0.05, [](glm::dvec3 x) { return x.x; });
      const HexElementSource source(m.block);
      std::size_t curved = 0;
      for (std::size_t e = 0; e < m.block.element_count; ++e)
        curved += source.is_curved(e);
      EXPECT_GT(curved, 0u) << describe(q, q, nodes);
      EXPECT_GT(
          expect_plane_hits(source, 0.137, describe(q, q, nodes), nodes != NodeSet::gauss_legendre),
          1000u);
    }
}

TEST(CurvedHex, TrilinearElementsFromCornersAreAccepted) {
  // Eight corners that are not a parallelepiped: the trilinear hexahedron (geometry order 1).
  // Interior vertices of a 3³ mesh moved at random; p = 1 with equispaced nodes puts the field's
  // nodes at the corners, so the field x(ξ) is the element's own x and x = c is a plane.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> jitter(-0.04, 0.04);
  const int n = 3;
  std::vector<glm::dvec3> vertex((n + 1) * (n + 1) * (n + 1));
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        glm::dvec3 x = kBox.lo + (kBox.hi - kBox.lo) * glm::dvec3(i, j, k) / double(n);
        for (int a = 0; a < 3; ++a) {
          const int index[3] = {i, j, k};
          if (index[a] > 0 && index[a] < n) x[a] += jitter(rng);
        }
        vertex[i + (n + 1) * (j + (n + 1) * k)] = x;
      }
  std::vector<double> corners, values;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < 8; ++c) {
          const glm::dvec3 x =
              vertex[(i + (c & 1)) + (n + 1) * ((j + ((c >> 1) & 1)) + (n + 1) * (k + (c >> 2)))];
          corners.insert(corners.end(), {x.x, x.y, x.z});
          values.push_back(x.x);
        }
  const HexBlock block{1,
                       NodeSet::equispaced,
                       std::size_t(n * n * n),
                       corners.data(),
                       values.data(),
                       ScalarType::float64};
  const HexElementSource source(block);
  EXPECT_TRUE(source.is_curved(13));  // the middle element: all its corners moved
  EXPECT_GT(expect_plane_hits(source, -0.0731, "trilinear"), 1000u);
}

// A smooth field with several crossings per ray.
double wavy(glm::dvec3 x) {
  return std::sin(5.0 * x.x + 1.0) * std::cos(4.0 * x.y) + 0.7 * std::sin(6.0 * x.z + x.x) - 0.1;
}

// The field r² on curved elements of a spherical shell: with p = 2q the elements represent
// r² ∘ x(ξ) exactly (degree 2q in each variable), so its isosurface r² = c is the sphere of
// radius √c itself, however the shell is meshed. Every hit lies on that sphere with a radial
// normal, every pixel ray that passes the centre closer than √c (away from tangency) meets it
// twice and the others not at all, and two different meshes of the shell (other element counts,
// geometry orders and node sets) give the same hits.
TEST(CurvedHex, RSquaredOnCurvedShellsIsTheExactSphere) {
  const double radius = 0.72;
  const Box domain{glm::dvec3(-1.0), glm::dvec3(1.0)};
  const std::vector<glm::dvec3> directions{glm::dvec3(1, 0, 0), glm::dvec3(0, 0, -1),
                                           glm::dvec3(0, 1, 0), glm::dvec3(0.4, -0.3, 0.85)};
  std::vector<std::vector<Ldi>> ldis;
  for (const auto& [n, layers, q, nodes] : {std::tuple{2, 2, 2, NodeSet::gauss_lobatto_legendre},
                                            std::tuple{3, 1, 3, NodeSet::equispaced}}) {
    const std::string what = "shell " + std::to_string(n) + " × " + std::to_string(n) + " × " +
                             std::to_string(layers) + ", " + describe(2 * q, q, nodes);
    const CurvedMesh m = shell_mesh(n, layers, 2 * q, q, nodes, 0.5, 1.0,
                                    [](glm::dvec3 x) { return glm::dot(x, x); });
    const HexElementSource source(m.block);
    std::size_t curved = 0;
    for (std::size_t e = 0; e < m.block.element_count; ++e)
      curved += source.is_curved(e);
    EXPECT_EQ(curved, m.block.element_count) << what;
    const RayCaster caster(source, radius * radius);
    ldis.emplace_back();
    std::size_t hits = 0, rays = 0;
    for (const glm::dvec3& dir : directions) {
      const View view = make_view(domain, dir, 48);
      EXPECT_EQ(caster.uses_axis_casters(view), exact_axis(dir) >= 0);
      const Ldi ldi = caster.cast(view);
      for (int j = 0; j < view.height; ++j)
        for (int i = 0; i < view.width; ++i) {
          const std::size_t pixel = std::size_t(j) * view.width + i;
          const glm::dvec3 o = view.pixel_point(i, j, 0.0);
          const double passing = glm::length(o - glm::dot(o, view.dir) * view.dir);
          const std::uint32_t begin = ldi.offsets[pixel], count = ldi.offsets[pixel + 1] - begin;
          if (std::abs(passing - radius) > 1e-3) {
            EXPECT_EQ(count, passing < radius ? 2u : 0u) << what << " pixel " << i << ", " << j;
            ++rays;
          }
          for (std::uint32_t h = begin; h < begin + count; ++h) {
            const glm::dvec3 x = view.pixel_point(i, j, ldi.depth[h]);
            EXPECT_NEAR(glm::length(x), radius, 1e-6) << what;
            EXPECT_NEAR(std::abs(glm::dot(glm::dvec3(ldi.normal[h]), glm::normalize(x))), 1.0, 1e-5)
                << what;
            ++hits;
          }
        }
      ldis.back().push_back(ldi);
    }
    EXPECT_GT(hits, 4000u) << what;
    EXPECT_GT(rays, 8000u) << what;
  }
  for (std::size_t v = 0; v < directions.size(); ++v) {
    const Ldi &a = ldis[0][v], &b = ldis[1][v];
    EXPECT_EQ(a.offsets, b.offsets) << "view " << v;
    if (a.depth.size() != b.depth.size()) continue;
    for (std::size_t h = 0; h < a.depth.size(); ++h) {
      EXPECT_NEAR(a.depth[h], b.depth[h], 1e-6) << "view " << v;
      EXPECT_NEAR(glm::length(a.normal[h] - b.normal[h]), 0.0, 1e-5) << "view " << v;
    }
  }
}

// The same mesh with every element's nodes numbered from another corner — each element turned
// or mirrored by one of the cube's 48 symmetries, its values and geometry nodes alike — and the
// elements listed in another order: the same hits.
TEST(CurvedHex, TurnedAndReorderedElementsGiveTheSameHits) {
  std::mt19937 rng(29);
  for (const auto& [p, q, nodes] : {std::tuple{3, 2, NodeSet::gauss_lobatto_legendre},
                                    std::tuple{2, 3, NodeSet::gauss_legendre}}) {
    const CurvedMesh m = curved_mesh(2, p, q, nodes, 0.08, wavy);
    const std::size_t elements = m.block.element_count;
    std::vector<std::size_t> order(elements);
    for (std::size_t e = 0; e < elements; ++e)
      order[e] = e;
    std::shuffle(order.begin(), order.end(), rng);
    // Node (i, j, k) of the turned element is node old of the original, old[axes[a]] = new[a]
    // or its mirror N − new[a].
    const auto turned = [](const int axes[3], const bool flip[3], int N, int i, int j, int k) {
      const int fresh[3] = {i, j, k};
      int old[3];
      for (int a = 0; a < 3; ++a)
        old[axes[a]] = flip[a] ? N - fresh[a] : fresh[a];
      return old[0] + (N + 1) * (old[1] + (N + 1) * old[2]);
    };
    CurvedMesh t = m;
    std::uniform_int_distribution<int> coin(0, 1), six(0, 5);
    const int permutations[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2},
                                    {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    const std::size_t np = std::size_t(p + 1) * (p + 1) * (p + 1),
                      nq = std::size_t(q + 1) * (q + 1) * (q + 1);
    int mirrored = 0;
    for (std::size_t e = 0; e < elements; ++e) {
      const std::size_t from = order[e];
      const int which = six(rng);
      const int* axes = permutations[which];
      const bool flip[3] = {coin(rng) == 1, coin(rng) == 1, coin(rng) == 1};
      const int odd_permutation[6] = {0, 1, 1, 0, 0, 1};
      mirrored += (flip[0] + flip[1] + flip[2] + odd_permutation[which]) % 2;
      std::size_t m_out = 0;
      for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
          for (int i = 0; i <= p; ++i)
            t.values[e * np + m_out++] = m.values[from * np + turned(axes, flip, p, i, j, k)];
      m_out = 0;
      for (int k = 0; k <= q; ++k)
        for (int j = 0; j <= q; ++j)
          for (int i = 0; i <= q; ++i, ++m_out)
            for (int c = 0; c < 3; ++c)
              t.geometry[3 * (e * nq + m_out) + c] =
                  m.geometry[3 * (from * nq + turned(axes, flip, q, i, j, k)) + c];
    }
    t.block.values = t.values.data();
    t.block.geometry = t.geometry.data();
    const HexElementSource a(m.block), b(t.block);
    const RayCaster ca(a, 0.0), cb(b, 0.0);
    std::size_t compared = 0;
    for (const View& view : make_axis_views(a.bounds(), 32)) {
      const Ldi la = ca.cast(view), lb = cb.cast(view);
      EXPECT_EQ(la.offsets, lb.offsets) << describe(p, q, nodes);
      if (la.depth.size() != lb.depth.size()) continue;
      for (std::size_t h = 0; h < la.depth.size(); ++h) {
        EXPECT_NEAR(la.depth[h], lb.depth[h], 1e-6) << describe(p, q, nodes);
        EXPECT_NEAR(glm::length(la.normal[h] - lb.normal[h]), 0.0, 1e-5) << describe(p, q, nodes);
      }
      compared += la.depth.size();
    }
    EXPECT_GT(compared, 300u) << describe(p, q, nodes);
    EXPECT_GT(mirrored, 0) << "no element was mirrored";
  }
}

TEST(CurvedHex, AxisAndEmbreeCastersGiveTheSameHits) {
  for (const auto& [p, q, nodes] :
       {std::tuple{3, 2, NodeSet::gauss_lobatto_legendre}, std::tuple{2, 3, NodeSet::equispaced},
        std::tuple{4, 2, NodeSet::gauss_legendre}}) {
    const CurvedMesh m = curved_mesh(2, p, q, nodes, 0.08, wavy);
    const HexElementSource source(m.block);
    const RayCaster fast(source, 0.0), reference(source, 0.0, RayCasterOptions{CastPath::embree});
    for (const View& view : make_axis_views(source.bounds(), 32)) {
      ASSERT_TRUE(fast.uses_axis_casters(view));
      const Ldi a = fast.cast(view), b = reference.cast(view);
      EXPECT_EQ(a.offsets, b.offsets) << describe(p, q, nodes);
      ASSERT_EQ(a.depth.size(), b.depth.size());
      EXPECT_GT(a.sample_count(), 300u) << describe(p, q, nodes);
      for (std::size_t k = 0; k < a.depth.size(); ++k) {
        EXPECT_NEAR(a.depth[k], b.depth[k], 1e-6) << describe(p, q, nodes);
        EXPECT_NEAR(glm::length(a.normal[k] - b.normal[k]), 0.0, 1e-5) << describe(p, q, nodes);
      }
    }
  }
}

// The search's AVX2 copy and its baseline copy give the same bits (double depths, normals): on
// random elements of mixed degrees, for batches of axis rays through an element's pieces and
// for single oblique rays.
TEST(CurvedHex, SearchCopiesGiveTheSameBits) {
  if (!curved::prefer_avx2(true)) GTEST_SKIP() << "no AVX2 on this processor: one copy only";
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(-0.06, 0.06), value(-1.0, 1.0);
  std::size_t compared = 0;
  for (const auto& [p, q] : {std::pair{4, 4}, std::pair{2, 3}, std::pair{6, 2}}) {
    // Geometry: the unit cube's Bernstein coefficients (i / q per axis) moved at random; field:
    // random coefficients.
    std::vector<glm::dvec3> geometry;
    for (int k = 0; k <= q; ++k)
      for (int j = 0; j <= q; ++j)
        for (int i = 0; i <= q; ++i)
          geometry.push_back(glm::dvec3(i, j, k) / double(q) +
                             glm::dvec3(jitter(rng), jitter(rng), jitter(rng)));
    std::vector<double> field(std::size_t((p + 1) * (p + 1) * (p + 1)));
    for (double& f : field)
      f = value(rng);
    const curved::Element e{p, q, field.data(), geometry.data()};
    // Each copy splits the element into its pieces too.
    std::vector<curved::Piece> boxes[2];
    const auto run = [&](bool avx2, std::vector<std::uint32_t>& ids, std::vector<RayHit>& hits) {
      EXPECT_EQ(curved::prefer_avx2(avx2), avx2);
      const curved::Pieces pieces(e, 0.25);
      boxes[avx2] = pieces.pieces();
      ids.clear(), hits.clear();
      AxisHits out;
      for (int axis = 0; axis < 3; ++axis) {
        glm::dvec3 d(0.0);
        d[axis] = axis == 1 ? -1.0 : 1.0;
        std::vector<curved::RayRef> rays;
        for (int j = 0; j < 24; ++j)
          for (int i = 0; i < 24; ++i) {
            glm::dvec3 o(0.0);
            o[(axis + 1) % 3] = (i + 0.5) / 24.0, o[(axis + 2) % 3] = (j + 0.5) / 24.0;
            o[axis] = axis == 1 ? 2.0 : -1.0;
            rays.push_back({std::uint32_t(rays.size()), o, 0.0, 3.0});
          }
        for (std::size_t k = 0; k < pieces.pieces().size(); ++k) {
          out.clear();
          pieces.intersect(k, rays, d, out);
          ids.insert(ids.end(), out.rays().begin(), out.rays().end());
          hits.insert(hits.end(), out.hits().begin(), out.hits().end());
        }
      }
      for (int r = 0; r < 200; ++r) {
        const glm::dvec3 o(value(rng), value(rng), -1.5), d(0.2 * value(rng), 0.3, 1.0);
        curved::intersect(e, o, d, 0.0, 5.0, hits);
      }
    };
    std::vector<std::uint32_t> ids_a, ids_b;
    std::vector<RayHit> a, b;
    const std::mt19937 start = rng;
    run(true, ids_a, a);
    rng = start;  // the same oblique rays
    run(false, ids_b, b);
    curved::prefer_avx2(true);
    ASSERT_EQ(boxes[0].size(), boxes[1].size()) << p << " " << q;
    for (std::size_t k = 0; k < boxes[0].size(); ++k) {
      EXPECT_EQ(boxes[0][k].lo, boxes[1][k].lo);
      EXPECT_EQ(boxes[0][k].world_lo, boxes[1][k].world_lo);
      EXPECT_EQ(boxes[0][k].world_hi, boxes[1][k].world_hi);
    }
    EXPECT_EQ(ids_a, ids_b) << p << " " << q;
    ASSERT_EQ(a.size(), b.size()) << p << " " << q;
    EXPECT_GT(a.size(), 200u) << p << " " << q;
    for (std::size_t h = 0; h < a.size(); ++h) {
      EXPECT_EQ(a[h].t, b[h].t) << p << " " << q << " hit " << h;
      EXPECT_EQ(a[h].normal, b[h].normal) << p << " " << q << " hit " << h;
    }
    compared += a.size();
  }
  EXPECT_GT(compared, 1000u);
}

// The roots along one ray by dense sampling: in each element whose box the ray passes, the
// field at 1000 depths, each mapped to reference coordinates by the source's inversion, sign
// changes between samples inside the element refined by bisection. nullopt where the scan
// cannot decide (roots near a face or each other, a near-tangency).
std::optional<std::vector<double>> dense_scan(const HexElementSource& source, glm::dvec3 o,
                                              glm::dvec3 d, double t_max) {
  const int p = source.block().order;
  const std::size_t n = std::size_t(p + 1) * (p + 1) * (p + 1);
  std::vector<double> c(n), roots;
  constexpr int kSteps = 1000;
  const auto inside = [](glm::dvec3 xi, double pad) {
    return xi.x >= -pad && xi.x <= 1 + pad && xi.y >= -pad && xi.y <= 1 + pad && xi.z >= -pad &&
           xi.z <= 1 + pad;
  };
  std::vector<double> value(kSteps + 1);
  std::vector<char> in(kSteps + 1);
  for (std::size_t e = 0; e < source.block().element_count; ++e) {
    source.element_bernstein(e, c);
    Box box{glm::dvec3(1e300), glm::dvec3(-1e300)};  // the geometry's convex hull
    for (const glm::dvec3& x : source.curved_geometry(e))
      box.lo = glm::min(box.lo, x), box.hi = glm::max(box.hi, x);
    const auto sample = [&](double t, glm::dvec3& xi) {
      xi = source.to_reference(e, o + t * d);
      return evaluate_bernstein(p, c, xi).value;
    };
    double scale = 0.0;
    for (int k = 0; k <= kSteps; ++k) {
      const double t = t_max * k / kSteps;
      const glm::dvec3 x = o + t * d;
      in[k] = false;
      if (glm::any(glm::lessThan(x, box.lo - 1e-9)) || glm::any(glm::greaterThan(x, box.hi + 1e-9)))
        continue;
      glm::dvec3 xi;
      value[k] = sample(t, xi);
      in[k] = inside(xi, 0.0);
      if (in[k] && inside(xi, 1e-4) != inside(xi, -1e-4) && std::abs(value[k]) < 1e-2)
        return std::nullopt;  // the surface near a face
      if (in[k]) scale = std::max(scale, std::abs(value[k]));
    }
    int last = -100;
    for (int k = 1; k <= kSteps; ++k) {
      if (!in[k] || !in[k - 1]) continue;
      if (positive(value[k]) != positive(value[k - 1])) {
        if (k - last <= 3) return std::nullopt;  // two roots within a few steps
        last = k;
        double a = t_max * (k - 1) / kSteps, b = t_max * k / kSteps;
        const bool left = positive(value[k - 1]);
        for (int iter = 0; iter < 60; ++iter) {
          const double mid = 0.5 * (a + b);
          glm::dvec3 unused;
          (positive(sample(mid, unused)) == left ? a : b) = mid;
        }
        roots.push_back(0.5 * (a + b));
      } else if (k < kSteps && in[k + 1] && std::abs(value[k]) <= std::abs(value[k - 1]) &&
                 std::abs(value[k]) <= std::abs(value[k + 1]) &&
                 positive(value[k]) == positive(value[k + 1]) &&
                 std::abs(value[k]) < 0.02 * scale) {
        return std::nullopt;  // a local minimum of |f| near zero: maybe two close roots
      }
    }
  }
  std::sort(roots.begin(), roots.end());
  return roots;
}

TEST(CurvedHex, RootsMatchADenseScan) {
  std::mt19937 rng(11);
  int rays = 0, roots = 0;
  // p > q, p < q, and a high p over a low q: the search raises the lower degree to the higher.
  for (const auto& [p, q, nodes] :
       {std::tuple{3, 2, NodeSet::gauss_lobatto_legendre}, std::tuple{2, 4, NodeSet::equispaced},
        std::tuple{6, 2, NodeSet::gauss_legendre}}) {
    const CurvedMesh m = curved_mesh(2, p, q, nodes, 0.1, wavy);
    const HexElementSource source(m.block);
    const RayCaster caster(source, 0.0);
    for (const glm::dvec3 dir :
         {glm::dvec3(1, 0, 0), glm::dvec3(0, 0, -1), glm::dvec3(0.3, -0.5, 0.8)}) {
      const View view = make_view(source.bounds(), dir, 32);
      std::uniform_real_distribution<double> ux(0.0, view.width), uy(0.0, view.height);
      std::vector<glm::dvec2> points(40);
      for (glm::dvec2& pt : points)
        pt = {ux(rng), uy(rng)};
      const RayHitList hits = caster.cast_points(view, points);
      for (std::size_t r = 0; r < points.size(); ++r) {
        const glm::dvec3 o = view.point(points[r].x, points[r].y, 0.0);
        const auto expected = dense_scan(source, o, view.dir, view.depth_extent);
        if (!expected) continue;
        ++rays;
        const std::uint32_t begin = hits.offsets[r], count = hits.offsets[r + 1] - begin;
        EXPECT_EQ(count, expected->size()) << describe(p, q, nodes) << " ray " << r;
        if (count != expected->size()) continue;
        for (std::uint32_t h = 0; h < count; ++h)
          EXPECT_NEAR(hits.depth[begin + h], (*expected)[h], 1e-6) << describe(p, q, nodes);
        roots += int(count);
      }
    }
  }
  EXPECT_GT(rays, 120);
  EXPECT_GT(roots, 150);
}

// Rays exactly along element faces, through element edges and through a vertex of a curved
// mesh: 2³ elements over [0, 2]³ whose interiors are bent while their faces stay the planes of
// integer coordinates (the bend vanishes there), and the field 0.3 x + 0.5 y + z, represented
// exactly, at the isovalues whose planes pass through the mesh's middle vertex (1, 1, 1) and
// through the middle of its edge from (1, 1, 0) to (1, 1, 1). Each ray meets the plane once,
// however many elements share the point where it does — by both casters.
TEST(CurvedHex, RaysAlongFacesEdgesAndThroughAVertexHitOnce) {
  const glm::dvec3 normal(0.3, 0.5, 1.0);
  for (const auto& [p, q, iso] : {std::tuple{2, 2, glm::dot(normal, glm::dvec3(1.0))},
                                  std::tuple{3, 2, glm::dot(normal, glm::dvec3(1.0, 1.0, 0.5))},
                                  std::tuple{4, 3, glm::dot(normal, glm::dvec3(1.0))},
                                  std::tuple{4, 3, glm::dot(normal, glm::dvec3(1.0, 1.0, 0.5))}}) {
    const CurvedMesh m = mesh_of(
        8, p, q, NodeSet::gauss_lobatto_legendre,
        [](std::size_t e, glm::dvec3 xi) {
          const glm::dvec3 x = glm::dvec3(double(e % 2), double(e / 2 % 2), double(e / 4)) + xi;
          const double bump = std::sin(kPi * x.x) * std::sin(kPi * x.y) * std::sin(kPi * x.z);
          return x + 0.08 * bump * glm::dvec3(1.0, -0.7, 0.4);
        },
        [&](glm::dvec3 x) { return glm::dot(normal, x); });
    const HexElementSource source(m.block);
    for (std::size_t e = 0; e < 8; ++e)
      ASSERT_TRUE(source.is_curved(e)) << describe(p, q, NodeSet::gauss_lobatto_legendre);
    const Box domain{glm::dvec3(0.0), glm::dvec3(2.0)};
    const RayCaster fast(source, iso), reference(source, iso, RayCasterOptions{CastPath::embree});
    std::size_t checked = 0;
    for (int axis = 0; axis < 3; ++axis) {
      glm::dvec3 dir(0.0);
      dir[axis] = 1.0;
      const View view = make_view(domain, dir, 8);
      // The rays' two coordinates across: on element faces (1), edges (both 1) and between, in
      // the interior of the mesh's cross-section.
      std::vector<glm::dvec2> positions;
      std::vector<glm::dvec3> across;  // the world point of each ray at depth 0
      for (double a : {0.25, 0.5, 1.0, 1.375, 1.75})
        for (double b : {0.25, 0.625, 1.0, 1.5, 1.75}) {
          glm::dvec3 x = view.origin;
          x[(axis + 1) % 3] = a, x[(axis + 2) % 3] = b;
          const glm::dvec3 r = x - view.origin;
          const glm::dvec2 image(glm::dot(r, view.u) / view.spacing,
                                 glm::dot(r, view.v) / view.spacing);
          const glm::dvec3 back = view.point(image.x, image.y, 0.0);
          // The ray passes exactly there.
          ASSERT_EQ(back[(axis + 1) % 3], a);
          ASSERT_EQ(back[(axis + 2) % 3], b);
          positions.push_back(image);
          across.push_back(back);
        }
      for (const RayCaster* caster : {&fast, &reference}) {
        const std::string what = describe(p, q, NodeSet::gauss_lobatto_legendre) + " axis " +
                                 std::to_string(axis) + (caster == &fast ? " coherent" : " Embree");
        EXPECT_EQ(caster->uses_axis_casters(view), caster == &fast) << what;
        const RayHitList hits = caster->cast_points(view, positions);
        for (std::size_t r = 0; r < positions.size(); ++r) {
          // Where the ray meets the plane, along the axis.
          const glm::dvec3 o = across[r];
          const double along = (iso - glm::dot(normal, o) + normal[axis] * o[axis]) / normal[axis];
          const std::uint32_t count = hits.offsets[r + 1] - hits.offsets[r];
          if (along < -1e-3 || along > 2.0 + 1e-3) {
            EXPECT_EQ(count, 0u) << what << " ray " << r;
            continue;
          }
          if (along < 1e-3 || along > 2.0 - 1e-3) continue;  // on the mesh's boundary
          EXPECT_EQ(count, 1u) << what << " ray " << r << " at (" << o.x << ", " << o.y << ", "
                               << o.z << ")";
          if (count != 1u) continue;
          const glm::dvec3 x =
              view.point(positions[r].x, positions[r].y, hits.depth[hits.offsets[r]]);
          EXPECT_NEAR(x[axis], along, 1e-6) << what;
          EXPECT_NEAR(
              glm::length(glm::dvec3(hits.normal[hits.offsets[r]]) - glm::normalize(normal)), 0.0,
              1e-5)
              << what;
          ++checked;
        }
      }
    }
    EXPECT_GE(checked, 80u) << describe(p, q, NodeSet::gauss_lobatto_legendre);
  }
}

// Everything a source derives from its block's geometry, and its values' Bernstein form, equal
// in two sources.
void expect_same_source(const HexElementSource& a, const HexElementSource& b,
                        const std::string& what) {
  ASSERT_EQ(a.geometry_degree(), b.geometry_degree()) << what;
  ASSERT_EQ(a.block().element_count, b.block().element_count) << what;
  EXPECT_EQ(a.block().element_stride, b.block().element_stride) << what;
  EXPECT_EQ(a.bounds().lo, b.bounds().lo) << what;
  EXPECT_EQ(a.bounds().hi, b.bounds().hi) << what;
  const int p = a.block().order;
  std::vector<double> ca(std::size_t(p + 1) * (p + 1) * (p + 1)), cb(ca.size());
  for (std::size_t e = 0; e < a.block().element_count; ++e) {
    ASSERT_EQ(a.is_curved(e), b.is_curved(e)) << what << " element " << e;
    const auto ga = a.curved_geometry(e), gb = b.curved_geometry(e);
    EXPECT_TRUE(std::equal(ga.begin(), ga.end(), gb.begin(), gb.end())) << what << " " << e;
    EXPECT_TRUE(std::equal(a.corners_of(e), a.corners_of(e) + 24, b.corners_of(e))) << what;
    a.element_bernstein(e, ca);
    b.element_bernstein(e, cb);
    EXPECT_EQ(ca, cb) << what << " element " << e;
  }
}

// The adaptor's snapshot: a source over copies of a block's arrays with new values (packed,
// element_stride 0), its geometry taken from the block's prepared source, is the source built
// from the copies from scratch, and casts the same LDIs — for curved elements, straight ones
// given by geometry nodes, and corner blocks with a trilinear element and a padded stride; a
// copy whose layout differs is refused.
TEST(CurvedHex, SourceOverACopyReusesThePreparedGeometry) {
  const auto field = [](glm::dvec3 x) { return x.x + x.y * x.y - x.z; };
  // A copy of `m`'s block: its geometry in other arrays, the values of `field` packed.
  struct Copy {
    std::vector<double> geometry, values;
    HexBlock block;
  };
  const auto copy_of = [&](const CurvedMesh& m, const HexElementSource& prepared) {
    Copy c;
    c.block = m.block;
    const int p = m.block.order;
    const std::size_t n = std::size_t(p + 1) * (p + 1) * (p + 1);
    const std::vector<double> xp = node_positions(p, m.block.nodes);
    for (std::size_t e = 0; e < m.block.element_count; ++e)
      for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
          for (int i = 0; i <= p; ++i)
            c.values.push_back(field(prepared.to_world(e, {xp[i], xp[j], xp[k]})));
    EXPECT_EQ(c.values.size(), n * m.block.element_count);
    c.geometry = m.geometry;
    if (m.block.geometry_order > 0)
      c.block.geometry = c.geometry.data();
    else
      c.block.corners = c.geometry.data();
    c.block.values = c.values.data();
    c.block.element_stride = 0;
    return c;
  };
  const auto check = [&](const CurvedMesh& m, const std::string& what) {
    const HexElementSource prepared(m.block);
    const Copy c = copy_of(m, prepared);
    const HexElementSource reused(prepared, c.block), scratch(c.block);
    expect_same_source(reused, scratch, what);
    std::size_t hits = 0;
    for (const glm::dvec3& dir :
         {glm::dvec3(1, 0, 0), glm::dvec3(0, 0, -1), glm::dvec3(0.3, 0.5, 0.8)}) {
      const View view = make_view(scratch.bounds(), dir, 40);
      const Ldi a = RayCaster(reused, 0.1).cast(view), b = RayCaster(scratch, 0.1).cast(view);
      EXPECT_EQ(a.offsets, b.offsets) << what;
      EXPECT_EQ(a.depth, b.depth) << what;
      EXPECT_EQ(a.normal, b.normal) << what;
      hits += a.depth.size();
    }
    EXPECT_GT(hits, 500u) << what;
  };

  // Curved elements (a shell, geometry order 4).
  const CurvedMesh shell = shell_mesh(2, 2, 4, 4, NodeSet::equispaced, 0.5, 1.0, field);
  check(shell, "curved shell");
  // Straight elements given by geometry nodes (order 2, undistorted box).
  const CurvedMesh box = curved_mesh(3, 3, 2, NodeSet::gauss_lobatto_legendre, 0.0, field);
  check(box, "straight elements of geometry order 2");
  {
    const HexElementSource s(box.block);
    EXPECT_FALSE(s.is_curved(0));
  }
  // A corner block (geometry order 0): two elements, one trilinear (a corner moved), values
  // at a padded stride.
  {
    CurvedMesh corners;
    const int p = 3;
    const std::size_t n = (p + 1) * (p + 1) * (p + 1), stride = n + 3;
    for (int e = 0; e < 2; ++e)
      for (int c = 0; c < 8; ++c) {
        glm::dvec3 x(double(e + (c & 1)), double((c >> 1) & 1), double((c >> 2) & 1));
        if (e == 1 && c == 7) x += glm::dvec3(0.2, 0.1, 0.15);
        corners.geometry.insert(corners.geometry.end(), {0.5 * x.x, 0.5 * x.y, 0.5 * x.z});
      }
    corners.block.order = p;
    corners.block.nodes = NodeSet::gauss_legendre;
    corners.block.element_count = 2;
    corners.block.corners = corners.geometry.data();
    corners.block.element_stride = stride;
    corners.values.assign(2 * stride, 0.0);
    corners.block.values = corners.values.data();
    const HexElementSource geometry(corners.block);
    EXPECT_FALSE(geometry.is_curved(0));
    EXPECT_TRUE(geometry.is_curved(1));
    const std::vector<double> xp = node_positions(p, corners.block.nodes);
    for (std::size_t e = 0; e < 2; ++e) {
      std::size_t v = e * stride;
      for (int k = 0; k <= p; ++k)
        for (int j = 0; j <= p; ++j)
          for (int i = 0; i <= p; ++i)
            corners.values[v++] = field(geometry.to_world(e, {xp[i], xp[j], xp[k]}));
    }
    check(corners, "corner block with a trilinear element, padded stride");
  }

  // Another layout is refused.
  const HexElementSource prepared(shell.block);
  const auto refused = [&](auto change, const char* what) {
    HexBlock other = shell.block;
    change(other);
    EXPECT_THROW(HexElementSource(prepared, other), std::invalid_argument) << what;
  };
  refused([](HexBlock& b) { b.order = 3; }, "order");
  refused([](HexBlock& b) { b.element_count -= 1; }, "element count");
  refused([](HexBlock& b) { b.geometry_order = 3; }, "geometry order");
  refused([](HexBlock& b) { b.nodes = NodeSet::gauss_legendre; }, "node set");
  refused([](HexBlock& b) { b.ordering = NodeOrdering::vtk_lagrange; }, "ordering");
  refused([](HexBlock& b) { b.values = nullptr; }, "values");
  refused([](HexBlock& b) { b.element_stride = 10; }, "stride");
  // The geometry is prepared's, shared: the block's arrays are not read, and may be null.
  HexBlock no_geometry = shell.block;
  no_geometry.geometry = nullptr;
  const HexElementSource shared(prepared, no_geometry);
  std::size_t curved = 0;
  for (std::size_t e = 0; e < shell.block.element_count; e += 7) {
    EXPECT_EQ(shared.to_world(e, glm::dvec3(0.3, 0.6, 0.2)),
              prepared.to_world(e, glm::dvec3(0.3, 0.6, 0.2)));
    ASSERT_EQ(shared.is_curved(e), prepared.is_curved(e));
    if (!prepared.is_curved(e)) continue;
    ++curved;
    EXPECT_EQ(shared.curved_geometry(e).data(), prepared.curved_geometry(e).data());
  }
  EXPECT_GT(curved, 0u);
  // A block of corners likewise: the source keeps them.
  std::vector<double> corners(24);
  for (int c = 0; c < 8; ++c)
    for (int a = 0; a < 3; ++a)
      corners[std::size_t(3 * c + a)] = ((c >> a) & 1) + 0.1 * a;
  const std::vector<double> values(8, 1.0);
  HexBlock cube;
  cube.order = 1;
  cube.element_count = 1;
  cube.corners = corners.data();
  cube.values = values.data();
  const HexElementSource box_source(cube);
  const std::vector<double> kept(box_source.corners_of(0), box_source.corners_of(0) + 24);
  std::fill(corners.begin(), corners.end(), -7.0);  // the block's array is not read again
  cube.corners = nullptr;
  const HexElementSource box_shared(box_source, cube);
  EXPECT_EQ(std::vector<double>(box_shared.corners_of(0), box_shared.corners_of(0) + 24), kept);
  EXPECT_EQ(kept[3], 1.0);  // corner 1 at x = 1
}

TEST(CurvedHex, InvalidCurvedBlocksAreRejected) {
  // One element: only its centre node is off the box's faces, and the distortion moves it.
  const CurvedMesh good =
      curved_mesh(1, 2, 2, NodeSet::gauss_lobatto_legendre, 0.05, [](glm::dvec3 x) { return x.x; });
  EXPECT_TRUE(HexElementSource(good.block).is_curved(0));
  auto rejects = [&](const HexBlock& block, const char* needle) {
    try {
      HexElementSource source(block);
      ADD_FAILURE() << "accepted a block that should throw (" << needle << ")";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  HexBlock b = good.block;
  b.geometry_order = kMaxHexOrder + 1;
  rejects(b, "geometry order 9");
  b = good.block;
  b.geometry = nullptr;
  rejects(b, "null geometry");
  std::vector<double> geometry = good.geometry;
  geometry[3 * 13 + 1] = std::numeric_limits<double>::quiet_NaN();
  b = good.block;
  b.geometry = geometry.data();
  rejects(b, "element 0 has a non-finite geometry node");
  // The centre node (1, 1, 1) pulled beyond a face: the element folds over.
  geometry = good.geometry;
  geometry[3 * 13 + 0] = kBox.hi.x + 0.6 * (kBox.hi.x - kBox.lo.x);
  b.geometry = geometry.data();
  rejects(b, "element 0 is inverted or degenerate");
  // The same element mirrored (ξ reversed, a left-handed map) is fine, and has the same hits.
  std::vector<double> mirrored(good.geometry.size()), mirrored_values(good.values.size());
  for (int k = 0; k <= 2; ++k)
    for (int j = 0; j <= 2; ++j)
      for (int i = 0; i <= 2; ++i)
        for (int a = 0; a < 3; ++a) {
          mirrored[3 * (i + 3 * (j + 3 * k)) + a] =
              good.geometry[3 * ((2 - i) + 3 * (j + 3 * k)) + a];
          if (a == 0) mirrored_values[i + 3 * (j + 3 * k)] = good.values[(2 - i) + 3 * (j + 3 * k)];
        }
  b = good.block;
  b.geometry = mirrored.data();
  b.values = mirrored_values.data();
  const HexElementSource left(b), right(good.block);
  for (const View& view : make_axis_views(right.bounds(), 16)) {
    const Ldi l = RayCaster(left, 0.1).cast(view), r = RayCaster(right, 0.1).cast(view);
    EXPECT_EQ(l.offsets, r.offsets);
    EXPECT_EQ(l.depth.size(), r.depth.size());
    for (std::size_t k = 0; k < std::min(l.depth.size(), r.depth.size()); ++k)
      EXPECT_NEAR(l.depth[k], r.depth[k], 1e-6);
  }
}

TEST(CurvedHex, VtkLagrangeIndexIsVtks) {
  // vtkLagrangeHexahedron::PointIndexFromIJK(i, j, k, {p, p, p}) of VTK 9.1 for p = 2 and 3, node
  // (i, j, k) in lexicographic order (printed with Debian's python3-vtk9); p = 1..8 agreed with
  // it when this was written.
  const std::vector<std::size_t> vtk2 = {0,  8,  1,  11, 24, 9,  3, 10, 2,  16, 22, 17, 20, 26,
                                         21, 19, 23, 18, 4,  12, 5, 15, 25, 13, 7,  14, 6};
  const std::vector<std::size_t> vtk3 = {
      0,  8,  9,  1,  14, 48, 49, 10, 15, 50, 51, 11, 3,  12, 13, 2,  24, 40, 41, 26, 32, 56,
      57, 36, 33, 58, 59, 37, 30, 44, 45, 28, 25, 42, 43, 27, 34, 60, 61, 38, 35, 62, 63, 39,
      31, 46, 47, 29, 4,  16, 17, 5,  22, 52, 53, 18, 23, 54, 55, 19, 7,  20, 21, 6};
  for (const auto& [p, expected] : {std::pair{2, vtk2}, std::pair{3, vtk3}}) {
    std::vector<std::size_t> got;
    for (int k = 0; k <= p; ++k)
      for (int j = 0; j <= p; ++j)
        for (int i = 0; i <= p; ++i)
          got.push_back(vtk_lagrange_index(i, j, k, p));
    EXPECT_EQ(got, expected) << "p " << p;
  }
  // Every order: a permutation of the element's nodes.
  for (int p = 1; p <= kMaxHexOrder; ++p) {
    std::vector<bool> seen((p + 1) * (p + 1) * (p + 1), false);
    for (int k = 0; k <= p; ++k)
      for (int j = 0; j <= p; ++j)
        for (int i = 0; i <= p; ++i) {
          const std::size_t at = vtk_lagrange_index(i, j, k, p);
          ASSERT_LT(at, seen.size());
          EXPECT_FALSE(seen[at]) << "p " << p;
          seen[at] = true;
        }
  }
  EXPECT_THROW(vtk_lagrange_index(3, 0, 0, 2), std::invalid_argument);
  EXPECT_THROW(vtk_lagrange_index(0, 0, 0, 9), std::invalid_argument);
}

TEST(CurvedHex, VtkOrderedBlocksGiveTheSameHits) {
  // The same curved mesh with its values and geometry nodes in VTK's order: the same numbers
  // reach the source, so the LDIs are equal to the bit.
  const int p = 3, q = 2;
  const CurvedMesh m = curved_mesh(2, p, q, NodeSet::equispaced, 0.08, wavy);
  const int np = (p + 1) * (p + 1) * (p + 1), nq = (q + 1) * (q + 1) * (q + 1);
  std::vector<double> values(m.values.size()), geometry(m.geometry.size());
  for (std::size_t e = 0; e < m.block.element_count; ++e) {
    for (int k = 0; k <= p; ++k)
      for (int j = 0; j <= p; ++j)
        for (int i = 0; i <= p; ++i)
          values[e * np + vtk_lagrange_index(i, j, k, p)] =
              m.values[e * np + i + (p + 1) * (j + (p + 1) * k)];
    for (int k = 0; k <= q; ++k)
      for (int j = 0; j <= q; ++j)
        for (int i = 0; i <= q; ++i)
          for (int a = 0; a < 3; ++a)
            geometry[3 * (e * nq + vtk_lagrange_index(i, j, k, q)) + a] =
                m.geometry[3 * (e * nq + i + (q + 1) * (j + (q + 1) * k)) + a];
  }
  HexBlock vtk = m.block;
  vtk.values = values.data();
  vtk.geometry = geometry.data();
  vtk.ordering = NodeOrdering::vtk_lagrange;
  const HexElementSource a(m.block), b(vtk);
  for (const View& view : make_axis_views(a.bounds(), 24)) {
    const Ldi la = RayCaster(a, 0.0).cast(view), lb = RayCaster(b, 0.0).cast(view);
    EXPECT_GT(la.sample_count(), 100u);
    EXPECT_EQ(la.offsets, lb.offsets);
    EXPECT_EQ(la.depth, lb.depth);
    EXPECT_EQ(la.normal, lb.normal);
  }
  // Read as lexicographic, the VTK-ordered arrays are another field: the test can fail.
  HexBlock wrong = vtk;
  wrong.ordering = NodeOrdering::lexicographic;
  wrong.geometry = m.geometry.data();
  const HexElementSource c(wrong);
  const View view = make_view(a.bounds(), {1, 0, 0}, 24);
  EXPECT_NE(RayCaster(a, 0.0).cast(view).depth, RayCaster(c, 0.0).cast(view).depth);
}

}  // namespace
}  // namespace ldimesh

#include "ldimesh/core/metrics/distance.hpp"

#include <cmath>
#include <map>
#include <random>
#include <stdexcept>
#include <utility>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

// The unit icosphere: the icosahedron with every triangle split into four `levels` times,
// vertices pushed onto the sphere; counter-clockwise seen from outside.
Mesh icosphere(int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<glm::dvec3> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                               {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                               {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (glm::dvec3& v : p)
    v = glm::normalize(v);
  std::vector<std::uint32_t> tris = {0, 11, 5, 0, 5,  1,  0,  1,  7,  0,  7, 10, 0, 10, 11,
                                     1, 5,  9, 5, 11, 4,  11, 10, 2,  10, 7, 6,  7, 1,  8,
                                     3, 9,  4, 3, 4,  2,  3,  2,  6,  3,  6, 8,  3, 8,  9,
                                     4, 9,  5, 2, 4,  11, 6,  2,  10, 8,  6, 7,  9, 8,  1};
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> middle;
    auto mid = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      auto [it, added] = middle.try_emplace(key, std::uint32_t(p.size()));
      if (added) p.push_back(glm::normalize(p[a] + p[b]));
      return it->second;
    };
    std::vector<std::uint32_t> next;
    for (std::size_t f = 0; f < tris.size(); f += 3) {
      const std::uint32_t a = tris[f], b = tris[f + 1], c = tris[f + 2];
      const std::uint32_t ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
      next.insert(next.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
    }
    tris = std::move(next);
  }
  Mesh m;
  for (const glm::dvec3& v : p) {
    m.positions.push_back(glm::vec3(v));
    m.normals.push_back(glm::vec3(v));
  }
  m.triangles = tris;
  m.triangle_view.assign(tris.size() / 3, 0);
  return m;
}

Mesh scaled(Mesh m, double s) {
  for (glm::vec3& p : m.positions)
    p = glm::vec3(s * glm::dvec3(p));
  return m;
}

// The deepest point of a face of a mesh inscribed in the unit sphere lies 1 − h below the
// sphere, h the distance of the face's plane from the origin (the foot of the origin lies
// inside every face of an icosphere): the largest such sagitta.
double largest_sagitta(const Mesh& m) {
  double sag = 0.0;
  for (std::size_t f = 0; f < m.triangle_count(); ++f) {
    const glm::dvec3 a(m.positions[m.triangles[3 * f]]), b(m.positions[m.triangles[3 * f + 1]]),
        c(m.positions[m.triangles[3 * f + 2]]);
    const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
    sag = std::max(sag, 1.0 - std::abs(glm::dot(n, a)));
  }
  return sag;
}

double longest_edge(const Mesh& m) {
  double e = 0.0;
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    const std::uint32_t a = m.triangles[f], b = m.triangles[f % 3 == 2 ? f - 2 : f + 1];
    e = std::max(e, glm::length(glm::dvec3(m.positions[a]) - glm::dvec3(m.positions[b])));
  }
  return e;
}

// Float vertices sit within 2⁻²⁴ of where the double construction put them: this covers it.
constexpr double kFloat = 1e-6;

TEST(Distance, IdenticalMeshesAreAtDistanceZero) {
  const Mesh a = icosphere(4);
  const Mesh b = a;
  const MeshDistance d = mesh_distance(a, b);
  for (const DistanceStats* s : {&d.forward, &d.backward}) {
    EXPECT_EQ(s->mean, 0.0);
    EXPECT_EQ(s->rms, 0.0);
    EXPECT_EQ(s->max, 0.0);
    // Ten samples per triangle: every vertex, the rest on edges and faces 1 : 3.
    EXPECT_EQ(s->samples.total(), 10 * a.triangle_count());
    EXPECT_EQ(s->samples.vertices, a.vertex_count());
    EXPECT_NEAR(double(s->samples.edges) / double(s->samples.faces), 1.0 / 3.0, 1e-3);
  }
  EXPECT_NEAR(d.diagonal, 2.0 * std::sqrt(3.0), 0.1);
}

TEST(Distance, QuadMeshAndItsTriangulationAreAtDistanceZero) {
  // The mesher's quads and its triangles split along the shorter diagonal, as distances do.
  const SurfaceInfo* s = find_surface("torus");
  const auto source = make_surface_source("torus");
  const RayCaster caster(*source, s->isovalue);
  std::vector<Ldi> ldis;
  for (const View& v : make_axis_views(s->domain, 64))
    ldis.push_back(caster.cast(v));
  MeshingOptions options;
  options.faces = FaceType::quads;
  const Mesh quads = mesh_ldis(ldis, options).mesh;
  options.faces = FaceType::triangles;
  const Mesh triangles = mesh_ldis(ldis, options).mesh;
  ASSERT_GT(quads.quad_count(), 1000u);
  ASSERT_EQ(quads.triangle_count(), 0u);
  const MeshDistance d = mesh_distance(quads, triangles);
  EXPECT_EQ(d.max(), 0.0);
  // A quad counts as two triangles for the default sample count.
  EXPECT_EQ(d.forward.samples.total(), 10 * triangles.triangle_count());
}

TEST(Distance, TinyOffsetsAreMeasuredNotRoundedAway) {
  const Mesh a = icosphere(3);
  const MeshDistance d = mesh_distance(a, scaled(a, 1.0 + 1e-5));
  EXPECT_GT(d.forward.mean, 0.9e-5);
  EXPECT_LT(d.forward.max, 1.1e-5);
  EXPECT_GT(d.backward.mean, 0.9e-5);
}

// A mesh inscribed in the unit sphere against the same scaled by 1.01: every sample of either
// lies between 1.01 h_min − 1 and 0.01 from the other (the other's faces lie between radii
// 1.01 h_min and 1.01, resp. h_min and 1, and x ↦ 1.01 x maps a point onto the other mesh),
// h_min = 1 − largest sagitta.
TEST(Distance, SphereScaledByOnePercentIsOnePercentAway) {
  const Mesh a = icosphere(5);
  const double sag = largest_sagitta(a);
  ASSERT_LT(sag, 3e-4);
  const MeshDistance d = mesh_distance(a, scaled(a, 1.01));
  const double lo = 0.01 - 1.01 * sag - kFloat, hi = 0.01 + kFloat;
  for (const DistanceStats* s : {&d.forward, &d.backward}) {
    EXPECT_GT(s->mean, lo);
    EXPECT_LT(s->max, hi);
    EXPECT_GE(s->max, s->rms);
    EXPECT_GE(s->rms, s->mean);
    EXPECT_GT(s->rms, lo);
  }
  EXPECT_EQ(d.max(), std::max(d.forward.max, d.backward.max));
}

// Cut a cap out of the sphere: A's samples all lie on B (forward 0), while B's samples in the
// hole are up to the hole's radius from A: the chord 2 sin(θ/2) from the cap's centre (a vertex,
// so a sample) to its rim, which is jagged by up to one edge length.
TEST(Distance, HoleShowsInTheBackwardDistanceOnly) {
  const Mesh full = icosphere(5);
  const glm::dvec3 centre(full.positions[0]);
  const double theta = 0.5;
  Mesh holed = full;
  holed.triangles.clear();
  holed.triangle_view.clear();
  for (std::size_t f = 0; f < full.triangle_count(); ++f) {
    const std::uint32_t* t = &full.triangles[3 * f];
    const glm::dvec3 c =
        glm::normalize(glm::dvec3(full.positions[t[0]]) + glm::dvec3(full.positions[t[1]]) +
                       glm::dvec3(full.positions[t[2]]));
    if (std::acos(std::clamp(glm::dot(c, centre), -1.0, 1.0)) < theta) continue;
    holed.triangles.insert(holed.triangles.end(), t, t + 3);
    holed.triangle_view.push_back(0);
  }
  ASSERT_LT(holed.triangle_count(), full.triangle_count() - 500);
  const MeshDistance d = mesh_distance(holed, full);
  EXPECT_EQ(d.forward.max, 0.0);
  const double radius = 2.0 * std::sin(theta / 2.0), edge = longest_edge(full);
  EXPECT_NEAR(d.backward.max, radius, edge);
  EXPECT_LT(glm::length(d.backward.max_at - centre), edge);
  EXPECT_EQ(d.max(), d.backward.max);
  // Only the hole's share of the samples is far: the mean is far below the maximum.
  EXPECT_GT(d.backward.mean, 0.0);
  EXPECT_LT(d.backward.mean, 0.1 * d.backward.max);
}

// To the implicit unit sphere, a sample x is 1 − |x| away (inside, within the sagitta) or
// |x| − 1 (the scaled mesh: between 1.01 h_min − 1 and 0.01).
TEST(Distance, SphereMeshToTheImplicitSphere) {
  const SurfaceInfo& sphere = *find_surface("sphere");
  const Mesh a = icosphere(5);
  const double sag = largest_sagitta(a);
  const SurfaceDistance d = surface_distance(a, sphere, 1.0);
  EXPECT_EQ(d.not_converged, 0u);
  EXPECT_EQ(d.outside_clip, 0u);
  EXPECT_EQ(d.forward.samples.total(), 10 * a.triangle_count());
  EXPECT_LE(d.forward.max, sag + kFloat);
  // ~7 samples per face, thousands of faces: some land near a face's deepest point.
  EXPECT_GT(d.forward.max, 0.9 * sag);
  // Over a near-equilateral face the sagitta averages 3/4 of its largest, 1/2 along edges, 0 at
  // vertices: with the 5 : 24 : 71 split about 0.65.
  EXPECT_GT(d.forward.mean, 0.5 * sag);
  EXPECT_LT(d.forward.mean, 0.8 * sag);

  const SurfaceDistance s = surface_distance(scaled(a, 1.01), sphere, 1.0);
  EXPECT_EQ(s.not_converged, 0u);
  EXPECT_GT(s.forward.mean, 0.01 - 1.01 * sag - kFloat);
  EXPECT_LT(s.forward.max, 0.01 + kFloat);
  EXPECT_GT(s.forward.max, 0.01 - kFloat);  // the vertices are 0.01 out
}

// The torus's distance function is known in closed form: the Newton projection and foot-point
// iteration must find it on a mesh that is not a sphere (there Newton alone is exact).
TEST(Distance, LdiTorusMeshToTheImplicitTorusMatchesTheClosedForm) {
  const SurfaceInfo& torus = *find_surface("torus");
  const auto source = make_surface_source("torus");
  const RayCaster caster(*source, torus.isovalue);
  std::vector<Ldi> ldis;
  const std::vector<View> views = make_axis_views(torus.domain, 96);
  for (const View& v : views)
    ldis.push_back(caster.cast(v));
  const Mesh m = mesh_ldis(ldis).mesh;
  // Displace every vertex along its normal by 0.002: the closed-form distance then is 0.002 at
  // every vertex.
  Mesh moved = m;
  for (std::size_t i = 0; i < m.vertex_count(); ++i)
    moved.positions[i] = glm::vec3(glm::dvec3(m.positions[i]) + 0.002 * glm::dvec3(m.normals[i]));
  const SurfaceDistance d = surface_distance(moved, torus, torus.isovalue);
  EXPECT_EQ(d.not_converged, 0u);
  EXPECT_EQ(d.outside_clip, 0u);
  EXPECT_LT(d.forward.max, 0.002 + 0.25 * views[0].spacing);
  EXPECT_NEAR(d.forward.mean, 0.002, 0.1 * views[0].spacing);
  // The vertices alone: their distances in closed form, |√((√(x² + y²) − R)² + z²) − a|.
  DistanceOptions vertices_only;
  vertices_only.samples = 1;
  const SurfaceDistance v = surface_distance(moved, torus, torus.isovalue, vertices_only);
  ASSERT_EQ(v.forward.samples.total(), moved.vertex_count());
  const fields::Torus t;
  double sum = 0.0, max = 0.0;
  for (const glm::vec3& q : moved.positions) {
    const glm::dvec3 p(q);
    const double e = std::abs(std::hypot(std::hypot(p.x, p.y) - t.R, p.z) - t.a);
    sum += e;
    max = std::max(max, e);
  }
  EXPECT_NEAR(v.forward.mean, sum / double(moved.vertex_count()), 1e-12);
  EXPECT_NEAR(v.forward.max, max, 1e-12);
  EXPECT_NEAR(max, 0.002, 1e-5);  // the displacement, up to the mesh's accuracy
}

TEST(Distance, SamplesWhoseClosestPointIsClippedAwayAreCountedApart) {
  // The sphere clipped to z ≤ 0.5: the cap above (a quarter of the area) has no surface.
  SurfaceInfo clipped = *find_surface("sphere");
  clipped.domain.hi.z = 0.5;
  const Mesh a = icosphere(4);
  const SurfaceDistance d = surface_distance(a, clipped, 1.0);
  const double total = double(d.forward.samples.total() + d.outside_clip);
  EXPECT_NEAR(d.outside_clip / total, 0.25, 0.01);
  EXPECT_LE(d.forward.max, largest_sagitta(a) + kFloat);
  // Clipped to a ball inside the sphere: nothing is left to measure against.
  SurfaceInfo ball = *find_surface("sphere");
  ball.clip_radius = 0.5;
  const SurfaceDistance none = surface_distance(a, ball, 1.0);
  EXPECT_EQ(none.forward.samples.total(), 0u);
  EXPECT_EQ(none.outside_clip, 10 * a.triangle_count());
}

TEST(Distance, ProjectionsThatDoNotConvergeAreCountedApart) {
  // x² + y² + z² = −1 has no solution: Newton cannot converge anywhere.
  const Mesh a = icosphere(2);
  const SurfaceDistance d = surface_distance(a, *find_surface("sphere"), -1.0);
  EXPECT_EQ(d.forward.samples.total(), 0u);
  EXPECT_EQ(d.not_converged, 10 * a.triangle_count());
  EXPECT_EQ(d.forward.mean, 0.0);
}

TEST(Distance, SameFiguresForAnyNumberOfThreads) {
  Mesh a = icosphere(5);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> noise(-1e-3f, 1e-3f);
  for (glm::vec3& p : a.positions)
    p += glm::vec3(noise(rng), noise(rng), noise(rng));
  const Mesh b = icosphere(4);
  const SurfaceInfo& sphere = *find_surface("sphere");
  auto run = [&](std::size_t threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return std::make_pair(mesh_distance(a, b), surface_distance(a, sphere, 1.0));
  };
  const auto [one, one_surface] = run(1);
  const auto [all, all_surface] = run(std::max(4, tbb::info::default_concurrency()));
  for (auto [x, y] : {std::pair{one.forward, all.forward}, std::pair{one.backward, all.backward},
                      std::pair{one_surface.forward, all_surface.forward}}) {
    EXPECT_GT(x.mean, 0.0);
    EXPECT_EQ(x.mean, y.mean);  // bit-identical
    EXPECT_EQ(x.rms, y.rms);
    EXPECT_EQ(x.max, y.max);
    EXPECT_EQ(x.max_at, y.max_at);
    EXPECT_EQ(x.samples.total(), y.samples.total());
  }
}

TEST(Distance, SampleCountIsATarget) {
  const Mesh a = icosphere(3), b = icosphere(4);
  DistanceOptions options;
  options.samples = 50000;
  const MeshDistance d = mesh_distance(a, b, options);
  EXPECT_EQ(d.forward.samples.total(), 50000u);
  EXPECT_EQ(d.backward.samples.total(), 50000u);
  EXPECT_EQ(d.forward.samples.vertices, a.vertex_count());
  // Fewer than the vertices: every vertex still is a sample.
  options.samples = 10;
  const MeshDistance v = mesh_distance(a, b, options);
  EXPECT_EQ(v.forward.samples.total(), a.vertex_count());
  EXPECT_EQ(v.backward.samples.total(), b.vertex_count());
  // The default: ten per triangle of the larger mesh, for both.
  const MeshDistance def = mesh_distance(a, b);
  EXPECT_EQ(def.forward.samples.total(), 10 * b.triangle_count());
  EXPECT_EQ(def.backward.samples.total(), 10 * b.triangle_count());
}

TEST(Distance, BadMeshesAreErrors) {
  const Mesh good = icosphere(1);
  Mesh empty;
  empty.positions = good.positions;
  try {
    mesh_distance(good, empty);
    FAIL() << "no error for a mesh without faces";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("mesh B has no faces"), std::string::npos) << e.what();
  }
  EXPECT_THROW(mesh_distance(Mesh{}, good), std::invalid_argument);
  EXPECT_THROW(surface_distance(Mesh{}, *find_surface("sphere"), 1.0), std::invalid_argument);
  Mesh bad_index = good;
  bad_index.triangles[5] = std::uint32_t(good.vertex_count());
  EXPECT_THROW(mesh_distance(good, bad_index), std::invalid_argument);
  Mesh nan = good;
  nan.positions[3].y = std::nanf("");
  EXPECT_THROW(mesh_distance(nan, good), std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

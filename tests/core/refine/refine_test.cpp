#include "ldimesh/core/refine/refine.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <numbers>
#include <tuple>
#include <unordered_map>

#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/metrics/distance.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace ldimesh {
namespace {

// A sample source that counts its round trips.
class CountingSource final : public SampleSource {
 public:
  explicit CountingSource(SampleSource& inner) : inner_(inner) {}
  RayHitList sample(std::span<const SamplePoint> points) override {
    ++calls;
    rays += points.size();
    return inner_.sample(points);
  }
  int calls = 0;
  std::size_t rays = 0;

 private:
  SampleSource& inner_;
};

struct Scene {
  std::unique_ptr<FieldSource> source;
  std::unique_ptr<RayCaster> caster;
  std::vector<View> views;
  std::vector<Ldi> ldis;
};

Scene cast_surface(std::string_view name, int res, std::string_view axes = "xyz") {
  Scene s;
  const SurfaceInfo* info = find_surface(name);
  s.source = make_surface_source(name);
  s.caster = std::make_unique<RayCaster>(*s.source, info->isovalue);
  s.views = make_axis_views(info->domain, res, axes);
  for (const View& v : s.views)
    s.ldis.push_back(s.caster->cast(v));
  return s;
}

MeshingResult mesh_scene(const Scene& s, FaceType faces, int levels, double r = 0.5,
                         SampleSource* counting = nullptr) {
  MeshingOptions options;
  options.r = r;
  options.faces = faces;
  options.refinement.levels = levels;
  LocalSampleSource local(*s.caster, s.views);
  return mesh_ldis(s.ldis, options, levels > 0 ? (counting ? counting : &local) : nullptr);
}

// Conformity of the faces of each view: every edge has at most two faces, and no vertex of the
// view lies inside an edge of its faces (a hanging vertex, a T-junction). Vertices are compared
// in the view's image plane, where refinement places new vertices exactly on the edges they
// split; a vertex counts as hanging on an edge when an edge of the mesh also joins it to an end
// of that edge (a vertex of another layer that merely projects onto the edge does not).
void expect_conforming(const Mesh& mesh, std::span<const View> views) {
  const bool quads = mesh.quad_count() > 0;
  const int arity = quads ? 4 : 3;
  const std::vector<std::uint32_t>& faces = quads ? mesh.quads : mesh.triangles;
  const std::vector<std::uint8_t>& face_view = quads ? mesh.quad_view : mesh.triangle_view;
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> edge_faces;
  for (std::size_t f = 0; f < faces.size(); f += arity)
    for (int k = 0; k < arity; ++k) {
      const std::uint32_t a = faces[f + k], b = faces[f + (k + 1) % arity];
      ++edge_faces[{std::min(a, b), std::max(a, b)}];
    }
  for (const auto& [edge, count] : edge_faces)
    ASSERT_LE(count, 2) << "edge " << edge.first << "-" << edge.second;

  for (std::size_t v = 0; v < views.size(); ++v) {
    const View& view = views[v];
    const auto image = [&](std::uint32_t i) {
      const glm::dvec3 d = glm::dvec3(mesh.positions[i]) - view.origin;
      return glm::dvec3(glm::dot(d, view.u) / view.spacing, glm::dot(d, view.v) / view.spacing,
                        glm::dot(d, view.dir) / view.spacing);
    };
    // The view's vertices, bucketed by pixel.
    std::unordered_map<std::int64_t, std::vector<std::uint32_t>> buckets;
    const auto key = [](int x, int y) { return std::int64_t(x) * 1000003 + y; };
    std::vector<std::uint8_t> seen(mesh.vertex_count(), 0);
    for (std::size_t f = 0; f < faces.size(); f += arity) {
      if (face_view[f / arity] != v) continue;
      for (int k = 0; k < arity; ++k) {
        const std::uint32_t i = faces[f + k];
        if (seen[i]) continue;
        seen[i] = 1;
        const glm::dvec3 p = image(i);
        buckets[key(int(std::floor(p.x)), int(std::floor(p.y)))].push_back(i);
      }
    }
    for (std::size_t f = 0; f < faces.size(); f += arity) {
      if (face_view[f / arity] != v) continue;
      for (int k = 0; k < arity; ++k) {
        const std::uint32_t a = faces[f + k], b = faces[f + (k + 1) % arity];
        const glm::dvec3 pa = image(a), pb = image(b);
        const glm::dvec2 ab(pb - pa);
        const double length2 = glm::dot(ab, ab);
        for (int x = int(std::floor(std::min(pa.x, pb.x)));
             x <= int(std::floor(std::max(pa.x, pb.x))); ++x)
          for (int y = int(std::floor(std::min(pa.y, pb.y)));
               y <= int(std::floor(std::max(pa.y, pb.y))); ++y) {
            const auto it = buckets.find(key(x, y));
            if (it == buckets.end()) continue;
            for (std::uint32_t m : it->second) {
              if (m == a || m == b) continue;
              const glm::dvec3 pm = image(m);
              const glm::dvec2 am(pm - pa);
              const double t = glm::dot(am, ab) / length2;
              if (t <= 1e-3 || t >= 1 - 1e-3) continue;
              const glm::dvec2 off = am - t * ab;
              if (glm::dot(off, off) > 1e-6) continue;
              // Another layer's vertex may project onto the edge too; a hanging vertex is
              // joined to an end of the edge by the faces on the other side.
              if (!edge_faces.count({std::min(a, m), std::max(a, m)}) &&
                  !edge_faces.count({std::min(b, m), std::max(b, m)}))
                continue;
              ADD_FAILURE() << "view " << v << ": vertex " << m << " hangs on edge " << a << "-"
                            << b << " at t = " << t << ": a (" << pa.x << ", " << pa.y << ", "
                            << pa.z << ") b (" << pb.x << ", " << pb.y << ", " << pb.z << ") m ("
                            << pm.x << ", " << pm.y << ", " << pm.z << ")";
              return;
            }
          }
      }
    }
  }
}

void expect_same_mesh(const Mesh& a, const Mesh& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  EXPECT_EQ(0, std::memcmp(a.positions.data(), b.positions.data(), a.positions.size() * 12));
  EXPECT_EQ(0, std::memcmp(a.normals.data(), b.normals.data(), a.normals.size() * 12));
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.quads, b.quads);
}

TEST(Refine, TrianglesAndQuadsHaveNoHangingVertices) {
  for (const auto& [name, res] : {std::pair{"marschner-lobb", 32}, {"sphere", 24}, {"torus", 24}}) {
    const Scene s = cast_surface(name, res);
    const std::size_t unrefined = mesh_scene(s, FaceType::quads, 0).mesh.quad_count();
    for (FaceType faces : {FaceType::triangles, FaceType::quads}) {
      SCOPED_TRACE(std::string(name) + (faces == FaceType::quads ? " quads" : " triangles"));
      const MeshingResult m = mesh_scene(s, faces, 3);
      EXPECT_GT(m.refinement.subdivided_cells, 100u);
      expect_conforming(m.mesh, s.views);
      if (faces == FaceType::quads) {
        EXPECT_EQ(m.mesh.triangle_count(), 0u);
        EXPECT_GT(m.mesh.quad_count(), unrefined);
      } else {
        EXPECT_EQ(m.mesh.quad_count(), 0u);
        EXPECT_GT(m.mesh.triangle_count(), 2 * unrefined);
      }
    }
  }
}

// The checker itself: a cell split on one side only is found.
TEST(Refine, ConformityCheckFindsAHangingVertex) {
  const View view = make_axis_views(Box{{0, 0, 0}, {2, 1, 1}}, 2, "z")[0];
  Mesh m;
  // Two unit squares side by side at depth 0.5; the right one split into four.
  const auto at = [&](double x, double y) {
    m.positions.emplace_back(view.point(x, y, 0.5));
    m.normals.emplace_back(0, 0, 1);
    return std::uint32_t(m.positions.size() - 1);
  };
  const std::uint32_t a = at(0, 0), b = at(1, 0), c = at(1, 1), d = at(0, 1), e = at(2, 0),
                      f = at(2, 1), mb = at(1.5, 0), mr = at(2, 0.5), mt = at(1.5, 1),
                      ml = at(1, 0.5), x = at(1.5, 0.5);
  m.quads = {a, b, c, d, b, mb, x, ml, mb, e, mr, x, x, mr, f, mt, ml, x, mt, c};
  m.quad_view.assign(5, 0);
  m.view_dirs = {view.dir};
  const std::vector<View> views{view};
  EXPECT_NONFATAL_FAILURE(expect_conforming(m, views), "hangs on edge");
}

struct Plane {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    return z - 0.3 * x - 0.2 * y;
  }
};

// §4 (iii) toward boundaries: a tilted plane cut by the domain box. Without growth nothing is
// marked (equal normals, no invalid vertex): no pass, no round trip. With growth the mesh
// reaches closer to the box than the pixel centres.
TEST(Refine, PlaneGrowsTowardTheDomainBoundary) {
  const Box box{{-1, -1, -1}, {1, 1, 1}};
  Scene s;
  s.source = std::make_unique<AnalyticSource<Plane>>(Plane{}, box);
  s.caster = std::make_unique<RayCaster>(*s.source, 0.0);
  s.views = make_axis_views(box, 16, "z");
  s.ldis.push_back(s.caster->cast(s.views[0]));
  const MeshingResult plain = mesh_scene(s, FaceType::quads, 0, 0.0);

  LocalSampleSource local(*s.caster, s.views);
  CountingSource counting(local);
  MeshingOptions options;
  options.r = 0.0;
  options.faces = FaceType::quads;
  options.refinement.levels = 3;
  options.refinement.grow = false;
  const MeshingResult still = mesh_ldis(s.ldis, options, &counting);
  EXPECT_EQ(still.refinement.passes, 0);
  EXPECT_EQ(counting.calls, 0);
  // The same quads (vertex order aside): the same sorted corner positions.
  const auto corners = [](const Mesh& m) {
    std::vector<std::array<float, 12>> out;
    for (std::size_t q = 0; q < m.quads.size(); q += 4) {
      std::array<glm::vec3, 4> c;
      for (int k = 0; k < 4; ++k)
        c[k] = m.positions[m.quads[q + k]];
      std::rotate(c.begin(),
                  std::min_element(c.begin(), c.end(),
                                   [](glm::vec3 a, glm::vec3 b) {
                                     return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
                                   }),
                  c.end());
      std::array<float, 12> flat;
      std::memcpy(flat.data(), c.data(), sizeof flat);
      out.push_back(flat);
    }
    std::sort(out.begin(), out.end());
    return out;
  };
  EXPECT_EQ(still.mesh.quad_count(), plain.mesh.quad_count());
  EXPECT_TRUE(corners(still.mesh) == corners(plain.mesh));

  const auto x_extent = [](const Mesh& m) {
    float lo = 1e9f, hi = -1e9f;
    for (const glm::vec3& p : m.positions) {
      lo = std::min(lo, p.x);
      hi = std::max(hi, p.x);
    }
    return std::pair{lo, hi};
  };
  for (FaceType faces : {FaceType::triangles, FaceType::quads}) {
    const MeshingResult grown = mesh_scene(s, faces, 3, 0.0);
    EXPECT_GT(grown.refinement.grown_cells, 4u * 15u);
    expect_conforming(grown.mesh, s.views);
    const double h = s.views[0].spacing;
    const auto [lo0, hi0] = x_extent(plain.mesh);
    const auto [lo, hi] = x_extent(grown.mesh);
    // Pixel centres stop half a pixel inside the box; three levels reach within 1/16 pixel.
    EXPECT_NEAR(lo0, -1.0 + 0.5 * h, 1e-5);
    EXPECT_LT(lo, -1.0 + 0.07 * h);
    EXPECT_GT(hi, 1.0 - 0.07 * h);
    EXPECT_NEAR(hi0, 1.0 - 0.5 * h, 1e-5);
  }
}

// A fine triangulated unit sphere (latitude–longitude), the reference for backward distances.
Mesh unit_sphere(int n) {
  Mesh m;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j < 2 * n; ++j) {
      const double theta = std::numbers::pi * i / n, phi = std::numbers::pi * j / n;
      m.positions.emplace_back(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                               std::cos(theta));
      m.normals.push_back(m.positions.back());
    }
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < 2 * n; ++j) {
      const std::uint32_t a = i * 2 * n + j, b = i * 2 * n + (j + 1) % (2 * n), c = a + 2 * n,
                          d = b + 2 * n;
      m.triangles.insert(m.triangles.end(), {a, c, d, a, d, b});
    }
  return m;
}

// One view along z without trimming: the §3 mesh stops short of the silhouette (the equator);
// growth and refinement reach it, halving the largest distance from the sphere to the mesh.
TEST(Refine, SphereSilhouetteIsReachedAtCoarseResolution) {
  const Mesh sphere = unit_sphere(150);
  DistanceOptions sampling;
  sampling.samples = 200000;
  for (int res : {12, 16, 24}) {
    const Scene s = cast_surface("sphere", res, "z");
    for (FaceType faces : {FaceType::triangles, FaceType::quads}) {
      const double before =
          mesh_distance(mesh_scene(s, faces, 0, 0.0).mesh, sphere, sampling).backward.max;
      const MeshingResult refined = mesh_scene(s, faces, 3, 0.0);
      const double after = mesh_distance(refined.mesh, sphere, sampling).backward.max;
      EXPECT_LT(after, 0.5 * before) << "res " << res;
      EXPECT_GT(refined.refinement.grown_cells, 0u);
    }
  }
}

// Refinement brings Marschner–Lobb at 64² closer to the surface both ways: forward (mesh to the
// true surface) and backward (from a fine §3 mesh at 384² to the mesh).
TEST(Refine, MarschnerLobbGetsCloserBothWays) {
  const SurfaceInfo& ml = *find_surface("marschner-lobb");
  const Scene fine = cast_surface("marschner-lobb", 384);
  const Mesh reference = mesh_scene(fine, FaceType::triangles, 0).mesh;
  const Scene s = cast_surface("marschner-lobb", 64);
  for (FaceType faces : {FaceType::triangles, FaceType::quads}) {
    const Mesh before = mesh_scene(s, faces, 0).mesh;
    const Mesh after = mesh_scene(s, faces, 2).mesh;
    const SurfaceDistance fb = surface_distance(before, ml, ml.isovalue);
    const SurfaceDistance fa = surface_distance(after, ml, ml.isovalue);
    DistanceOptions sampling;
    sampling.samples = 300000;
    const MeshDistance bb = mesh_distance(before, reference, sampling),
                       ba = mesh_distance(after, reference, sampling);
    std::printf(
        "ML 64^2 %s: forward mean %.3g -> %.3g, max %.3g -> %.3g; backward mean %.3g -> "
        "%.3g, max %.3g -> %.3g\n",
        faces == FaceType::quads ? "quads" : "triangles", fb.forward.mean, fa.forward.mean,
        fb.forward.max, fa.forward.max, bb.backward.mean, ba.backward.mean, bb.backward.max,
        ba.backward.max);
    EXPECT_LT(fa.forward.mean, 0.9 * fb.forward.mean);
    EXPECT_LT(fa.forward.max, fb.forward.max);
    EXPECT_LT(ba.backward.mean, 0.9 * bb.backward.mean);
    EXPECT_LE(ba.backward.max, bb.backward.max);
  }
}

TEST(Refine, SameMeshForOneAndAllThreads) {
  const Scene s = cast_surface("marschner-lobb", 32);
  for (FaceType faces : {FaceType::triangles, FaceType::quads}) {
    MeshingResult one;
    {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
      one = mesh_scene(s, faces, 3);
    }
    const MeshingResult all = mesh_scene(s, faces, 3);
    EXPECT_GT(one.refinement.subdivided_cells, 1000u);
    expect_same_mesh(one.mesh, all.mesh);
  }
}

// §4 (ii): all requests of one pass go out together, for all views: one round trip per pass.
TEST(Refine, OneRoundTripPerPass) {
  const Scene s = cast_surface("marschner-lobb", 32);
  for (FaceType faces : {FaceType::triangles, FaceType::quads}) {
    LocalSampleSource local(*s.caster, s.views);
    CountingSource counting(local);
    const MeshingResult m = mesh_scene(s, faces, 4, 0.5, &counting);
    EXPECT_EQ(m.refinement.passes, 4);
    EXPECT_EQ(counting.calls, m.refinement.passes);
    EXPECT_EQ(m.refinement.round_trips, std::size_t(m.refinement.passes));
    ASSERT_EQ(m.refinement.rays_per_pass.size(), 4u);
    std::size_t rays = 0;
    for (std::size_t r : m.refinement.rays_per_pass)
      rays += r;
    EXPECT_EQ(counting.rays, rays);
  }
}

TEST(Refine, RejectsBadArguments) {
  const Scene s = cast_surface("sphere", 8);
  LocalSampleSource local(*s.caster, s.views);
  MeshingOptions options;
  options.refinement.levels = 2;
  EXPECT_THROW(mesh_ldis(s.ldis, options), std::invalid_argument);  // no sample source
  for (int levels : {-1, 17}) {
    options.refinement.levels = levels;
    EXPECT_THROW(mesh_ldis(s.ldis, options, &local), std::invalid_argument) << levels;
  }
  const std::vector<ViewQuads> one(1);
  RefinementStats stats;
  EXPECT_THROW(refine_views(s.ldis, one, FaceType::quads, {}, {}, {}, 0.5, local, stats),
               std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

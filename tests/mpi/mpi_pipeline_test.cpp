// The distributed pipeline under mpiexec (1 to 4 ranks): every rank ray casts its subdomain,
// the fragments are reduced to the root, the root meshes them. The root compares with what one
// process computes. Tests are collective: every rank runs every test; only the root checks
// (with EXPECT_*, never returning early, so that no rank is left alone in a collective call).
#include <mpi.h>

#include <algorithm>
#include <memory>
#include <random>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include "ldimesh/core/analytic_fields.hpp"
#include "ldimesh/core/analytic_source.hpp"
#include "ldimesh/core/decomposition.hpp"
#include "ldimesh/core/grid_source.hpp"
#include "ldimesh/core/surfaces.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "mpi_gtest.hpp"

namespace ldimesh {
namespace {

using testing::rank_of;
using testing::ranks;

// What one process meshes from `ldis`, after the same quantization the ranks apply.
MeshingResult one_process(std::vector<Ldi> ldis, const DistributedOptions& options) {
  for (std::size_t v = 0; v < ldis.size(); ++v) {
    LdiFragment f = fragment_from_ldi(ldis[v], std::uint32_t(v));
    const std::vector<std::uint8_t> bytes = encode_fragment(f, options.encoding);
    EXPECT_TRUE(decode_fragment(bytes, f));
    ldis[v] = ldi_from_fragment(f, ldis[v].view);
  }
  return mesh_ldis(ldis, options.meshing);
}

// Same quads (the same samples joined), positions within `tolerance`.
void expect_same_mesh(const Mesh& a, const Mesh& b, double tolerance) {
  EXPECT_GT(a.face_count(), 100u);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.triangle_view, b.triangle_view);
  EXPECT_EQ(a.vertex_count(), b.vertex_count());
  if (a.vertex_count() != b.vertex_count()) return;
  double worst = 0.0;
  for (std::size_t i = 0; i < a.vertex_count(); ++i)
    worst = std::max(worst, double(glm::length(a.positions[i] - b.positions[i])));
  EXPECT_LE(worst, tolerance);
}

DistributedOptions lossless() {
  DistributedOptions o;
  o.encoding.lossless = true;
  return o;
}

// Runs the distributed pipeline for `source` with subdomain `sub` and checks on the root that
// the mesh is the one-process mesh of `reference` (the whole domain's source).
void expect_distributed_equals_one_process(const FieldSource& mine, const Subdomain& sub,
                                           const FieldSource& reference, double iso, int res) {
  const std::vector<View> views = make_axis_views(sub.global, res);
  const RayCaster caster(mine, iso);
  for (const DistributedOptions& options : {lossless(), DistributedOptions{}}) {
    DistributedResult result;
    const Status status = mesh_distributed(MPI_COMM_WORLD, caster, sub, views, options, result);
    EXPECT_TRUE(status) << status.message();
    if (rank_of() != 0) continue;
    const RayCaster whole(reference, iso);
    std::vector<Ldi> ldis;
    for (const View& v : views)
      ldis.push_back(whole.cast(v));
    const MeshingResult expected = one_process(ldis, options);
    SCOPED_TRACE(options.encoding.lossless ? "lossless" : "quantized");
    expect_same_mesh(result.meshing.mesh, expected.mesh, 1e-6);
    if (!options.encoding.lossless) {
      // Against the unquantized LDIs: the same samples, each within the stated error bounds.
      for (std::size_t v = 0; v < views.size(); ++v) {
        const Ldi& got = result.ldis[v];
        EXPECT_EQ(got.offsets, ldis[v].offsets);
        if (got.offsets != ldis[v].offsets) continue;
        const double depth_bound = depth_error_bound(options.encoding, 0.0, views[v].depth_extent);
        const double angle_bound = normal_error_bound(options.encoding);
        double worst_depth = 0.0, worst_angle = 0.0;
        for (std::size_t k = 0; k < got.sample_count(); ++k) {
          worst_depth =
              std::max(worst_depth, std::abs(double(got.depth[k]) - double(ldis[v].depth[k])));
          const double c =
              std::clamp(double(glm::dot(got.normal[k], ldis[v].normal[k])), -1.0, 1.0);
          worst_angle = std::max(worst_angle, std::acos(c));
        }
        EXPECT_LE(worst_depth, depth_bound + 1e-6);
        EXPECT_LE(worst_angle, angle_bound + 1e-3);
      }
      // The mesh itself may differ where a match sits at the rejection threshold.
      const MeshingResult exact = mesh_ldis(ldis, options.meshing);
      EXPECT_NEAR(double(result.meshing.mesh.face_count()), double(exact.mesh.face_count()),
                  0.005 * double(exact.mesh.face_count()));
    }
  }
}

TEST(MpiPipeline, AnalyticSurfacesGiveTheOneProcessMesh) {
  for (const char* name : {"sphere", "torus", "barth"}) {
    SCOPED_TRACE(name);
    const SurfaceInfo* s = find_surface(name);
    const auto source = make_surface_source(name);
    const Subdomain sub{decompose_box(s->domain, ranks())[rank_of()], s->domain};
    expect_distributed_equals_one_process(*source, sub, *source, s->isovalue, 48);
  }
}

TEST(MpiPipeline, GridBlocksWithGhostLayersSplitAcrossRanks) {
  const int n = 33;
  std::vector<float> values(std::size_t(n) * n * n);
  const fields::MarschnerLobb ml;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        values[(std::size_t(k) * n + j) * n + i] =
            float(ml(-1 + 2.0 * i / (n - 1), -1 + 2.0 * j / (n - 1), -1 + 2.0 * k / (n - 1)));
  GridBlock whole;
  whole.dims = {n, n, n};
  whole.values = values.data();
  whole.origin = glm::dvec3(-1.0);
  whole.spacing = glm::dvec3(2.0 / (n - 1));
  const GridSource reference(whole);
  const std::array<int, 3> blocks = block_grid(reference.bounds(), ranks());
  const int r = rank_of();
  const GridPart part = grid_part(
      whole, blocks, {r % blocks[0], (r / blocks[0]) % blocks[1], r / (blocks[0] * blocks[1])});
  const GridSource mine(part.block);
  expect_distributed_equals_one_process(mine, {part.owned, reference.bounds()}, reference, 0.5, 64);
}

TEST(MpiPipeline, ARankWithAnEmptySubdomainSendsAnEmptyFragment) {
  const SurfaceInfo* s = find_surface("torus");
  const auto source = make_surface_source("torus");
  // The last rank gets nothing; the others tile the domain.
  const int workers = std::max(1, ranks() - 1);
  Subdomain sub{Box{s->domain.lo, s->domain.lo}, s->domain};
  if (rank_of() < workers) sub.box = decompose_box(s->domain, workers)[rank_of()];
  expect_distributed_equals_one_process(*source, sub, *source, s->isovalue, 40);
}

// A small sphere in one corner: most ranks' subdomains hold no surface.
struct CornerSphere {
  template <class T>
  T operator()(const T& x, const T& y, const T& z) const {
    return sqr(x - 0.6) + sqr(y - 0.6) + sqr(z - 0.6);
  }
};

TEST(MpiPipeline, RanksWhoseSubdomainHoldsNoSurface) {
  const Box box{{-1, -1, -1}, {1, 1, 1}};
  const AnalyticSource<CornerSphere> source(CornerSphere{}, box);
  const Subdomain sub{decompose_box(box, ranks())[rank_of()], box};
  expect_distributed_equals_one_process(source, sub, source, 0.09, 48);
}

TEST(MpiPipeline, AllRanksEmptyGiveAnEmptyMesh) {
  const SurfaceInfo* s = find_surface("sphere");
  const auto source = make_surface_source("sphere");
  const RayCaster caster(*source, 100.0);  // the field never reaches 100 in the box
  const Subdomain sub{decompose_box(s->domain, ranks())[rank_of()], s->domain};
  DistributedResult result;
  const Status status =
      mesh_distributed(MPI_COMM_WORLD, caster, sub, make_axis_views(s->domain, 32), {}, result);
  EXPECT_TRUE(status) << status.message();
  if (rank_of() == 0) {
    EXPECT_EQ(result.meshing.samples, 0u);
    EXPECT_EQ(result.meshing.mesh.face_count(), 0u);
  }
}

TEST(MpiPipeline, SampleRequestsAreAnsweredAsInOneProcess) {
  const SurfaceInfo* s = find_surface("barth");
  const auto source = make_surface_source("barth");
  const RayCaster caster(*source, s->isovalue);
  std::vector<View> views = make_axis_views(s->domain, 64);
  views.push_back(make_view(s->domain, {0.3, 0.4, -0.8}, 64));
  const Subdomain sub{decompose_box(s->domain, ranks())[rank_of()], s->domain};
  MpiSampleSource remote(MPI_COMM_WORLD, caster, sub, views, 1e-9 * s->domain.diagonal());
  if (rank_of() != 0) {
    remote.serve();
    return;
  }
  LocalSampleSource local(caster, views);
  std::mt19937 rng(9);
  std::size_t hits = 0;
  for (std::uint32_t v = 0; v < views.size(); ++v) {
    std::uniform_real_distribution<double> x(0.0, views[v].width), y(0.0, views[v].height);
    std::vector<glm::dvec2> positions(300);
    for (auto& p : positions)
      p = {x(rng), y(rng)};
    const RayHitList a = remote.sample(v, positions), b = local.sample(v, positions);
    EXPECT_EQ(a.offsets, b.offsets);
    if (a.offsets != b.offsets) continue;
    for (std::size_t k = 0; k < a.depth.size(); ++k)
      EXPECT_NEAR(a.depth[k], b.depth[k], 1e-6);
    hits += a.depth.size();
  }
  remote.finish();
  EXPECT_GT(hits, 500u);
}

}  // namespace
}  // namespace ldimesh

int main(int argc, char** argv) {
  // Share the cores between the ranks (tests run oversubscribed on small machines).
  return ldimesh::testing::run_mpi_tests(argc, argv, [] {
    return std::make_unique<tbb::global_control>(
        tbb::global_control::max_allowed_parallelism,
        std::size_t(std::max(1, tbb::info::default_concurrency() / ldimesh::testing::ranks())));
  });
}

// The distributed pipeline under mpiexec (1 to 4 ranks): every rank ray casts its subdomain,
// the fragments are reduced to the root, the root meshes them and refines them (§4) with extra
// samples from all ranks. The root compares with what one
// process computes. Tests are collective: every rank runs every test; only the root checks
// (with EXPECT_*, never returning early, so that no rank is left alone in a collective call).
#include <mpi.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "ldimesh/transport/mpi_reduce.hpp"
#include "mpi_gtest.hpp"
#include "support/quantization_caps.hpp"

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
          worst_angle =
              std::max(worst_angle, testing::angle_between(got.normal[k], ldis[v].normal[k]));
        }
        EXPECT_LE(worst_depth, depth_bound + 1e-6);
        EXPECT_LE(worst_angle, angle_bound);
        EXPECT_LE(angle_bound, testing::octahedral_angle_cap(options.encoding.normal_bits));
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

// Marschner–Lobb on a 33³ float grid over [−1, 1]³, and this rank's block of it (with ghost
// layers) in a decomposition over the ranks.
struct MlGrid {
  static constexpr int n = 33;
  std::vector<float> values;
  GridBlock whole;
  GridPart part;
  MlGrid(const MlGrid&) = delete;  // whole and part point into values
  MlGrid& operator=(const MlGrid&) = delete;
  MlGrid() : values(std::size_t(n) * n * n) {
    const fields::MarschnerLobb ml;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          values[(std::size_t(k) * n + j) * n + i] =
              float(ml(-1 + 2.0 * i / (n - 1), -1 + 2.0 * j / (n - 1), -1 + 2.0 * k / (n - 1)));
    whole.dims = {n, n, n};
    whole.values = values.data();
    whole.origin = glm::dvec3(-1.0);
    whole.spacing = glm::dvec3(2.0 / (n - 1));
    const std::array<int, 3> blocks = block_grid(GridSource(whole).bounds(), ranks());
    const int r = rank_of();
    part = grid_part(whole, blocks,
                     {r % blocks[0], (r / blocks[0]) % blocks[1], r / (blocks[0] * blocks[1])});
  }
};

TEST(MpiPipeline, GridBlocksWithGhostLayersSplitAcrossRanks) {
  const MlGrid grid;
  const GridSource reference(grid.whole), mine(grid.part.block);
  const GridPart& part = grid.part;
  expect_distributed_equals_one_process(mine, {part.owned, reference.bounds()}, reference, 0.5, 64);
}

// Curved elements (geometry of order 2, interiors bent) dealt out to the ranks one by one (element
// e on rank e mod ranks, as an unstructured mesh's partition may put neighbours anywhere): each
// rank casts its elements over the whole domain, roots on faces shared across ranks meet in the
// reduction, and the root's mesh is the one process's.
TEST(MpiPipeline, CurvedElementsDealtToTheRanksGiveTheOneProcessMesh) {
  const int n = 3, p = 3, q = 2;
  const std::vector<double> xq = node_positions(q, NodeSet::gauss_lobatto_legendre);
  const std::vector<double> xp = node_positions(p, NodeSet::gauss_lobatto_legendre);
  const auto bend = [](glm::dvec3 x) {
    x.x += 0.06 * std::sin(3.14159 * x.y) * std::sin(3.14159 * x.z) * std::sin(3.14159 * x.x);
    return x;
  };
  const auto field = [](glm::dvec3 x) {
    return std::sin(4.0 * x.x + 0.5) * std::cos(3.0 * x.y) + 0.6 * std::sin(5.0 * x.z) - 0.1;
  };
  // All elements, and this rank's share, with the field at the field's nodes through the
  // geometry's own polynomial.
  std::vector<double> all_geometry, all_values, my_geometry, my_values;
  std::size_t mine_count = 0;
  for (int e = 0; e < n * n * n; ++e) {
    const glm::dvec3 cell(e % n, (e / n) % n, e / (n * n));
    std::vector<double> geometry;
    for (int k = 0; k <= q; ++k)
      for (int j = 0; j <= q; ++j)
        for (int i = 0; i <= q; ++i) {
          const glm::dvec3 x = bend((cell + glm::dvec3(xq[i], xq[j], xq[k])) / double(n));
          geometry.insert(geometry.end(), {x.x, x.y, x.z});
        }
    HexBlock one;
    one.order = p;
    one.element_count = 1;
    one.geometry_order = q;
    one.geometry = geometry.data();
    std::vector<double> zeros(std::size_t(p + 1) * (p + 1) * (p + 1), 0.0), values;
    one.values = zeros.data();
    const HexElementSource shape(one);
    for (int k = 0; k <= p; ++k)
      for (int j = 0; j <= p; ++j)
        for (int i = 0; i <= p; ++i)
          values.push_back(field(shape.to_world(0, {xp[i], xp[j], xp[k]})));
    all_geometry.insert(all_geometry.end(), geometry.begin(), geometry.end());
    all_values.insert(all_values.end(), values.begin(), values.end());
    if (e % ranks() == rank_of()) {
      my_geometry.insert(my_geometry.end(), geometry.begin(), geometry.end());
      my_values.insert(my_values.end(), values.begin(), values.end());
      ++mine_count;
    }
  }
  const auto block_of = [&](const std::vector<double>& geometry, const std::vector<double>& values,
                            std::size_t count) {
    HexBlock b;
    b.order = p;
    b.element_count = count;
    b.geometry_order = q;
    b.geometry = geometry.data();
    b.values = values.data();
    return b;
  };
  const HexElementSource reference(block_of(all_geometry, all_values, std::size_t(n) * n * n));
  const HexElementSource mine(block_of(my_geometry, my_values, mine_count));
  EXPECT_TRUE(reference.is_curved(13));  // the middle element: its interior nodes bent
  const Box domain{glm::dvec3(0.0), glm::dvec3(1.0)};
  expect_distributed_equals_one_process(mine, {domain, domain}, reference, 0.0, 48);
}

// The root may leave the decoding and merging of what it receives to later (its worker thread):
// finish_reduction then gives the fragments of the plain reduction, to the bit; a message that does
// not decode is an error there.
TEST(MpiPipeline, DeferredMergeOnTheRootGivesTheReducedFragments) {
  const SurfaceInfo* s = find_surface("torus");
  const auto source = make_surface_source("torus");
  const Subdomain sub{decompose_box(s->domain, ranks())[rank_of()], s->domain};
  const std::vector<View> views = make_axis_views(s->domain, 48);
  const RayCaster caster(*source, s->isovalue);
  std::vector<LdiFragment> cast;
  for (std::size_t v = 0; v < views.size(); ++v)
    cast.push_back(caster.cast_fragment(views[v], std::uint32_t(v), sub));
  const FragmentEncoding encoding;
  DuplicateRule tolerance{1e-6, {}};
  for (const View& view : views)
    tolerance.dirs.push_back(glm::vec3(view.dir));
  std::vector<LdiFragment> plain = cast, deferred = cast;
  ReductionStats stats;
  EXPECT_TRUE(reduce_fragments(MPI_COMM_WORLD, 0, plain, encoding, tolerance, stats));
  PendingReduction pending;
  EXPECT_TRUE(reduce_fragments(MPI_COMM_WORLD, 0, deferred, encoding, tolerance, stats, &pending));
  // Views that differ between the ranks (rank 1 casts at another resolution) fail both
  // reductions on the root, the deferred one inside the step as the plain one.
  std::vector<LdiFragment> odd = cast;
  if (rank_of() == 1) {
    const std::vector<View> other = make_axis_views(s->domain, 40);
    for (std::size_t v = 0; v < other.size(); ++v)
      odd[v] = caster.cast_fragment(other[v], std::uint32_t(v), sub);
  }
  std::vector<LdiFragment> odd_plain = odd;
  const Status plain_odd =
      reduce_fragments(MPI_COMM_WORLD, 0, odd_plain, encoding, tolerance, stats);
  PendingReduction odd_pending;
  const Status deferred_odd =
      reduce_fragments(MPI_COMM_WORLD, 0, odd, encoding, tolerance, stats, &odd_pending);
  if (rank_of() != 0) return;  // nothing collective below
  if (ranks() > 1) {
    EXPECT_FALSE(plain_odd);
    EXPECT_FALSE(deferred_odd);
    // Rank 1's message is rejected, not kept; the root's other children's are.
    EXPECT_EQ(odd_pending.messages.size(), std::size_t(std::bit_width(unsigned(ranks() - 1))) - 1);
  }
  EXPECT_EQ(pending.messages.size(), std::size_t(std::bit_width(unsigned(ranks() - 1))));
  PendingReduction broken = pending;
  ASSERT_TRUE(finish_reduction(pending, deferred, stats));
  EXPECT_TRUE(pending.messages.empty());
  ASSERT_EQ(deferred.size(), plain.size());
  std::size_t samples = 0;
  for (std::size_t v = 0; v < plain.size(); ++v) {
    EXPECT_EQ(deferred[v].pixels, plain[v].pixels);
    EXPECT_EQ(deferred[v].counts, plain[v].counts);
    EXPECT_EQ(deferred[v].depth, plain[v].depth);
    EXPECT_EQ(deferred[v].normal, plain[v].normal);
    samples += plain[v].depth.size();
  }
  EXPECT_GT(samples, 1000u);
  if (!broken.messages.empty()) {
    broken.messages.front().resize(broken.messages.front().size() / 2);  // truncated
    std::vector<LdiFragment> own = cast;
    for (LdiFragment& f : own)
      quantize_fragment(f, encoding);
    EXPECT_FALSE(finish_reduction(broken, own, stats));
  }
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

// `a` and `b` the same, bit for bit.
template <class T>
void expect_identical(const std::vector<T>& a, const std::vector<T>& b, const char* what) {
  EXPECT_EQ(a.size(), b.size()) << what;
  if (a.size() != b.size()) return;
  std::size_t differ = 0, first = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::memcmp(&a[i], &b[i], sizeof(T)) != 0 && differ++ == 0) first = i;
  EXPECT_EQ(differ, 0u) << what << ": " << differ << " differ, the first at " << first;
}

void expect_identical_mesh(const Mesh& a, const Mesh& b) {
  expect_identical(a.positions, b.positions, "positions");
  expect_identical(a.normals, b.normals, "normals");
  expect_identical(a.scalars, b.scalars, "scalars");
  expect_identical(a.triangles, b.triangles, "triangles");
  expect_identical(a.triangle_view, b.triangle_view, "triangle views");
  expect_identical(a.quads, b.quads, "quads");
  expect_identical(a.quad_view, b.quad_view, "quad views");
}

void expect_identical_hits(const RayHitList& a, const RayHitList& b) {
  expect_identical(a.offsets, b.offsets, "offsets");
  expect_identical(a.depth, b.depth, "depths");
  expect_identical(a.normal, b.normal, "normals");
  expect_identical(a.scalar, b.scalar, "scalars");
}

// The round trip gives exactly what the ray caster of the whole domain gives in one process.
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
  // One request mixing all views in random order, as a refinement pass asks.
  std::mt19937 rng(9);
  std::uniform_int_distribution<std::uint32_t> view_of(0, std::uint32_t(views.size() - 1));
  std::vector<SamplePoint> points(300 * views.size());
  for (SamplePoint& p : points) {
    p.view = view_of(rng);
    std::uniform_real_distribution<double> x(0.0, views[p.view].width),
        y(0.0, views[p.view].height);
    p.position = {x(rng), y(rng)};
  }
  // Every third ray only over a stretch of its depth, as refinement asks; some cross the
  // subdomain faces.
  for (std::size_t k = 0; k < points.size(); k += 3) {
    const double extent = views[points[k].view].depth_extent;
    std::uniform_real_distribution<double> from(0.0, extent), length(0.0, 0.5 * extent);
    points[k].depth_min = from(rng);
    points[k].depth_max = points[k].depth_min + length(rng);
  }
  const RayHitList a = remote.sample(points);
  expect_identical_hits(a, local.sample(points));
  EXPECT_GT(a.depth.size(), 500u);

  // A bad request is refused on the root before anything is sent; the other ranks go on
  // serving: the next requests (a part of the first, then none) are answered as before.
  std::vector<SamplePoint> bad(points.begin(), points.begin() + 10);
  bad[7].view = std::uint32_t(views.size());
  EXPECT_THROW(remote.sample(bad), std::out_of_range);
  const std::span<const SamplePoint> some = std::span<const SamplePoint>(points).first(40);
  expect_identical_hits(remote.sample(some), local.sample(some));
  EXPECT_EQ(remote.sample({}).offsets, std::vector<std::uint32_t>{0});
  remote.finish();
}

// §4 over MPI: the refined mesh is, bit for bit, the one the root refines with samples from a
// ray caster of the whole domain in one process (the round trips give exactly the local
// answers), and each pass is one round trip.
TEST(MpiPipeline, RefinedMeshIsTheOneProcessRefinedMesh) {
  for (const char* name : {"sphere", "marschner-lobb"})
    for (const FaceType faces : {FaceType::triangles, FaceType::quads}) {
      SCOPED_TRACE(std::string(name) + (faces == FaceType::quads ? ", quads" : ", triangles"));
      const SurfaceInfo* s = find_surface(name);
      const auto source = make_surface_source(name);
      const RayCaster caster(*source, s->isovalue);
      const Subdomain sub{decompose_box(s->domain, ranks())[rank_of()], s->domain};
      const std::vector<View> views = make_axis_views(s->domain, 24);
      DistributedOptions options;
      options.meshing.faces = faces;
      options.meshing.refinement.levels = 2;
      DistributedResult result;
      const Status status = mesh_distributed(MPI_COMM_WORLD, caster, sub, views, options, result);
      EXPECT_TRUE(status) << status.message();
      if (rank_of() != 0 || !status) continue;
      LocalSampleSource local(caster, views);  // every rank's caster sees the whole field
      const MeshingResult expected = mesh_ldis(result.ldis, options.meshing, &local);
      EXPECT_GT(expected.mesh.face_count(), 100u);
      expect_identical_mesh(result.meshing.mesh, expected.mesh);
      const RefinementStats& got = result.meshing.refinement;
      const RefinementStats& want = expected.refinement;
      EXPECT_GT(got.passes, 0);
      EXPECT_EQ(got.round_trips, std::size_t(got.passes));
      EXPECT_EQ(got.rays_per_pass, want.rays_per_pass);
      EXPECT_EQ(got.subdivided_cells, want.subdivided_cells);
      EXPECT_EQ(got.grown_cells, want.grown_cells);
      EXPECT_EQ(got.invalid_vertices, want.invalid_vertices);
    }
}

// Whether every rank's `status` is an error with the root's (non-empty) message.
bool same_error_on_every_rank(const Status& status) {
  std::string root_message = status.message();
  int length = int(root_message.size());
  MPI_Bcast(&length, 1, MPI_INT, 0, MPI_COMM_WORLD);
  root_message.resize(std::size_t(length));
  MPI_Bcast(root_message.data(), length, MPI_CHAR, 0, MPI_COMM_WORLD);
  int mine = !status && !root_message.empty() && status.message() == root_message ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  return all == 1;
}

// One step of the sphere at 16² with this rank's refinement `levels`, merged or not.
Status mesh_sphere_step(int levels, DistributedResult& result, bool merge = false) {
  const SurfaceInfo* s = find_surface("sphere");
  const auto source = make_surface_source("sphere");
  const RayCaster caster(*source, s->isovalue);
  const Subdomain sub{decompose_box(s->domain, ranks())[rank_of()], s->domain};
  DistributedOptions options;
  options.meshing.refinement.levels = levels;
  options.meshing.merging.enabled = merge;
  return mesh_distributed(MPI_COMM_WORLD, caster, sub, make_axis_views(s->domain, 16), options,
                          result);
}

// Refinement that fails on the root (here: more levels than allowed) fails on every rank with
// the root's message, and leaves no rank waiting for requests.
TEST(MpiPipeline, RefinementFailingOnTheRootFailsOnEveryRank) {
  DistributedResult result;
  const Status status = mesh_sphere_step(17, result);
  const bool same = same_error_on_every_rank(status);
  if (rank_of() == 0) {
    EXPECT_TRUE(same) << status.message();
    EXPECT_EQ(result.meshing.mesh.face_count(), 0u);
  }
  // The ranks are in step afterwards: a step without refinement works.
  const Status next = mesh_sphere_step(0, result);
  EXPECT_TRUE(next) << next.message();
}

// A grid source whose casts along x throw (as a failed allocation would). The step's views are
// cast side by side: the y view (a grid's, cast in blocks of columns and put back in row order)
// is under way when the x view fails.
class FailingAlongX final : public FieldSource {
 public:
  explicit FailingAlongX(const FieldSource& inner) : inner_(inner) {}
  Box bounds() const override { return inner_.bounds(); }
  std::unique_ptr<GeometryBinding> bind(RTCDevice device, double isovalue) const override {
    return inner_.bind(device, isovalue);
  }
  std::unique_ptr<AxisCaster> bind_axis(double isovalue) const override {
    return std::make_unique<Caster>(inner_.bind_axis(isovalue));
  }
  double duplicate_tolerance() const override { return inner_.duplicate_tolerance(); }

 private:
  class Caster final : public AxisCaster {
   public:
    explicit Caster(std::unique_ptr<AxisCaster> inner) : inner_(std::move(inner)) {}
    void cast(const AxisRays& rays, AxisHits& hits) const override {
      if (rays.axis == 0) throw std::runtime_error("no memory left for the x view (test)");
      inner_->cast(rays, hits);
    }
    void prepare(int axis) const override { inner_->prepare(axis); }
    std::size_t primitive_count() const override { return inner_->primitive_count(); }
    bool prefers_column_tasks(const View& view) const override {
      return inner_->prefers_column_tasks(view);
    }
    std::uint64_t nonfinite_values() const override { return inner_->nonfinite_values(); }

   private:
    std::unique_ptr<AxisCaster> inner_;
  };
  const FieldSource& inner_;
};

// A cast that throws fails the step on every rank with the casting's message — no crash, no
// rank left waiting — and the next step works.
TEST(MpiPipeline, CastingFailingInOneViewFailsTheStepOnEveryRank) {
  const MlGrid grid;
  const GridSource reference(grid.whole), mine(grid.part.block);
  const GridPart& part = grid.part;
  const FailingAlongX failing(mine);
  const Subdomain sub{part.owned, reference.bounds()};
  const std::vector<View> views = make_axis_views(reference.bounds(), 256);
  DistributedResult result;
  const Status status = mesh_distributed(MPI_COMM_WORLD, RayCaster(failing, 0.5), sub, views,
                                         DistributedOptions{}, result);
  EXPECT_FALSE(status);
  const bool same = same_error_on_every_rank(status);
  if (rank_of() == 0) {
    EXPECT_TRUE(same) << status.message();
    EXPECT_NE(status.message().find("ray casting: no memory left for the x view (test)"),
              std::string::npos)
        << status.message();
    EXPECT_EQ(result.meshing.mesh.face_count(), 0u);
  }
  const Status next = mesh_distributed(MPI_COMM_WORLD, RayCaster(mine, 0.5), sub, views,
                                       DistributedOptions{}, result);
  EXPECT_TRUE(next) << next.message();
  if (rank_of() == 0) {
    EXPECT_GT(result.meshing.mesh.face_count(), 100u);
  }
}

// Ranks that disagree on refinement (a misconfigured job) get an error, not a hang.
TEST(MpiPipeline, RefinementLevelsThatDifferBetweenRanksAreAnError) {
  if (ranks() == 1) GTEST_SKIP() << "needs two ranks";
  DistributedResult result;
  const Status status = mesh_sphere_step(rank_of() == ranks() - 1 ? 1 : 0, result);
  const bool same = same_error_on_every_rank(status);
  if (rank_of() == 0) {
    EXPECT_TRUE(same) << status.message();
  }
}

// §5 merging asks for samples too (its new vertices are projected onto the surface): every rank
// serves, and the root gets the one-process merged mesh, closed, for any number of ranks.
TEST(MpiPipeline, MergingProjectsWithSamplesFromAllRanks) {
  DistributedResult result;
  const Status status = mesh_sphere_step(0, result, true);
  EXPECT_TRUE(status) << status.message();
  if (rank_of() != 0 || !status) return;
  const MergeStats& m = result.meshing.merging;
  EXPECT_GT(m.split_edges, 0u);
  EXPECT_GT(m.projected, 0u);
  EXPECT_EQ(m.components, 1u);
  EXPECT_EQ(m.unfilled_holes, 0u);
  const SurfaceInfo* s = find_surface("sphere");
  const auto source = make_surface_source("sphere");
  const RayCaster caster(*source, s->isovalue);
  const std::vector<View> views = make_axis_views(s->domain, 16);
  LocalSampleSource local(caster, views);
  MeshingOptions options;
  options.merging.enabled = true;
  const MeshingResult expected = mesh_ldis(result.ldis, options, &local);
  expect_identical_mesh(result.meshing.mesh, expected.mesh);
}

// Ranks that disagree on merging would disagree on serving samples: an error, not a hang.
TEST(MpiPipeline, MergingThatDiffersBetweenRanksIsAnError) {
  if (ranks() == 1) GTEST_SKIP() << "needs two ranks";
  DistributedResult result;
  const Status status = mesh_sphere_step(0, result, rank_of() == ranks() - 1);
  EXPECT_FALSE(status);
  const bool same = same_error_on_every_rank(status);
  if (rank_of() == 0) {
    EXPECT_TRUE(same) << status.message();
  }
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

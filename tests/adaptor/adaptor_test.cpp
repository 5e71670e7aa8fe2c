// The C++ adaptor under mpiexec, as a solver uses it. Collective tests: every rank runs every
// test and only non-fatal EXPECTs are used, so that no rank is left alone in a collective call.
#include <mpi.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "../mpi/mpi_gtest.hpp"
#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/field/cell_source.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/snapshot_store.hpp"
#include "published_step.hpp"

namespace ldimesh {
namespace {

using testing::rank_of;
using testing::ranks;

// An adaptor over the built-in `surface`, this rank's block of its domain.
std::unique_ptr<Adaptor> make(const std::string& options, const char* surface = "sphere") {
  std::unique_ptr<Adaptor> a;
  const Status s = Adaptor::create(MPI_COMM_WORLD, options, a);
  EXPECT_TRUE(s) << s.message();
  if (!a) return a;
  const SurfaceInfo* info = find_surface(surface);
  EXPECT_TRUE(a->set_domain(info->domain));
  EXPECT_TRUE(
      a->add_source(make_surface_source(surface), decompose_box(info->domain, ranks())[rank_of()]));
  return a;
}

using testing::thread_multiple;

std::string temp_dir(const std::string& name) {
  return testing::adaptor_temp_dir("ldimesh_adaptor", name);
}

TEST(Adaptor, InvalidOptionsAreReportedOnEveryRankWithTheKey) {
  std::unique_ptr<Adaptor> a;
  Status s = Adaptor::create(MPI_COMM_WORLD, R"({"resolutin": 64})", a);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("resolutin"), std::string::npos) << s.message();
  EXPECT_EQ(a, nullptr);
  s = Adaptor::create(MPI_COMM_WORLD, R"({"r": 2})", a);
  EXPECT_NE(s.message().find("'r'"), std::string::npos) << s.message();
  s = Adaptor::create(MPI_COMM_WORLD, R"({"cadence": {"every_steps": 0}})", a);
  EXPECT_NE(s.message().find("cadence.every_steps"), std::string::npos) << s.message();
  s = Adaptor::create(MPI_COMM_WORLD, "{not json", a);
  EXPECT_FALSE(s);
  for (const char* doc : {R"({"merging": "yes"})", R"({"merging": 1})"}) {
    s = Adaptor::create(MPI_COMM_WORLD, doc, a);
    EXPECT_EQ(s.code(), StatusCode::invalid_options) << doc;
    EXPECT_NE(s.message().find("'merging' must be true, false or \"auto\""), std::string::npos)
        << s.message();
  }
  for (const char* doc : {R"({"refinement": 7})", R"({"refinement": -1})", R"({"refinement": 1.5})",
                          R"({"refinement": "2"})"}) {
    s = Adaptor::create(MPI_COMM_WORLD, doc, a);
    EXPECT_EQ(s.code(), StatusCode::invalid_options) << doc;
    EXPECT_NE(s.message().find("'refinement' must be true, false or a number of levels in 0..6"),
              std::string::npos)
        << s.message();
  }
  for (const char* doc : {R"({"colour_by": ""})", R"({"colour_by": 3})", R"({"colour_by": {}})",
                          R"({"isovalues": [0.3, 0.5], "colour_by": ["U"]})",
                          R"({"isovalues": [0.3, 0.5], "colour_by": ["U", 3]})",
                          R"({"isovalues": [0.3, 0.5], "colour_by": ["U", ""]})"}) {
    s = Adaptor::create(MPI_COMM_WORLD, doc, a);
    EXPECT_EQ(s.code(), StatusCode::invalid_options) << doc;
    EXPECT_NE(s.message().find("'colour_by'"), std::string::npos) << s.message();
  }
  // null, or null for every isovalue: nothing coloured.
  for (const char* doc : {R"({"colour_by": null, "server": {"enabled": false}, "log": false})",
                          R"({"isovalues": [0.3, 0.5], "colour_by": [null, null],
                              "server": {"enabled": false}, "log": false})"}) {
    s = Adaptor::create(MPI_COMM_WORLD, doc, a);
    EXPECT_TRUE(s) << doc << ": " << s.message();
    if (a) {
      EXPECT_TRUE(a->finalize());
    }
    a.reset();
  }
  s = Adaptor::create(MPI_COMM_WORLD, R"({"isovalues": [0.3, 0.5], "colour_by": ["U"]})", a);
  EXPECT_NE(s.message().find("must have one entry per isovalue (2), a field's name or null; it "
                             "has 1"),
            std::string::npos)
      << s.message();
  // Integers out of their type's range or not integral: named errors, not undefined behaviour
  // in the conversion (UBSan reported it in the options fuzz target for 1e20).
  for (const char* doc :
       {R"({"resolution": 1e20})", R"({"resolution": 512.5})", R"({"keep": 1.5e19})",
        R"({"server": {"port": -1e30}})", R"({"encoding": {"depth_bits": "16"}})",
        R"({"encoding": {"scalar_bits": 1}})", R"({"encoding": {"scalar_bits": 25}})",
        R"({"glb": {"normal_bits": 1}})", R"({"glb": {"normal_bits": 17}})",
        R"({"glb": {"scalar_bits": 0}})", R"({"glb": {"scalar_bits": 8.5}})"}) {
    s = Adaptor::create(MPI_COMM_WORLD, doc, a);
    EXPECT_EQ(s.code(), StatusCode::invalid_options) << doc;
    EXPECT_NE(s.message().find("must be an integer in"), std::string::npos) << s.message();
    EXPECT_EQ(a, nullptr);
  }
}

TEST(Adaptor, DueStepsArePublishedAndWrittenOffTheSolversPath) {
  const std::string dir = temp_dir("publish");
  // "coalesce": a due step the busy root cannot take yet waits, replacing an older waiting
  // one, so the newest due step is always published.
  auto a =
      make(R"({"server": {"enabled": false}, "resolution": 48, "log": false, "busy": "coalesce",
                    "cadence": {"every_steps": 2}, "output_dir": ")" +
           dir + R"("})");
  if (!a) return;
  for (std::uint64_t step = 0; step < 6; ++step) {
    EXPECT_TRUE(a->execute(step, 0.1 * double(step)));
    // The report says which steps ran: the odd ones were not due (every rank's report).
    const StepReport& report = a->last_report();
    if (step % 2 == 1) {
      EXPECT_FALSE(report.executed) << "step " << step;
      EXPECT_FALSE(report.skipped_busy) << "step " << step;
    }
    if (step == 0) {
      EXPECT_TRUE(report.executed);
    }
  }
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_GE(a->published_steps(), 1u);
    EXPECT_TRUE(std::filesystem::exists(dir + "/step_000004.glb"));  // the newest due step
    EXPECT_TRUE(std::filesystem::exists(dir + "/step_000004.json"));
    EXPECT_FALSE(std::filesystem::exists(dir + "/step_000001.glb"));  // not due
    EXPECT_FALSE(std::filesystem::exists(dir + "/step_000005.glb"));
  }
}

// Root only: waits (up to 60 s) until `a` has published `count` steps.
bool wait_for_published(const Adaptor& a, std::uint64_t count) {
  for (int k = 0; k < 6000 && a.published_steps() < count; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  return a.published_steps() >= count;
}

TEST(Adaptor, AStepThatCannotBeWrittenIsStillPublishedAndWritingResumes) {
  const std::string dir = temp_dir("unwritable");
  auto a = make(R"({"server": {"enabled": false}, "resolution": 32, "log": false,
                    "output_dir": ")" +
                dir + R"("})");
  if (!a) return;
  const bool root = rank_of() == 0;
  // The output folder turns into a file (as if it vanished and something else took its name;
  // a read-only folder would not stop root): step 0 cannot be written.
  if (root) {
    ::testing::internal::CaptureStderr();
    std::filesystem::remove_all(dir);
    std::ofstream(dir) << "not a folder";
  }
  MPI_Barrier(MPI_COMM_WORLD);
  EXPECT_TRUE(a->execute(0, 0.0));
  if (root) {
    EXPECT_TRUE(wait_for_published(*a, 1));
    std::filesystem::remove(dir);  // writable again: the next step recreates the folder
  }
  MPI_Barrier(MPI_COMM_WORLD);
  EXPECT_TRUE(a->execute(1, 0.1));
  if (root) {
    EXPECT_TRUE(wait_for_published(*a, 2));
  }
  MPI_Barrier(MPI_COMM_WORLD);
  EXPECT_TRUE(a->finalize()) << a->last_error();
  if (!root) return;
  const std::string log = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(a->published_steps(), 2u);  // both served, though step 0 has no files
  EXPECT_FALSE(std::filesystem::exists(dir + "/step_000000.glb"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/step_000001.glb"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/step_000001.json"));
  EXPECT_NE(log.find("step 0 not written"), std::string::npos) << log;
  EXPECT_NE(log.find("again from step 1 (1 steps were not written)"), std::string::npos) << log;
  EXPECT_TRUE(a->last_error().empty()) << a->last_error();
}

TEST(Adaptor, ASlowRootMakesStepsBeSkippedNotTheSolverWait) {
  const std::string dir = temp_dir("slow");
  auto a = make(R"({"server": {"enabled": false}, "resolution": 32, "log": false, "busy": "skip",
                    "testing": {"slow_root_seconds": 0.4}, "output_dir": ")" +
                dir + R"("})");
  if (!a) return;
  int skipped = 0, skipped_since_handoff = 0;
  double worst = 0.0;
  for (std::uint64_t step = 0; step < 5; ++step) {
    EXPECT_TRUE(a->execute(step, 0.0));
    if (a->last_report().skipped_busy) {
      ++skipped;
      ++skipped_since_handoff;
    } else {
      skipped_since_handoff = 0;
    }
    worst = std::max(worst, a->last_report().blocked_seconds);
  }
  // Once the worker is idle again the next step is published and counts the steps dropped
  // since the last one handed over.
  std::this_thread::sleep_for(std::chrono::milliseconds(900));
  EXPECT_TRUE(a->execute(5, 0.0));
  EXPECT_FALSE(a->last_report().skipped_busy);
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_GE(skipped, 3);   // the worker sleeps 0.4 s per step, the solver does not
    EXPECT_LT(worst, 0.35);  // no execute() waited for the worker
    EXPECT_LE(a->published_steps(), 3u);
    EXPECT_EQ(testing::published_step(dir, 5).skipped_steps, std::uint64_t(skipped_since_handoff));
  }
}

TEST(Adaptor, AStepWithoutSurfaceIsPublishedEmpty) {
  auto a =
      make(R"({"server": {"enabled": false}, "resolution": 32, "log": false, "isovalues": [100]})");
  if (!a) return;
  EXPECT_TRUE(a->execute(0, 0.0));
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_EQ(a->published_steps(), 1u);
  }
}

// Curved element blocks (geometry of order 2, each rank its share of the elements): the field
// x on them (p = q: exact) has the plane x = c as its isosurface, and the published mesh lies on
// it — through both the synchronous and the background (snapshot) path. A second block reads
// the same geometry array with another field (y; two fields of one solver on one mesh): its
// plane y = c is published beside the first, and the shared array is left as it was.
// This rank's share (every ranks()-th element) of n³ elements of the unit cube with geometry of
// order q at GLL nodes, bent inside along `axis` (the nodes on the cube's faces stay): curved
// elements. Their nodes element after element, ξ fastest, and as a geometry array.
struct BentCube {
  std::size_t count = 0;
  std::vector<glm::dvec3> nodes;
  std::vector<double> geometry;
};
BentCube bent_cube(int q, int n, int axis) {
  const std::vector<double> x = node_positions(q, NodeSet::gauss_lobatto_legendre);
  BentCube cube;
  for (int e = 0; e < n * n * n; ++e) {
    if (e % ranks() != rank_of()) continue;
    ++cube.count;
    const glm::dvec3 cell(e % n, (e / n) % n, e / (n * n));
    for (int k = 0; k <= q; ++k)
      for (int j = 0; j <= q; ++j)
        for (int i = 0; i <= q; ++i) {
          glm::dvec3 p = (cell + glm::dvec3(x[i], x[j], x[k])) / double(n);
          p[axis] +=
              0.05 * std::sin(3.14159 * p.y) * std::sin(3.14159 * p.z) * std::sin(3.14159 * p.x);
          cube.nodes.push_back(p);
          cube.geometry.insert(cube.geometry.end(), {p.x, p.y, p.z});
        }
  }
  return cube;
}

TEST(Adaptor, CurvedElementBlocksArePublished) {
  const int q = 2;
  const BentCube cube = bent_cube(q, 2, 0);
  std::vector<double> geometry = cube.geometry, values, values_y;
  const std::size_t count = cube.count;
  for (const glm::dvec3& p : cube.nodes) {
    values.push_back(p.x);
    values_y.push_back(p.y);
  }
  const std::vector<double> geometry_before = geometry;
  for (const bool background : {false, true}) {
    const std::string dir = temp_dir(background ? "curved_background" : "curved");
    auto a = [&] {
      std::unique_ptr<Adaptor> out;
      const Status s = Adaptor::create(
          MPI_COMM_WORLD,
          R"({"server": {"enabled": false}, "resolution": 48, "log": false, "isovalues": [0.3],
              "background": )" +
              std::string(background ? "true" : "false") + R"(, "output_dir": ")" + dir + R"("})",
          out);
      EXPECT_TRUE(s) << s.message();
      return out;
    }();
    if (!a) return;
    EXPECT_TRUE(a->set_domain({glm::dvec3(0.0), glm::dvec3(1.0)}));
    HexBlock block;
    block.order = q;
    block.nodes = NodeSet::gauss_lobatto_legendre;
    block.element_count = count;
    block.geometry_order = q;
    block.geometry = geometry.data();
    block.values = values.data();
    HexBlock block_y = block;
    block_y.values = values_y.data();
    if (count > 0) {
      EXPECT_TRUE(a->add_hex_block(block));
      EXPECT_TRUE(a->add_hex_block(block_y));
    }
    EXPECT_TRUE(a->execute(0, 0.0));
    EXPECT_TRUE(a->finalize());
    EXPECT_EQ(geometry, geometry_before);
    if (rank_of() != 0) continue;
    const Mesh mesh = testing::published_mesh(dir, 0);
    const char* path = background ? "background" : "synchronous";
    EXPECT_GT(mesh.vertex_count(), 1000u) << path;
    // Every vertex on one of the planes, and each plane away from the other holds vertices.
    // Within the GLB's position step, a tenth of a pixel (the mesh now spans the box along x
    // and y, so its quantization shows).
    const double tolerance = 0.1 / 48;
    double far = 0.0;
    std::size_t on_x = 0, on_y = 0;
    for (const glm::vec3& v : mesh.positions) {
      const double dx = std::abs(double(v.x) - 0.3), dy = std::abs(double(v.y) - 0.3);
      far = std::max(far, std::min(dx, dy));
      on_x += dx < tolerance && dy > 0.05;
      on_y += dy < tolerance && dx > 0.05;
    }
    EXPECT_LT(far, tolerance) << path;
    EXPECT_GT(on_x, 300u) << path;
    EXPECT_GT(on_y, 300u) << path;
  }
}

// "merging": the root publishes one merged mesh (§5): for the sphere a closed triangle mesh,
// so its counts satisfy Euler's V − E + F = 2 with E = 3F/2, i.e. F = 2 (V − 2).
TEST(Adaptor, MergingPublishesOneClosedMesh) {
  const std::string dir = temp_dir("merging");
  auto a = make(R"({"server": {"enabled": false}, "resolution": 32, "log": false, "isovalues": [1],
                    "merging": true, "output_dir": ")" +
                dir + R"("})");
  if (!a) return;
  EXPECT_TRUE(a->execute(0, 0.0));
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    const StepMetadata meta = testing::published_step(dir, 0);
    EXPECT_GT(meta.triangles, 1000u);
    EXPECT_EQ(meta.triangles, 2 * (meta.vertices - 2));
  }
}

// Collective: runs the CLI's pipeline (mesh_distributed, then encode_glb as `ldimesh mesh --out
// x.glb` calls it) on `caster` over `sub`, three 40² views of sub.global, with `meshing` (merged,
// refined or neither), and checks on the root that the adaptor published those bytes as step
// `step` in `dir`.
void expect_cli_mesh_published(const RayCaster& caster, const Subdomain& sub,
                               const MeshingOptions& meshing, const std::string& dir,
                               std::uint64_t step) {
  const std::vector<View> views = make_axis_views(sub.global, 40);
  DistributedOptions options;
  options.meshing = meshing;
  DistributedResult cli;
  const Status s = mesh_distributed(MPI_COMM_WORLD, caster, sub, views, options, cli);
  EXPECT_TRUE(s) << s.message();
  if (rank_of() != 0) return;
  std::vector<std::uint8_t> expected;
  EXPECT_TRUE(encode_glb(cli.meshing.mesh, step_glb_options(views.front()), expected));
  EXPECT_GT(cli.meshing.mesh.face_count(), 500u);
  if (meshing.refinement.levels > 0) {  // refinement did something: the test means it
    EXPECT_GT(cli.meshing.refinement.subdivided_cells, 0u);
  }
  Snapshot published;
  const Status r = read_step_files(dir, step, published);
  EXPECT_TRUE(r) << r.message();
  if (!r) return;
  EXPECT_TRUE(*published.glb == expected)
      << "published " << published.glb->size() << " bytes, the CLI's pipeline " << expected.size();
}

// The meshing variants the adaptor is checked against the CLI's pipeline with, and the options
// document's keys that ask for them.
struct MeshingVariant {
  const char* name;
  const char* keys;  // inserted at the start of the options object
  MeshingOptions meshing;
};
std::vector<MeshingVariant> meshing_variants() {
  MeshingOptions merged, refined;
  merged.merging.enabled = true;
  refined.refinement.levels = 2;
  return {{"views", R"("merging": false, )", {}},
          {"merged", R"("merging": true, )", merged},
          {"refined", R"("refinement": true, "merging": false, )", refined}};
}

// One pipeline, one result: the adaptor publishes the GLB that the CLI's pipeline
// (mesh_distributed, then encode_glb as `ldimesh mesh --out x.glb` calls it) gives for the same
// blocks and options, byte for byte — plain, merged (§5, its new vertices projected with
// samples that every rank casts from its blocks: in the step on the synchronous path, on the
// caster threads on the background one) and refined (§4, two levels, with samples the same way).
TEST(Adaptor, PublishesTheMeshOfTheCommandLinePipeline) {
  const SurfaceInfo* info = find_surface("torus");
  for (const MeshingVariant& variant : meshing_variants()) {
    SCOPED_TRACE(variant.name);
    const std::string dir = temp_dir(std::string("same_as_cli_") + variant.name);
    auto a = make(std::string("{") + variant.keys +
                      R"("server": {"enabled": false}, "resolution": 40, "log": false,
                      "isovalues": [)" +
                      std::to_string(info->isovalue) + R"(], "output_dir": ")" + dir + R"("})",
                  "torus");
    if (!a) return;
    EXPECT_TRUE(a->execute(3, 0.0)) << a->last_error();
    EXPECT_TRUE(a->finalize()) << a->last_error();

    const auto source = make_surface_source("torus");
    const RayCaster caster(*source, info->isovalue);
    const Subdomain sub{decompose_box(info->domain, ranks())[rank_of()], info->domain};
    expect_cli_mesh_published(caster, sub, variant.meshing, dir, 3);
  }
}

// ---- The background path (MPI_THREAD_MULTIPLE: the binary's --thread-multiple run) and the
// synchronous one (MPI_THREAD_FUNNELED).

// This rank's slab (split along z) of an n³-point float32 grid over [−1, 1]³ holding
// f = |x|² + shift, as a solver hands it over: owned points tile the grid, one ghost point layer
// towards each neighbour (miniapps/grayscott describes the rule).
struct GridSlab {
  std::vector<float> values;
  GridBlock block;

  GridSlab(int n, double shift) {
    const int r = rank_of(), size = ranks();
    const int p0 = n * r / size, p1 = n * (r + 1) / size - 1;  // owned points along z
    const int g_lo = r > 0 ? 1 : 0, g_hi = r + 1 < size ? 1 : 0;
    const int k0 = p0 - g_lo, nz = p1 + g_hi - k0 + 1;
    const double h = 2.0 / (n - 1);
    values.resize(std::size_t(n) * n * nz);
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const double x = -1 + i * h, y = -1 + j * h, z = -1 + (k0 + k) * h;
          values[(std::size_t(k) * n + j) * n + i] = float(x * x + y * y + z * z + shift);
        }
    block.dims = {n, n, nz};
    block.values = values.data();
    block.type = ScalarType::float32;
    block.origin = {-1.0, -1.0, -1.0 + k0 * h};
    block.spacing = glm::dvec3(h);
    block.ghost_lo = {0, 0, g_lo};
    block.ghost_hi = {0, 0, g_hi};
  }
};

constexpr int kSlabPoints = 40;

// What a viewer would see of the slab's field |x|² at isovalue `iso` (resolution 40).
void expect_on_the_slab_sphere(const Mesh& mesh, double iso) {
  testing::expect_on_grid_sphere(mesh, iso, 2.0 / (kSlabPoints - 1), 40);
}

std::unique_ptr<Adaptor> make_grid_adaptor(const std::string& options, const GridBlock& block) {
  std::unique_ptr<Adaptor> a;
  const Status s = Adaptor::create(MPI_COMM_WORLD, options, a);
  EXPECT_TRUE(s) << s.message();
  if (!a) return a;
  EXPECT_TRUE(a->set_domain({glm::dvec3(-1.0), glm::dvec3(1.0)}));
  EXPECT_TRUE(a->add_grid_block(block));
  return a;
}
std::unique_ptr<Adaptor> make_grid_adaptor(const std::string& options, GridSlab& slab) {
  return make_grid_adaptor(options, slab.block);
}

std::string grid_options(const std::string& dir, bool background,
                         const std::string& isovalues = "[0.36]") {
  return R"({"server": {"enabled": false}, "resolution": 40, "log": false, "isovalues": )" +
         isovalues + R"(, "busy": "coalesce", "background": )" +
         std::string(background ? "true" : "false") + R"(, "output_dir": ")" + dir + R"("})";
}

// What the snapshot of a grid block's array of `size`-byte values holds for `isovalues`: the
// pages, in an array with x fastest, of the points of the bricks that hold the surface and of
// the points around them that the normals read (GridSource::for_each_needed_run).
std::size_t snapshot_pages(const GridBlock& block, const std::vector<double>& isovalues,
                           std::size_t size) {
  const GridSource source(block);
  const std::size_t page = std::size_t(sysconf(_SC_PAGESIZE));
  const std::size_t bytes = std::size_t(block.dims[0] * block.dims[1] * block.dims[2]) * size;
  std::vector<std::atomic<bool>> touched((bytes + page - 1) / page);
  source.for_each_needed_run(
      source.needed_bricks(isovalues),
      [&](std::int64_t j, std::int64_t k, std::int64_t i0, std::int64_t i1) {
        const std::size_t at = std::size_t((k * block.dims[1] + j) * block.dims[0] + i0) * size;
        for (std::size_t p = at / page; p <= (at + std::size_t(i1 - i0 + 1) * size - 1) / page; ++p)
          touched[p] = true;
      });
  std::size_t total = 0;
  for (std::size_t p = 0; p < touched.size(); ++p)
    total += touched[p] ? std::min(page, bytes - p * page) : 0;
  return total;
}

std::vector<std::uint8_t> published_glb(const std::string& dir, std::uint64_t step) {
  Snapshot snapshot;
  const Status s = read_step_files(dir, step, snapshot);
  EXPECT_TRUE(s) << s.message();
  return s && snapshot.glb ? *snapshot.glb : std::vector<std::uint8_t>{};
}

// This rank's slab of |x|² and the CLI pipeline's caster over the same block (isovalue 0.36),
// to compare what the adaptor publishes with (expect_cli_mesh_published).
struct SlabBesideCli {
  GridSlab slab{kSlabPoints, 0.0};
  GridSource source{slab.block};
  RayCaster caster{source, 0.36};
  Subdomain sub{source.bounds(), {glm::dvec3(-1.0), glm::dvec3(1.0)}};
};

// The same for a grid block on both paths: synchronous, and (with --thread-multiple) cast,
// reduced and — merged — sampled by the caster threads from the snapshot.
TEST(Adaptor, GridBlocksPublishTheMeshOfTheCommandLinePipelineOnBothPaths) {
  SlabBesideCli g;
  for (const MeshingVariant& variant : meshing_variants())
    for (const bool background : {false, true}) {
      SCOPED_TRACE(std::string(variant.name) + (background ? ", background" : ", synchronous"));
      const std::string dir =
          temp_dir(std::string("grid_as_cli_") + variant.name + (background ? "_b" : "_s"));
      const std::string options =
          std::string("{") + variant.keys + grid_options(dir, background).substr(1);
      auto a = make_grid_adaptor(options, g.slab);
      if (!a) return;
      EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
      EXPECT_EQ(a->last_report().background, background && thread_multiple());
      EXPECT_TRUE(a->finalize()) << a->last_error();

      expect_cli_mesh_published(g.caster, g.sub, variant.meshing, dir, 1);
      if (rank_of() == 0) expect_on_the_slab_sphere(testing::published_mesh(dir, 1), 0.36);
    }
}

// "merging" by default ("auto"): the steps that run in the background are merged (the caster
// threads serve the merge's samples), the synchronous ones publish the trimmed views (the
// solver would wait for the merge).
TEST(Adaptor, ByDefaultBackgroundStepsAreMergedAndSynchronousOnesNot) {
  SlabBesideCli g;
  for (const bool background : {false, true}) {
    SCOPED_TRACE(background ? "background" : "synchronous");
    const std::string dir = temp_dir(std::string("auto_merge_") + (background ? "b" : "s"));
    auto a = make_grid_adaptor(grid_options(dir, background), g.slab);
    if (!a) return;
    EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
    const bool merged = background && thread_multiple();
    EXPECT_EQ(a->last_report().background, merged);
    EXPECT_TRUE(a->finalize()) << a->last_error();
    MeshingOptions meshing;
    meshing.merging.enabled = merged;
    expect_cli_mesh_published(g.caster, g.sub, meshing, dir, 1);
    if (rank_of() == 0) {  // merged: one closed surface, V − E + F = 2 with E = 3F/2
      const StepMetadata meta = testing::published_step(dir, 1);
      EXPECT_EQ(meta.triangles == 2 * (meta.vertices - 2), merged)
          << meta.triangles << " triangles, " << meta.vertices << " vertices";
    }
  }
}

// Several isovalues: the published GLB holds a mesh per isovalue, each on a node whose extras
// name its index (the viewer's checkboxes show or hide them), and both spheres of the slab's
// field |x|² are there.
TEST(Adaptor, EachIsovalueIsASurfaceOfItsOwnInTheGlb) {
  GridSlab slab(kSlabPoints, 0.0);
  const std::string dir = temp_dir("two_isovalues");
  auto a = make_grid_adaptor(R"({"server": {"enabled": false}, "resolution": 40, "log": false,
                                  "isovalues": [0.36, 0.64], "merging": false, "output_dir": ")" +
                                 dir + R"("})",
                             slab);
  if (!a) return;
  EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
  EXPECT_TRUE(a->finalize()) << a->last_error();
  if (rank_of() != 0) return;
  const std::vector<std::uint8_t> glb = published_glb(dir, 1);
  ASSERT_GT(glb.size(), 20u);
  std::uint32_t length = 0;
  std::memcpy(&length, glb.data() + 12, 4);
  ASSERT_LE(20 + std::size_t(length), glb.size());
  const std::string json(glb.begin() + 20, glb.begin() + 20 + length);
  EXPECT_NE(json.find(R"("extras":{"ldimesh_surface":0})"), std::string::npos) << json;
  EXPECT_NE(json.find(R"("extras":{"ldimesh_surface":1})"), std::string::npos) << json;
  const Mesh mesh = testing::published_mesh(dir, 1);
  std::size_t inner = 0, outer = 0;
  for (const glm::vec3& p : mesh.positions)
    (glm::length(p) < 0.7f ? inner : outer)++;
  EXPECT_GT(inner, 500u);
  EXPECT_GT(outer, 500u);
}

TEST(Adaptor, GridBlocksRunInTheBackgroundWhereMpiAllowsIt) {
  GridSlab slab(kSlabPoints, 0.0);
  auto a = make_grid_adaptor(grid_options(temp_dir("background"), true), slab);
  if (!a) return;
  EXPECT_TRUE(a->execute(0, 0.0));
  EXPECT_EQ(a->last_report().background, thread_multiple());
  // The copy: the pages of the points of the bricks that hold the surface and around them.
  const auto expect_copied = [&](const GridSlab& s) {
    if (thread_multiple()) {
      EXPECT_EQ(a->last_report().snapshot_bytes, snapshot_pages(s.block, {0.36}, sizeof(float)));
    }
  };
  expect_copied(slab);
  // A sphere of radius 0.15 instead of 0.6: a small part of the slabs is copied.
  GridSlab small(kSlabPoints, 0.36 - 0.0225);
  a->clear_blocks();
  EXPECT_TRUE(a->add_grid_block(small.block));
  for (int wait = 0; rank_of() == 0 && a->published_steps() < 1 && wait < 1000; ++wait)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_TRUE(a->execute(1, 0.0));
  expect_copied(small);
  if (thread_multiple()) {  // at most 40 % of all ranks' slabs
    std::uint64_t sums[2] = {a->last_report().snapshot_bytes, small.values.size() * sizeof(float)};
    MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_LE(double(sums[0]), 0.4 * double(sums[1]));
  }
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_EQ(a->published_steps(), 2u);
  }
  // A FieldSource cannot be copied: such steps run synchronously whatever the thread level.
  auto b = make(R"({"server": {"enabled": false}, "resolution": 32, "log": false})");
  if (!b) return;
  EXPECT_TRUE(b->execute(0, 0.0));
  EXPECT_FALSE(b->last_report().background);
  EXPECT_TRUE(b->finalize());
}

// "memory_mb" bounds what the snapshot holds, not the blocks: with 1 MiB, 120³ float points
// (6.6 MiB over all ranks) are snapshotted while the surface is a small sphere, and the step runs
// synchronously once the surface is large. (Whether a rank's copy fits is computed here from the
// pages its points lie in; the two spheres are chosen so that one fits on every rank and the
// other not, as the test checks.)
TEST(Adaptor, MemoryMbBoundsTheSnapshotNotTheBlocks) {
  const std::string dir = temp_dir("memory_mb");
  GridSlab small(120, 0.36 - 0.01), large(120, 0.0);
  std::string options = R"({"memory_mb": 1, )" + grid_options(dir, true).substr(1);
  options.replace(options.find(R"("log": false)"), 12, R"("log": true)");
  auto a = make_grid_adaptor(options, small);
  if (!a) return;
  // Small, large, large, small: the log says where the path changes, not at every step.
  ::testing::internal::CaptureStdout();
  for (std::uint64_t step = 0; step < 4; ++step) {
    const bool is_small = step == 0 || step == 3;
    const GridSlab& slab = is_small ? small : large;
    SCOPED_TRACE(is_small ? "a sphere of radius 0.1" : "a sphere of radius 0.6");
    std::uint64_t largest = snapshot_pages(slab.block, {0.36}, sizeof(float));
    MPI_Allreduce(MPI_IN_PLACE, &largest, 1, MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD);
    const bool fits = largest <= (std::uint64_t(1) << 20);
    EXPECT_EQ(fits, is_small) << largest << " bytes on the largest rank";
    a->clear_blocks();
    EXPECT_TRUE(a->add_grid_block(slab.block));
    EXPECT_TRUE(a->execute(step, 0.0)) << a->last_error();
    EXPECT_EQ(a->last_report().background, thread_multiple() && fits);
    if (a->last_report().background) {
      EXPECT_EQ(a->last_report().snapshot_bytes, snapshot_pages(slab.block, {0.36}, sizeof(float)));
    } else {
      EXPECT_EQ(a->last_report().snapshot_bytes, 0u);
    }
    // Published before the next step (which would otherwise find the worker busy).
    for (int wait = 0; rank_of() == 0 && a->published_steps() < step + 1 && wait < 1000; ++wait)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(a->finalize()) << a->last_error();
  const std::string log = ::testing::internal::GetCapturedStdout();
  if (rank_of() == 0) {
    const auto count = [&](const std::string& what) {
      std::size_t n = 0;
      for (std::size_t at = log.find(what); at != std::string::npos; at = log.find(what, at + 1))
        ++n;
      return n;
    };
    const std::size_t changes = thread_multiple() ? 1 : 0;
    EXPECT_EQ(count("from step 1 on, steps run synchronously: a rank's copy of what it reads"),
              changes)
        << log;
    EXPECT_EQ(count("runs synchronously"), 0u) << log;  // not step by step
    EXPECT_EQ(count("from step 3 on, steps run in the background again"), changes) << log;
    EXPECT_EQ(a->published_steps(), 4u);
    const double h = 2.0 / 119;
    testing::expect_on_grid_sphere(testing::published_mesh(dir, 1), 0.36, h, 40);
    // The small sphere (4 pixels across): its vertices at radius 0.1, within the grid's
    // interpolation error (inwards) and the GLB's quantization.
    const Mesh small_mesh = testing::published_mesh(dir, 0);
    EXPECT_GT(small_mesh.vertex_count(), 20u);
    for (const glm::vec3& p : small_mesh.positions) {
      EXPECT_GE(glm::length(glm::dvec3(p)), 0.1 - 3.0 * h * h / 0.8 - 0.1 * 2.0 / 40);
      EXPECT_LE(glm::length(glm::dvec3(p)), 0.1 + 0.1 * 2.0 / 40);
    }
  }
}

// Both paths publish the same bytes; and the solver may overwrite its arrays as soon as
// execute() returns: the published mesh is that of the values at the call. Merged, so that the
// snapshot also answers the merge's samples after the solver has moved on.
TEST(Adaptor, TheSnapshotPathPublishesTheSynchronousMeshWhateverTheSolverDoesNext) {
  const std::string sync_dir = temp_dir("sync"), snap_dir = temp_dir("snapshot");
  const auto merged_options = [](const std::string& dir, bool background) {
    return R"({"merging": true, )" + grid_options(dir, background).substr(1);
  };
  constexpr int kSteps = 3;
  const auto shift = [](int step) { return -0.02 * step; };  // the sphere grows step by step
  {
    std::vector<GridSlab> slabs;
    for (int step = 0; step < kSteps; ++step)
      slabs.emplace_back(kSlabPoints, shift(step));
    auto a = make_grid_adaptor(merged_options(sync_dir, false), slabs[0]);
    if (!a) return;
    for (int step = 0; step < kSteps; ++step) {
      a->clear_blocks();
      EXPECT_TRUE(a->add_grid_block(slabs[step].block));
      EXPECT_TRUE(a->execute(step, 0.0));
      EXPECT_FALSE(a->last_report().background);
      // Every step of the reference published (the others wait in the next collective).
      for (int wait = 0;
           rank_of() == 0 && a->published_steps() < std::uint64_t(step + 1) && wait < 1000; ++wait)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_TRUE(a->finalize());
  }
  // One array, overwritten with the next step's values right after each execute(), and with
  // values that hold no surface at all after the last one.
  GridSlab slab(kSlabPoints, shift(0));
  auto b = make_grid_adaptor(merged_options(snap_dir, true), slab);
  if (!b) return;
  for (int step = 0; step < kSteps; ++step) {
    EXPECT_TRUE(b->execute(step, 0.0));
    EXPECT_EQ(b->last_report().background, thread_multiple());
    const GridSlab next(kSlabPoints, step + 1 < kSteps ? shift(step + 1) : 100.0);
    std::copy(next.values.begin(), next.values.end(), slab.values.begin());
    // Then wait for the step to be published (a due step finding the background busy would be
    // skipped).
    for (int wait = 0;
         rank_of() == 0 && b->published_steps() < std::uint64_t(step + 1) && wait < 1000; ++wait)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(b->finalize());
  if (rank_of() == 0) {
    for (int step = 0; step < kSteps; ++step) {
      const auto expected = published_glb(sync_dir, step), got = published_glb(snap_dir, step);
      EXPECT_GT(expected.size(), 1000u);
      EXPECT_TRUE(expected == got)
          << "step " << step << ": " << expected.size() << " vs " << got.size() << " bytes";
    }
  }
}

// ---- Colour by a named field (add_field, option "colour_by").

// The colour field of the slab's points: C = x + 2y − z, linear, so that its trilinear
// interpolant is C itself and a published vertex's colour can be checked against C at the
// vertex.
std::vector<float> slab_colour(const GridSlab& slab) {
  std::vector<float> c(slab.values.size());
  const auto& d = slab.block.dims;
  for (std::int64_t k = 0; k < d[2]; ++k)
    for (std::int64_t j = 0; j < d[1]; ++j)
      for (std::int64_t i = 0; i < d[0]; ++i) {
        const glm::dvec3 x = slab.block.origin + glm::dvec3(i, j, k) * slab.block.spacing;
        c[std::size_t((k * d[1] + j) * d[0] + i)] = float(x.x + 2.0 * x.y - x.z);
      }
  return c;
}

TEST(Adaptor, GridBlocksAreColouredByANamedFieldOnBothPaths) {
  for (const bool merging : {false, true}) {
    std::vector<std::uint8_t> synchronous;
    for (const bool background : {false, true}) {
      SCOPED_TRACE(std::string(merging ? "merged" : "views") +
                   (background ? ", background" : ", synchronous"));
      GridSlab slab(kSlabPoints, 0.0);
      std::vector<float> colour = slab_colour(slab);
      const std::string dir =
          temp_dir(std::string("colour_") + (merging ? "m" : "v") + (background ? "b" : "s"));
      std::string options = R"({"colour_by": "C", )" + grid_options(dir, background).substr(1);
      options =
          std::string(R"({"merging": )") + (merging ? "true" : "false") + ", " + options.substr(1);
      auto a = make_grid_adaptor(options, slab);
      if (!a) return;
      EXPECT_TRUE(a->add_field("unused", slab.values.data(), ScalarType::float32));
      EXPECT_TRUE(a->add_field("C", colour.data(), ScalarType::float32));
      EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
      if (background && thread_multiple()) {  // the copy: the values and the colour there
        EXPECT_EQ(a->last_report().snapshot_bytes,
                  2 * snapshot_pages(slab.block, {0.36}, sizeof(float)));
      }
      // The solver overwrites both arrays at once: the published step is that of the call.
      std::fill(colour.begin(), colour.end(), 1e6f);
      std::fill(slab.values.begin(), slab.values.end(), 100.0f);
      EXPECT_TRUE(a->finalize()) << a->last_error();
      if (rank_of() != 0) continue;
      const Mesh mesh = testing::published_mesh(dir, 1);
      expect_on_the_slab_sphere(mesh, 0.36);
      testing::expect_coloured_by(
          mesh, testing::published_step(dir, 1), "C",
          [](glm::dvec3 x) { return x.x + 2.0 * x.y - x.z; }, 2.0, 2.0 / 40);
      if (!background) {
        synchronous = published_glb(dir, 1);
      } else {
        EXPECT_TRUE(published_glb(dir, 1) == synchronous) << "the two paths differ";
      }
    }
  }
}

// Two nested spheres of the slab's |x|², r = 0.4 and 0.8, each isovalue with its own entry of
// "colour_by": the inner one coloured by C (float, x + 2y − z), the outer one by nothing or by D
// (double, 10 + 100z: other units). On both paths (the snapshot copies each field the step
// reads) and merged or not, the same GLB; its metadata gives each surface's field and range.
TEST(Adaptor, EachIsovalueIsColouredByItsOwnFieldOrByNone) {
  for (const bool merging : {false, true})
    for (const bool outer_by_d : {false, true}) {
      std::vector<std::uint8_t> synchronous;
      for (const bool background : {false, true}) {
        SCOPED_TRACE(std::string(merging ? "merged" : "views") +
                     (outer_by_d ? ", [C, D]" : ", [C, null]") +
                     (background ? ", background" : ", synchronous"));
        GridSlab slab(kSlabPoints, 0.0);
        std::vector<float> c = slab_colour(slab);
        std::vector<double> d(slab.values.size());
        for (std::size_t p = 0; p < d.size(); ++p) {
          const auto& n = slab.block.dims;
          const std::int64_t k = std::int64_t(p) / (n[0] * n[1]);
          d[p] = 10.0 + 100.0 * (slab.block.origin.z + double(k) * slab.block.spacing.z);
        }
        const std::string dir = temp_dir(std::string("colours_") + (merging ? "m" : "v") +
                                         (outer_by_d ? "d" : "n") + (background ? "b" : "s"));
        const std::string options = std::string(R"({"colour_by": ["C", )") +
                                    (outer_by_d ? R"("D")" : "null") + R"(], "merging": )" +
                                    (merging ? "true" : "false") + ", " +
                                    grid_options(dir, background, "[0.16, 0.64]").substr(1);
        auto a = make_grid_adaptor(options, slab);
        if (!a) return;
        EXPECT_TRUE(a->add_field("D", d.data(), ScalarType::float64));
        EXPECT_TRUE(a->add_field("C", c.data(), ScalarType::float32));
        EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
        // The copy: the values for both isovalues, each field only for the isovalue it colours
        // (over all ranks the inner sphere's pages are fewer; a middle rank's may be all).
        if (background && thread_multiple()) {
          const std::size_t values = snapshot_pages(slab.block, {0.16, 0.64}, sizeof(float)),
                            c_pages = snapshot_pages(slab.block, {0.16}, sizeof(float));
          EXPECT_EQ(a->last_report().snapshot_bytes,
                    values + c_pages +
                        (outer_by_d ? snapshot_pages(slab.block, {0.64}, sizeof(double)) : 0));
          unsigned long long pages[2] = {c_pages, values};
          MPI_Allreduce(MPI_IN_PLACE, pages, 2, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
          EXPECT_LT(pages[0], pages[1]);
        }
        // The solver overwrites its arrays at once: the published step is that of the call.
        std::fill(c.begin(), c.end(), 1e6f);
        std::fill(d.begin(), d.end(), -1e6);
        std::fill(slab.values.begin(), slab.values.end(), 100.0f);
        EXPECT_TRUE(a->finalize()) << a->last_error();
        if (rank_of() != 0) continue;
        // Checks that stop at a failed assertion (the other ranks go on to the next step).
        [&] {
          const Mesh mesh = testing::published_mesh(dir, 1);
          const StepMetadata meta = testing::published_step(dir, 1);
          ASSERT_EQ(mesh.scalars.size(), mesh.vertex_count());
          ASSERT_EQ(meta.surface_scalars.size(), 2u);
          ASSERT_TRUE(meta.surface_scalars[0].has_value());
          EXPECT_EQ(meta.surface_scalars[0]->name, "C");
          // One field: "scalar" names it too; two: none does.
          EXPECT_EQ(meta.scalar.has_value(), !outer_by_d);
          if (meta.scalar) {
            EXPECT_EQ(meta.scalar->name, "C");
          }
          const auto inner = [](glm::dvec3 x) { return glm::length(x) < 0.6; };
          const auto outer = [](glm::dvec3 x) { return glm::length(x) >= 0.6; };
          testing::expect_part_coloured_by(
              mesh, *meta.surface_scalars[0], inner,
              [](glm::dvec3 x) { return x.x + 2.0 * x.y - x.z; }, 2.0, 2.0 / 40);
          if (outer_by_d) {
            ASSERT_TRUE(meta.surface_scalars[1].has_value());
            EXPECT_EQ(meta.surface_scalars[1]->name, "D");
            EXPECT_GT(meta.surface_scalars[1]->max, 80.0);  // D's range, not C's
            testing::expect_part_coloured_by(
                mesh, *meta.surface_scalars[1], outer,
                [](glm::dvec3 x) { return 10.0 + 100.0 * x.z; }, 100.0, 2.0 / 40);
          } else {
            EXPECT_FALSE(meta.surface_scalars[1].has_value());
            std::size_t plain = 0, coloured = 0;
            for (std::size_t v = 0; v < mesh.vertex_count(); ++v)
              if (outer(glm::dvec3(mesh.positions[v])))
                ++(std::isnan(mesh.scalars[v]) ? plain : coloured);
            EXPECT_GT(plain, 300u);
            EXPECT_EQ(coloured, 0u) << "the outer sphere has no colour";
          }
        }();
        if (!background) {
          synchronous = published_glb(dir, 1);
        } else {
          EXPECT_TRUE(published_glb(dir, 1) == synchronous) << "the two paths differ";
        }
      }
    }
}

// One field for every isovalue, as a name or as the same name in every entry: the same GLB, one
// "scalar" in the metadata and no per-surface ranges (the form before per-isovalue colours).
TEST(Adaptor, TheSameFieldInEveryEntryIsTheSingleNameForm) {
  std::vector<std::vector<std::uint8_t>> glbs;
  std::vector<StepMetadata> metas;
  for (const std::string form : {R"("C")", R"(["C", "C"])"}) {
    SCOPED_TRACE(form);
    GridSlab slab(kSlabPoints, 0.0);
    const std::vector<float> colour = slab_colour(slab);
    const std::string dir = temp_dir(form.size() == 3 ? "one_field_name" : "one_field_list");
    auto a = make_grid_adaptor(
        R"({"colour_by": )" + form + ", " + grid_options(dir, false, "[0.16, 0.64]").substr(1),
        slab);
    if (!a) return;
    EXPECT_TRUE(a->add_field("C", colour.data(), ScalarType::float32));
    EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
    EXPECT_TRUE(a->finalize()) << a->last_error();
    if (rank_of() != 0) continue;
    glbs.push_back(published_glb(dir, 1));
    metas.push_back(testing::published_step(dir, 1));
  }
  if (rank_of() != 0 || glbs.size() != 2) return;
  EXPECT_GT(glbs[0].size(), 1000u);
  EXPECT_TRUE(glbs[0] == glbs[1]) << glbs[0].size() << " vs " << glbs[1].size() << " bytes";
  const std::string text(glbs[1].begin(), glbs[1].end());
  EXPECT_NE(text.find("\"scalar_range\""), std::string::npos);
  EXPECT_EQ(text.find("surface_scalar_ranges"), std::string::npos);
  for (const StepMetadata& m : metas) {
    ASSERT_TRUE(m.scalar.has_value());
    EXPECT_EQ(m.scalar->name, "C");
    EXPECT_EQ(m.scalar->min, metas[0].scalar->min);
    EXPECT_EQ(m.scalar->max, metas[0].scalar->max);
    EXPECT_TRUE(m.surface_scalars.empty());
  }
}

// The slab's values, and a colour field in double, in a solver's own layout instead of x fastest
// without gaps: rows and layers padded (a halo, as Gray–Scott's), or z fastest. The padding
// holds NaN: a copy that took it for points would change the mesh.
enum class Layout { padded, z_fastest };
struct LaidOutSlab {
  std::vector<float> values;  // the block's first point at `offset`, as the colour's
  std::vector<double> colour;
  std::int64_t offset = 0;
  GridBlock block;
  LaidOutSlab(const GridSlab& slab, const std::vector<float>& dense_colour, Layout layout)
      : block(slab.block) {
    const auto& d = slab.block.dims;
    std::array<std::int64_t, 3> s;
    std::size_t count = 0;
    if (layout == Layout::padded) {
      s = {1, d[0] + 3, (d[0] + 3) * (d[1] + 2) + 5};
      offset = 2 * s[1] + 1 + s[2];
      count = std::size_t(offset + s[2] * (d[2] + 1));
    } else {
      s = {d[1] * d[2], d[2], 1};
      count = std::size_t(d[0] * d[1] * d[2]);
    }
    values.assign(count, std::numeric_limits<float>::quiet_NaN());
    colour.assign(count, std::numeric_limits<double>::quiet_NaN());
    for (std::int64_t k = 0; k < d[2]; ++k)
      for (std::int64_t j = 0; j < d[1]; ++j)
        for (std::int64_t i = 0; i < d[0]; ++i) {
          const std::size_t from = std::size_t((k * d[1] + j) * d[0] + i),
                            to = std::size_t(offset + i * s[0] + j * s[1] + k * s[2]);
          values[to] = slab.values[from];
          colour[to] = dense_colour[from];
        }
    block.values = values.data() + offset;
    block.strides = s;
  }
};

// The snapshot copies a block in the solver's layout (whole pages, row by row, where x is
// fastest; point by point otherwise): the same bytes as the synchronous path on the block
// without gaps, coloured (a double field on float values) and merged (the merge's samples come
// from the snapshot), although the solver overwrites everything right after execute(). The
// sphere of radius 0.6 fills most of the copy's pages from its first; the one of radius 0.15
// leaves the first pages out and starts its runs of pages in the middle of rows.
TEST(Adaptor, TheSnapshotOfABlockInTheSolversLayoutPublishesTheSynchronousMesh) {
  const auto options = [](const std::string& dir, bool background) {
    return R"({"colour_by": "C", "merging": true, )" + grid_options(dir, background).substr(1);
  };
  for (const double shift : {0.0, 0.36 - 0.0225}) {
    SCOPED_TRACE(shift == 0.0 ? "a sphere of radius 0.6" : "a sphere of radius 0.15");
    const GridSlab dense(kSlabPoints, shift);
    const std::vector<float> dense_colour = slab_colour(dense);
    std::vector<std::uint8_t> synchronous;
    {
      GridSlab slab(kSlabPoints, shift);
      const std::vector<double> colour(dense_colour.begin(), dense_colour.end());
      const std::string dir = temp_dir("layout_sync");
      auto a = make_grid_adaptor(options(dir, false), slab.block);
      if (!a) return;
      EXPECT_TRUE(a->add_field("C", colour.data(), ScalarType::float64));
      EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
      EXPECT_TRUE(a->finalize()) << a->last_error();
      if (rank_of() == 0) synchronous = published_glb(dir, 1);
    }
    for (const Layout layout : {Layout::padded, Layout::z_fastest}) {
      SCOPED_TRACE(layout == Layout::padded ? "padded rows and layers" : "z fastest");
      LaidOutSlab slab(dense, dense_colour, layout);
      const std::string dir = temp_dir(layout == Layout::padded ? "layout_padded" : "layout_z");
      auto a = make_grid_adaptor(options(dir, true), slab.block);
      if (!a) return;
      EXPECT_TRUE(a->add_field("C", slab.colour.data() + slab.offset, ScalarType::float64));
      EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
      EXPECT_EQ(a->last_report().background, thread_multiple());
      if (thread_multiple()) {  // the pages of the copies (laid out without gaps)
        EXPECT_EQ(a->last_report().snapshot_bytes,
                  snapshot_pages(dense.block, {0.36}, sizeof(float)) +
                      snapshot_pages(dense.block, {0.36}, sizeof(double)));
      }
      std::fill(slab.values.begin(), slab.values.end(), 100.0f);
      std::fill(slab.colour.begin(), slab.colour.end(), 1e6);
      EXPECT_TRUE(a->finalize()) << a->last_error();
      if (rank_of() == 0) {
        EXPECT_GT(synchronous.size(), 1000u);
        EXPECT_TRUE(published_glb(dir, 1) == synchronous) << "differs from the synchronous step";
      }
    }
  }
}

// Option "glb": the published GLB's normals and _SCALAR take the bits asked for. With 3 scalar
// bits a decoded u is one of the 8 values k/7 and the colour stays within half of such a step;
// with 4 normal bits every decoded normal is one of the 16 × 16 points of Draco's unfolded
// octahedron (coordinates 0..2^4 − 1; the default's bits give more distinct normals here); the
// GLB shrinks.
TEST(Adaptor, TheGlbOptionSetsThePublishedNormalAndScalarBits) {
  std::size_t bytes[2] = {0, 0};
  std::size_t normals[2] = {0, 0}, values[2] = {0, 0};
  for (const bool coarse : {false, true}) {
    SCOPED_TRACE(coarse ? "4 normal bits, 3 scalar bits" : "default bits");
    GridSlab slab(kSlabPoints, 0.0);
    std::vector<float> colour = slab_colour(slab);
    const std::string dir = temp_dir(coarse ? "glb_bits_coarse" : "glb_bits_default");
    std::string options =
        R"({"colour_by": "C", "merging": false, )" + grid_options(dir, false).substr(1);
    if (coarse) options = R"({"glb": {"normal_bits": 4, "scalar_bits": 3}, )" + options.substr(1);
    auto a = make_grid_adaptor(options, slab);
    if (!a) return;
    EXPECT_TRUE(a->add_field("C", colour.data(), ScalarType::float32));
    EXPECT_TRUE(a->execute(1, 0.0)) << a->last_error();
    EXPECT_TRUE(a->finalize()) << a->last_error();
    if (rank_of() != 0) continue;
    const Mesh mesh = testing::published_mesh(dir, 1);
    ASSERT_GT(mesh.vertex_count(), 300u);
    testing::expect_coloured_by(
        mesh, testing::published_step(dir, 1), "C",
        [](glm::dvec3 x) { return x.x + 2.0 * x.y - x.z; }, 2.0, 2.0 / 40,
        coarse ? 3 : StepGlbSettings{}.scalar_bits);
    std::set<std::array<float, 3>> n;
    for (const glm::vec3& v : mesh.normals)
      n.insert({v.x, v.y, v.z});
    normals[coarse] = n.size();
    values[coarse] = std::set<float>(mesh.scalars.begin(), mesh.scalars.end()).size();
    bytes[coarse] = published_glb(dir, 1).size();
  }
  if (rank_of() != 0) return;
  EXPECT_LE(values[1], 8u);
  EXPECT_GT(values[0], 8u);
  EXPECT_LE(normals[1], 16u * 16u);
  EXPECT_GT(normals[0], 16u * 16u);
  EXPECT_LT(bytes[1], bytes[0]);
}

TEST(Adaptor, ColourByAFieldABlockLacksFailsTheStepNamingIt) {
  GridSlab slab(kSlabPoints, 0.0);
  auto a = make_grid_adaptor(
      R"({"colour_by": "T", )" + grid_options(temp_dir("colour_missing"), true).substr(1), slab);
  if (!a) return;
  EXPECT_TRUE(a->add_field("U", slab.values.data(), ScalarType::float32));  // not T
  const Status s = a->execute(0, 0.0);
  if (thread_multiple()) {  // the snapshot path reports it later, from the caster thread
    const Status f = a->finalize();
    EXPECT_FALSE(f);
    EXPECT_NE(f.message().find("no field named 'T'"), std::string::npos) << f.message();
  } else {
    EXPECT_FALSE(s);
    EXPECT_NE(s.message().find("no field named 'T'"), std::string::npos) << s.message();
    EXPECT_TRUE(a->finalize());
  }
  // A FieldSource has one colour field (bind_scalar): two named fail the step, naming it.
  auto two = make(R"({"server": {"enabled": false}, "log": false, "resolution": 32,
                     "isovalues": [0.3, 0.5], "colour_by": ["T", "U"], "background": false})");
  if (two) {
    const Status step = two->execute(0, 0.0);
    EXPECT_FALSE(step);
    EXPECT_NE(step.message().find("is a FieldSource, which has one colour field (bind_scalar), and "
                                  "2 fields are named"),
              std::string::npos)
        << step.message();
    EXPECT_TRUE(two->finalize());
  }
  // A FieldSource without a colour field of its own: the step fails, naming it.
  auto c = make(R"({"server": {"enabled": false}, "log": false, "resolution": 32, "colour_by": "T",
                   "background": false})");
  if (c) {
    const Status step = c->execute(0, 0.0);
    EXPECT_FALSE(step);
    EXPECT_NE(step.message().find("is a FieldSource without a colour field"), std::string::npos)
        << step.message();
    EXPECT_TRUE(c->finalize());
  }
  // add_field before any block, with no name or no values: errors, nothing added.
  std::unique_ptr<Adaptor> b;
  EXPECT_TRUE(
      Adaptor::create(MPI_COMM_WORLD, R"({"server": {"enabled": false}, "log": false})", b));
  if (!b) return;
  const float x = 0.0f;
  Status e = b->add_field("T", &x, ScalarType::float32);
  EXPECT_NE(e.message().find("no block added yet"), std::string::npos) << e.message();
  EXPECT_TRUE(b->add_grid_block(slab.block));
  e = b->add_field("", &x, ScalarType::float32);
  EXPECT_NE(e.message().find("name is empty"), std::string::npos) << e.message();
  e = b->add_field("T", nullptr, ScalarType::float32);
  EXPECT_NE(e.message().find("null values"), std::string::npos) << e.message();
  // After a refused block the field would belong to the block before: refused.
  GridBlock broken = slab.block;
  broken.values = nullptr;
  EXPECT_FALSE(b->add_grid_block(broken));
  e = b->add_field("T", slab.values.data(), ScalarType::float32);
  EXPECT_NE(e.message().find("the block added last was refused"), std::string::npos) << e.message();
  EXPECT_TRUE(b->finalize());
}

// Curved elements coloured by z: a field of order p = q on geometry of order q represents z
// exactly, so a vertex's colour is its own z. And each isovalue by its own field: the sphere of
// radius 0.35 by z, the one of radius 0.2 inside it by x (each exact, each over its own range).
// Both paths publish the same bytes, merged (the snapshot answers the merge's samples), though
// the snapshot copies only the values of the elements that may hold the sphere (4³ elements, the
// sphere misses the corner ones) and the solver overwrites its arrays as soon as execute()
// returns.
TEST(Adaptor, CurvedElementBlocksAreColouredByTheirNodalField) {
  const int q = 2;
  BentCube cube = bent_cube(q, 4, 2);
  std::vector<double> values, x, z;
  const std::size_t count = cube.count;
  for (const glm::dvec3& p : cube.nodes) {
    values.push_back(glm::length(p - glm::dvec3(0.5)));
    x.push_back(p.x);
    z.push_back(p.z);
  }
  for (const bool per_isovalue : {false, true}) {
    std::vector<std::uint8_t> synchronous;
    for (const bool background : {false, true}) {
      std::vector<double> solver_values = values, solver_x = x, solver_z = z;
      const std::string dir = temp_dir(std::string("curved_colour_") + (per_isovalue ? "i" : "o") +
                                       (background ? "b" : "s"));
      std::unique_ptr<Adaptor> a;
      EXPECT_TRUE(Adaptor::create(
          MPI_COMM_WORLD,
          R"({"server": {"enabled": false}, "resolution": 64, "log": false, )" +
              std::string(per_isovalue ? R"("isovalues": [0.35, 0.2], "colour_by": ["z", "x"])"
                                       : R"("isovalues": [0.35], "colour_by": "z")") +
              R"(, "merging": true, "background": )" + (background ? "true" : "false") +
              R"(, "output_dir": ")" + dir + R"("})",
          a));
      if (!a) return;
      EXPECT_TRUE(a->set_domain({glm::dvec3(0.0), glm::dvec3(1.0)}));
      HexBlock block;
      block.order = q;
      block.element_count = count;
      block.geometry_order = q;
      block.geometry = cube.geometry.data();
      block.values = solver_values.data();
      if (count > 0) {
        EXPECT_TRUE(a->add_hex_block(block));
        EXPECT_TRUE(a->add_field("z", solver_z.data(), ScalarType::float64));
        EXPECT_TRUE(a->add_field("x", solver_x.data(), ScalarType::float64));
      }
      EXPECT_TRUE(a->execute(0, 0.0)) << a->last_error();
      EXPECT_EQ(a->last_report().background, background && thread_multiple());
      std::fill(solver_values.begin(), solver_values.end(), 0.35);
      std::fill(solver_x.begin(), solver_x.end(), -1e6);
      std::fill(solver_z.begin(), solver_z.end(), 1e6);
      EXPECT_TRUE(a->finalize()) << a->last_error();
      if (rank_of() != 0) continue;
      SCOPED_TRACE(std::string(per_isovalue ? "[z, x]" : "z") +
                   (background ? ", background" : ", synchronous"));
      const Mesh mesh = testing::published_mesh(dir, 0);
      const StepMetadata meta = testing::published_step(dir, 0);
      if (!per_isovalue) {
        testing::expect_coloured_by(
            mesh, meta, "z", [](glm::dvec3 p) { return p.z; }, 1.0, 1.0 / 64);
      } else {
        [&] {
          ASSERT_EQ(meta.surface_scalars.size(), 2u);
          ASSERT_TRUE(meta.surface_scalars[0] && meta.surface_scalars[1]);
          EXPECT_EQ(meta.surface_scalars[0]->name, "z");
          EXPECT_EQ(meta.surface_scalars[1]->name, "x");
          EXPECT_FALSE(meta.scalar.has_value());
          const auto from_centre = [](glm::dvec3 p) { return glm::length(p - glm::dvec3(0.5)); };
          testing::expect_part_coloured_by(
              mesh, *meta.surface_scalars[0], [&](glm::dvec3 p) { return from_centre(p) > 0.275; },
              [](glm::dvec3 p) { return p.z; }, 1.0, 1.0 / 64);
          testing::expect_part_coloured_by(
              mesh, *meta.surface_scalars[1], [&](glm::dvec3 p) { return from_centre(p) <= 0.275; },
              [](glm::dvec3 p) { return p.x; }, 1.0, 1.0 / 64);
        }();
      }
      if (!background) {
        synchronous = published_glb(dir, 0);
      } else {
        EXPECT_TRUE(published_glb(dir, 0) == synchronous) << "the two paths differ";
      }
    }
  }
}

// Cell blocks (add_cell_block): quadratic tetrahedra and wedges, a block per type, each rank its
// share of 3³ sub-cubes of [0, 1]³ (the first 2 as a second tetrahedral block of float32 values
// with a stride); |x − c|² is exact in both, so the published surface is the sphere of radius
// 0.35 (to the GLB's quantization), coloured by z, and both paths publish the same bytes.
TEST(Adaptor, CellBlocksOfEveryShapePublishTheSameMeshOnBothPaths) {
  const int n = 3;
  const glm::dvec3 c(0.5);
  struct Cells {
    CellType type = CellType::tetrahedron;
    std::vector<double> points, values, z;
    std::size_t count = 0;
  };
  Cells tets, wedges;
  tets.type = CellType::tetrahedron;
  wedges.type = CellType::wedge;
  const auto add = [&](Cells& cells, const std::vector<glm::dvec3>& corners) {
    const CellType linear = cells.type;
    for (const glm::dvec3& r : cell_reference_nodes(cells.type, 2)) {
      const std::vector<double> w = cell_shape_functions(linear, 1, r);
      glm::dvec3 x(0.0);
      for (std::size_t v = 0; v < w.size(); ++v)
        x += w[v] * corners[v];
      cells.points.insert(cells.points.end(), {x.x, x.y, x.z});
      cells.values.push_back(glm::dot(x - c, x - c));
      cells.z.push_back(x.z);
    }
    ++cells.count;
  };
  for (int e = 0; e < n * n * n; ++e) {
    if (e % ranks() != rank_of()) continue;
    const glm::dvec3 o = glm::dvec3(e % n, (e / n) % n, e / (n * n)) / double(n);
    const double h = 1.0 / n;
    const glm::dvec3 k[8] = {o,
                             o + h * glm::dvec3(1, 0, 0),
                             o + h * glm::dvec3(1, 1, 0),
                             o + h * glm::dvec3(0, 1, 0),
                             o + h * glm::dvec3(0, 0, 1),
                             o + h * glm::dvec3(1, 0, 1),
                             o + h * glm::dvec3(1, 1, 1),
                             o + h * glm::dvec3(0, 1, 1)};
    if (e % 2 == 0) {
      for (const auto& t : {std::vector<int>{0, 1, 2, 6},
                            {0, 2, 3, 6},
                            {0, 3, 7, 6},
                            {0, 7, 4, 6},
                            {0, 4, 5, 6},
                            {0, 5, 1, 6}})
        add(tets, {k[t[0]], k[t[1]], k[t[2]], k[t[3]]});
    } else {
      add(wedges, {k[0], k[1], k[2], k[4], k[5], k[6]});
      add(wedges, {k[0], k[2], k[3], k[4], k[6], k[7]});
    }
  }
  // The first two tetrahedra again as float32 values, 12 apart (10 nodes each).
  std::vector<float> strided(24, 0.0f), strided_z(24, 0.0f);
  std::vector<double> two_points;
  const std::size_t two = std::min<std::size_t>(tets.count, 2);
  for (std::size_t e = 0; e < two; ++e)
    for (int i = 0; i < 10; ++i) {
      strided[12 * e + i] = float(tets.values[10 * e + i]);
      strided_z[12 * e + i] = float(tets.z[10 * e + i]);
      for (int a = 0; a < 3; ++a)
        two_points.push_back(tets.points[3 * (10 * e + i) + a]);
    }
  std::vector<std::uint8_t> synchronous;
  for (const bool background : {false, true}) {
    const std::string dir = temp_dir(std::string("cells_") + (background ? "b" : "s"));
    std::unique_ptr<Adaptor> a;
    EXPECT_TRUE(Adaptor::create(MPI_COMM_WORLD,
                                R"({"server": {"enabled": false}, "resolution": 64, "log": false, )"
                                R"("isovalues": [0.1225], "colour_by": "z", "merging": true, )"
                                R"("background": )" +
                                    std::string(background ? "true" : "false") +
                                    R"(, "output_dir": ")" + dir + R"("})",
                                a));
    if (!a) return;
    EXPECT_TRUE(a->set_domain({glm::dvec3(0.0), glm::dvec3(1.0)}));
    std::vector<double> tet_values = tets.values, wedge_values = wedges.values;
    for (Cells* cells : {&tets, &wedges}) {
      if (cells->count == 0) continue;
      CellBlock b;
      b.type = cells->type;
      b.order = 2;
      b.element_count = cells->count;
      b.points = cells->points.data();
      b.values = cells == &tets ? tet_values.data() : wedge_values.data();
      EXPECT_TRUE(a->add_cell_block(b)) << a->last_error();
      EXPECT_TRUE(a->add_field("z", cells->z.data(), ScalarType::float64));
    }
    if (two > 0) {
      CellBlock b;
      b.type = CellType::tetrahedron;
      b.order = 2;
      b.element_count = two;
      b.points = two_points.data();
      b.values = strided.data();
      b.value_type = ScalarType::float32;
      b.element_stride = 12;
      EXPECT_TRUE(a->add_cell_block(b)) << a->last_error();
      EXPECT_TRUE(a->add_field("z", strided_z.data(), ScalarType::float32));
    }
    EXPECT_TRUE(a->execute(0, 0.0)) << a->last_error();
    EXPECT_EQ(a->last_report().background, background && thread_multiple());
    // The solver overwrites its arrays at once: the background path reads its copy.
    std::fill(tet_values.begin(), tet_values.end(), 0.1225);
    std::fill(wedge_values.begin(), wedge_values.end(), 0.1225);
    std::fill(strided.begin(), strided.end(), 0.1225f);
    EXPECT_TRUE(a->finalize()) << a->last_error();
    if (rank_of() != 0) continue;
    SCOPED_TRACE(background ? "background" : "synchronous");
    const Mesh mesh = testing::published_mesh(dir, 0);
    ASSERT_GT(mesh.positions.size(), 1000u);
    double worst = 0.0;
    for (const glm::vec3& p : mesh.positions)
      worst = std::max(worst, std::abs(glm::length(glm::dvec3(p) - c) - 0.35));
    EXPECT_LT(worst, 2e-3);  // the GLB's positions: a tenth of a pixel (1/64)
    testing::expect_coloured_by(
        mesh, testing::published_step(dir, 0), "z", [](glm::dvec3 p) { return p.z; }, 1.0,
        1.0 / 64);
    if (!background)
      synchronous = published_glb(dir, 0);
    else
      EXPECT_TRUE(published_glb(dir, 0) == synchronous) << "the two paths differ";
  }
}

// With less than MPI_THREAD_MULTIPLE the adaptor says that steps run synchronously.
TEST(Adaptor, WithoutThreadMultipleTheLogSaysStepsRunSynchronously) {
  ::testing::internal::CaptureStderr();
  std::unique_ptr<Adaptor> a;
  const Status s = Adaptor::create(MPI_COMM_WORLD, R"({"server": {"enabled": false}})", a);
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_TRUE(s) << s.message();
  if (rank_of() == 0) {
    const bool says = err.find("MPI_THREAD_MULTIPLE") != std::string::npos &&
                      err.find("synchronously") != std::string::npos;
    EXPECT_EQ(says, !thread_multiple()) << err;
  }
  if (a) {
    EXPECT_TRUE(a->finalize());
  }
}

TEST(Adaptor, ExecuteWithoutADomainFailsCleanly) {
  std::unique_ptr<Adaptor> a;
  EXPECT_TRUE(
      Adaptor::create(MPI_COMM_WORLD, R"({"server": {"enabled": false}, "log": false})", a));
  if (!a) return;
  const Status s = a->execute(0, 0.0);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("set_domain"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace ldimesh

int main(int argc, char** argv) {
  return ldimesh::testing::run_mpi_tests(argc, argv);
}

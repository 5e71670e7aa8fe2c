// Times the single-process pipeline on the paper's Table 1 cases (Barth at 64²…512², Klein
// bottle at 128², three views, r = 0.5): ray casting separately from mesh + trim, which is what
// Table 1 reports. Prints a Markdown table for docs/performance.md.
//
//   build/bin/ldimesh_bench_mesh [--repeat 5] [--threads N] [--clip-sweep]
//
// --clip-sweep adds how the Barth triangle count at 512² depends on the ball the unbounded
// surface is clipped to (domain box = the ball's bounding cube).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <CLI/CLI.hpp>

#include "bench_util.hpp"
#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/analytic_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

namespace {

using ldimesh::bench::median;
using ldimesh::bench::seconds_since;

struct Case {
  const char* surface;
  int res;
  const char* paper;  // Table 1 / Fig. 2 figures for the same case
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ldimesh mesh + trim benchmark (paper Table 1 cases)"};
  int repeat = 5;
  int threads = 0;
  app.add_option("--repeat", repeat, "runs per case; the median is reported")
      ->check(CLI::Range(1, 1000));
  app.add_option("--threads", threads, "threads (default: all cores)")->check(CLI::Range(1, 4096));
  bool clip_sweep = false;
  app.add_flag("--clip-sweep", clip_sweep, "also: Barth 512² triangles for several clip radii");
  CLI11_PARSE(app, argc, argv);
  if (threads == 0) threads = tbb::info::default_concurrency();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));

  const std::vector<Case> cases{{"barth", 64, "0.02 s, 24k"},
                                {"barth", 128, "0.11 s, 136k"},
                                {"barth", 256, "0.43 s, 625k"},
                                {"barth", 512, "1.84 s, 2 646k"},
                                {"klein", 128, "0.04 s, n/a"}};

  std::printf("threads: %d, runs per case: %d (median)\n\n", threads, repeat);
  std::printf(
      "| data set | LDI | scene s | ray cast s | Mrays/s | Mhits/s | samples | mesh s | trim s "
      "| mesh+trim s | assemble s | quads | triangles | paper (1 core): mesh s, triangles |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Case& c : cases) {
    const ldimesh::SurfaceInfo* s = ldimesh::find_surface(c.surface);
    const std::vector<ldimesh::View> views = ldimesh::make_axis_views(s->domain, c.res, "xyz");
    std::size_t rays = 0;
    for (const ldimesh::View& v : views)
      rays += v.pixel_count();

    std::vector<double> scene, cast, match, trim, total, assemble;
    ldimesh::MeshingResult result;
    for (int k = 0; k < repeat; ++k) {
      auto start = std::chrono::steady_clock::now();
      const auto source = ldimesh::make_surface_source(s->name);
      const ldimesh::RayCaster caster(*source, s->isovalue);
      scene.push_back(seconds_since(start));
      start = std::chrono::steady_clock::now();
      std::vector<ldimesh::Ldi> ldis;
      for (const ldimesh::View& v : views)
        ldis.push_back(caster.cast(v));
      cast.push_back(seconds_since(start));
      result = ldimesh::mesh_ldis(ldis, {});
      match.push_back(result.seconds.match);
      trim.push_back(result.seconds.trim);
      total.push_back(result.seconds.match + result.seconds.trim);
      assemble.push_back(result.seconds.assemble);
    }
    const double cast_s = median(cast);
    std::printf(
        "| %s | %d² | %.4f | %.3f | %.2f | %.2f | %zu | %.4f | %.4f | %.4f | %.4f | %zu | %zu | %s "
        "|\n",
        c.surface, c.res, median(scene), cast_s, rays / cast_s * 1e-6,
        result.samples / cast_s * 1e-6, result.samples, median(match), median(trim), median(total),
        median(assemble), result.quads, result.mesh.triangle_count(), c.paper);
    std::fflush(stdout);
  }

  if (clip_sweep) {
    std::printf(
        "\n| Barth clip radius R (domain [-R, R]³) | samples | triangles at 512², r = 0.5 "
        "|\n|---|---|---|\n");
    for (double R : {1.0, 1.25, 1.5, 2.0, 3.0}) {
      const ldimesh::AnalyticSource<ldimesh::fields::BarthSextic> source(
          {}, {{-R, -R, -R}, {R, R, R}}, R);
      const ldimesh::RayCaster caster(source, 0.0);
      std::vector<ldimesh::Ldi> ldis;
      for (const ldimesh::View& v : ldimesh::make_axis_views(source.bounds(), 512))
        ldis.push_back(caster.cast(v));
      const ldimesh::MeshingResult result = ldimesh::mesh_ldis(ldis, {});
      std::printf("| %.2f | %zu | %zu |\n", R, result.samples, result.mesh.triangle_count());
    }
  }
  return 0;
}

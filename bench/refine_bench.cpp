// Times §4 refinement on the paper's Table 1 refinement rows: Marschner–Lobb at 64² (three axis
// views, Fig. 6(h)) and a stand-in for the Shock Channel (one view, Fig. 3), triangles and quads,
// levels 1–3, r = 0.5, one process (mesh_ldis with a LocalSampleSource). Casting the LDIs is
// outside every meshing figure (Table 1 excludes ray casting); refinement's own extension samples
// are cast inside it and are reported apart ("sampling"), so it can be compared both ways.
// Prints two Markdown tables for docs/performance.md: the timings, and rays, hits per ray and time
// per ray of the LDIs' pixel-centre rays and of the extension samples.
//
//   build/bin/ldimesh_bench_refine [--repeat 7] [--threads N] [--only DATASET] [--out DIR]
//
// The Shock Channel stand-in: we do not have the paper's DG data (Üffinger et al.), so
// shock_density() below is an analytic bow shock in front of a box obstacle, sampled at the GLL
// nodes of 16³ hexahedra of order 4 (the elements inside the obstacle left out), isovalue 4.6.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <CLI/CLI.hpp>

#include "bench_util.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/core/raycast/sample_source.hpp"

namespace {

using ldimesh::bench::median;
using ldimesh::bench::seconds_since;

// Density of a supersonic flow along +x around the box obstacle [0, 0.5] × [−0.25, 0.25]²: free
// stream 1; a bow shock (a paraboloid with its apex 0.3 ahead of the obstacle's front face,
// smoothed by tanh over ≈ one element) compresses it up to 6 near the axis, less off the axis;
// the expansion around the obstacle's shoulders lowers it again downstream. The 4.6 isosurface
// is a shell around the front of the obstacle: the curved shock front, its flanks, and a back
// that ends on the obstacle's walls (where the elements are left out).
double shock_density(double x, double y, double z) {
  const double r2 = y * y + z * z;
  const double shock_x = -0.3 + 0.8 * r2;
  const double compressed = 0.5 * (1.0 + std::tanh((x - shock_x) / 0.06));
  const double behind = std::max(0.0, x - 0.1) / 0.5;
  return 1.0 + 5.0 * compressed * std::exp(-r2) * std::exp(-behind * behind);
}

// 16³ elements of order 4 (GLL nodes) over [−1, 1]³ holding shock_density at their nodes, the
// 4³ elements inside the obstacle left out. Owns the arrays the source points into.
struct ShockChannel {
  static constexpr int kElements = 16;
  static constexpr int kOrder = 4;
  std::vector<double> corners;
  std::vector<double> values;
  std::unique_ptr<ldimesh::HexElementSource> source;

  ShockChannel() {
    constexpr int p1 = kOrder + 1;
    constexpr double size = 2.0 / kElements;
    const std::vector<double> nodes =
        ldimesh::node_positions(kOrder, ldimesh::NodeSet::gauss_lobatto_legendre);
    for (int k = 0; k < kElements; ++k)
      for (int j = 0; j < kElements; ++j)
        for (int i = 0; i < kElements; ++i) {
          const glm::dvec3 lo{-1 + size * i, -1 + size * j, -1 + size * k};
          const glm::dvec3 centre = lo + 0.5 * size;
          if (centre.x > 0.0 && centre.x < 0.5 && std::abs(centre.y) < 0.25 &&
              std::abs(centre.z) < 0.25)
            continue;  // inside the obstacle: no flow, no element
          for (int c = 0; c < 8; ++c)
            for (int a = 0; a < 3; ++a)
              corners.push_back(lo[a] + size * ((c >> a) & 1));
          for (int nk = 0; nk < p1; ++nk)
            for (int nj = 0; nj < p1; ++nj)
              for (int ni = 0; ni < p1; ++ni)
                values.push_back(shock_density(lo.x + size * nodes[ni], lo.y + size * nodes[nj],
                                               lo.z + size * nodes[nk]));
        }
    ldimesh::HexBlock block;
    block.order = kOrder;
    block.nodes = ldimesh::NodeSet::gauss_lobatto_legendre;
    block.element_count = corners.size() / 24;
    block.corners = corners.data();
    block.values = values.data();
    block.type = ldimesh::ScalarType::float64;
    source = std::make_unique<ldimesh::HexElementSource>(block);
  }
};

struct Case {
  std::string name;  // data set, for the table and file names
  const ldimesh::FieldSource* source;
  double isovalue;
  int res;
  const char* axes;   // views
  const char* paper;  // Table 1: Mesh. / Ref. seconds on one core, figure
};

// Counts the rays asked for and the hits returned, around the sample source refinement uses (one
// virtual call per pass, not per sample).
class CountingSampleSource final : public ldimesh::SampleSource {
 public:
  explicit CountingSampleSource(ldimesh::SampleSource& inner) : inner_(inner) {}
  ldimesh::RayHitList sample(std::span<const ldimesh::SamplePoint> points) override {
    ldimesh::RayHitList hits = inner_.sample(points);
    rays += points.size();
    this->hits += hits.depth.size();
    return hits;
  }
  std::size_t rays = 0;
  std::size_t hits = 0;

 private:
  ldimesh::SampleSource& inner_;
};

std::string joined(const std::vector<std::size_t>& v) {
  std::string s;
  for (std::size_t k = 0; k < v.size(); ++k)
    s += (k ? " / " : "") + std::to_string(v[k]);
  return s;
}

std::string joined_seconds(const std::vector<double>& v) {
  std::string s;
  char buf[32];
  for (std::size_t k = 0; k < v.size(); ++k) {
    std::snprintf(buf, sizeof buf, "%s%.4f", k ? " / " : "", v[k]);
    s += buf;
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ldimesh §4 refinement benchmark (paper Table 1 refinement rows)"};
  int repeat = 5;
  int threads = 0;
  std::string out_dir;
  app.add_option("--repeat", repeat, "runs per case; the median is reported")
      ->check(CLI::Range(1, 1000));
  app.add_option("--threads", threads, "threads (default: all cores)")->check(CLI::Range(1, 4096));
  std::string only;
  app.add_option("--only", only, "only this data set")
      ->check(CLI::IsMember({"marschner-lobb", "shock-channel-standin"}));
  app.add_option("--out", out_dir, "also write each case's mesh (last run) as DIR/<case>.ply")
      ->check(CLI::ExistingDirectory);
  CLI11_PARSE(app, argc, argv);
  if (threads == 0) threads = tbb::info::default_concurrency();
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));

  const std::unique_ptr<ldimesh::FieldSource> ml = ldimesh::make_surface_source("marschner-lobb");
  const ShockChannel shock;
  const std::vector<Case> cases{
      {"marschner-lobb", ml.get(), ldimesh::find_surface("marschner-lobb")->isovalue, 64, "xyz",
       "0.08 / 0.73, 6(h)"},
      {"shock-channel-standin", shock.source.get(), 4.6, 64, "z", "< 0.01 / 0.01, 3"}};

  std::printf("threads: %d, runs per case: %d (median)\n\n", threads, repeat);
  std::printf(
      "| data set | LDI | faces | levels | threads | §3 mesh+trim s | refinement s | of which "
      "sampling s | refinement w/o sampling s | passes | ray stretches per pass | seconds per pass "
      "| "
      "grown cells | output faces | paper (1 core): Mesh. / Ref. s, Fig. |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  // Where the sampling time goes: rays, hits per ray and time per ray, for the LDI's pixel
  // centres and for refinement's extension samples; printed after the main table.
  std::vector<std::string> ray_rows;
  char row[512];
  for (const Case& c : cases) {
    if (!only.empty() && c.name != only) continue;
    const ldimesh::RayCaster caster(*c.source, c.isovalue);
    const std::vector<ldimesh::View> views =
        ldimesh::make_axis_views(c.source->bounds(), c.res, c.axes);
    std::vector<ldimesh::Ldi> ldis;
    std::vector<double> cast;
    for (int k = 0; k < repeat; ++k) {
      const auto start = std::chrono::steady_clock::now();
      ldis.clear();
      for (const ldimesh::View& v : views)
        ldis.push_back(caster.cast(v));
      cast.push_back(seconds_since(start));
    }
    std::size_t rays = 0, hits = 0;
    for (const ldimesh::Ldi& ldi : ldis) {
      rays += ldi.pixel_count();
      hits += ldi.sample_count();
    }
    std::snprintf(row, sizeof row, "| %s | LDI (pixel centres) | | %zu | %.2f | %.4f | %.2f |",
                  c.name.c_str(), rays, double(hits) / rays, median(cast),
                  median(cast) / rays * 1e6);
    ray_rows.push_back(row);
    ldimesh::LocalSampleSource local(caster, views);

    for (const ldimesh::FaceType faces : {ldimesh::FaceType::triangles, ldimesh::FaceType::quads})
      for (int levels = 1; levels <= 3; ++levels) {
        ldimesh::MeshingOptions options;
        options.faces = faces;
        options.refinement.levels = levels;
        std::vector<double> mesh, refine, sampling, without;
        std::vector<std::vector<double>> per_pass;
        ldimesh::MeshingResult result;
        CountingSampleSource samples(local);
        for (int k = 0; k < repeat; ++k) {
          samples.rays = samples.hits = 0;
          result = ldimesh::mesh_ldis(ldis, options, &samples);
          const ldimesh::RefinementStats& s = result.refinement;
          mesh.push_back(result.seconds.match + result.seconds.trim);
          // The pipeline's time for refine_views: RefinementStats::seconds plus the freeing of
          // refinement's working state after it (< 0.1 ms on Marschner–Lobb 64²: flat arrays).
          refine.push_back(result.seconds.refine);
          sampling.push_back(s.sample_seconds);
          without.push_back(result.seconds.refine - s.sample_seconds);
          per_pass.push_back(s.seconds_per_pass);
        }
        // Pass p's median over the runs (every run makes the same passes: refinement is
        // deterministic).
        std::vector<double> pass_seconds(result.refinement.seconds_per_pass.size());
        for (std::size_t p = 0; p < pass_seconds.size(); ++p) {
          std::vector<double> t;
          for (const std::vector<double>& run : per_pass)
            t.push_back(run[p]);
          pass_seconds[p] = median(t);
        }
        const bool quads = faces == ldimesh::FaceType::quads;
        const char* faces_name = quads ? "quads" : "triangles";
        const ldimesh::RefinementStats& s = result.refinement;
        std::printf(
            "| %s | %d² × %zu | %s | %d | %d | %.4f | %.4f | %.4f | %.4f | %d | %s | %s | %zu | "
            "%zu | %s |\n",
            c.name.c_str(), c.res, views.size(), faces_name, levels, threads, median(mesh),
            median(refine), median(sampling), median(without), s.passes,
            joined(s.rays_per_pass).c_str(), joined_seconds(pass_seconds).c_str(), s.grown_cells,
            result.mesh.face_count(), c.paper);
        std::fflush(stdout);
        std::snprintf(row, sizeof row,
                      "| %s | extension samples | %s, %d | %zu | %.2f | %.4f | %.2f |",
                      c.name.c_str(), faces_name, levels, samples.rays,
                      samples.rays ? double(samples.hits) / samples.rays : 0.0, median(sampling),
                      samples.rays ? median(sampling) / samples.rays * 1e6 : 0.0);
        ray_rows.push_back(row);
        if (!out_dir.empty()) {
          const std::string path =
              out_dir + "/" + c.name + "_" + faces_name + "_ref" + std::to_string(levels) + ".ply";
          if (const ldimesh::Status st = ldimesh::write_ply(path, result.mesh); !st)
            std::fprintf(stderr, "cannot write %s: %s\n", path.c_str(), st.message().c_str());
        }
      }
  }

  std::printf(
      "\n| data set | which rays | faces, levels | rays (stretches) | hits per ray | seconds | µs "
      "per ray "
      "|\n|---|---|---|---|---|---|---|\n");
  for (const std::string& r : ray_rows)
    std::printf("%s\n", r.c_str());
  return 0;
}

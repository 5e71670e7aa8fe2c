// Ray casting simulation data: a 256³ structured grid and 16³ high-order elements of order 4,
// both holding the Marschner–Lobb signal, isovalue 0.5. Reports primitives before and after
// culling, scene build times (for a new isovalue and for new values in the same arrays, i.e. a
// new time step), and rays/s and hits/s with all hits, on one thread and on all cores, for the
// coherent axis casters (the default) and, with --embree, for Embree on every ray.
//
//   build/bin/ldimesh_bench_sources [--grid-points 256] [--elements 16] [--order 4] [--res 512]
//                                   [--embree] [--json]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench_util.hpp"
#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/cubed_shell.hpp"
#include "ldimesh/core/field/grid_source.hpp"
#include "ldimesh/core/field/hex_source.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"

#include "field/hex/curved_element.hpp"  // the curved search's copies (internal)

namespace {

using ldimesh::bench::seconds_since;

// Binds `source` and casts the three axis views at `res` on `threads` threads with `path`
// (best of 3); prints one table row and records it in `rows` (JSON).
void cast_row(const char* label, const ldimesh::FieldSource& source, double iso, int res,
              int threads, ldimesh::CastPath path, nlohmann::json& rows) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  const std::vector<ldimesh::View> views = ldimesh::make_axis_views(source.bounds(), res);
  double best = 1e30, best_bind = 1e30;
  std::size_t rays = 0, hits = 0, primitives = 0;
  for (int run = 0; run < 3; ++run) {  // best of 3
    rays = hits = 0;
    const auto start = std::chrono::steady_clock::now();
    const ldimesh::RayCaster caster(source, iso, {path});
    const double bind = seconds_since(start);
    for (const ldimesh::View& v : views) {
      hits += caster.cast(v).sample_count();
      rays += v.pixel_count();
    }
    const double total = seconds_since(start);
    if (total < best) best = total, best_bind = bind;
    primitives = caster.primitive_count();  // after culling (not timed)
  }
  const char* caster = path == ldimesh::CastPath::embree ? "Embree" : "coherent";
  std::printf("| %s | %s | %d | %d² × 3 | %.3f | %.3f | %.2f | %.2f | %zu |\n", label, caster,
              threads, res, best_bind, best, rays / best * 1e-6, hits / best * 1e-6, hits);
  rows.push_back({{"source", label},
                  {"caster", caster},
                  {"threads", threads},
                  {"resolution", res},
                  {"bind_seconds", best_bind},
                  {"primitives", primitives},
                  {"seconds", best},
                  {"rays", rays},
                  {"hits", hits}});
}

// Scene build for `iso`: primitives kept and seconds (median of 5), all cores.
void build_row(const char* label, const ldimesh::FieldSource& source, std::size_t before,
               double iso) {
  std::vector<double> t;
  std::size_t kept = 0;
  for (int k = 0; k < 5; ++k) {
    const auto start = std::chrono::steady_clock::now();
    const ldimesh::RayCaster caster(source, iso);
    t.push_back(seconds_since(start));
    kept = caster.primitive_count();
  }
  std::sort(t.begin(), t.end());
  std::printf("| %s | %g | %zu | %zu | %.4f |\n", label, iso, before, kept, t[2]);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ldimesh ray casting benchmark on grid blocks and high-order elements"};
  int n = 256, elements = 16, order = 4, res = 512;
  app.add_option("--grid-points", n, "grid points per axis")->check(CLI::Range(8, 1024));
  app.add_option("--elements", elements, "elements per axis")->check(CLI::Range(1, 128));
  app.add_option("--order", order, "element order p")->check(CLI::Range(1, ldimesh::kMaxHexOrder));
  app.add_option("--res", res, "pixels per view side")->check(CLI::Range(8, 8192));
  int curved = 0;
  app.add_option("--curved", curved,
                 "give the elements curved geometry of this order q (their interiors bent, the "
                 "cube's faces kept); 0: affine cubes from corners")
      ->check(CLI::Range(0, ldimesh::kMaxHexOrder));
  bool with_embree = false, json = false;
  int shell = 0;
  app.add_option("--shell", shell,
                 "elements of a spherical shell 0.5 ≤ r ≤ 1 instead of cubes: a cubed sphere of 6 "
                 "× E² × SHELL elements (E = --elements), geometry of order --curved (≥ 1)")
      ->check(CLI::Range(0, 64));
  app.add_flag("--embree", with_embree, "also cast with Embree for every ray (the reference)");
  app.add_flag("--json", json, "end with one JSON line of the cast rows");
  std::string only;
  app.add_option("--only", only, "cast only this source (to profile one)")
      ->check(CLI::IsMember({"grid", "elements"}));
  bool baseline = false;
  app.add_flag("--baseline", baseline,
               "curved elements: run the search's baseline copy (as on a processor without AVX2) "
               "instead of its AVX2 one");
  CLI11_PARSE(app, argc, argv);
  if (baseline) ldimesh::curved::prefer_avx2(false);
  const int all = tbb::info::default_concurrency();
  const ldimesh::fields::MarschnerLobb ml;

  // Grid: n³ points over [−1, 1]³, float32, x fastest.
  std::vector<float> values(std::size_t(n) * n * n);
  auto fill_grid = [&](double shift) {
    tbb::parallel_for(0, n, [&](int k) {
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const double h = 2.0 / (n - 1);
          values[(std::size_t(k) * n + j) * n + i] =
              float(ml(-1 + i * h, -1 + j * h, -1 + k * h) + shift);
        }
    });
  };
  fill_grid(0.0);
  ldimesh::GridBlock block;
  block.dims = {n, n, n};
  block.values = values.data();
  block.type = ldimesh::ScalarType::float32;
  block.origin = glm::dvec3(-1.0);
  block.spacing = glm::dvec3(2.0 / (n - 1));
  const ldimesh::GridSource grid(block);

  if (shell > 0 && curved == 0) {
    std::fprintf(stderr, "ldimesh_bench_sources: --shell needs --curved Q (the geometry order)\n");
    return 2;
  }
  // Elements: elements³ cubes over [−1, 1]³, order p, GLL nodes, float64 — or the shell.
  const int p1 = order + 1;
  const std::size_t count = shell > 0 ? std::size_t(6) * elements * elements * shell
                                      : std::size_t(elements) * elements * elements;
  std::vector<double> corners(count * 24), nodal(count * p1 * p1 * p1);
  const std::vector<double> nodes =
      ldimesh::node_positions(order, ldimesh::NodeSet::gauss_lobatto_legendre);
  const double size = 2.0 / elements;
  // The bend of --curved: a smooth displacement that vanishes on the faces of [−1, 1]³.
  const auto bend = [&](glm::dvec3 x) {
    if (curved == 0) return x;
    const double pi = 3.14159265358979323846;
    const double bump =
        std::cos(0.5 * pi * x.x) * std::cos(0.5 * pi * x.y) * std::cos(0.5 * pi * x.z);
    return x + 0.1 * size * bump *
                   glm::dvec3(std::sin(pi * x.y + 0.3), std::cos(pi * x.z), std::sin(pi * x.x));
  };
  const int q1 = curved + 1;
  const std::vector<double> geometry_nodes =
      ldimesh::node_positions(std::max(curved, 1), ldimesh::NodeSet::gauss_lobatto_legendre);
  std::vector<double> geometry(curved > 0 ? count * 3 * q1 * q1 * q1 : 0);
  // The shell's map of element e's reference point ξ (a cubed sphere, 0.5 ≤ r ≤ 1).
  const ldimesh::CubedShell cubed{elements, std::max(shell, 1), 0.5, 1.0};
  const auto shell_point = [&](std::size_t e, glm::dvec3 xi) { return cubed.point(e, xi); };
  for (std::size_t e = 0; e < count && shell > 0; ++e) {
    for (int k = 0; k < q1; ++k)
      for (int j = 0; j < q1; ++j)
        for (int i = 0; i < q1; ++i) {
          const glm::dvec3 x =
              shell_point(e, glm::dvec3(geometry_nodes[i], geometry_nodes[j], geometry_nodes[k]));
          double* g = &geometry[3 * (e * q1 * q1 * q1 + (std::size_t(k) * q1 + j) * q1 + i)];
          g[0] = x.x, g[1] = x.y, g[2] = x.z;
        }
    for (int k = 0; k < p1; ++k)
      for (int j = 0; j < p1; ++j)
        for (int i = 0; i < p1; ++i) {
          const glm::dvec3 x = shell_point(e, glm::dvec3(nodes[i], nodes[j], nodes[k]));
          nodal[e * p1 * p1 * p1 + (std::size_t(k) * p1 + j) * p1 + i] = ml(x.x, x.y, x.z);
        }
  }
  for (std::size_t e = 0; e < count && shell == 0; ++e) {
    const glm::dvec3 lo{-1 + size * double(e % elements),
                        -1 + size * double((e / elements) % elements),
                        -1 + size * double(e / (std::size_t(elements) * elements))};
    for (int c = 0; c < 8; ++c)
      for (int a = 0; a < 3; ++a)
        corners[e * 24 + c * 3 + a] = lo[a] + size * ((c >> a) & 1);
    for (int k = 0; k < q1 && curved > 0; ++k)
      for (int j = 0; j < q1; ++j)
        for (int i = 0; i < q1; ++i) {
          const glm::dvec3 x =
              bend(lo + size * glm::dvec3(geometry_nodes[i], geometry_nodes[j], geometry_nodes[k]));
          double* g = &geometry[3 * (e * q1 * q1 * q1 + (std::size_t(k) * q1 + j) * q1 + i)];
          g[0] = x.x, g[1] = x.y, g[2] = x.z;
        }
    for (int k = 0; k < p1; ++k)
      for (int j = 0; j < p1; ++j)
        for (int i = 0; i < p1; ++i) {
          const glm::dvec3 x = bend(lo + size * glm::dvec3(nodes[i], nodes[j], nodes[k]));
          nodal[e * p1 * p1 * p1 + (std::size_t(k) * p1 + j) * p1 + i] = ml(x.x, x.y, x.z);
        }
  }
  ldimesh::HexBlock hex;
  hex.order = order;
  hex.nodes = ldimesh::NodeSet::gauss_lobatto_legendre;
  hex.element_count = count;
  hex.corners = corners.data();
  hex.values = nodal.data();
  hex.type = ldimesh::ScalarType::float64;
  hex.geometry_order = curved;
  hex.geometry = curved > 0 ? geometry.data() : nullptr;
  const ldimesh::HexElementSource elems(hex);

  std::printf("Marschner–Lobb on [-1, 1]^3; %d cores\n\n", all);
  std::printf(
      "| source | isovalue | primitives | after culling | scene build s "
      "|\n|---|---|---|---|---|\n");
  char grid_label[96], hex_label[128];
  std::snprintf(grid_label, sizeof grid_label, "grid %d³ float32, 8³-cell bricks", n);
  if (shell > 0)
    std::snprintf(hex_label, sizeof hex_label,
                  "shell 6 × %d² × %d curved elements, p = %d, q = %d, GLL", elements, shell, order,
                  curved);
  else if (curved > 0)
    std::snprintf(hex_label, sizeof hex_label, "%d³ curved elements, p = %d, q = %d, GLL", elements,
                  order, curved);
  else
    std::snprintf(hex_label, sizeof hex_label, "%d³ elements, p = %d, GLL", elements, order);
  build_row(grid_label, grid, grid.brick_count(), 0.5);
  build_row(grid_label, grid, grid.brick_count(), 0.4);
  fill_grid(0.01);  // a new time step in the same array
  build_row("same grid, new values", grid, grid.brick_count(), 0.5);
  fill_grid(0.0);
  build_row(hex_label, elems, count, 0.5);
  build_row(hex_label, elems, count, 0.4);

  std::printf(
      "\n| source | caster | threads | rays | bind s | bind + cast s | Mrays/s | Mhits/s | hits "
      "|\n|---|---|---|---|---|---|---|---|---|\n");
  nlohmann::json rows = nlohmann::json::array();
  for (ldimesh::CastPath path : {ldimesh::CastPath::automatic, ldimesh::CastPath::embree}) {
    if (path == ldimesh::CastPath::embree && !with_embree) continue;
    for (int threads : {1, all})
      if (only != "elements") cast_row(grid_label, grid, 0.5, res, threads, path, rows);
    for (int threads : {1, all})
      if (only != "grid") cast_row(hex_label, elems, 0.5, res, threads, path, rows);
  }
  if (json) std::printf("%s\n", nlohmann::json{{"casts", rows}}.dump().c_str());
  return 0;
}

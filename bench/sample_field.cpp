// Samples the field of a built-in analytic surface on a regular grid over its domain box, for the
// Marching Cubes baseline of bench/evaluate (bench/mc_baseline.py reads the file).
//
//   build/bin/ldimesh_sample_field --surface marschner-lobb --n 256 --out ml.raw [--threads N]
//   build/bin/ldimesh_sample_field --surface torus --dims 301,301,101 --out torus.raw
//
// --n N: N points along the longest side of the domain box; the other sides get as many points
// as keep the spacing (nearly) the same, round(extent / h) + 1, and the grid covers the box
// exactly (first point on box.lo, last on box.hi), as the ray caster's views do. --dims sets the
// three counts directly. The file holds float32 values, x fastest, then y, then z
// (little-endian, no header). One JSON line on stdout: dims, origin, spacing, isovalue, the
// clip (the ball the ray caster clips the surface to, or null), the domain box, and the
// sampling seconds (evaluation only, all threads) and the writing seconds.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include <tbb/blocked_range2d.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench_util.hpp"
#include "ldimesh/core/field/analytic_fields.hpp"
#include "ldimesh/core/field/surfaces.hpp"

namespace {

using ldimesh::bench::seconds_since;

using FieldFn = std::function<double(double, double, double)>;

template <class Field>
FieldFn plain() {
  return [](double x, double y, double z) { return Field{}(x, y, z); };
}

// The field of `s` as a plain double function: the analytic template itself where we know it
// (no derivatives, the cheapest), otherwise the registry's field with its gradient dropped.
FieldFn field_of(const ldimesh::SurfaceInfo& s) {
  namespace f = ldimesh::fields;
  if (s.name == "sphere") return plain<f::Sphere>();
  if (s.name == "torus") return plain<f::Torus>();
  if (s.name == "barth") return plain<f::BarthSextic>();
  if (s.name == "klein") return plain<f::KleinBottle>();
  if (s.name == "marschner-lobb") return plain<f::MarschnerLobb>();
  if (s.name == "slices") return plain<f::Slices>();
  auto fn = s.field;
  return [fn](double x, double y, double z) {
    glm::dvec3 g;
    return fn({x, y, z}, g);
  };
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"sample a built-in surface's field on a regular grid (raw float32, x fastest)"};
  std::string name, out;
  int n = 0;
  std::vector<int> dims_arg;
  int threads = 0;
  app.add_option("--surface", name, "built-in surface (ldimesh surfaces)")->required();
  auto* n_opt = app.add_option("--n", n, "points along the longest side of the domain box")
                    ->check(CLI::Range(2, 1 << 14));
  app.add_option("--dims", dims_arg, "NX,NY,NZ points instead of --n")
      ->delimiter(',')
      ->expected(3)
      ->excludes(n_opt);
  app.add_option("--out", out, "output raw file (float32, x fastest)")->required();
  app.add_option("--threads", threads, "threads (default: all cores)")->check(CLI::Range(1, 4096));
  CLI11_PARSE(app, argc, argv);

  try {
    const ldimesh::SurfaceInfo* s = ldimesh::find_surface(name);
    if (!s) throw std::runtime_error("unknown surface '" + name + "' (see 'ldimesh surfaces')");
    const ldimesh::Box box = s->domain;
    const glm::dvec3 extent = box.extent();
    std::array<std::int64_t, 3> dims{};
    if (!dims_arg.empty()) {
      for (int a = 0; a < 3; ++a) {
        if (dims_arg[a] < 2) throw std::runtime_error("--dims: at least 2 points per axis");
        dims[a] = dims_arg[a];
      }
    } else {
      if (n == 0) throw std::runtime_error("give --n N or --dims NX,NY,NZ");
      const double longest = std::max({extent.x, extent.y, extent.z});
      const double h = longest / double(n - 1);
      for (int a = 0; a < 3; ++a)
        dims[a] = std::max<std::int64_t>(2, std::llround(extent[a] / h) + 1);
    }
    std::array<double, 3> spacing{}, origin{};
    for (int a = 0; a < 3; ++a) {
      spacing[a] = extent[a] / double(dims[a] - 1);
      origin[a] = box.lo[a];
    }
    if (threads == 0) threads = tbb::info::default_concurrency();
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));

    const FieldFn field = field_of(*s);
    const std::int64_t nx = dims[0], ny = dims[1], nz = dims[2];
    std::vector<float> values(std::size_t(nx * ny * nz));
    auto start = std::chrono::steady_clock::now();
    tbb::parallel_for(tbb::blocked_range2d<std::int64_t>(0, nz, 0, ny),
                      [&](const tbb::blocked_range2d<std::int64_t>& r) {
                        for (std::int64_t k = r.rows().begin(); k != r.rows().end(); ++k) {
                          const double z = k + 1 == nz ? box.hi.z : origin[2] + k * spacing[2];
                          for (std::int64_t j = r.cols().begin(); j != r.cols().end(); ++j) {
                            const double y = j + 1 == ny ? box.hi.y : origin[1] + j * spacing[1];
                            float* row = values.data() + (k * ny + j) * nx;
                            for (std::int64_t i = 0; i < nx; ++i) {
                              const double x = i + 1 == nx ? box.hi.x : origin[0] + i * spacing[0];
                              row[i] = float(field(x, y, z));
                            }
                          }
                        }
                      });
    const double sample_seconds = seconds_since(start);

    start = std::chrono::steady_clock::now();
    std::ofstream file(out, std::ios::binary);
    if (!file) throw std::runtime_error("cannot write '" + out + "'");
    file.write(reinterpret_cast<const char*>(values.data()),
               std::streamsize(values.size() * sizeof(float)));
    file.close();
    if (!file) throw std::runtime_error("cannot write '" + out + "'");
    const double write_seconds = seconds_since(start);

    float lo = values[0], hi = values[0];
    for (float v : values) {
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    nlohmann::json j;
    j["surface"] = s->name;
    j["file"] = out;
    j["type"] = "float32";
    j["dims"] = dims;
    j["origin"] = origin;
    j["spacing"] = spacing;
    j["points"] = nx * ny * nz;
    j["isovalue"] = s->isovalue;
    j["value_range"] = {lo, hi};
    j["domain"] = {{"lo", {box.lo.x, box.lo.y, box.lo.z}}, {"hi", {box.hi.x, box.hi.y, box.hi.z}}};
    j["diagonal"] = box.diagonal();
    if (s->clip_radius > 0.0)
      j["clip"] = {{"type", "ball"}, {"center", {0.0, 0.0, 0.0}}, {"radius", s->clip_radius}};
    else
      j["clip"] = nullptr;
    j["threads"] = threads;
    j["seconds"] = sample_seconds;
    j["write_seconds"] = write_seconds;
    std::cout << j.dump() << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ldimesh_sample_field: error: %s\n", e.what());
    return 1;
  }
}

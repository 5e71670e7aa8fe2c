// Mesh delivery: the Draco GLB (GlbOptions' defaults: 10 normal bits; published steps take 8,
// StepGlbSettings — pass --normal-bits 8 for those) against the binary PLY the CLI writes, on
// every built-in analytic surface at each --res: three axis views, r = 0.5, triangles. Reports
// triangles, GLB bytes (and per triangle), PLY bytes (and per triangle), the position bits
// chosen (automatic: step ≤ a tenth of the LDI pixel) with glb_position_error_bound in pixels,
// and the encode times on one thread and on --threads (meshes above 200 000 triangles are
// encoded in parts, concurrently), the decode time (one thread), each the median of --repeat,
// the two encodes alternating. Prints a Markdown table.
//
//   build/bin/ldimesh_bench_glb [--res 256 512] [--repeat 5] [--level 7] [--normal-bits 10]
//                               [--threads N]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>
#include <CLI/CLI.hpp>

#include "bench_util.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/glb.hpp"

namespace {

using ldimesh::bench::median;
using ldimesh::bench::seconds_since;

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ldimesh mesh delivery benchmark: Draco GLB against binary PLY"};
  std::vector<int> resolutions = {256, 512};
  int repeat = 5;
  int threads = int(std::max(1u, std::thread::hardware_concurrency()));
  ldimesh::GlbOptions options;
  app.add_option("--res", resolutions, "pixels per view side (several allowed)")
      ->check(CLI::Range(8, 8192));
  app.add_option("--repeat", repeat, "encodes and decodes per mesh; the median is reported")
      ->check(CLI::Range(1, 1000));
  app.add_option("--level", options.compression_level, "Draco compression level")
      ->check(CLI::Range(0, 10));
  app.add_option("--normal-bits", options.normal_bits, "normal quantization bits")
      ->check(CLI::Range(2, 30));
  app.add_option("--threads", threads, "threads of the second encode timing")
      ->check(CLI::Range(1, 1024));
  CLI11_PARSE(app, argc, argv);

  std::printf(
      "Three axis views per surface, r = 0.5, triangles; GLB: Draco level %d, automatic "
      "position bits (step ≤ 0.1 pixel), %d normal bits, colours; PLY: binary, "
      "ldimesh::write_ply (float position + normal, uint indices, view byte); encode on one "
      "thread and on %d, decode on one, median of %d\n\n",
      options.compression_level, options.normal_bits, threads, repeat);
  std::printf(
      "| surface | res | triangles | vertices | GLB bytes | GLB B/tri | PLY bytes | PLY B/tri | "
      "PLY / GLB | position bits | error bound (pixels) | encode s | encode s, %d threads | "
      "decode s |\n",
      threads);
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  const std::filesystem::path ply = std::filesystem::temp_directory_path() /
                                    ("ldimesh_bench_glb_" + std::to_string(getpid()) + ".ply");
  for (const int res : resolutions) {
    std::size_t total_triangles = 0, total_glb = 0, total_ply = 0;
    double total_encode = 0.0, total_encode_threads = 0.0, total_decode = 0.0;
    for (const ldimesh::SurfaceInfo& s : ldimesh::builtin_surfaces()) {
      ldimesh::Mesh mesh;
      double pixel = 0.0;
      {
        const auto source = ldimesh::make_surface_source(s.name);
        const ldimesh::RayCaster caster(*source, s.isovalue);
        std::vector<ldimesh::Ldi> ldis;
        const std::vector<ldimesh::View> views = ldimesh::make_axis_views(s.domain, res);
        for (const ldimesh::View& v : views)
          ldis.push_back(caster.cast(v));
        pixel = views[0].spacing;
        mesh = ldimesh::mesh_ldis(ldis).mesh;
      }
      ldimesh::GlbOptions o = options;
      o.pixel_size = pixel;

      std::vector<double> enc, enc_threads, dec;
      std::vector<std::uint8_t> glb, glb_threads;
      ldimesh::GlbInfo info;
      ldimesh::Mesh back;
      for (int r = 0; r < repeat; ++r) {
        {
          ldimesh::GlbOptions with_threads = o;
          with_threads.threads = threads;
          const auto start = std::chrono::steady_clock::now();
          if (ldimesh::Status st = ldimesh::encode_glb(mesh, with_threads, glb_threads); !st) {
            std::fprintf(stderr, "%s\n", st.message().c_str());
            return 1;
          }
          enc_threads.push_back(seconds_since(start));
        }
        // One thread (the parts one after another), and the decode.
        ldimesh::GlbOptions one_thread = o;
        one_thread.threads = 1;
        auto start = std::chrono::steady_clock::now();
        if (ldimesh::Status st = ldimesh::encode_glb(mesh, one_thread, glb, &info); !st) {
          std::fprintf(stderr, "%s\n", st.message().c_str());
          return 1;
        }
        enc.push_back(seconds_since(start));
        if (glb != glb_threads) {
          std::fprintf(stderr, "%s: the GLB depends on the threads\n", s.name.c_str());
          return 1;
        }
        start = std::chrono::steady_clock::now();
        if (ldimesh::Status st = ldimesh::decode_glb(glb, back); !st) {
          std::fprintf(stderr, "%s\n", st.message().c_str());
          return 1;
        }
        dec.push_back(seconds_since(start));
      }
      if (back.triangle_count() != mesh.triangle_count()) {
        std::fprintf(stderr, "%s: decoded %zu triangles of %zu\n", s.name.c_str(),
                     back.triangle_count(), mesh.triangle_count());
        return 1;
      }
      if (ldimesh::Status st = ldimesh::write_ply(ply.string(), mesh); !st) {
        std::fprintf(stderr, "%s\n", st.message().c_str());
        return 1;
      }
      const std::size_t ply_bytes = std::filesystem::file_size(ply);
      const double t = double(mesh.triangle_count());
      std::printf(
          "| %s | %d² | %zu | %zu | %zu | %.2f | %zu | %.2f | %.1f | %d | %.3f | %.4f | %.4f | "
          "%.4f |\n",
          s.name.c_str(), res, mesh.triangle_count(), mesh.vertex_count(), glb.size(),
          double(glb.size()) / t, ply_bytes, double(ply_bytes) / t,
          double(ply_bytes) / double(glb.size()), info.position_bits,
          info.position_error_bound / pixel, median(enc), median(enc_threads), median(dec));
      total_triangles += mesh.triangle_count();
      total_glb += glb.size();
      total_ply += ply_bytes;
      total_encode += median(enc);
      total_encode_threads += median(enc_threads);
      total_decode += median(dec);
    }
    std::printf(
        "| **all** | %d² | %zu | | %zu | %.2f | %zu | %.2f | %.1f | | | %.4f | %.4f | %.4f |\n",
        res, total_triangles, total_glb, double(total_glb) / double(total_triangles), total_ply,
        double(total_ply) / double(total_triangles), double(total_ply) / double(total_glb),
        total_encode, total_encode_threads, total_decode);
  }
  std::filesystem::remove(ply);
  return 0;
}

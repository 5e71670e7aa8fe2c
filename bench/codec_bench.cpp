// The LDI fragment codec on every built-in analytic surface: three axis views at --res, each
// view one fragment. Reports encoded bytes per sample (lossy at the given settings, and
// lossless) against the 16 raw bytes (float depth + float3 normal), the largest depth and
// normal errors against the original floats next to the codec's stated bounds, and the
// single-thread encode and decode times (MB/s of raw sample data). Prints Markdown tables.
//
//   build/bin/ldimesh_bench_codec [--res 512] [--repeat 5] [--depth-bits 20] [--normal-bits 12]
//                                 [--zstd-level 3]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench_util.hpp"
#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/fragment_codec.hpp"

namespace {

using ldimesh::bench::median;
using ldimesh::bench::seconds_since;

constexpr double kRawBytesPerSample = 16.0;  // float depth + float3 normal
constexpr double kDegrees = 180.0 / 3.141592653589793;

double angle(glm::vec3 a, glm::vec3 b) {
  const glm::dvec3 u = glm::normalize(glm::dvec3(a)), v = glm::normalize(glm::dvec3(b));
  return std::atan2(glm::length(glm::cross(u, v)), glm::dot(u, v));
}

struct Row {
  std::size_t samples = 0;
  std::size_t lossy_bytes = 0, lossless_bytes = 0;
  double depth_err = 0, depth_bound = 0, depth_err_px = 0, depth_bound_px = 0;
  double normal_err = 0;
  double encode_s = 0, decode_s = 0, lossless_encode_s = 0, lossless_decode_s = 0;
};

// Encodes and decodes every fragment `repeat` times; sizes, errors and median times.
void measure(const std::vector<ldimesh::LdiFragment>& fragments,
             const std::vector<ldimesh::View>& views, const ldimesh::FragmentEncoding& lossy,
             int repeat, Row& row) {
  const ldimesh::FragmentEncoding lossless{.lossless = true, .zstd_level = lossy.zstd_level};
  for (std::size_t k = 0; k < fragments.size(); ++k) {
    const ldimesh::LdiFragment& f = fragments[k];
    row.samples += f.sample_count();
    std::vector<double> enc, dec, enc_ll, dec_ll;
    std::vector<std::uint8_t> bytes, bytes_ll;
    ldimesh::LdiFragment back, back_ll;
    for (int r = 0; r < repeat; ++r) {
      auto start = std::chrono::steady_clock::now();
      bytes = ldimesh::encode_fragment(f, lossy);
      enc.push_back(seconds_since(start));
      start = std::chrono::steady_clock::now();
      if (!ldimesh::decode_fragment(bytes, back)) std::abort();
      dec.push_back(seconds_since(start));
      start = std::chrono::steady_clock::now();
      bytes_ll = ldimesh::encode_fragment(f, lossless);
      enc_ll.push_back(seconds_since(start));
      start = std::chrono::steady_clock::now();
      if (!ldimesh::decode_fragment(bytes_ll, back_ll)) std::abort();
      dec_ll.push_back(seconds_since(start));
    }
    row.encode_s += median(enc);
    row.decode_s += median(dec);
    row.lossless_encode_s += median(enc_ll);
    row.lossless_decode_s += median(dec_ll);
    row.lossy_bytes += bytes.size();
    row.lossless_bytes += bytes_ll.size();
    // Lossless decoding is exact; the errors are against the original floats.
    if (back_ll.depth != f.depth) std::abort();
    const double pixel = views[k].spacing;
    const double bound = ldimesh::depth_error_bound(lossy, f.depth_lo, f.depth_hi);
    row.depth_bound = std::max(row.depth_bound, bound);
    row.depth_bound_px = std::max(row.depth_bound_px, bound / pixel);
    for (std::size_t s = 0; s < f.sample_count(); ++s) {
      const double e = std::abs(double(back.depth[s]) - double(f.depth[s]));
      row.depth_err = std::max(row.depth_err, e);
      row.depth_err_px = std::max(row.depth_err_px, e / pixel);
      row.normal_err = std::max(row.normal_err, angle(back.normal[s], f.normal[s]));
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ldimesh LDI fragment codec benchmark on the built-in surfaces"};
  int res = 512, repeat = 5;
  ldimesh::FragmentEncoding lossy;
  app.add_option("--res", res, "pixels per view side")->check(CLI::Range(8, 8192));
  app.add_option("--repeat", repeat, "runs per fragment; the median is reported")
      ->check(CLI::Range(1, 1000));
  app.add_option("--depth-bits", lossy.depth_bits, "lossy depth bits")->check(CLI::Range(1, 24));
  app.add_option("--normal-bits", lossy.normal_bits, "lossy normal bits per coordinate")
      ->check(CLI::Range(2, 16));
  app.add_option("--zstd-level", lossy.zstd_level, "zstd level")->check(CLI::Range(-7, 22));
  CLI11_PARSE(app, argc, argv);

  std::printf(
      "%d² × 3 axis views per surface, one fragment per view; lossy: %d depth bits, %d normal "
      "bits, zstd %d; one thread, median of %d\n\n",
      res, lossy.depth_bits, lossy.normal_bits, lossy.zstd_level, repeat);
  std::printf(
      "| surface | samples | raw B/sample | lossy B/sample | lossless B/sample | max depth error "
      "(bound) | in pixels (bound) | max normal error ° (bound) | lossy encode s (MB/s) | "
      "lossy decode s (MB/s) | lossless encode s (MB/s) | lossless decode s (MB/s) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  Row total;
  for (const ldimesh::SurfaceInfo& s : ldimesh::builtin_surfaces()) {
    const auto source = ldimesh::make_surface_source(s.name);
    const ldimesh::RayCaster caster(*source, s.isovalue);
    const std::vector<ldimesh::View> views = ldimesh::make_axis_views(s.domain, res);
    std::vector<ldimesh::LdiFragment> fragments;
    for (std::size_t k = 0; k < views.size(); ++k)
      fragments.push_back(ldimesh::fragment_from_ldi(caster.cast(views[k]), std::uint32_t(k)));
    Row row;
    measure(fragments, views, lossy, repeat, row);
    const double n = double(row.samples), raw_mb = n * kRawBytesPerSample * 1e-6;
    std::printf(
        "| %s | %zu | %.0f | %.2f | %.2f | %.2e (%.2e) | %.1e (%.1e) | %.4f (%.4f) | %.4f (%.0f) "
        "| %.4f (%.0f) | %.4f (%.0f) | %.4f (%.0f) |\n",
        s.name.c_str(), row.samples, kRawBytesPerSample, row.lossy_bytes / n,
        row.lossless_bytes / n, row.depth_err, row.depth_bound, row.depth_err_px,
        row.depth_bound_px, row.normal_err * kDegrees,
        ldimesh::normal_error_bound(lossy) * kDegrees, row.encode_s, raw_mb / row.encode_s,
        row.decode_s, raw_mb / row.decode_s, row.lossless_encode_s, raw_mb / row.lossless_encode_s,
        row.lossless_decode_s, raw_mb / row.lossless_decode_s);
    std::fflush(stdout);
    total.samples += row.samples;
    total.lossy_bytes += row.lossy_bytes;
    total.lossless_bytes += row.lossless_bytes;
  }
  std::printf("\nAll surfaces: %zu samples, lossy %.2f B/sample, lossless %.2f B/sample\n",
              total.samples, double(total.lossy_bytes) / double(total.samples),
              double(total.lossless_bytes) / double(total.samples));
  return 0;
}

// libFuzzer target for read_raw_volume (scripts/fuzz.sh raw builds and runs it with ASan and
// UBSan): the file `ldimesh mesh --grid FILE --dims NX,NY,NZ` reads, with the dimensions and
// value type a user gives. The first byte picks the value type and how the dimensions are given:
// small ones (2–17 along each axis, from the next three bytes), so that files of the right size
// occur, or any three 64-bit integers (overflow, negative and huge products); the rest is the
// file. A volume the reader accepts must hold exactly the values it was given, all finite, its
// range must be theirs, and its block must describe them.
//
// With LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes a seed corpus into DIR and exits:
// float32 and float64 volumes of a sphere's distance field (as numpy's tofile writes them), one
// a byte short, one with a NaN, one whose dimensions overflow.
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <unistd.h>

#include "ldimesh/core/io/raw_volume.hpp"

#include "fuzz_seeds.hpp"

namespace {

// The input's header: byte 0 = type (bit 0: float64) and mode (bit 1: 64-bit dimensions), then
// three bytes (small dimensions) or 24 (64-bit dimensions).
std::string header(bool float64, std::array<std::int64_t, 3> dims, bool wide) {
  std::string h(1, char((float64 ? 1 : 0) | (wide ? 2 : 0)));
  for (std::int64_t d : dims) {
    if (wide)
      h.append(reinterpret_cast<const char*>(&d), sizeof d);
    else
      h.push_back(char(d - 2));
  }
  return h;
}

template <class T>
std::string sphere(int n) {
  std::string bytes;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const T x = T(i - n / 2), y = T(j - n / 2), z = T(k - n / 2);
        const T v = std::sqrt(x * x + y * y + z * z);
        bytes.append(reinterpret_cast<const char*>(&v), sizeof v);
      }
  return bytes;
}

}  // namespace

void ldimesh::fuzz::write_seeds(const std::string& dir) {
  write_file(dir + "/seed-float32.bin", header(false, {9, 9, 9}, false) + sphere<float>(9));
  write_file(dir + "/seed-float64.bin", header(true, {6, 6, 6}, false) + sphere<double>(6));
  std::string nan = header(false, {3, 3, 3}, false) + sphere<float>(3);
  const float q = NAN;
  std::memcpy(&nan[1 + 13 * sizeof(float)], &q, sizeof q);
  write_file(dir + "/seed-nan.bin", nan);
  std::string shorter = header(true, {4, 4, 4}, false) + sphere<double>(4);
  shorter.pop_back();
  write_file(dir + "/seed-short.bin", shorter);
  write_file(dir + "/seed-wide.bin",
             header(false, {std::int64_t(1) << 40, std::int64_t(1) << 40, 5}, true) + "abcd");
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 4) return 0;
  const bool float64 = data[0] & 1, wide = data[0] & 2;
  std::array<std::int64_t, 3> dims{};
  std::size_t at = 1;
  if (wide) {
    if (size < 1 + 3 * sizeof(std::int64_t)) return 0;
    std::memcpy(dims.data(), data + 1, 3 * sizeof(std::int64_t));
    at += 3 * sizeof(std::int64_t);
  } else {
    for (int a = 0; a < 3; ++a)
      dims[a] = 2 + data[1 + a] % 16;
    at += 3;
  }
  static const std::string path = ldimesh::fuzz::scratch_path(".raw");
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || std::fwrite(data + at, 1, size - at, f) != size - at) std::abort();
  std::fclose(f);

  const ldimesh::ScalarType type =
      float64 ? ldimesh::ScalarType::float64 : ldimesh::ScalarType::float32;
  ldimesh::RawVolume volume;
  const ldimesh::Status s =
      ldimesh::read_raw_volume(path, dims, type, {0, 0, 0}, {1, 1, 1}, volume);
  std::remove(path.c_str());
  if (!s) {
    if (s.message().empty()) __builtin_trap();
    return 0;
  }
  // Accepted: exactly the file's values, finite, and their range.
  const std::size_t count = std::size_t(dims[0] * dims[1] * dims[2]);
  if (count * ldimesh::scalar_size(type) != size - at) __builtin_trap();
  if (volume.block.dims != dims || volume.block.values != volume.storage.data()) __builtin_trap();
  if (std::memcmp(volume.storage.data(), data + at, size - at) != 0) __builtin_trap();
  double lo = INFINITY, hi = -INFINITY;
  for (std::size_t i = 0; i < count; ++i) {
    double v;
    if (float64) {
      std::memcpy(&v, data + at + 8 * i, 8);
    } else {
      float x;
      std::memcpy(&x, data + at + 4 * i, 4);
      v = x;
    }
    if (!std::isfinite(v)) __builtin_trap();
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  if (lo != volume.min_value || hi != volume.max_value) __builtin_trap();
  if (volume.block.type != type || volume.block.origin != glm::dvec3(0.0) ||
      volume.block.spacing != glm::dvec3(1.0))
    __builtin_trap();
  return 0;
}

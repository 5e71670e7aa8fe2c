#include "ldimesh/core/io/raw_volume.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

namespace ldimesh {

Status read_raw_volume(const std::string& path, std::array<std::int64_t, 3> dims, ScalarType type,
                       glm::dvec3 origin, glm::dvec3 spacing, RawVolume& out) {
  std::uint64_t count = 1;
  for (std::int64_t d : dims) {
    if (d < 2) return Status::invalid_argument("raw volume: every dimension must be at least 2");
    if (count > std::numeric_limits<std::uint64_t>::max() / std::uint64_t(d))
      return Status::invalid_argument("raw volume: dimensions overflow");
    count *= std::uint64_t(d);
  }
  // The byte count overflows before the value count can (found by fuzzing: 2⁶³ float32 values
  // "needed" 0 bytes, and an empty file was accepted).
  if (count > std::numeric_limits<std::uint64_t>::max() / scalar_size(type))
    return Status::invalid_argument("raw volume: dimensions overflow");
  const std::uint64_t bytes = count * scalar_size(type);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return Status::io("cannot read '" + path + "': " + std::strerror(errno));
  std::fseek(f, 0, SEEK_END);
  const long size = std::ftell(f);
  std::fseek(f, 0, SEEK_SET);
  if (size < 0 || std::uint64_t(size) != bytes) {
    std::fclose(f);
    return Status::corrupt_input("'" + path + "' has " + std::to_string(size) + " bytes, but " +
                                 std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                 std::to_string(dims[2]) + " " +
                                 (type == ScalarType::float32 ? "float32" : "float64") +
                                 " values need " + std::to_string(bytes));
  }
  out.storage.assign((bytes + 7) / 8, 0.0);
  const std::size_t got = std::fread(out.storage.data(), 1, bytes, f);
  std::fclose(f);
  if (got != bytes)
    return Status::io("reading '" + path + "' failed after " + std::to_string(got) + " bytes");

  out.min_value = INFINITY;
  out.max_value = -INFINITY;
  auto scan = [&](const auto* v) {
    for (std::uint64_t i = 0; i < count; ++i) {
      const double x = double(v[i]);
      if (!std::isfinite(x)) return false;
      out.min_value = std::min(out.min_value, x);
      out.max_value = std::max(out.max_value, x);
    }
    return true;
  };
  const bool finite = type == ScalarType::float32
                          ? scan(reinterpret_cast<const float*>(out.storage.data()))
                          : scan(out.storage.data());
  if (!finite) return Status::corrupt_input("'" + path + "' holds NaN or infinite values");

  out.block = GridBlock{};
  out.block.dims = dims;
  out.block.values = out.storage.data();
  out.block.type = type;
  out.block.origin = origin;
  out.block.spacing = spacing;
  return Status::ok();
}

}  // namespace ldimesh

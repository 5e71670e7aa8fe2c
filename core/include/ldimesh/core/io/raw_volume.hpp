// Raw volume files: a headerless array of point values, x fastest, native (little-endian)
// byte order, as many tools write them (e.g. `numpy.ndarray.tofile`, ParaView's raw export).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/field/grid_source.hpp"

namespace ldimesh {

// A volume read into memory and the grid block describing it (values point into `storage`).
struct RawVolume {
  std::vector<double> storage;  // the file's bytes, 8-byte aligned
  GridBlock block;
  double min_value = 0.0;
  double max_value = 0.0;
};

// Reads `path` as dims[0]·dims[1]·dims[2] values of `type`, placed at origin + index·spacing.
// The file size must match exactly; a mismatch, an unreadable file, dimensions below 2 or
// non-finite values give an error Status with the reason (and leave `out` unspecified).
Status read_raw_volume(const std::string& path, std::array<std::int64_t, 3> dims, ScalarType type,
                       glm::dvec3 origin, glm::dvec3 spacing, RawVolume& out);

}  // namespace ldimesh

// Shared by the benchmark programs: timing and the median of repeated runs.
#pragma once

#include <algorithm>
#include <vector>

#include "ldimesh/core/base/timing.hpp"

namespace ldimesh::bench {

using ldimesh::seconds_since;

// The median of `v` (the upper one of the middle two for an even count); `v` not empty.
inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace ldimesh::bench

// Wall-clock seconds for the per-stage timings the pipeline reports.
#pragma once

#include <chrono>

namespace ldimesh {

inline double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace ldimesh

// The element types of solver arrays that field sources read in place.
#pragma once

#include <cstddef>

namespace ldimesh {

enum class ScalarType { float32, float64 };

// Bytes per value of `type`.
inline std::size_t scalar_size(ScalarType type) {
  return type == ScalarType::float32 ? 4 : 8;
}

}  // namespace ldimesh

// Caps on the codecs' quantization errors computed from their bit budgets alone, for tests that
// check both the measured errors and the codecs' stated bounds (normal_error_bound,
// glb_normal_error_bound, glb_scalar_error_bound) against something the code under test did
// not compute. The caps are looser than the bounds (a few quantization steps) but still fail
// when a bound grows to cover a codec that lost precision.
#pragma once

#include <cmath>
#include <cstdint>

#include <gtest/gtest.h>
#include <glm/glm.hpp>

namespace ldimesh::testing {

// The angle between two (not necessarily unit) vectors, accurate near 0 (acos of the dot
// product is not: for float vectors it is off by ~5e-4 rad there).
inline double angle_between(glm::vec3 a, glm::vec3 b) {
  const glm::dvec3 u = glm::normalize(glm::dvec3(a)), v = glm::normalize(glm::dvec3(b));
  return std::atan2(glm::length(glm::cross(u, v)), glm::dot(u, v));
}

// Octahedral normals with `bits` per coordinate: the octahedron's square [−1, 1]² is cut into
// steps of 2 / (2^bits − 2); three steps of angle (in radians) cap any rounding of it.
inline double octahedral_angle_cap(int bits) {
  EXPECT_TRUE(bits >= 2 && bits <= 30) << bits << " normal bits";
  return 3.0 * 2.0 / double((std::uint64_t(1) << bits) - 2);
}

// A value in [0, 1] quantized to `bits` (at most 20: beyond, float arithmetic, not the step,
// bounds the error): one full step caps the rounding (half a step) and the float arithmetic
// around it.
inline double unit_interval_cap(int bits) {
  EXPECT_TRUE(bits >= 1 && bits <= 20) << bits << " scalar bits";
  return 1.0 / double((std::uint64_t(1) << bits) - 1);
}

}  // namespace ldimesh::testing

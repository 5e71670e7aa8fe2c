// Steps that look like what a job publishes, without running the pipeline or the Draco
// encoder: a valid glTF 2.0 binary container (header + JSON chunk, no meshes) whose bytes
// differ per step, and typed metadata. For the HTTP tests and ldimesh_make_steps.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh::testing {

// A GLB of 20 + ~60 + `padding` bytes holding `step` in its JSON.
inline std::vector<std::uint8_t> fake_glb(std::uint64_t step, std::size_t padding = 0) {
  std::string json = R"({"asset":{"version":"2.0"},"extras":{"step":)" + std::to_string(step) +
                     R"(,"pad":")" + std::string(padding, static_cast<char>('a' + step % 26)) +
                     "\"}}";
  while (json.size() % 4 != 0)
    json += ' ';  // chunks are 4-byte aligned
  std::vector<std::uint8_t> glb{'g', 'l', 'T', 'F'};
  const auto put32 = [&glb](std::uint32_t v) {
    for (int i = 0; i < 4; ++i)
      glb.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  };
  put32(2);
  put32(static_cast<std::uint32_t>(12 + 8 + json.size()));
  put32(static_cast<std::uint32_t>(json.size()));
  put32(0x4E4F534A);  // "JSON"
  glb.insert(glb.end(), json.begin(), json.end());
  return glb;
}

inline StepMetadata fake_metadata(std::uint64_t step) {
  StepMetadata m;
  m.step = step;
  m.time = 0.01 * static_cast<double>(step);
  m.isovalues = {0.5};
  m.triangles = 1000 + step;
  m.vertices = 500 + step;
  m.samples = 600 + step;
  m.quads = 500;
  m.views = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.resolution = 64;
  m.r = 0.5;
  m.seconds = {{"cast", 0.25}, {"mesh", 0.04}, {"glb", 0.1}};
  return m;
}

inline Snapshot fake_snapshot(std::uint64_t step, std::size_t padding = 0) {
  return make_snapshot(fake_metadata(step), fake_glb(step, padding));
}

}  // namespace ldimesh::testing

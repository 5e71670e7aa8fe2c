// `ldimesh distance`: Metro-style distances between two meshes (PLY or GLB), or from one to a
// built-in surface or a VTU file's exact isosurface.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace ldimesh::cli {

struct DistanceArgs {
  std::vector<std::string> files;  // A, or A and B
  std::string surface;
  std::string vtu, field;  // or the isosurface of a VTU file's field
  std::optional<double> isovalue;
  std::uint64_t samples = 0;
  int threads = 0;
  bool json = false;
};

// The options of `ldimesh distance` into `args`.
void add_distance_options(CLI::App& distance, DistanceArgs& args);

// Measures and prints (text or JSON). Returns the exit code; throws on failure.
int run_distance(const DistanceArgs& args);

}  // namespace ldimesh::cli

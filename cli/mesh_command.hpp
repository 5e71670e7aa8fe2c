// `ldimesh mesh` (the pipeline on a built-in surface, a raw volume or a VTU file, in one process
// or over MPI ranks) and `ldimesh surfaces`.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/transport/fragment_codec.hpp"
#include "ldimesh/transport/glb.hpp"

namespace ldimesh::cli {

struct MeshArgs {
  std::string surface;
  std::string grid;   // raw volume file
  std::string vtu;    // VTK XML unstructured grid (.vtu, .pvtu)
  std::string field;  // its point array
  // The field to colour by: a --vtu file's point array, or a raw volume of --grid's layout.
  std::string colour_by;
  std::vector<std::int64_t> dims;
  std::string type = "float32";
  std::vector<double> spacing{1.0, 1.0, 1.0};
  std::vector<double> origin{0.0, 0.0, 0.0};
  int res = 256;
  std::string views = "xyz";
  double r = 0.5;
  std::string out;
  bool quads = false;
  int threads = 0;
  bool json = false;
  int bricks = 32;
  std::string caster = "auto";
  int repeat = 1;
  std::optional<double> isovalue;
  double max_cost = ldimesh::MatchOptions{}.max_cost;
  bool lossless = false;
  std::string steps_dir;
  std::uint64_t step = 1;
  double time = 0.0;
  int depth_bits = ldimesh::FragmentEncoding{}.depth_bits;
  int normal_bits = ldimesh::FragmentEncoding{}.normal_bits;
  ldimesh::StepGlbSettings glb;
  ldimesh::RefinementOptions refinement;
  bool no_grow = false;
  bool merge = false;
  bool triangles = false;  // --tri, the default
};

// The options of `ldimesh mesh` into `args`.
void add_mesh_options(CLI::App& mesh, MeshArgs& args);

// `ldimesh mesh`: every rank of MPI_COMM_WORLD loads its part and casts it, the root meshes,
// writes and reports. Returns the exit code; throws on failure (the same on every rank).
int run_mesh(const MeshArgs& args);

// `ldimesh surfaces`: the built-in surfaces, their formulas, domains and isovalues.
int run_surfaces();

}  // namespace ldimesh::cli

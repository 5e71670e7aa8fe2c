// What `ldimesh mesh` reports on the root: its figures as text or as JSON (--json).
#pragma once

#include <cstddef>
#include <vector>

#include <nlohmann/json.hpp>

#include "ldimesh/transport/distributed.hpp"
#include "mesh_command.hpp"
#include "mesh_input.hpp"

namespace ldimesh::cli {

// One `ldimesh mesh` run: its input, the step's options and result (the last of --repeat), and
// its figures.
struct MeshRun {
  Input input;
  double iso = 0.0;
  std::vector<View> views;
  int ranks = 1, threads = 1;
  DistributedOptions options;
  DistributedResult step;
  nlohmann::json repeats = nlohmann::json::array();  // each run's seconds (--repeat)
  double r_used = 0.0;                               // the trimming's r (1 where merging)
  double load_seconds = 0.0, scene_seconds = 0.0, max_scene = 0.0, write_seconds = 0.0;
  std::size_t uncoloured = 0;  // vertices without a finite colour value

  std::size_t rays() const;         // of the views
  std::size_t refine_rays() const;  // §4's requests
};

void print_mesh_json(const MeshArgs& args, const MeshRun& run);
void print_mesh_text(const MeshArgs& args, const MeshRun& run);

}  // namespace ldimesh::cli

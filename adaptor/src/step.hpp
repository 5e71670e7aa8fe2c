// One in situ step's work, whichever thread does it: the collective half (every rank casts its
// blocks and reduces to the root), the root's meshing where it needs every rank's samples, and
// what goes from one thread to the next. Internal to the adaptor library.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <mpi.h>

#include "block.hpp"
#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/transport/distributed.hpp"
#include "options.hpp"

namespace ldimesh {

// One due step's work for the root's worker.
struct Job {
  std::uint64_t step = 0;
  double time = 0.0;
  std::vector<View> views;
  CastStep cast;  // the collective half's fragments (isovalue-major) and the others' pending ones
  // Meshed already, one per isovalue (refinement, or merging that projects: on the thread that made
  // the step's MPI calls, while every rank served samples); otherwise the worker meshes.
  std::optional<std::vector<MeshingResult>> meshed;
  std::map<std::string, double> seconds;
  std::uint64_t skipped_steps = 0;  // due steps dropped since the previous job was handed over
  std::uint64_t nonfinite_values = 0;
  bool merge = false;  // §5 merging (the same on every rank: the ranks serve its samples)
};

// This rank's casters of one step (one per block and isovalue) and the step's views: alive
// until the root has meshed, for it may ask every rank for samples.
struct StepCasters {
  std::vector<std::unique_ptr<RayCaster>> owned;
  StepBlocks blocks;
  std::vector<View> views;
  double tolerance = 0.0;
};

// The meshing of a step, merged (§5) or not.
MeshingOptions meshing_options(const AdaptorOptions& options, bool merge);

// The collective half of a due step over `comm` (cast_and_reduce): every rank binds and casts
// `blocks` and takes part in the reduction to the root, whose `job` gets the views, the
// fragments, the others' pending ones and the timings (all but "blocked"). A local failure
// (`local`, or one while binding) fails the step everywhere. The solver's thread runs it on
// the adaptor's communicator (synchronous path), the caster thread on its duplicate
// (background path).
Status collective_step(MPI_Comm comm, const AdaptorOptions& options,
                       const std::vector<Block>& blocks, std::optional<Box> domain, Status local,
                       Job& job, StepCasters& casters);

// The root half where meshing needs every rank's samples (refinement, merging that projects),
// collective over `comm`: the root meshes (mesh_step) while the other ranks serve from `casters`;
// the root's worker then only encodes and publishes. On the thread that made the step's MPI
// calls.
Status mesh_with_samples(MPI_Comm comm, const AdaptorOptions& options, const StepCasters& casters,
                         Job& job);

}  // namespace ldimesh

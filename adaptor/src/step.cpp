#include "step.hpp"

#include <algorithm>
#include <chrono>
#include <new>
#include <stdexcept>

#include "ldimesh/core/base/timing.hpp"

namespace ldimesh {
namespace {

// Whether the options inject `kind` into rank `rank`'s step `step` (testing only).
bool fault_here(const AdaptorOptions& options, int rank, const char* kind, std::uint64_t step) {
  return options.fault == kind && options.fault_step == step && options.fault_rank == rank;
}

// Binds a caster per block and isovalue into `casters`. The hits of an isovalue carry a colour
// where "colour_by" names a field for it, and then every block's.
Status bind_casters(const AdaptorOptions& options, int rank, const std::vector<Block>& blocks,
                    const Box& domain, StepCasters& casters) {
  casters.views = make_axis_views(domain, options.resolution, options.views);
  for (const View& v : casters.views)
    casters.tolerance =
        std::max(casters.tolerance, reduction_tolerance(options.encoding, v, domain.diagonal()));
  for (std::size_t i = 0; i < options.isovalues.size(); ++i) {
    const int f = options.surface_field.empty() ? -1 : options.surface_field[i];
    RayCasterOptions caster_options;
    caster_options.scalars = f >= 0;
    for (std::size_t k = 0; k < blocks.size(); ++k) {
      const Block& b = blocks[k];
      const auto which = [&] {
        return "colour_by: block " + std::to_string(k) + " of rank " + std::to_string(rank);
      };
      const FieldSource* source = b.source.get();
      if (f >= 0 && b.copyable()) {
        source = b.colours[std::size_t(f)].source.get();
        if (!source)
          return Status::invalid_argument(which() + " has no field named '" +
                                          options.colour_fields[std::size_t(f)] + "' (add_field)");
      } else if (f >= 0 && options.colour_fields.size() > 1) {
        return Status::invalid_argument(
            which() + " is a FieldSource, which has one colour field (bind_scalar), and " +
            std::to_string(options.colour_fields.size()) + " fields are named");
      }
      casters.owned.push_back(
          std::make_unique<RayCaster>(*source, options.isovalues[i], caster_options));
      if (caster_options.scalars && !casters.owned.back()->carries_scalars())
        return Status::invalid_argument(which() +
                                        " is a FieldSource without a colour field (bind_scalar)");
      casters.blocks[i].push_back(
          {casters.owned.back().get(),
           {b.owned ? *b.owned : element_box(b.source->bounds(), domain), domain}});
    }
  }
  return Status::ok();
}

}  // namespace

MeshingOptions meshing_options(const AdaptorOptions& options, bool merge) {
  MeshingOptions meshing;
  meshing.r = options.r;
  meshing.refinement.levels = options.refinement_levels;
  meshing.merging.enabled = merge;
  return meshing;
}

Status collective_step(MPI_Comm comm, const AdaptorOptions& options,
                       const std::vector<Block>& blocks, std::optional<Box> domain, Status local,
                       Job& job, StepCasters& casters) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  casters = {};
  casters.blocks.resize(options.isovalues.size());
  const auto bind_start = std::chrono::steady_clock::now();
  if (local && !domain) local = Status::invalid_argument("set_domain() was not called");
  if (local)
    local = guard("binding the blocks: ", [&] {
      if (fault_here(options, rank, "out_of_memory", job.step)) throw std::bad_alloc();
      if (fault_here(options, rank, "exception", job.step))
        throw std::logic_error("testing.fault: an injected exception");
      return bind_casters(options, rank, blocks, *domain, casters);
    });
  if (!local) {
    casters = {};
    casters.blocks.resize(options.isovalues.size());
  }
  ReductionFaults faults;
  faults.damage_sent_message = fault_here(options, rank, "corrupt_message", job.step);
  // The root combines what it receives on its worker (mesh_step), off the solver's path.
  LDIMESH_RETURN_IF_ERROR(cast_and_reduce(comm, casters.blocks, casters.views, options.encoding,
                                          casters.tolerance, local, true, job.cast,
                                          seconds_since(bind_start), faults));
  if (rank == 0) {
    job.views = casters.views;
    job.seconds = {{"cast", job.cast.seconds.cast},
                   {"encode", job.cast.seconds.encode},
                   {"reduce", job.cast.seconds.reduce}};
    job.nonfinite_values = job.cast.nonfinite_values;
  }
  return Status::ok();
}

Status mesh_with_samples(MPI_Comm comm, const AdaptorOptions& options, const StepCasters& casters,
                         Job& job) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  CastStep none;
  std::vector<MeshingResult> results;
  const Status s =
      mesh_step(comm, casters.blocks, casters.views, casters.tolerance,
                meshing_options(options, job.merge), rank == 0 ? job.cast : none, results);
  if (s && rank == 0) job.meshed = std::move(results);
  return s;
}

}  // namespace ldimesh

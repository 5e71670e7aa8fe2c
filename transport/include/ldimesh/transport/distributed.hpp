// The distributed pipeline: every rank ray casts its own subdomain, the fragments travel
// compressed to the root, the root meshes them (paper §3).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <mpi.h>

#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycaster.hpp"
#include "ldimesh/core/sample_source.hpp"
#include "ldimesh/transport/fragment_codec.hpp"
#include "ldimesh/transport/mpi_reduce.hpp"

namespace ldimesh {

struct DistributedOptions {
  FragmentEncoding encoding;
  MeshingOptions meshing;
};

// Seconds per stage of one step; cast and encode are the maxima over ranks (what the slowest
// rank spent), the others are the root's.
struct DistributedTimes {
  double cast = 0.0;
  double encode = 0.0;
  double reduce = 0.0;  // the root's wall time in the reduction (waiting included)
  double decode = 0.0;
  double mesh = 0.0;  // match + trim + assemble on the root
};

struct DistributedResult {
  MeshingResult meshing;  // on the root only
  std::vector<Ldi> ldis;  // on the root only: the full LDIs, one per view
  DistributedTimes seconds;
  std::uint64_t bytes_to_root = 0;  // bytes the root received
  std::uint64_t bytes_moved = 0;    // bytes sent by all ranks together
};

// The tolerance below which two samples of one pixel from different ranks are one root: the
// larger of 1e-9 of the domain diagonal and twice the depth quantization error.
double merge_tolerance(const FragmentEncoding& encoding, const View& view, double domain_diagonal);

// Collective over `comm` (rank 0 is the root). Every rank ray casts the part `sub` owns of
// each of `views` (the same views on every rank, derived from the global domain), the
// fragments are reduced to the root, which turns them into full LDIs and meshes them with
// options.meshing. Ranks with nothing to cast contribute empty fragments. Returns an error
// Status (on every rank) if a fragment failed to decode anywhere; the mesh is then not built.
Status mesh_distributed(MPI_Comm comm, const RayCaster& caster, const Subdomain& sub,
                        std::span<const View> views, const DistributedOptions& options,
                        DistributedResult& result);

// Extra samples by an MPI round trip (§4 (ii)). The root calls sample(); every other rank
// calls serve(), which answers the root's requests until the root calls finish(). A request
// (view index + image positions) is broadcast; every rank casts the rays' parts it owns
// (RayCaster::cast_points with its subdomain); the answers are gathered to the root and merged
// per ray (concatenated, sorted, duplicates merged), so the root gets what one process would.
class MpiSampleSource final : public SampleSource {
 public:
  // `caster` must outlive this object; `views` and `sub` as for mesh_distributed.
  MpiSampleSource(MPI_Comm comm, const RayCaster& caster, Subdomain sub, std::vector<View> views,
                  double tolerance);
  // Root only (collective with the other ranks' serve()).
  RayHitList sample(std::uint32_t view_index, std::span<const glm::dvec2> image_positions) override;
  // Root only: ends every rank's serve().
  void finish();
  // Every rank but the root: answers requests until finish().
  void serve();

 private:
  RayHitList answer(std::uint32_t view_index, std::span<const glm::dvec2> positions);
  MPI_Comm comm_;
  const RayCaster& caster_;
  Subdomain sub_;
  std::vector<View> views_;
  double tolerance_;
};

}  // namespace ldimesh

// The distributed pipeline: every rank ray casts its own subdomain, the fragments travel
// compressed to the root, the root meshes them (paper §3) and refines the meshes with extra
// samples that every rank casts in its subdomain (§4).
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
  double mesh = 0.0;  // match + trim + refine (its round trips included) + assemble on the root
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
// options.meshing. Ranks with nothing to cast contribute empty fragments. `options` must be the
// same on every rank.
//
// Without refinement (options.meshing.refinement.levels == 0) and without merging that projects
// (§5, options.meshing.merging enabled with project) the other ranks return as soon as the
// reduction is done. With either, the root meshes with an MpiSampleSource while every other rank
// serves its sample requests, so all ranks return when the mesh is built.
//
// Returns an error Status, on every rank, if a fragment failed to decode anywhere, or the
// refinement levels or the merging projection differ between ranks (the mesh is then not
// built), or, when the other ranks serve samples, if meshing failed on the root (the root's
// message; no rank is left waiting). Otherwise an exception from meshing (e.g. r outside
// [0, 1]) propagates on the root only.
Status mesh_distributed(MPI_Comm comm, const RayCaster& caster, const Subdomain& sub,
                        std::span<const View> views, const DistributedOptions& options,
                        DistributedResult& result);

// Extra samples by an MPI round trip (§4 (ii)). The root calls sample(); every other rank
// calls serve(), which answers the root's requests until the root calls finish(). One
// sample() call is one round trip, whatever the number of views: the root broadcasts a header
// (ray count) and all rays (view index and image position each); every rank casts the parts it
// owns of the rays (cast_sample_points with its subdomain); the answers are gathered to the
// root and merged per ray (concatenated, sorted by depth, hits closer than `tolerance` merged),
// so the root gets what one process would.
//
// Requests are checked on the root before anything is sent: an unknown view throws
// std::out_of_range, more than 715,827,882 rays std::invalid_argument, and the other ranks
// keep waiting for the next request. A rank that fails to answer (e.g. out of memory) sends
// its error instead; sample() then throws std::runtime_error naming the rank, after the round
// trip, so the ranks stay in step and serve() goes on. Every MPI call is made by the calling
// thread (MPI_THREAD_FUNNELED is enough); ranks of one job are assumed homogeneous (floats
// travel as raw bytes).
class MpiSampleSource final : public SampleSource {
 public:
  // `caster` must outlive this object; `views` and `sub` as for mesh_distributed; `tolerance`
  // as for the reduction (merge_tolerance).
  MpiSampleSource(MPI_Comm comm, const RayCaster& caster, Subdomain sub, std::vector<View> views,
                  double tolerance);
  // Root only (collective with the other ranks' serve()).
  RayHitList sample(std::span<const SamplePoint> points) override;
  // Root only: ends every rank's serve(). Call it exactly once, also when meshing failed.
  void finish();
  // Every rank but the root: answers requests until finish().
  void serve();

 private:
  // This rank's serialized answer: its hits of `points`, or the error that stopped it.
  std::vector<std::uint8_t> answer(std::span<const SamplePoint> points) const;
  // Every rank's hits of `points` (the request broadcast, the answers gathered).
  std::vector<RayHitList> ask_all(std::span<const SamplePoint> points);
  // Per ray, the hits of all answers by depth, those within tolerance of the previous one
  // dropped (a hit on a shared face, seen by both ranks).
  RayHitList merge_answers(const std::vector<RayHitList>& answers, std::size_t rays) const;
  MPI_Comm comm_;
  const RayCaster& caster_;
  Subdomain sub_;
  std::vector<View> views_;
  double tolerance_;
};

}  // namespace ldimesh

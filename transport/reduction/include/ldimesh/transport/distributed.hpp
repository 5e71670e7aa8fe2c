// The distributed pipeline: every rank ray casts its own subdomain, the fragments travel
// compressed to the root, the root meshes them (paper §3) and refines the meshes with extra
// samples that every rank casts in its subdomain (§4).
//
// Threads: every MPI call is made by the thread that calls the function (MPI_THREAD_FUNNELED is
// enough), and a rank runs one collective of `comm` at a time; casting and meshing use the
// TBB arena of the calling thread. Determinism: the root's mesh is the same for any number of
// ranks, any split of the domain into blocks and any thread count (each rank's samples are
// quantized as if received, hits are sorted with a total order). Errors are Status values,
// the same on every rank where a function is collective; nothing throws out of them but the
// MpiSampleSource calls named below.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <mpi.h>

#include "ldimesh/core/pipeline.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "ldimesh/core/raycast/sample_source.hpp"
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
double reduction_tolerance(const FragmentEncoding& encoding, const View& view,
                           double domain_diagonal);

// ---------------------------------------------------------------------------------------------
// One step of the method over MPI, in two halves. The CLI (mesh_distributed) and the in situ
// adaptor run the same functions:
//   collective half, every rank:  cast its blocks along the views → fragments → reduction
//                                 (cast_and_reduce)
//   root half:                    decode → §3 match and trim → §4 refinement and §5 merging,
//                                 with samples from every rank's blocks (mesh_step)

// One of this rank's blocks for one isovalue: its caster and the part of the domain it owns.
struct CastBlock {
  const RayCaster* caster = nullptr;
  Subdomain sub;
};

// This rank's blocks of a step, per isovalue: blocks[i] are cast for isovalue i (the same count
// of isovalues on every rank; a rank may have no blocks).
using StepBlocks = std::vector<std::vector<CastBlock>>;

// What the collective half gives the root (the other ranks: only `seconds.cast` and `encode`).
struct CastStep {
  // Isovalue-major: isovalue i, view v at i · views + v (their view_index likewise).
  std::vector<LdiFragment> fragments;
  PendingReduction pending;  // a deferred reduction's messages, combined by mesh_step
  DistributedTimes seconds;
  std::uint64_t bytes_to_root = 0;
  std::uint64_t bytes_moved = 0;       // all ranks' bytes sent together
  std::uint64_t nonfinite_values = 0;  // NaN/Inf values in all ranks' blocks (isovalue 0's)
};

// Whether meshing with these options asks every rank for samples (§4 refinement, or §5 merging
// that projects): then mesh_step is collective.
bool meshing_samples(const MeshingOptions& options);

// The collective half, on every rank of `comm` (rank 0 the root). Every rank casts each of its
// blocks along every view (a block's samples only where it owns the ray, the half-open rule of
// subdomain_segment) and combines its blocks' fragments per view; the fragments are reduced to
// the root (reduce_fragments with `tolerance`; with `defer`, the root's combining of what it
// received is left to mesh_step, off the collective part). A failed `local` status (this rank
// could not set up its blocks) or an exception while casting sends no fragments and fails the
// step on every rank: the failing rank returns its own status (an exception's by
// status_from_current_exception), the others other_rank. `views` and the number of isovalues
// must be the same on every rank. `bind_seconds` (this rank's time to bind its casters) is
// counted in seconds.cast; `faults` go to reduce_fragments (tests only).
Status cast_and_reduce(MPI_Comm comm, const StepBlocks& blocks, std::span<const View> views,
                       const FragmentEncoding& encoding, double tolerance, const Status& local,
                       bool defer, CastStep& step, double bind_seconds = 0.0,
                       const ReductionFaults& faults = {});

// The root half. On the root: combines what a deferred reduction left (finish_reduction), decodes
// each isovalue's LDIs and meshes them with `options` (mesh_ldis), results[i] for isovalue i (ldis,
// when given, gets the LDIs too). Where meshing_samples(options), every rank calls it: the root
// meshes with an MpiSampleSource over each isovalue's blocks while the other ranks serve it,
// and every rank returns the root's status. Otherwise only the root calls it: it is not
// collective and makes no MPI call (any thread may run it; `comm` is not used, and of `blocks`
// only the count of isovalues).
// Errors (a failed combination, meshing's exceptions) come back as a Status.
Status mesh_step(MPI_Comm comm, const StepBlocks& blocks, std::span<const View> views,
                 double tolerance, const MeshingOptions& options, CastStep& step,
                 std::vector<MeshingResult>& results,
                 std::vector<std::vector<Ldi>>* ldis = nullptr);

// The root half where meshing asks no rank for samples (meshing_samples(options) false): the
// root's meshing of mesh_step (the same code) for `isovalues` isovalues, with neither a
// communicator nor blocks — not collective, no MPI call, any one thread. invalid_argument where
// the options need samples.
Status mesh_on_root(std::size_t isovalues, std::span<const View> views,
                    const MeshingOptions& options, CastStep& step,
                    std::vector<MeshingResult>& results);

// Collective over `comm` (rank 0 is the root): one step of one caster over the subdomain `sub`
// it owns. Every rank ray casts the part `sub` owns of each of `views` (the same views on
// every rank, derived from the global domain), the fragments are reduced to the root, which
// turns them into full LDIs and meshes them with options.meshing. Ranks with nothing to cast
// contribute empty fragments. `options` must be the same on every rank.
//
// Without refinement (options.meshing.refinement.levels == 0) and without merging that projects
// (§5, options.meshing.merging enabled with project) the other ranks return as soon as the
// reduction is done. With either, the root meshes with an MpiSampleSource while every other rank
// serves its sample requests, so all ranks return when the mesh is built.
//
// Returns an error Status, on every rank, if a fragment failed to decode anywhere, or the
// refinement levels or the merging projection differ between ranks (the mesh is then not
// built), or, when the other ranks serve samples, if meshing failed on the root (the root's
// message; no rank is left waiting). Without samples, meshing's errors (e.g. r outside [0, 1])
// come back on the root only.
Status mesh_distributed(MPI_Comm comm, const RayCaster& caster, const Subdomain& sub,
                        std::span<const View> views, const DistributedOptions& options,
                        DistributedResult& result);

// Extra samples by an MPI round trip (§4 (ii)). The root calls sample(); every other rank
// calls serve(), which answers the root's requests until the root calls finish(). One
// sample() call is one round trip, whatever the number of views: the root broadcasts a header
// (ray count) and all rays (view index and image position each); every rank casts the parts it
// owns of the rays (cast_sample_points with its subdomain; a ray lying in a face plane two
// ranks share is cast by both); the answers are gathered to the root and combined per ray
// (concatenated, sorted by depth, each run of hits within `tolerance` of its first collapsed into
// the one whose normal faces the viewer most, as a RayCaster collapses the duplicates of its own
// primitives), so the root gets what one process would.
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
  // as for the reduction (reduction_tolerance).
  MpiSampleSource(MPI_Comm comm, const RayCaster& caster, Subdomain sub, std::vector<View> views,
                  double tolerance);
  // This rank's answers from several blocks (each cast where it owns the ray, their hits combined
  // per ray as the ranks' are); none: this rank answers without hits. Their casters must
  // outlive this object.
  MpiSampleSource(MPI_Comm comm, std::vector<CastBlock> blocks, std::vector<View> views,
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
  // This rank's hits of `points` from its blocks.
  RayHitList cast_here(std::span<const SamplePoint> points) const;
  MPI_Comm comm_;
  std::vector<CastBlock> blocks_;
  std::vector<View> views_;
  double tolerance_;
};

}  // namespace ldimesh

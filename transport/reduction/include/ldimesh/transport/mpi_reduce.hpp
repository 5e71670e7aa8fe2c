// Reducing the ranks' LDI fragments to the root over MPI.
#pragma once

#include <cstdint>
#include <vector>

#include <mpi.h>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/raycast/fragment.hpp"
#include "ldimesh/transport/fragment_codec.hpp"

namespace ldimesh {

struct ReductionStats {
  double encode_seconds = 0.0;   // this rank, encoding what it sends
  double decode_seconds = 0.0;   // this rank, decoding what it receives (and, on the root, last)
  double combine_seconds = 0.0;  // this rank, combining what it received
  double wall_seconds = 0.0;     // this rank, from entry to return
  std::uint64_t bytes_sent = 0;
  std::uint64_t bytes_received = 0;
  int messages_received = 0;
};

// How the reduction collapses the samples of one pixel that ranks found twice (combine_fragments):
// closer than `tolerance` in depth, the one kept_before chooses for the direction of the
// fragment's view, dirs[k] for fragments[k].
struct DuplicateRule {
  double tolerance = 0.0;
  std::vector<glm::vec3> dirs;
};

// What the root of a deferred reduction received but has not combined (see reduce_fragments).
struct PendingReduction {
  std::vector<std::vector<std::uint8_t>> messages;  // the root's children's, in combining order
  DuplicateRule rule;
};

// Faults a reduction injects on purpose, to test its receivers' validation on real damaged
// messages (the adaptor's `testing.fault` option). Off by default.
struct ReductionFaults {
  bool damage_sent_message = false;  // this rank's message leaves with its magic number broken
};

// Collective over `comm`. Every rank passes its fragments, one per view, in the same view
// order on all ranks. On `root` the result is the combined fragment of every view (samples of
// all ranks per pixel, sorted, duplicates collapsed by `rule`, whose dirs hold one direction per
// fragment, else invalid_argument); on the other ranks it is left empty. The reduction is a
// binomial tree: in round k a rank receives from the rank 2^k above it, decodes, combines and
// forwards one message to the rank below it, so the root receives ⌈log2 P⌉ messages whose total
// size is that of the combined data, not P of them. Combining decodes and re-encodes, which the
// codec keeps exact (re-encoding decoded data gives the same bytes). A fragment that does not
// decode makes the result an error Status on the rank that received it and on the root; no rank
// blocks.
//
// With `deferred` (used on the root; reset on every rank), the root receives its children's
// messages but does not decompress or combine them: they are returned in *deferred and the root's
// `fragments` hold its own (quantized) samples; finish_reduction later — on another thread, after
// the collective part — gives the fragments the reduction would have given, to the bit (the
// same combinations in the same order). Each message is checked when it arrives (its envelope, each
// fragment's frame and checksums, views equal to the root's: check_fragment), so what combining
// would reject fails the reduction as without `deferred`; finish_reduction can then fail only on a
// payload its encoder wrote inconsistently under a valid checksum.
//
// Errors: corrupt_input (a message that fails its checks or does not decode), invalid_argument
// (ranks disagree about the views, a message over 2 GiB), other_rank on the root for a failure
// below it. Threads: MPI is called from the calling thread only (MPI_THREAD_FUNNELED suffices);
// quantizing runs on TBB; the result is the same for any thread count.
Status reduce_fragments(MPI_Comm comm, int root, std::vector<LdiFragment>& fragments,
                        const FragmentEncoding& encoding, const DuplicateRule& rule,
                        ReductionStats& stats, PendingReduction* deferred = nullptr,
                        const ReductionFaults& faults = {});

// Decodes and combines the messages reduce_fragments deferred into `fragments` (the root's own,
// as it returned them); leaves `pending` empty. Not collective; any one thread (the root's
// worker), not concurrently on the same `pending` or `fragments`. Errors as reduce_fragments's.
Status finish_reduction(PendingReduction& pending, std::vector<LdiFragment>& fragments,
                        ReductionStats& stats);

}  // namespace ldimesh

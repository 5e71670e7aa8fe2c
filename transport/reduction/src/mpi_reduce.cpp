#include "ldimesh/transport/mpi_reduce.hpp"

#include <chrono>
#include <climits>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "ldimesh/core/base/timing.hpp"

namespace ldimesh {
namespace {

constexpr int kTag = 7301;
constexpr std::uint32_t kEnvelopeMagic = 0x4549444c;  // "LDIE"
constexpr std::uint32_t kUpstreamError = 1;

void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i)
    out.push_back(std::uint8_t(v >> (8 * i)));
}
void put_u64(std::vector<std::uint8_t>& out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i)
    out.push_back(std::uint8_t(v >> (8 * i)));
}
bool get_u32(std::span<const std::uint8_t> in, std::size_t& at, std::uint32_t& v) {
  if (in.size() - at < 4) return false;
  v = 0;
  for (int i = 0; i < 4; ++i)
    v |= std::uint32_t(in[at + i]) << (8 * i);
  at += 4;
  return true;
}
bool get_u64(std::span<const std::uint8_t> in, std::size_t& at, std::uint64_t& v) {
  if (in.size() - at < 8) return false;
  v = 0;
  for (int i = 0; i < 8; ++i)
    v |= std::uint64_t(in[at + i]) << (8 * i);
  at += 8;
  return true;
}

// One message up the tree: the sender's fragments (one per view), each encoded, and whether
// anything below it failed.
std::vector<std::uint8_t> pack(const std::vector<LdiFragment>& fragments,
                               const FragmentEncoding& encoding, bool upstream_error) {
  std::vector<std::uint8_t> out;
  put_u32(out, kEnvelopeMagic);
  put_u32(out, upstream_error ? kUpstreamError : 0);
  put_u32(out, std::uint32_t(fragments.size()));
  std::vector<std::vector<std::uint8_t>> encoded(fragments.size());
  tbb::parallel_for(std::size_t(0), fragments.size(),
                    [&](std::size_t v) { encoded[v] = encode_fragment(fragments[v], encoding); });
  for (const std::vector<std::uint8_t>& bytes : encoded) {
    put_u64(out, bytes.size());
    out.insert(out.end(), bytes.begin(), bytes.end());
  }
  return out;
}

// The envelope of a message: its flags and the bytes of each of its `views` fragments.
Status open_envelope(std::span<const std::uint8_t> in, std::size_t views,
                     std::vector<std::span<const std::uint8_t>>& parts, bool& upstream_error) {
  std::size_t at = 0;
  std::uint32_t magic = 0, flags = 0, count = 0;
  if (!get_u32(in, at, magic) || !get_u32(in, at, flags) || !get_u32(in, at, count))
    return Status::corrupt_input("reduction: truncated message");
  if (magic != kEnvelopeMagic) return Status::corrupt_input("reduction: not a fragment message");
  if (count != views)
    return Status::corrupt_input("reduction: message holds " + std::to_string(count) +
                                 " views, expected " + std::to_string(views));
  upstream_error = (flags & kUpstreamError) != 0;
  parts.clear();
  for (std::uint32_t k = 0; k < count; ++k) {
    std::uint64_t size = 0;
    if (!get_u64(in, at, size) || size > in.size() - at)
      return Status::corrupt_input("reduction: truncated message");
    parts.push_back(in.subspan(at, std::size_t(size)));
    at += std::size_t(size);
  }
  if (at != in.size()) return Status::corrupt_input("reduction: trailing bytes in message");
  return Status::ok();
}

Status unpack(std::span<const std::uint8_t> in, std::size_t views, std::vector<LdiFragment>& out,
              bool& upstream_error) {
  std::vector<std::span<const std::uint8_t>> parts;
  if (Status s = open_envelope(in, views, parts, upstream_error); !s) return s;
  out.resize(parts.size());
  for (std::size_t k = 0; k < parts.size(); ++k)
    if (Status s = decode_fragment(parts[k], out[k]); !s) return s;
  return Status::ok();
}

// What combine_message would reject, found without decompressing: the envelope, each fragment's
// frame and checksums, and views that differ from `fragments`' (as combine_fragments checks them).
Status check_message(std::span<const std::uint8_t> in, const std::vector<LdiFragment>& fragments,
                     bool& upstream_error) {
  std::vector<std::span<const std::uint8_t>> parts;
  if (Status s = open_envelope(in, fragments.size(), parts, upstream_error); !s) return s;
  for (std::size_t v = 0; v < parts.size(); ++v) {
    LdiFragment shape;
    if (Status s = check_fragment(parts[v], shape); !s) return s;
    const LdiFragment& own = fragments[v];
    if (shape.view != own.view || shape.pixel_count != own.pixel_count ||
        shape.depth_lo != own.depth_lo || shape.depth_hi != own.depth_hi)
      return Status::corrupt_input("reduction: combine_fragments: fragments of different views");
  }
  return Status::ok();
}

}  // namespace

namespace {

// Collective: sets every fragment's scalar range to the union over the ranks of their ranges
// and finite scalars (left unset where no rank has one). Ranks that disagree about the number
// of fragments leave them as they are (the reduction's envelope check then fails the step).
void agree_on_scalar_ranges(MPI_Comm comm, std::vector<LdiFragment>& fragments) {
  long long counts[2] = {(long long)fragments.size(), -(long long)fragments.size()};
  MPI_Allreduce(MPI_IN_PLACE, counts, 2, MPI_LONG_LONG, MPI_MAX, comm);
  if (counts[0] != -counts[1]) return;
  // lo and −hi per fragment, reduced by MIN; +∞ where unset.
  std::vector<double> ends(2 * fragments.size(), INFINITY);
  for (std::size_t v = 0; v < fragments.size(); ++v) {
    float lo, hi;
    fragment_scalar_range(fragments[v], lo, hi);
    if (std::isnan(lo)) continue;
    ends[2 * v] = lo;
    ends[2 * v + 1] = -double(hi);
  }
  MPI_Allreduce(MPI_IN_PLACE, ends.data(), int(ends.size()), MPI_DOUBLE, MPI_MIN, comm);
  for (std::size_t v = 0; v < fragments.size(); ++v) {
    if (!std::isfinite(ends[2 * v])) continue;
    fragments[v].scalar_lo = float(ends[2 * v]);
    fragments[v].scalar_hi = float(-ends[2 * v + 1]);
  }
}

// One round of the tree on the receiving side: decodes a child's message and combines it into
// `fragments`. A message that does not decode leaves `fragments` as they were and sets `status`.
void combine_message(std::span<const std::uint8_t> message, std::vector<LdiFragment>& fragments,
                     const DuplicateRule& rule, Status& status, bool& upstream_error,
                     ReductionStats& stats) {
  auto t = std::chrono::steady_clock::now();
  std::vector<LdiFragment> received;
  bool child_error = false;
  const Status unpacked = unpack(message, fragments.size(), received, child_error);
  stats.decode_seconds += seconds_since(t);
  if (!unpacked) {
    status = unpacked;
    return;
  }
  if (child_error) upstream_error = true;
  t = std::chrono::steady_clock::now();
  try {
    for (std::size_t v = 0; v < fragments.size(); ++v) {
      const LdiFragment pair[2] = {std::move(fragments[v]), std::move(received[v])};
      fragments[v] = combine_fragments(pair, rule.tolerance, rule.dirs[v]);
    }
  } catch (const std::invalid_argument& e) {  // ranks disagree about the views
    status = Status::invalid_argument(std::string("reduction: ") + e.what());
  }
  stats.combine_seconds += seconds_since(t);
}

}  // namespace

Status reduce_fragments(MPI_Comm comm, int root, std::vector<LdiFragment>& fragments,
                        const FragmentEncoding& encoding, const DuplicateRule& rule,
                        ReductionStats& stats, PendingReduction* deferred,
                        const ReductionFaults& faults) {
  const auto start = std::chrono::steady_clock::now();
  stats = {};
  if (rule.dirs.size() != fragments.size())
    return Status::invalid_argument("reduction: " + std::to_string(rule.dirs.size()) +
                                    " view directions for " + std::to_string(fragments.size()) +
                                    " fragments");
  if (deferred) *deferred = PendingReduction{{}, rule};
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const int vrank = (rank - root + size) % size;
  Status status = Status::ok();
  bool upstream_error = false;

  // The ranks agree on each view's scalar range (the union of their finite scalars): the lossy
  // codec quantizes a fragment's scalars over it, so that every rank, and every intermediate
  // rank that re-encodes a combination, puts a value on the same grid.
  agree_on_scalar_ranges(comm, fragments);

  // Quantize this rank's own samples first, as they would arrive from any other rank, so that
  // the result does not depend on which rank a sample came from (nor on the number of ranks).
  {
    const auto t = std::chrono::steady_clock::now();
    std::vector<Status> errors(fragments.size(), Status::ok());
    tbb::parallel_for(std::size_t(0), fragments.size(), [&](std::size_t v) {
      LdiFragment& f = fragments[v];
      try {
        const FragmentQuantizer quantizer = check_fragment_encodable(f, encoding);
        // The samples in parallel too: a rank has few views (three fragments on its threads).
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, f.depth.size(), 8192),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                            quantize_samples(f, quantizer, r.begin(), r.end());
                          });
        if (!encoding.lossless && !f.scalar.empty()) {
          f.scalar_lo = quantizer.scalar_lo;
          f.scalar_hi = quantizer.scalar_hi;
        }
      } catch (...) {
        // Never leave the collective: go on with the fragment emptied (its view kept), and
        // report the failure up the tree.
        errors[v] = status_from_current_exception("reduction: ");
        f.pixels.clear();
        f.counts.clear();
        f.depth.clear();
        f.normal.clear();
        f.scalar.clear();
      }
    });
    for (const Status& error : errors)
      if (!error) status = error;
    stats.encode_seconds += seconds_since(t);
  }

  for (int mask = 1; mask < size; mask <<= 1) {
    if (vrank & mask) {
      const int parent = ((vrank ^ mask) + root) % size;
      auto t = std::chrono::steady_clock::now();
      std::vector<std::uint8_t> message = pack(fragments, encoding, upstream_error || !status);
      if (faults.damage_sent_message && !message.empty()) message[0] ^= 0xFF;
      stats.encode_seconds += seconds_since(t);
      if (message.size() > std::size_t(INT_MAX)) {
        // Still send a (small) error message so that the parent does not wait forever.
        const std::vector<std::uint8_t> failed = pack({}, encoding, true);
        MPI_Send(failed.data(), int(failed.size()), MPI_BYTE, parent, kTag, comm);
        status = Status::invalid_argument("reduction: a message over 2 GiB is not supported");
      } else {
        MPI_Send(message.data(), int(message.size()), MPI_BYTE, parent, kTag, comm);
        stats.bytes_sent += message.size();
      }
      fragments.clear();
      break;
    }
    const int child_v = vrank | mask;
    if (child_v >= size) continue;
    const int child = (child_v + root) % size;
    MPI_Status probe;
    MPI_Probe(child, kTag, comm, &probe);
    int count = 0;
    MPI_Get_count(&probe, MPI_BYTE, &count);
    std::vector<std::uint8_t> message(std::size_t(std::max(count, 0)));
    MPI_Recv(message.data(), count, MPI_BYTE, child, kTag, comm, MPI_STATUS_IGNORE);
    stats.bytes_received += message.size();
    ++stats.messages_received;

    if (deferred && rank == root) {
      // Decoded and combined later (finish_reduction); checked now, so that a message combining
      // would reject fails the step here, as the plain reduction does.
      bool child_error = false;
      if (const Status checked = check_message(message, fragments, child_error); !checked) {
        status = checked;
        continue;
      }
      if (child_error) upstream_error = true;
      deferred->messages.push_back(std::move(message));
      continue;
    }
    combine_message(message, fragments, rule, status, upstream_error, stats);
  }
  stats.wall_seconds = seconds_since(start);
  if (status && upstream_error && rank == root)
    status = Status::other_rank("reduction: a fragment failed to decode on another rank");
  return status;
}

Status finish_reduction(PendingReduction& pending, std::vector<LdiFragment>& fragments,
                        ReductionStats& stats) {
  Status status = Status::ok();
  bool upstream_error = false;
  for (const std::vector<std::uint8_t>& message : pending.messages)
    combine_message(message, fragments, pending.rule, status, upstream_error, stats);
  pending.messages.clear();
  if (status && upstream_error)
    status = Status::other_rank("reduction: a fragment failed to decode on another rank");
  return status;
}

}  // namespace ldimesh

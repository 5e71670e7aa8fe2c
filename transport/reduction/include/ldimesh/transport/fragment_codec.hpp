// The wire format of LDI fragments: quantized, predicted and zstd-compressed, behind a
// versioned, checksummed header. The decoder is safe for untrusted input.
//
// Layout (docs/method.md, "LDI fragments on the wire"), all integers little-endian:
//
//   offset size  field
//        0    4  magic "LDIF"
//        4    1  format version (2)
//        5    1  flags: bit 0 lossless, bit 1 has_scalar
//        6    1  depth_bits (0..24 lossy, 0 lossless)
//        7    1  normal_bits (2..16 lossy, 0 lossless)
//        8    4  view index
//       12    8  pixel_count
//       20    8  depth_lo (IEEE 754 double)
//       28    8  depth_hi (IEEE 754 double)
//       36    8  listed pixels
//       44    8  samples
//       52    8  payload size before zstd
//       60    8  payload size after zstd (= bytes after the header)
//       68    4  CRC-32 of the compressed payload
//       72    4  CRC-32 of bytes 0..71
//       76       one zstd frame: pixel ids, counts, depths, normals, scalars (separate streams)
//
// Threads: every function is reentrant (no shared state; each call has its own zstd context),
// so ranks' threads may encode and decode at once.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/raycast/fragment.hpp"

namespace ldimesh {

struct FragmentEncoding {
  // Lossless: depths, normals and scalars as raw floats (for tests and comparisons).
  bool lossless = false;
  // Depth quantized to this many bits over the fragment's [depth_lo, depth_hi] (1..24). The
  // encoder uses fewer where a step would fall below two float spacings at the interval's
  // larger end (a finer step cannot be held by a float depth); the header records the bits used.
  int depth_bits = 20;
  // Normals octahedral-encoded with this many bits per coordinate (2..16).
  int normal_bits = 12;
  // Scalars (a colour field) quantized to this many bits over the fragment's range of finite
  // scalars (2..24; fewer where a step would fall below two float spacings; the bits used are
  // in the scalar stream). A non-finite scalar stays non-finite (NaN).
  int scalar_bits = 12;
  // zstd level, ZSTD_minCLevel()..ZSTD_maxCLevel(); not stored, the decoder does not need it.
  int zstd_level = 3;
};

// Encodes `fragment`. It must satisfy validate_fragment, have finite non-zero normals, a depth
// interval within ±1e30, at most 65536 samples per pixel and at most 2³¹ samples; throws
// std::invalid_argument otherwise or for out-of-range encoding settings (std::runtime_error
// should zstd itself fail, std::bad_alloc without memory). Lossy encoding clamps
// depths outside [depth_lo, depth_hi] to the interval and quantizes scalars (scalar_bits)
// over the fragment's scalar range widened to its finite scalars (the decoded fragment has
// that range); lossless encoding stores them bit-exactly.
// Deterministic, and idempotent: encoding the decoded fragment again with the same `encoding`
// gives the same bytes (so a rank may decode, merge and re-encode without drift).
std::vector<std::uint8_t> encode_fragment(const LdiFragment& fragment,
                                          const FragmentEncoding& encoding = {});

// `fragment` as decode_fragment(encode_fragment(fragment, encoding)) gives it back, without the
// encoding: the depths and normals quantized and reconstructed in place. Same requirements and
// exceptions as encode_fragment. A rank's own samples take this path (they need the values the
// other ranks' samples arrive with, not the bytes).
void quantize_fragment(LdiFragment& fragment, const FragmentEncoding& encoding = {});

// quantize_fragment in two steps, so that a caller can quantize a large fragment's samples in
// parallel: check_fragment_encodable throws as quantize_fragment does (and changes nothing)
// and returns what the samples' quantization needs of the whole fragment (its scalars' range);
// quantize_samples then quantizes samples [begin, end) alone (each sample on its own, so any
// split gives the same values).
struct FragmentQuantizer {
  FragmentEncoding encoding;
  int scalar_bits = 1;  // lossy scalars: the bits used over [scalar_lo, scalar_hi]
  float scalar_lo = 0.0f, scalar_hi = 0.0f;
};
FragmentQuantizer check_fragment_encodable(const LdiFragment& fragment,
                                           const FragmentEncoding& encoding);
void quantize_samples(LdiFragment& fragment, const FragmentQuantizer& quantizer, std::size_t begin,
                      std::size_t end);

// Decodes `bytes` into `out`. Validates the header, every size and count, the checksum and the
// decoded fragment's invariants before use: truncated, corrupted or hostile input returns an
// error Status ("fragment: ...": corrupt_input; out_of_memory should an allocation fail) and
// never reads out of bounds, never throws, and allocates
// at most a small multiple of what the zstd frame really holds, never what a header claims
// (zstd's own window buffer stays within its default limit of 2²⁷ bytes). On error `out` is
// left unchanged. Every fragment it accepts is accepted by encode_fragment.
Status decode_fragment(std::span<const std::uint8_t> bytes, LdiFragment& out);

// What decode_fragment checks before it decompresses — the header, every size, both checksums —
// without decompressing: `shape` gets the fragment's view, pixel count and depth interval (no
// samples). A fragment it accepts fails to decode only if its encoder wrote an inconsistent
// payload under a valid checksum.
Status check_fragment(std::span<const std::uint8_t> bytes, LdiFragment& shape);

// The largest depth error of `encoding` for a depth in [lo, hi]:
// (hi − lo) / (2·(2^b − 1)) + u, with b the depth bits the encoder uses and u the float
// spacing at max(|lo|, |hi|) (the decoded depth is a float); (hi − lo) + u when b = 0
// (hi − lo below two float spacings); 0 for lossless encoding. lo ≤ hi, both finite (a
// fragment's depth interval); other arguments give no meaningful bound.
double depth_error_bound(const FragmentEncoding& encoding, double lo, double hi);
// The largest error of a decoded finite scalar of a fragment whose finite scalars span [lo, hi]:
// (hi − lo) / (2·(2^b − 2)) + u, with b the scalar bits the encoder uses and u the float spacing
// at max(|lo|, |hi|); (hi − lo) + u when b = 1; 0 for lossless encoding.
double scalar_error_bound(const FragmentEncoding& encoding, double lo, double hi);
// The largest angle (radians) between a unit normal and its decoded value:
// 3·√2 / (2^n − 2) + 2⁻²², with n the normal bits; 0 for lossless encoding. The axes are
// encoded exactly.
double normal_error_bound(const FragmentEncoding& encoding);

}  // namespace ldimesh

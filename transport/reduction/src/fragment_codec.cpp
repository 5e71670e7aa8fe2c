// LDI fragment codec: header, streams and predictors as in docs/method.md ("LDI fragments on
// the wire"). The decoder trusts nothing: every size is checked against the header's counts
// and against the bytes really present before it is used.
#include "ldimesh/transport/fragment_codec.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>

#include <zstd.h>

#include "fragment_quantizers.hpp"

namespace ldimesh {
namespace {

using namespace fragment_quantizers;

constexpr std::array<std::uint8_t, 4> kMagic{'L', 'D', 'I', 'F'};
constexpr std::uint8_t kVersion = 2;  // 2: lossy scalars quantized (1: raw floats)
constexpr std::size_t kHeaderSize = 76;
constexpr std::size_t kHeaderCrcOffset = 72;
constexpr std::uint8_t kFlagLossless = 1;
constexpr std::uint8_t kFlagHasScalar = 2;
constexpr std::uint8_t kKnownFlags = kFlagLossless | kFlagHasScalar;

// Limits shared by encoder and decoder, so that every encoded fragment decodes. They bound
// what a header may claim; 65536 layers is far beyond any ray through a real isosurface.
constexpr std::uint64_t kMaxLayers = 65536;
constexpr std::uint64_t kMaxSamples = std::uint64_t(1) << 31;
constexpr std::uint64_t kMaxListedPixels = std::uint64_t(1) << 32;  // pixel ids are u32
// Keeps lo + q·step and its rounding to float far from float overflow.
constexpr double kMaxDepthMagnitude = 1e30;

// Fuzzing builds (libFuzzer's FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION convention, as zlib and
// libpng do) skip the checksum comparisons, so that mutated inputs reach the parsers behind
// them; the checksums are covered by the unit tests.
#ifdef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
constexpr bool kVerifyChecksums = false;
#else
constexpr bool kVerifyChecksums = true;
#endif

// Stream sizes per element (varint bytes): used to bound the payload size a header may claim.
// A pixel: id gap (u32, ≤ 5 bytes) and count (≤ 65536, ≤ 3 bytes). A lossy sample: depth
// residual zigzag(±(2²⁴ − 1)) ≤ 4 bytes, two normal residuals zigzag(±(2¹⁶ − 1)) ≤ 3 bytes.
constexpr std::uint64_t kMinPixelBytes = 2, kMaxPixelBytes = 8;
constexpr std::uint64_t kMinLossySampleBytes = 3, kMaxLossySampleBytes = 10;
constexpr std::uint64_t kLosslessSampleBytes = 16;
constexpr std::uint64_t kScalarBytes = 4;  // lossless: a raw float
// Lossy scalars: the stream's bits (1 byte) and float range (2 × 4 bytes), then a residual per
// sample, zigzag(±(2²⁴ − 1)) ≤ 4 bytes.
constexpr std::uint64_t kScalarRangeBytes = 9;
constexpr std::uint64_t kMinLossyScalarBytes = 1, kMaxLossyScalarBytes = 4;

// CRC-32 of IEEE 802.3 / ISO-HDLC (zlib, PNG): reflected polynomial 0xEDB88320, initial and
// final XOR 0xFFFFFFFF; table-driven byte at a time (Sarwate 1988, CACM 31(8)). Check value
// of "123456789": 0xCBF43926.
constexpr std::array<std::uint32_t, 256> make_crc_table() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k)
      c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    table[i] = c;
  }
  return table;
}
constexpr std::array<std::uint32_t, 256> kCrcTable = make_crc_table();

std::uint32_t crc32(std::span<const std::uint8_t> bytes) {
  std::uint32_t c = 0xFFFFFFFFu;
  for (std::uint8_t b : bytes)
    c = kCrcTable[(c ^ b) & 0xFFu] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

// ---- Bytes out --------------------------------------------------------------------------

void put_le(std::vector<std::uint8_t>& out, std::uint64_t value, int bytes) {
  for (int k = 0; k < bytes; ++k)
    out.push_back(std::uint8_t(value >> (8 * k)));
}

// LEB128: 7 bits per byte, low bits first, high bit set on all but the last byte.
void put_varint(std::vector<std::uint8_t>& out, std::uint64_t value) {
  while (value >= 0x80) {
    out.push_back(std::uint8_t(value | 0x80));
    value >>= 7;
  }
  out.push_back(std::uint8_t(value));
}

// Zigzag (as in Protocol Buffers): small residuals of either sign become small unsigned ints.
std::uint64_t zigzag(std::int64_t v) {
  return (std::uint64_t(v) << 1) ^ std::uint64_t(v >> 63);
}
std::int64_t unzigzag(std::uint64_t z) {
  return std::int64_t(z >> 1) ^ -std::int64_t(z & 1);
}

// ---- Bytes in: every read is bounds-checked; a failed read sets `failed` and returns 0. ----

struct Reader {
  std::span<const std::uint8_t> bytes;
  std::size_t pos = 0;
  bool failed = false;

  std::uint64_t le(int n) {
    if (failed || bytes.size() - pos < std::size_t(n)) {
      failed = true;
      return 0;
    }
    std::uint64_t v = 0;
    for (int k = 0; k < n; ++k)
      v |= std::uint64_t(bytes[pos + k]) << (8 * k);
    pos += std::size_t(n);
    return v;
  }

  // A varint of at most `max_value`; only the shortest encoding is accepted, so that a payload
  // has one spelling and decode → encode gives the same bytes.
  std::uint64_t varint(std::uint64_t max_value) {
    std::uint64_t v = 0;
    for (int shift = 0; shift < 64 && !failed; shift += 7) {
      if (pos >= bytes.size()) break;
      const std::uint8_t b = bytes[pos++];
      const std::uint64_t bits = std::uint64_t(b & 0x7F);
      if (shift > 0 && b == 0) break;      // overlong
      if (shift == 63 && bits > 1) break;  // beyond 64 bits
      v |= bits << shift;
      if (!(b & 0x80)) {
        if (v > max_value) break;
        return v;
      }
    }
    failed = true;
    return 0;
  }
};

// ---- Prediction -----------------------------------------------------------------------------

constexpr std::uint64_t kNoPredictor = ~std::uint64_t(0);

// Calls f(sample, predictor) for every sample in order. Sample j of a pixel is predicted from
// sample j of the previous listed pixel when that pixel has one (the same layer of the
// neighbouring ray: the same sheet of the surface), else from sample j − 1 of the same pixel,
// else from nothing (kNoPredictor). The predictor always precedes the sample.
template <class F>
void for_each_sample_with_predictor(std::span<const std::uint32_t> counts, F&& f) {
  std::uint64_t prev_begin = 0, prev_count = 0, begin = 0;
  for (std::uint32_t count : counts) {
    for (std::uint64_t j = 0; j < count; ++j) {
      const std::uint64_t s = begin + j;
      const std::uint64_t p = j < prev_count ? prev_begin + j : (j > 0 ? s - 1 : kNoPredictor);
      f(s, p);
    }
    prev_begin = begin;
    prev_count = count;
    begin += count;
  }
}

// Residuals of `values` against their predictors as zigzag varints.
void put_predicted(std::vector<std::uint8_t>& out, std::span<const std::uint32_t> counts,
                   std::span<const std::uint32_t> values) {
  for_each_sample_with_predictor(counts, [&](std::uint64_t s, std::uint64_t p) {
    const std::int64_t pred = p == kNoPredictor ? 0 : std::int64_t(values[p]);
    put_varint(out, zigzag(std::int64_t(values[s]) - pred));
  });
}

// The inverse of put_predicted; false if a residual is unreadable or leaves [0, max_value].
bool get_predicted(Reader& in, std::span<const std::uint32_t> counts, std::uint32_t max_value,
                   std::span<std::uint32_t> values) {
  const std::uint64_t max_zigzag = 2 * std::uint64_t(max_value);
  bool ok = true;
  for_each_sample_with_predictor(counts, [&](std::uint64_t s, std::uint64_t p) {
    if (!ok) return;
    const std::int64_t pred = p == kNoPredictor ? 0 : std::int64_t(values[p]);
    const std::int64_t v = pred + unzigzag(in.varint(max_zigzag));
    if (in.failed || v < 0 || v > std::int64_t(max_value)) {
      ok = false;
      return;
    }
    values[s] = std::uint32_t(v);
  });
  return ok;
}

// ---- Header ---------------------------------------------------------------------------------

struct Header {
  std::uint8_t version = kVersion;
  std::uint8_t flags = 0;
  std::uint8_t depth_bits = 0;
  std::uint8_t normal_bits = 0;
  std::uint32_t view = 0;
  std::uint64_t pixel_count = 0;
  double depth_lo = 0.0, depth_hi = 0.0;
  std::uint64_t listed_pixels = 0;
  std::uint64_t samples = 0;
  std::uint64_t payload_size = 0;
  std::uint64_t compressed_size = 0;
  std::uint32_t payload_crc = 0;

  bool lossless() const { return flags & kFlagLossless; }
  bool has_scalar() const { return flags & kFlagHasScalar; }
};

// Appends the header to `out` (empty), field by field, little-endian whatever the host (no
// memcpy of a struct: no padding, no host byte order in the format).
void put_header(std::vector<std::uint8_t>& out, const Header& h) {
  out.insert(out.end(), kMagic.begin(), kMagic.end());
  put_le(out, h.version, 1);
  put_le(out, h.flags, 1);
  put_le(out, h.depth_bits, 1);
  put_le(out, h.normal_bits, 1);
  put_le(out, h.view, 4);
  put_le(out, h.pixel_count, 8);
  put_le(out, std::bit_cast<std::uint64_t>(h.depth_lo), 8);
  put_le(out, std::bit_cast<std::uint64_t>(h.depth_hi), 8);
  put_le(out, h.listed_pixels, 8);
  put_le(out, h.samples, 8);
  put_le(out, h.payload_size, 8);
  put_le(out, h.compressed_size, 8);
  put_le(out, h.payload_crc, 4);
  put_le(out, crc32(std::span(out).first(kHeaderCrcOffset)), 4);
}

// Bounds on the payload size of a header's counts (the streams' element sizes above).
std::uint64_t min_payload_size(const Header& h) {
  const std::uint64_t scalar = !h.has_scalar() ? 0
                               : h.lossless()  ? kScalarBytes
                                               : kMinLossyScalarBytes;
  const std::uint64_t sample =
      (h.lossless() ? kLosslessSampleBytes : kMinLossySampleBytes) + scalar;
  const std::uint64_t range = h.has_scalar() && !h.lossless() ? kScalarRangeBytes : 0;
  return h.listed_pixels * kMinPixelBytes + h.samples * sample + range;
}
std::uint64_t max_payload_size(const Header& h) {
  const std::uint64_t scalar = !h.has_scalar() ? 0
                               : h.lossless()  ? kScalarBytes
                                               : kMaxLossyScalarBytes;
  const std::uint64_t sample =
      (h.lossless() ? kLosslessSampleBytes : kMaxLossySampleBytes) + scalar;
  const std::uint64_t range = h.has_scalar() && !h.lossless() ? kScalarRangeBytes : 0;
  return h.listed_pixels * kMaxPixelBytes + h.samples * sample + range;
}

void check_encoding(const FragmentEncoding& e) {
  if (e.depth_bits < 1 || e.depth_bits > 24)
    throw std::invalid_argument("encode_fragment: depth_bits must be in 1..24, not " +
                                std::to_string(e.depth_bits));
  if (e.normal_bits < 2 || e.normal_bits > 16)
    throw std::invalid_argument("encode_fragment: normal_bits must be in 2..16, not " +
                                std::to_string(e.normal_bits));
  if (e.scalar_bits < 2 || e.scalar_bits > 24)
    throw std::invalid_argument("encode_fragment: scalar_bits must be in 2..24, not " +
                                std::to_string(e.scalar_bits));
  if (e.zstd_level < ZSTD_minCLevel() || e.zstd_level > ZSTD_maxCLevel())
    throw std::invalid_argument("encode_fragment: zstd_level must be in " +
                                std::to_string(ZSTD_minCLevel()) + ".." +
                                std::to_string(ZSTD_maxCLevel()));
}

// ---- Decoding -------------------------------------------------------------------------------

Status fail(const char* what) {
  return Status::corrupt_input(std::string("fragment: ") + what);
}

Status read_header(std::span<const std::uint8_t> bytes, Header& h) {
  if (bytes.size() < kHeaderSize) return fail("truncated header");
  if (!std::equal(kMagic.begin(), kMagic.end(), bytes.begin()))
    return fail("not an LDI fragment (bad magic)");
  // The version comes before the checksum: a later version may lay out the header otherwise.
  if (bytes[4] != kVersion)
    return Status::corrupt_input("fragment: unsupported format version " +
                                 std::to_string(bytes[4]));
  Reader in{bytes.first(kHeaderSize), kMagic.size()};
  h.version = std::uint8_t(in.le(1));
  h.flags = std::uint8_t(in.le(1));
  h.depth_bits = std::uint8_t(in.le(1));
  h.normal_bits = std::uint8_t(in.le(1));
  h.view = std::uint32_t(in.le(4));
  h.pixel_count = in.le(8);
  h.depth_lo = std::bit_cast<double>(in.le(8));
  h.depth_hi = std::bit_cast<double>(in.le(8));
  h.listed_pixels = in.le(8);
  h.samples = in.le(8);
  h.payload_size = in.le(8);
  h.compressed_size = in.le(8);
  h.payload_crc = std::uint32_t(in.le(4));
  const std::uint32_t header_crc = std::uint32_t(in.le(4));
  if (in.failed) return fail("truncated header");  // unreachable: the size was checked
  if (kVerifyChecksums && header_crc != crc32(bytes.first(kHeaderCrcOffset)))
    return fail("header checksum mismatch");

  if (h.flags & ~kKnownFlags) return fail("unknown flags");
  if (h.lossless() ? (h.depth_bits != 0 || h.normal_bits != 0)
                   : (h.depth_bits > 24 || h.normal_bits < 2 || h.normal_bits > 16))
    return fail("invalid quantization bits");
  if (!std::isfinite(h.depth_lo) || !std::isfinite(h.depth_hi) || !(h.depth_lo <= h.depth_hi) ||
      std::abs(h.depth_lo) > kMaxDepthMagnitude || std::abs(h.depth_hi) > kMaxDepthMagnitude)
    return fail("invalid depth interval");
  if (h.listed_pixels > h.pixel_count || h.listed_pixels > kMaxListedPixels ||
      h.samples < h.listed_pixels || h.samples > kMaxSamples ||
      h.samples > h.listed_pixels * kMaxLayers)
    return fail("pixel and sample counts inconsistent");
  // Both bounds are below 2⁶⁴: samples ≤ 2³¹, pixels ≤ 2³².
  if (h.payload_size < min_payload_size(h) || h.payload_size > max_payload_size(h) ||
      h.compressed_size > ZSTD_compressBound(std::size_t(h.payload_size)))
    return fail("payload size inconsistent with the counts");
  return Status::ok();
}

// Decompresses one zstd frame of exactly `size` bytes. The buffer grows with what really comes
// out of the frame (doubling), so a frame that claims more than it holds costs no memory.
Status decompress(std::span<const std::uint8_t> frame, std::size_t size,
                  std::vector<std::uint8_t>& out) {
  if (ZSTD_getFrameContentSize(frame.data(), frame.size()) != size ||
      ZSTD_findFrameCompressedSize(frame.data(), frame.size()) != frame.size())
    return fail("invalid zstd frame");
  struct DctxFree {
    void operator()(ZSTD_DCtx* d) const { ZSTD_freeDCtx(d); }
  };
  const std::unique_ptr<ZSTD_DCtx, DctxFree> dctx(ZSTD_createDCtx());
  if (!dctx) throw std::bad_alloc();
  out.resize(std::min(size, std::max<std::size_t>(std::size_t(1) << 16, 8 * frame.size())));
  ZSTD_inBuffer in{frame.data(), frame.size(), 0};
  std::size_t produced = 0;
  while (true) {
    ZSTD_outBuffer o{out.data() + produced, out.size() - produced, 0};
    const std::size_t ret = ZSTD_decompressStream(dctx.get(), &o, &in);
    if (ZSTD_isError(ret)) return fail("corrupt compressed payload");
    produced += o.pos;
    if (ret == 0) break;  // frame complete
    if (produced == out.size()) {
      if (out.size() == size) {
        // Full: only the frame's end may remain (zstd may hold it back); anything else is more
        // data than the header says.
        std::uint8_t extra = 0;
        ZSTD_outBuffer probe{&extra, 1, 0};
        const std::size_t r = ZSTD_decompressStream(dctx.get(), &probe, &in);
        if (ZSTD_isError(r) || probe.pos != 0 || r != 0) return fail("corrupt compressed payload");
        break;
      }
      out.resize(std::min(size, 2 * out.size()));
    } else if (in.pos == in.size) {
      return fail("corrupt compressed payload");  // input used up, frame not complete
    }
  }
  if (produced != size || in.pos != in.size) return fail("corrupt compressed payload");
  return Status::ok();
}

Status decode_payload(std::span<const std::uint8_t> payload, const Header& h, LdiFragment& f) {
  Reader in{payload};
  f.view = h.view;
  f.pixel_count = h.pixel_count;
  f.depth_lo = h.depth_lo;
  f.depth_hi = h.depth_hi;
  const std::size_t pixels = std::size_t(h.listed_pixels), samples = std::size_t(h.samples);

  f.pixels.resize(pixels);
  std::uint64_t next = 0;  // smallest id the next pixel may have
  for (std::size_t k = 0; k < pixels; ++k) {
    const std::uint64_t id = next + in.varint(std::numeric_limits<std::uint32_t>::max());
    if (in.failed) return fail("invalid pixel id stream");
    if (id >= h.pixel_count || id > std::numeric_limits<std::uint32_t>::max())
      return fail("pixel id out of range");
    f.pixels[k] = std::uint32_t(id);
    next = id + 1;  // gaps are stored minus one: ids strictly increase by construction
  }
  f.counts.resize(pixels);
  std::uint64_t total = 0;
  for (std::size_t k = 0; k < pixels; ++k) {
    const std::uint64_t c = in.varint(kMaxLayers);
    if (in.failed || c == 0) return fail("invalid sample count");
    f.counts[k] = std::uint32_t(c);
    total += c;
  }
  if (total != h.samples) return fail("counts do not sum to the samples");

  f.depth.resize(samples);
  f.normal.resize(samples);
  if (h.lossless()) {
    for_each_sample_with_predictor(f.counts, [&](std::uint64_t s, std::uint64_t p) {
      const std::uint32_t pred = p == kNoPredictor ? 0 : std::bit_cast<std::uint32_t>(f.depth[p]);
      f.depth[s] = std::bit_cast<float>(std::uint32_t(in.le(4)) ^ pred);
    });
    for (int a = 0; a < 3; ++a)
      for (std::size_t s = 0; s < samples; ++s)
        f.normal[s][a] = std::bit_cast<float>(std::uint32_t(in.le(4)));
    if (in.failed) return fail("truncated payload");
    for (const glm::vec3& n : f.normal)
      if (!std::isfinite(n.x) || !std::isfinite(n.y) || !std::isfinite(n.z) ||
          (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f))
        return fail("invalid normal");
  } else {
    std::vector<std::uint32_t> q(samples), v(samples);
    const DepthQuantizer dq(h.depth_bits, h.depth_lo, h.depth_hi);
    if (!get_predicted(in, f.counts, dq.max_q, q)) return fail("invalid depth residual");
    for (std::size_t s = 0; s < samples; ++s)
      f.depth[s] = dq.dequantize(q[s]);
    const NormalQuantizer nq(h.normal_bits);
    if (!get_predicted(in, f.counts, nq.max_u, q) || !get_predicted(in, f.counts, nq.max_u, v))
      return fail("invalid normal residual");
    for (std::size_t s = 0; s < samples; ++s)
      f.normal[s] = nq.dequantize(q[s], v[s]);
  }
  f.scalar.clear();
  if (h.has_scalar() && h.lossless()) {
    f.scalar.resize(samples);
    for (float& x : f.scalar)
      x = std::bit_cast<float>(std::uint32_t(in.le(4)));
    if (in.failed) return fail("truncated payload");
  } else if (h.has_scalar()) {
    const int bits = int(in.le(1));
    const float lo = std::bit_cast<float>(std::uint32_t(in.le(4)));
    const float hi = std::bit_cast<float>(std::uint32_t(in.le(4)));
    if (in.failed) return fail("truncated payload");
    if (bits < 1 || bits > 24 || !std::isfinite(lo) || !std::isfinite(hi) || !(lo <= hi) ||
        (bits == 1 && lo != hi) || std::signbit(lo) != (lo < 0.0f) ||
        std::signbit(hi) != (hi < 0.0f))
      return fail("invalid scalar range");
    const ScalarQuantizer sq(bits, lo, hi);
    std::vector<std::uint32_t> q(samples);
    if (!get_predicted(in, f.counts, sq.max_code(), q)) return fail("invalid scalar residual");
    f.scalar.resize(samples);
    for (std::size_t s = 0; s < samples; ++s)
      f.scalar[s] = sq.dequantize(q[s]);
    f.scalar_lo = lo;
    f.scalar_hi = hi;
  }
  if (in.pos != payload.size()) return fail("payload longer than its streams");
  return validate_fragment(f);
}

// The header and the frame around the payload: sizes and both checksums.
Status check_frame(std::span<const std::uint8_t> bytes, Header& h) {
  if (Status s = read_header(bytes, h); !s) return s;
  const std::span<const std::uint8_t> frame = bytes.subspan(kHeaderSize);
  if (frame.size() < h.compressed_size) return fail("truncated payload");
  if (frame.size() > h.compressed_size) return fail("trailing bytes after the payload");
  if (kVerifyChecksums && crc32(frame) != h.payload_crc) return fail("payload checksum mismatch");
  return Status::ok();
}

Status decode(std::span<const std::uint8_t> bytes, LdiFragment& out) {
  Header h;
  if (Status s = check_frame(bytes, h); !s) return s;
  const std::span<const std::uint8_t> frame = bytes.subspan(kHeaderSize);
  std::vector<std::uint8_t> payload;
  if (Status s = decompress(frame, std::size_t(h.payload_size), payload); !s) return s;
  LdiFragment f;
  if (Status s = decode_payload(payload, h, f); !s) return s;
  out = std::move(f);
  return Status::ok();
}

// What encode_fragment requires of a fragment; throws std::invalid_argument otherwise.
void check_encodable(const LdiFragment& f, const FragmentEncoding& e) {
  check_encoding(e);
  if (Status s = validate_fragment(f); !s)
    throw std::invalid_argument("encode_fragment: " + s.message());
  if (std::abs(f.depth_lo) > kMaxDepthMagnitude || std::abs(f.depth_hi) > kMaxDepthMagnitude)
    throw std::invalid_argument("encode_fragment: depth interval beyond ±1e30");
  if (f.sample_count() > kMaxSamples)
    throw std::invalid_argument("encode_fragment: more than 2^31 samples");
  for (std::uint32_t c : f.counts)
    if (c > kMaxLayers)
      throw std::invalid_argument("encode_fragment: a pixel with more than 65536 samples");
  for (const glm::vec3& n : f.normal)
    if (!std::isfinite(n.x) || !std::isfinite(n.y) || !std::isfinite(n.z) ||
        (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f))
      throw std::invalid_argument("encode_fragment: a normal is zero or not finite");
}

}  // namespace

FragmentQuantizer check_fragment_encodable(const LdiFragment& f, const FragmentEncoding& e) {
  check_encodable(f, e);
  FragmentQuantizer q;
  q.encoding = e;
  if (!e.lossless && !f.scalar.empty()) {
    const ScalarRange r = scalar_range(f, e.scalar_bits);
    q.scalar_bits = r.bits;
    q.scalar_lo = r.lo;
    q.scalar_hi = r.hi;
  }
  return q;
}

void quantize_samples(LdiFragment& f, const FragmentQuantizer& quantizer, std::size_t begin,
                      std::size_t end) {
  const FragmentEncoding& e = quantizer.encoding;
  if (e.lossless) return;
  end = std::min(end, f.depth.size());
  // The encoder's quantizers and the decoder's reconstruction; prediction and zstd are
  // lossless, so this is decode_fragment(encode_fragment(f)).
  const DepthQuantizer dq(effective_depth_bits(e.depth_bits, f.depth_lo, f.depth_hi), f.depth_lo,
                          f.depth_hi);
  const NormalQuantizer nq(e.normal_bits);
  for (std::size_t s = begin; s < end; ++s) {
    f.depth[s] = dq.dequantize(dq.quantize(f.depth[s]));
    std::uint32_t u = 0, v = 0;
    nq.quantize(f.normal[s], u, v);
    f.normal[s] = nq.dequantize(u, v);
  }
  if (f.scalar.empty()) return;
  const ScalarQuantizer sq(quantizer.scalar_bits, quantizer.scalar_lo, quantizer.scalar_hi);
  for (std::size_t s = begin; s < end; ++s)
    f.scalar[s] = sq.dequantize(sq.quantize(f.scalar[s]));
}

void quantize_fragment(LdiFragment& f, const FragmentEncoding& e) {
  const FragmentQuantizer quantizer = check_fragment_encodable(f, e);
  quantize_samples(f, quantizer, 0, f.depth.size());
  if (!e.lossless && !f.scalar.empty()) {
    f.scalar_lo = quantizer.scalar_lo;
    f.scalar_hi = quantizer.scalar_hi;
  }
}

std::vector<std::uint8_t> encode_fragment(const LdiFragment& f, const FragmentEncoding& e) {
  const FragmentQuantizer quantizer = check_fragment_encodable(f, e);

  Header h;
  h.flags =
      std::uint8_t((e.lossless ? kFlagLossless : 0) | (f.scalar.empty() ? 0 : kFlagHasScalar));
  h.depth_bits =
      e.lossless ? 0 : std::uint8_t(effective_depth_bits(e.depth_bits, f.depth_lo, f.depth_hi));
  h.normal_bits = e.lossless ? 0 : std::uint8_t(e.normal_bits);
  h.view = f.view;
  h.pixel_count = f.pixel_count;
  h.depth_lo = f.depth_lo;
  h.depth_hi = f.depth_hi;
  h.listed_pixels = f.pixels.size();
  h.samples = f.sample_count();

  // Separate streams, so that zstd sees similar bytes together.
  const std::size_t n = f.sample_count();
  std::vector<std::uint8_t> payload;
  payload.reserve(std::size_t(max_payload_size(h)) / 2);
  std::uint32_t next = 0;
  for (std::uint32_t id : f.pixels) {
    put_varint(payload, id - next);  // first id, then gaps − 1
    next = id + 1;
  }
  for (std::uint32_t c : f.counts)
    put_varint(payload, c);
  if (e.lossless) {
    // Depth bits XOR those of the predicting sample: equal sign, exponent and leading mantissa
    // bits become zero bytes that zstd removes.
    for_each_sample_with_predictor(f.counts, [&](std::uint64_t s, std::uint64_t p) {
      const std::uint32_t pred = p == kNoPredictor ? 0 : std::bit_cast<std::uint32_t>(f.depth[p]);
      put_le(payload, std::bit_cast<std::uint32_t>(f.depth[s]) ^ pred, 4);
    });
    for (int a = 0; a < 3; ++a)
      for (std::size_t s = 0; s < n; ++s)
        put_le(payload, std::bit_cast<std::uint32_t>(f.normal[s][a]), 4);
  } else {
    std::vector<std::uint32_t> q(n), v(n);
    const DepthQuantizer dq(h.depth_bits, f.depth_lo, f.depth_hi);
    for (std::size_t s = 0; s < n; ++s)
      q[s] = dq.quantize(f.depth[s]);
    put_predicted(payload, f.counts, q);
    const NormalQuantizer nq(h.normal_bits);
    for (std::size_t s = 0; s < n; ++s)
      nq.quantize(f.normal[s], q[s], v[s]);
    put_predicted(payload, f.counts, q);
    put_predicted(payload, f.counts, v);
  }
  if (e.lossless) {
    for (float x : f.scalar)
      put_le(payload, std::bit_cast<std::uint32_t>(x), 4);
  } else if (!f.scalar.empty()) {
    put_le(payload, std::uint64_t(quantizer.scalar_bits), 1);
    put_le(payload, std::bit_cast<std::uint32_t>(quantizer.scalar_lo), 4);
    put_le(payload, std::bit_cast<std::uint32_t>(quantizer.scalar_hi), 4);
    const ScalarQuantizer sq(quantizer.scalar_bits, quantizer.scalar_lo, quantizer.scalar_hi);
    std::vector<std::uint32_t> q(n);
    for (std::size_t s = 0; s < n; ++s)
      q[s] = sq.quantize(f.scalar[s]);
    put_predicted(payload, f.counts, q);
  }
  h.payload_size = payload.size();

  std::vector<std::uint8_t> out;
  std::vector<std::uint8_t> frame(ZSTD_compressBound(payload.size()));
  const std::size_t compressed =
      ZSTD_compress(frame.data(), frame.size(), payload.data(), payload.size(), e.zstd_level);
  if (ZSTD_isError(compressed))
    throw std::runtime_error(std::string("encode_fragment: zstd: ") +
                             ZSTD_getErrorName(compressed));
  frame.resize(compressed);
  h.compressed_size = compressed;
  h.payload_crc = crc32(frame);
  out.reserve(kHeaderSize + compressed);
  put_header(out, h);
  out.insert(out.end(), frame.begin(), frame.end());
  return out;
}

Status check_fragment(std::span<const std::uint8_t> bytes, LdiFragment& shape) {
  Header h;
  if (Status s = check_frame(bytes, h); !s) return s;
  shape = LdiFragment{};
  shape.view = h.view;
  shape.pixel_count = h.pixel_count;
  shape.depth_lo = h.depth_lo;
  shape.depth_hi = h.depth_hi;
  return Status::ok();
}

Status decode_fragment(std::span<const std::uint8_t> bytes, LdiFragment& out) {
  // Never throws into the caller (an MPI progress loop, the adaptor's C boundary).
  try {
    return decode(bytes, out);
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory("fragment: out of memory while decoding");
  } catch (const std::exception& e) {
    return Status::corrupt_input(std::string("fragment: ") + e.what());
  }
}

double depth_error_bound(const FragmentEncoding& e, double lo, double hi) {
  if (e.lossless) return 0.0;
  const int bits = effective_depth_bits(e.depth_bits, lo, hi);
  const double spacing = float_spacing_at(lo, hi);
  if (bits == 0) return (hi - lo) + spacing;
  return (hi - lo) / (2.0 * double((std::uint32_t(1) << bits) - 1)) + spacing;
}

double scalar_error_bound(const FragmentEncoding& e, double lo, double hi) {
  if (e.lossless) return 0.0;
  const int bits = effective_scalar_bits(e.scalar_bits, lo, hi);
  const double spacing = float_spacing_at(lo, hi);
  if (bits == 1) return (hi - lo) + spacing;
  return (hi - lo) / (2.0 * double((std::uint32_t(1) << bits) - 2)) + spacing;
}

double normal_error_bound(const FragmentEncoding& e) {
  if (e.lossless) return 0.0;
  // Rounding moves p by |δp|∞ ≤ e = 1/(2^n − 2) (half a step of 2/(2^n − 2)). Each face of
  // the octahedron is affine in p with |δz| = |δx ± δy|, so the octahedron point moves by at
  // most √6·e, and it lies at least 1/√3 from the origin: an angle of at most 3√2·e. 2⁻²²
  // covers the float rounding of the decoded unit vector.
  return 3.0 * std::sqrt(2.0) / double((std::uint32_t(1) << e.normal_bits) - 2) +
         std::ldexp(1.0, -22);
}

}  // namespace ldimesh

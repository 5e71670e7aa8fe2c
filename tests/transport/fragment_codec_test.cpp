#include "ldimesh/transport/fragment_codec.hpp"

#include <atomic>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/raycast/raycaster.hpp"
#include "support/quantization_caps.hpp"

// The largest single allocation through operator new, so that a test can tell that a hostile
// header was rejected before the decoder allocated what it claims.
namespace {
std::atomic<std::size_t> g_largest_allocation{0};
}  // namespace

void* operator new(std::size_t size) {
  std::size_t seen = g_largest_allocation.load(std::memory_order_relaxed);
  while (size > seen && !g_largest_allocation.compare_exchange_weak(seen, size)) {
  }
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
// Not inlined: GCC would otherwise see free() on a pointer from operator new and warn.
[[gnu::noinline]] void operator delete(void* p) noexcept {
  std::free(p);
}
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
// The nothrow forms too (libdraco uses them), so that every pair matches under sanitizers.
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  return std::malloc(size ? size : 1);
}
[[gnu::noinline]] void operator delete(void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}

namespace ldimesh {
namespace {

using Bytes = std::vector<std::uint8_t>;

// ---- Fragments ------------------------------------------------------------------------------

// The fragments of the three axis views of built-in surface `name` at `res`.
std::vector<LdiFragment> cast_fragments(const char* name, int res) {
  const SurfaceInfo* s = find_surface(name);
  const auto source = make_surface_source(name);
  const RayCaster caster(*source, s->isovalue);
  std::vector<LdiFragment> out;
  const std::vector<View> views = make_axis_views(s->domain, res);
  for (std::size_t k = 0; k < views.size(); ++k)
    out.push_back(fragment_from_ldi(caster.cast(views[k]), std::uint32_t(k)));
  return out;
}

const std::vector<LdiFragment>& torus_fragments() {
  static const std::vector<LdiFragment> f = cast_fragments("torus", 128);
  return f;
}

glm::vec3 unit(float x, float y, float z) {
  return glm::normalize(glm::vec3(x, y, z));
}

// Normals where octahedral encoding is delicate: the axes (octahedron vertices), the equator
// fold, the square's edges and corners (lower half), signed zeros, just off an edge.
std::vector<glm::vec3> special_normals() {
  return {{1, 0, 0},
          {-1, 0, 0},
          {0, 1, 0},
          {0, -1, 0},
          {0, 0, 1},
          {0, 0, -1},
          unit(1, 1, 0),
          unit(-1, 1, 0),
          unit(1, 0, -1),
          unit(-1, 0, -1),
          unit(0, 1, -1),
          unit(0, -1, -1),
          unit(1, 1, -1),
          unit(-1, -1, -1),
          unit(1, 1, 1),
          unit(0.3f, -1e-7f, -0.7f),
          unit(-1e-7f, 0.3f, -0.7f),
          {-0.0f, 0.6f, -0.8f},
          {0.6f, -0.0f, -0.8f},
          {-0.0f, -0.0f, -1.0f},
          {3.0f, 4.0f, 0.0f},  // not unit: only the direction counts
          unit(0.2f, 0.3f, -1e-8f)};
}

// Hand-made: pixel ids 0 and pixel_count − 1, one sample, a pixel with 64 layers (with equal
// depths), depths exactly lo and hi, every special normal, scalars that only bits can keep.
LdiFragment edge_case_fragment(bool with_scalar) {
  LdiFragment f;
  f.view = 2;
  f.pixel_count = 1000;
  f.depth_lo = -0.5;
  f.depth_hi = 2.5;
  const float lo = -0.5f, hi = 2.5f;
  f.pixels = {0, 1, 500, 998, 999};
  f.counts = {1, 2, 64, 1, 3};
  f.depth = {lo, lo, hi};
  for (int k = 0; k < 64; ++k)
    f.depth.push_back(k == 0 ? lo : k == 63 ? hi : lo + 3.0f * float(k / 2 * 2) / 63.0f);
  f.depth.insert(f.depth.end(), {1.25f, 0.1f, 0.2f, hi});
  const std::vector<glm::vec3> special = special_normals();
  for (std::size_t s = 0; s < f.depth.size(); ++s)
    f.normal.push_back(special[s % special.size()]);
  if (with_scalar) {
    const float odd[] = {std::nanf(""), -0.0f, INFINITY, 1e-40f, -3.5f, 7.0f};
    for (std::size_t s = 0; s < f.depth.size(); ++s)
      f.scalar.push_back(odd[s % 6]);
  }
  return f;
}

// One sample per pixel with the given normals (depth 0 in [0, 1]).
LdiFragment normals_fragment(const std::vector<glm::vec3>& normals) {
  LdiFragment f;
  f.pixel_count = normals.size();
  f.depth_hi = 1.0;
  for (std::size_t k = 0; k < normals.size(); ++k) {
    f.pixels.push_back(std::uint32_t(k));
    f.counts.push_back(1);
  }
  f.depth.assign(normals.size(), 0.0f);
  f.normal = normals;
  return f;
}

// ---- Checks ---------------------------------------------------------------------------------

LdiFragment decoded(const Bytes& bytes) {
  LdiFragment f;
  const Status s = decode_fragment(bytes, f);
  EXPECT_TRUE(s) << s.message();
  return f;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

using testing::angle_between;
using testing::octahedral_angle_cap;
using testing::unit_interval_cap;

void expect_same_layout(const LdiFragment& a, const LdiFragment& b) {
  EXPECT_EQ(a.view, b.view);
  EXPECT_EQ(a.pixel_count, b.pixel_count);
  EXPECT_EQ(a.depth_lo, b.depth_lo);
  EXPECT_EQ(a.depth_hi, b.depth_hi);
  EXPECT_EQ(a.pixels, b.pixels);
  EXPECT_EQ(a.counts, b.counts);
  EXPECT_EQ(a.scalar.size(), b.scalar.size());
}

void expect_exact(const LdiFragment& a, const LdiFragment& b) {
  expect_same_layout(a, b);
  EXPECT_TRUE(same_bits(a.depth, b.depth));
  EXPECT_TRUE(same_bits(a.normal, b.normal));
  EXPECT_TRUE(same_bits(a.scalar, b.scalar));
}

// Every decoded depth and normal of `b` within the stated bounds of the original `a`.
void expect_within_bounds(const LdiFragment& a, const LdiFragment& b, const FragmentEncoding& e) {
  expect_same_layout(a, b);
  ASSERT_EQ(a.sample_count(), b.sample_count());
  const double depth_bound = depth_error_bound(e, a.depth_lo, a.depth_hi);
  const double normal_bound = normal_error_bound(e);
  double depth_err = 0.0, normal_err = 0.0;
  for (std::size_t s = 0; s < a.sample_count(); ++s) {
    depth_err = std::max(depth_err, std::abs(double(a.depth[s]) - double(b.depth[s])));
    normal_err = std::max(normal_err, angle_between(a.normal[s], b.normal[s]));
    EXPECT_NEAR(glm::length(b.normal[s]), 1.0f, 1e-6f);
  }
  EXPECT_LE(depth_err, depth_bound);
  EXPECT_LE(normal_err, normal_bound);
  if (!e.lossless) {  // the stated bound itself, against the bit budget
    EXPECT_LE(normal_bound, octahedral_angle_cap(e.normal_bits));
    EXPECT_LE(normal_err, octahedral_angle_cap(e.normal_bits));
  }
  // Scalars: non-finite ones stay non-finite (lossless: the same bits), finite ones within the
  // stated bound over the range of the finite ones; and that bound within a cap from the bit
  // budget: one step of scalar_bits over the range, plus the float spacing there.
  ASSERT_EQ(a.scalar.size(), b.scalar.size());
  double lo = INFINITY, hi = -INFINITY, scalar_err = 0.0;
  for (float x : a.scalar)
    if (std::isfinite(x)) lo = std::min(lo, double(x)), hi = std::max(hi, double(x));
  std::size_t lost = 0;  // finite scalars decoded as non-finite (a NaN would hide in a max)
  for (std::size_t s = 0; s < a.scalar.size(); ++s) {
    if (!std::isfinite(a.scalar[s])) {
      EXPECT_FALSE(std::isfinite(b.scalar[s])) << "sample " << s;
      continue;
    }
    if (!std::isfinite(b.scalar[s])) ++lost;
    scalar_err = std::max(scalar_err, std::abs(double(a.scalar[s]) - double(b.scalar[s])));
  }
  EXPECT_EQ(lost, 0u);
  if (lo > hi) return;  // no finite scalar
  const double scalar_bound = scalar_error_bound(e, lo, hi);
  EXPECT_LE(scalar_err, scalar_bound);
  if (!e.lossless && hi > lo) {
    // Half a step of the nominal bits over the range (2^b − 2 steps) — or, where that step is
    // finer than floats hold (the encoder then keeps fewer bits), two float spacings — plus the
    // float spacing there (ulp: at most |x|·2⁻²³).
    const double ulp = std::max(std::abs(lo), std::abs(hi)) * std::ldexp(1.0, -23);
    const double half_step = (hi - lo) / (2.0 * double((std::uint64_t(1) << e.scalar_bits) - 2));
    const double cap = std::max(half_step, 2.0 * ulp) + ulp;
    EXPECT_LE(scalar_bound, cap);
    EXPECT_LE(scalar_err, cap);
  }
}

void expect_idempotent(const LdiFragment& f, const FragmentEncoding& e) {
  const Bytes once = encode_fragment(f, e);
  const Bytes twice = encode_fragment(decoded(once), e);
  EXPECT_EQ(once, twice) << "depth_bits " << e.depth_bits << ", normal_bits " << e.normal_bits
                         << (e.lossless ? ", lossless" : "");
}

// ---- Crafting hostile headers (offsets as documented in fragment_codec.hpp) ----------------

// Bitwise CRC-32 (IEEE 802.3), independent of the codec's table-driven one.
std::uint32_t crc32(const std::uint8_t* p, std::size_t n) {
  std::uint32_t c = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int k = 0; k < 8; ++k)
      c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
  }
  return ~c;
}

void put(Bytes& b, std::size_t offset, std::uint64_t value, int size) {
  for (int k = 0; k < size; ++k)
    b[offset + k] = std::uint8_t(value >> (8 * k));
}
std::uint64_t get(const Bytes& b, std::size_t offset, int size) {
  std::uint64_t v = 0;
  for (int k = 0; k < size; ++k)
    v |= std::uint64_t(b[offset + k]) << (8 * k);
  return v;
}
void reseal_header(Bytes& b) {
  put(b, 72, crc32(b.data(), 72), 4);
}
void reseal_payload(Bytes& b) {
  put(b, 60, b.size() - 76, 8);
  put(b, 68, crc32(b.data() + 76, b.size() - 76), 4);
  reseal_header(b);
}

void put_varint(Bytes& b, std::uint64_t v) {
  for (; v >= 0x80; v >>= 7)
    b.push_back(std::uint8_t(v | 0x80));
  b.push_back(std::uint8_t(v));
}

// One zstd frame (RFC 8878) holding `payload` as a single raw block: magic, a single-segment
// frame header with a 4-byte content size, a block header (last, raw, size), the bytes.
Bytes raw_zstd_frame(const Bytes& payload) {
  Bytes f{0x28, 0xB5, 0x2F, 0xFD, 0xA0};
  for (int k = 0; k < 4; ++k)
    f.push_back(std::uint8_t(payload.size() >> (8 * k)));
  const std::uint32_t block = 1u | std::uint32_t(payload.size() << 3);
  for (int k = 0; k < 3; ++k)
    f.push_back(std::uint8_t(block >> (8 * k)));
  f.insert(f.end(), payload.begin(), payload.end());
  return f;
}

// A complete fragment message around `payload`, header fields as documented.
Bytes sealed_fragment(std::uint8_t flags, std::uint8_t depth_bits, std::uint8_t normal_bits,
                      std::uint64_t pixel_count, double lo, double hi, std::uint64_t listed,
                      std::uint64_t samples, const Bytes& payload) {
  Bytes b(76);
  b[0] = 'L', b[1] = 'D', b[2] = 'I', b[3] = 'F';
  put(b, 4, 2, 1);
  put(b, 5, flags, 1);
  put(b, 6, depth_bits, 1);
  put(b, 7, normal_bits, 1);
  put(b, 8, 0, 4);
  put(b, 12, pixel_count, 8);
  put(b, 20, std::bit_cast<std::uint64_t>(lo), 8);
  put(b, 28, std::bit_cast<std::uint64_t>(hi), 8);
  put(b, 36, listed, 8);
  put(b, 44, samples, 8);
  put(b, 52, payload.size(), 8);
  const Bytes frame = raw_zstd_frame(payload);
  b.insert(b.end(), frame.begin(), frame.end());
  reseal_payload(b);
  return b;
}

// Decodes hostile `bytes`: must fail, with a message containing `why`, without touching `out`
// and without any allocation above 1 MiB.
void expect_rejected(const Bytes& bytes, const std::string& why) {
  LdiFragment out = edge_case_fragment(false);
  const LdiFragment before = out;
  g_largest_allocation = 0;
  const Status s = decode_fragment(bytes, out);
  const std::size_t largest = g_largest_allocation;
  ASSERT_FALSE(s) << "accepted; expected: " << why;
  EXPECT_NE(s.message().find(why), std::string::npos) << s.message();
  EXPECT_EQ(s.message().rfind("fragment: ", 0), 0u) << s.message();
  EXPECT_LE(largest, std::size_t(1) << 20) << s.message();
  expect_exact(before, out);
}

// ---- Round trips ----------------------------------------------------------------------------

TEST(FragmentCodec, LosslessRoundTripIsBitExact) {
  const FragmentEncoding lossless{.lossless = true};
  for (LdiFragment f : torus_fragments()) {
    expect_exact(f, decoded(encode_fragment(f, lossless)));
    for (std::size_t s = 0; s < f.sample_count(); ++s)
      f.scalar.push_back(f.depth[s] * 3.0f - float(s));
    expect_exact(f, decoded(encode_fragment(f, lossless)));
  }
  const LdiFragment edges = edge_case_fragment(true);
  expect_exact(edges, decoded(encode_fragment(edges, lossless)));
}

TEST(FragmentCodec, LossyRoundTripOfRayCastSurfacesWithinBounds) {
  std::vector<LdiFragment> fragments = torus_fragments();
  const std::vector<LdiFragment> barth = cast_fragments("barth", 96);
  fragments.insert(fragments.end(), barth.begin(), barth.end());
  for (const FragmentEncoding& e :
       {FragmentEncoding{}, FragmentEncoding{.depth_bits = 16, .normal_bits = 10}}) {
    for (const LdiFragment& f : fragments) {
      ASSERT_GT(f.sample_count(), 1000u);
      const Bytes bytes = encode_fragment(f, e);
      expect_within_bounds(f, decoded(bytes), e);
      // Worth it: under a third of the 16 raw bytes per sample.
      EXPECT_LT(bytes.size(), f.sample_count() * 16 / 3);
    }
  }
  // The depth error at the default settings is far below a pixel (128 pixels over 3 units).
  EXPECT_LT(depth_error_bound({}, 0.0, 3.0), 1e-3 * 3.0 / 128);
}

// A colour field on the torus's samples (smooth over the surface: a function of the hit's depth
// and pixel): within the stated bound at the default 12 bits and at 8, idempotent, and what it
// costs on the wire beside the samples without it.
TEST(FragmentCodec, LossyScalarsOfASmoothFieldWithinBounds) {
  for (LdiFragment f : torus_fragments()) {
    const Bytes plain = encode_fragment(f, {});
    std::size_t s = 0;
    for (std::size_t k = 0; k < f.pixels.size(); ++k)
      for (std::uint32_t j = 0; j < f.counts[k]; ++j, ++s)
        f.scalar.push_back(float(300.0 + 20.0 * std::sin(3.0 * f.depth[s]) +
                                 std::cos(1e-3 * double(f.pixels[k]))));
    for (const FragmentEncoding& e : {FragmentEncoding{}, FragmentEncoding{.scalar_bits = 8}}) {
      const Bytes bytes = encode_fragment(f, e);
      expect_within_bounds(f, decoded(bytes), e);
      expect_idempotent(f, e);
      const double extra = double(bytes.size() - plain.size()) / double(f.sample_count());
      std::printf("view %u, %zu samples, %d scalar bits: %.2f bytes per sample for the scalar\n",
                  f.view, f.sample_count(), e.scalar_bits, extra);
      EXPECT_LT(extra, e.scalar_bits / 8.0) << "no better than the raw codes";
    }
  }
}

// The scalar stream's edge cases: −0 as the lowest value (decoded q = 0 is +0: the range must
// come back the same), constant scalars and a range below two float spacings (one bit: every
// finite value lo), only non-finite scalars, the fewest and the most bits; each round trip
// within bounds and idempotent.
TEST(FragmentCodec, ScalarEdgeCasesRoundTripAndReencodeAlike) {
  LdiFragment base = normals_fragment({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0, 0, -1}});
  const std::vector<std::vector<float>> cases = {{-0.0f, 1.0f, 0.5f, 0.25f},
                                                 {2.5f, 2.5f, 2.5f, 2.5f},
                                                 {1e6f, std::nextafter(1e6f, 2e6f), 1e6f, 1e6f},
                                                 {NAN, INFINITY, -INFINITY, NAN},
                                                 {-3.0f, NAN, 7.0f, 1e-30f}};
  for (const std::vector<float>& scalars : cases)
    for (const int bits : {2, 12, 24}) {
      LdiFragment f = base;
      f.scalar = scalars;
      const FragmentEncoding e{.scalar_bits = bits};
      SCOPED_TRACE("scalars " + ::testing::PrintToString(scalars) + ", " + std::to_string(bits) +
                   " bits");
      const LdiFragment g = decoded(encode_fragment(f, e));
      expect_within_bounds(f, g, e);
      expect_idempotent(f, e);
      // The range the decoded fragment carries holds its finite values, +0 for a −0 end.
      for (float x : g.scalar) {
        if (std::isfinite(x)) {
          EXPECT_TRUE(x >= g.scalar_lo && x <= g.scalar_hi) << x;
        }
      }
      EXPECT_FALSE(std::signbit(g.scalar_lo) && g.scalar_lo == 0.0f);
    }
  // A range set on the fragment (the ranks' agreed one) is the grid, however narrow the data.
  LdiFragment f = base;
  f.scalar = {0.5f, 0.5f, 0.5f, 0.5f};
  f.scalar_lo = 0.0f;
  f.scalar_hi = 1.0f;
  const LdiFragment g = decoded(encode_fragment(f, {.scalar_bits = 2}));
  EXPECT_EQ(g.scalar, (std::vector<float>{0.5f, 0.5f, 0.5f, 0.5f}));  // code 1 of 0, 1, 2
  EXPECT_EQ(g.scalar_lo, 0.0f);
  EXPECT_EQ(g.scalar_hi, 1.0f);
  f.scalar_hi = 0.25f;  // narrower than the data: widened to hold it
  EXPECT_EQ(decoded(encode_fragment(f, {.scalar_bits = 2})).scalar_hi, 0.5f);
}

TEST(FragmentCodec, QuantizingInPlaceGivesTheRoundTripsFragment) {
  std::vector<LdiFragment> fragments = torus_fragments();
  const std::vector<LdiFragment> barth = cast_fragments("barth", 96);
  fragments.insert(fragments.end(), barth.begin(), barth.end());
  fragments.push_back(edge_case_fragment(false));
  fragments.push_back(edge_case_fragment(true));
  for (const FragmentEncoding& e :
       {FragmentEncoding{}, FragmentEncoding{.depth_bits = 1, .normal_bits = 2},
        FragmentEncoding{.depth_bits = 24, .normal_bits = 16},
        FragmentEncoding{.lossless = true}}) {
    for (const LdiFragment& f : fragments) {
      LdiFragment q = f;
      quantize_fragment(q, e);
      expect_exact(decoded(encode_fragment(f, e)), q);
      if (!e.lossless && f.sample_count() > 1000) {
        EXPECT_FALSE(same_bits(q.depth, f.depth));
      }
      // In pieces of any size (as the reduction quantizes a rank's samples in parallel): the
      // same fragment.
      for (std::size_t piece : {std::size_t(1), std::size_t(7), std::size_t(1000)}) {
        LdiFragment r = f;
        const FragmentQuantizer quantizer = check_fragment_encodable(r, e);
        for (std::size_t begin = 0; begin < r.depth.size(); begin += piece)
          quantize_samples(r, quantizer, begin, begin + piece);
        expect_exact(q, r);
      }
    }
  }
  LdiFragment bad = edge_case_fragment(false);
  bad.normal[0] = glm::vec3(0.0f);
  EXPECT_THROW(quantize_fragment(bad), std::invalid_argument);
  EXPECT_THROW(check_fragment_encodable(bad, {}), std::invalid_argument);
}

// check_fragment accepts what decode_fragment accepts and gives its shape; it rejects a
// truncated fragment, a flipped payload byte (checksum) and trailing bytes without decoding.
TEST(FragmentCodec, CheckingWithoutDecodingGivesTheShape) {
  for (const LdiFragment& f : torus_fragments())
    for (const FragmentEncoding& e : {FragmentEncoding{}, FragmentEncoding{.lossless = true}}) {
      std::vector<std::uint8_t> bytes = encode_fragment(f, e);
      LdiFragment shape;
      ASSERT_TRUE(check_fragment(bytes, shape));
      EXPECT_EQ(shape.view, f.view);
      EXPECT_EQ(shape.pixel_count, f.pixel_count);
      EXPECT_EQ(shape.depth_lo, f.depth_lo);
      EXPECT_EQ(shape.depth_hi, f.depth_hi);
      EXPECT_TRUE(shape.depth.empty() && shape.pixels.empty());
      const std::span<const std::uint8_t> all(bytes);
      EXPECT_FALSE(check_fragment(all.first(all.size() - 1), shape));
      std::vector<std::uint8_t> longer = bytes;
      longer.push_back(0);
      EXPECT_FALSE(check_fragment(longer, shape));
      bytes[bytes.size() - 3] ^= 0x10;  // in the compressed payload
      EXPECT_FALSE(check_fragment(bytes, shape));
      LdiFragment unused;
      EXPECT_FALSE(decode_fragment(bytes, unused));
    }
}

TEST(FragmentCodec, LossyRoundTripOfEdgeCasesWithinBounds) {
  for (bool with_scalar : {false, true})
    for (const FragmentEncoding& e :
         {FragmentEncoding{}, FragmentEncoding{.depth_bits = 1, .normal_bits = 2},
          FragmentEncoding{.depth_bits = 24, .normal_bits = 16, .zstd_level = 19}}) {
      const LdiFragment f = edge_case_fragment(with_scalar);
      const LdiFragment g = decoded(encode_fragment(f, e));
      expect_within_bounds(f, g, e);
      // The ends of the depth interval are kept exactly (q = 0 and q = 2^b − 1).
      EXPECT_EQ(g.depth.front(), -0.5f);
      EXPECT_EQ(g.depth.back(), 2.5f);
    }
  // The axes are octahedron vertices: exact at any resolution.
  const LdiFragment axes =
      normals_fragment({{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}});
  for (int bits : {2, 7, 12, 16}) {
    const LdiFragment g = decoded(encode_fragment(axes, {.normal_bits = bits}));
    EXPECT_TRUE(same_bits(g.normal, axes.normal)) << bits;
  }
}

TEST(FragmentCodec, EmptyFragmentRoundTrips) {
  LdiFragment f;
  f.view = 7;
  f.pixel_count = 512 * 512;
  f.depth_hi = 2.5;
  for (const FragmentEncoding& e : {FragmentEncoding{}, FragmentEncoding{.lossless = true}}) {
    const Bytes bytes = encode_fragment(f, e);
    EXPECT_LT(bytes.size(), 100u);
    expect_exact(f, decoded(bytes));
  }
}

TEST(FragmentCodec, NormalErrorWithinBoundOverTheSphere) {
  // A Fibonacci sphere plus the special normals, each also nudged toward the folds.
  std::vector<glm::vec3> normals = special_normals();
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    const double z = 1.0 - (2.0 * k + 1.0) / n, r = std::sqrt(1.0 - z * z);
    const double phi = k * 2.399963229728653;  // golden angle
    normals.emplace_back(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z));
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> tiny(-1e-4f, 1e-4f);
  for (const glm::vec3 s : special_normals())
    for (int k = 0; k < 20; ++k)
      normals.push_back(s + glm::vec3(tiny(rng), tiny(rng), tiny(rng)));
  const LdiFragment f = normals_fragment(normals);
  for (int bits : {2, 5, 8, 12, 16}) {
    const FragmentEncoding e{.normal_bits = bits};
    expect_within_bounds(f, decoded(encode_fragment(f, e)), e);
    expect_idempotent(f, e);
  }
}

TEST(FragmentCodec, DepthBoundHoldsBeyondFloatResolution) {
  // 24 bits over [0, 3] is finer than a float near 3; [1000, 1000.001] holds 17 floats; an
  // interval of zero width holds one depth. Errors stay within the bound, re-encoding is stable.
  struct Case {
    double lo, hi;
  };
  for (const Case c : {Case{0.0, 3.0}, Case{1000.0, 1000.001}, Case{1.5, 1.5}}) {
    LdiFragment f;
    f.pixel_count = 100;
    f.depth_lo = c.lo;
    f.depth_hi = c.hi;
    for (std::uint32_t k = 0; k < 100; ++k) {
      f.pixels.push_back(k);
      f.counts.push_back(1);
      float d = float(c.lo + (c.hi - c.lo) * k / 99.0);
      if (double(d) > c.hi) d = std::nextafter(d, -INFINITY);  // inside [lo, hi]
      f.depth.push_back(d);
      f.normal.push_back({0, 0, 1});
    }
    for (int bits : {1, 12, 20, 24}) {
      const FragmentEncoding e{.depth_bits = bits};
      expect_within_bounds(f, decoded(encode_fragment(f, e)), e);
      expect_idempotent(f, e);
    }
  }
  // Beyond float resolution the bound is a few float spacings, not 24 bits' worth.
  const double spacing = std::nextafter(3.0f, 4.0f) - 3.0f;
  EXPECT_LT(depth_error_bound({.depth_bits = 24}, 0.0, 3.0), 3 * spacing);
}

TEST(FragmentCodec, ReencodingDecodedFragmentGivesSameBytes) {
  for (const FragmentEncoding& e :
       {FragmentEncoding{}, FragmentEncoding{.depth_bits = 16, .normal_bits = 10},
        FragmentEncoding{.depth_bits = 24, .normal_bits = 16},
        FragmentEncoding{.depth_bits = 1, .normal_bits = 2}, FragmentEncoding{.lossless = true}}) {
    for (const LdiFragment& f : torus_fragments())
      expect_idempotent(f, e);
    expect_idempotent(edge_case_fragment(true), e);
  }
  // An intermediate rank: decode two fragments of one view, merge, re-encode; the root decodes
  // and re-encodes once more without drift.
  const LdiFragment& whole = torus_fragments()[2];
  LdiFragment a = make_empty_fragment({}, 0), b = a;
  for (LdiFragment* part : {&a, &b}) {
    part->view = whole.view;
    part->pixel_count = whole.pixel_count;
    part->depth_hi = whole.depth_hi;
  }
  std::size_t s = 0;
  for (std::size_t k = 0; k < whole.pixels.size(); ++k) {
    LdiFragment& part = k % 3 == 0 ? a : b;
    part.pixels.push_back(whole.pixels[k]);
    part.counts.push_back(whole.counts[k]);
    for (std::uint32_t j = 0; j < whole.counts[k]; ++j, ++s) {
      part.depth.push_back(whole.depth[s]);
      part.normal.push_back(whole.normal[s]);
    }
  }
  const std::vector<LdiFragment> parts{decoded(encode_fragment(a)), decoded(encode_fragment(b))};
  const LdiFragment merged = combine_fragments(parts, 0.0, glm::vec3(0, 0, 1));
  EXPECT_EQ(merged.pixels, whole.pixels);
  expect_idempotent(merged, {});
  expect_within_bounds(whole, decoded(encode_fragment(merged)), {});
}

// ---- Format ---------------------------------------------------------------------------------

TEST(FragmentCodec, HeaderFieldsAtDocumentedOffsets) {
  const LdiFragment f = edge_case_fragment(true);
  const Bytes b = encode_fragment(f);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "LDIF");
  EXPECT_EQ(get(b, 4, 1), 2u);      // version
  EXPECT_EQ(get(b, 5, 1), 2u);      // has_scalar, lossy
  EXPECT_EQ(get(b, 6, 1), 20u);     // depth bits
  EXPECT_EQ(get(b, 7, 1), 12u);     // normal bits
  EXPECT_EQ(get(b, 8, 4), 2u);      // view
  EXPECT_EQ(get(b, 12, 8), 1000u);  // pixel_count
  EXPECT_EQ(std::bit_cast<double>(get(b, 20, 8)), -0.5);
  EXPECT_EQ(std::bit_cast<double>(get(b, 28, 8)), 2.5);
  EXPECT_EQ(get(b, 36, 8), 5u);   // listed pixels
  EXPECT_EQ(get(b, 44, 8), 71u);  // samples
  EXPECT_EQ(get(b, 60, 8), b.size() - 76);
  EXPECT_EQ(get(b, 68, 4), crc32(b.data() + 76, b.size() - 76));
  EXPECT_EQ(get(b, 72, 4), crc32(b.data(), 72));
  EXPECT_EQ(get(encode_fragment(f, {.lossless = true}), 5, 1), 3u);
}

// ---- Hostile input --------------------------------------------------------------------------

TEST(FragmentCodec, RejectsTruncationAtEveryOffset) {
  for (const FragmentEncoding& e : {FragmentEncoding{}, FragmentEncoding{.lossless = true}}) {
    const Bytes full = encode_fragment(edge_case_fragment(true), e);
    for (std::size_t n = 0; n < full.size(); ++n)
      expect_rejected(Bytes(full.begin(), full.begin() + n), "truncated");
  }
}

TEST(FragmentCodec, RejectsEverySingleBitFlip) {
  for (const FragmentEncoding& e : {FragmentEncoding{}, FragmentEncoding{.lossless = true}}) {
    const Bytes good = encode_fragment(edge_case_fragment(true), e);
    for (std::size_t bit = 0; bit < 8 * good.size(); ++bit) {
      Bytes bad = good;
      bad[bit / 8] ^= std::uint8_t(1u << (bit % 8));
      // The magic, the version, or one of the checksums catches every flip.
      expect_rejected(bad, "");
    }
  }
}

TEST(FragmentCodec, RejectsWrongMagicVersionAndTrailingBytes) {
  const Bytes good = encode_fragment(edge_case_fragment(false));
  Bytes b = good;
  b[0] = 'X';
  expect_rejected(b, "bad magic");
  b = good;
  put(b, 4, 1, 1);  // version 1 kept scalars as raw floats: not read as version 2
  reseal_header(b);
  expect_rejected(b, "unsupported format version 1");
  put(b, 4, 3, 1);
  reseal_header(b);
  expect_rejected(b, "unsupported format version 3");
  b = good;
  b.push_back(0);
  expect_rejected(b, "trailing bytes");
  b = good;
  put(b, 5, 4, 1);  // unknown flag
  reseal_header(b);
  expect_rejected(b, "unknown flags");
}

TEST(FragmentCodec, RejectsAbsurdCountsBeforeAllocating) {
  const Bytes good = encode_fragment(edge_case_fragment(false));
  auto with = [&](std::size_t offset, std::uint64_t value) {
    Bytes b = good;
    put(b, offset, value, 8);
    reseal_header(b);  // a correct checksum: only the size checks stand in the way
    return b;
  };
  expect_rejected(with(44, std::uint64_t(1) << 40), "counts inconsistent");  // 2^40 samples
  expect_rejected(with(36, 1001), "counts inconsistent");  // more pixels than the view has
  expect_rejected(with(52, std::uint64_t(1) << 62), "payload size");
  expect_rejected(with(60, std::uint64_t(1) << 62), "payload size");
  // Counts and sizes that agree with each other (2^31 samples, 6.4 GB payload) but not with the
  // zstd frame that follows.
  Bytes b = with(12, std::uint64_t(1) << 32);
  put(b, 36, std::uint64_t(1) << 15, 8);
  put(b, 44, std::uint64_t(1) << 31, 8);
  put(b, 52, (std::uint64_t(3) << 31) + (std::uint64_t(2) << 15), 8);
  reseal_header(b);
  expect_rejected(b, "zstd frame");
  // The same with a zstd frame that claims those 6.4 GB too (content size in its header) but
  // holds one RLE block of 1000 bytes: decoding stops at what the frame really holds.
  Bytes frame{0x28, 0xB5, 0x2F, 0xFD,  // zstd magic
              0xE0};                   // single segment, 8-byte content size
  const std::uint64_t claimed = get(b, 52, 8);
  for (int k = 0; k < 8; ++k)
    frame.push_back(std::uint8_t(claimed >> (8 * k)));
  const std::uint32_t block = 1 | (1 << 1) | (1000 << 3);  // last, RLE, 1000 bytes
  frame.insert(frame.end(),
               {std::uint8_t(block), std::uint8_t(block >> 8), std::uint8_t(block >> 16), 0x00});
  b.resize(76);
  b.insert(b.end(), frame.begin(), frame.end());
  reseal_payload(b);
  expect_rejected(b, "corrupt compressed payload");
}

// A fragment written by hand to the documented format (one raw zstd block, so no zstd
// library is needed): a second implementation of the spec is understood, and payloads that
// are sealed correctly but wrong inside are rejected by the decoder's own checks.
TEST(FragmentCodec, DecodesTheDocumentedFormatAndChecksThePayload) {
  struct Sample {
    std::uint64_t depth_residual, u_residual, v_residual;  // zigzag-coded
  };
  auto lossy = [](std::uint64_t listed, std::uint64_t samples, const Bytes& pixel_and_count_stream,
                  const std::vector<Sample>& streams, const Bytes& extra = {}) {
    Bytes payload = pixel_and_count_stream;
    for (int k = 0; k < 3; ++k)
      for (const Sample& s : streams)
        put_varint(payload, k == 0 ? s.depth_residual : k == 1 ? s.u_residual : s.v_residual);
    payload.insert(payload.end(), extra.begin(), extra.end());
    return sealed_fragment(0, 20, 12, 10, 0.0, 2.0, listed, samples, payload);
  };
  // Pixels 3 and 4 (first id 3, gap − 1 = 0), one sample each; depth q = 0 then 2^20 − 1
  // (residual 2^20 − 1, zigzag 2^21 − 2); normals at grid point (2047, 2047), p = 0: +z.
  const std::vector<Sample> good{{0, 4094, 4094}, {(1u << 21) - 2, 0, 0}};
  const Bytes ids_counts{3, 0, 1, 1};
  LdiFragment f = decoded(lossy(2, 2, ids_counts, good));
  EXPECT_EQ(f.pixels, (std::vector<std::uint32_t>{3, 4}));
  EXPECT_EQ(f.counts, (std::vector<std::uint32_t>{1, 1}));
  EXPECT_EQ(f.depth, (std::vector<float>{0.0f, 2.0f}));
  EXPECT_EQ(f.normal, (std::vector<glm::vec3>{{0, 0, 1}, {0, 0, 1}}));

  expect_rejected(lossy(2, 2, {3, 0, 0, 2}, good), "invalid sample count");       // count 0
  expect_rejected(lossy(2, 2, {9, 0, 1, 1}, good), "pixel id out of range");      // id 10 of 10
  expect_rejected(lossy(2, 2, {0x83, 0x00, 0, 1, 1}, good), "invalid pixel id");  // overlong 3
  expect_rejected(lossy(2, 3, ids_counts, {good[0], good[1], good[1]}), "do not sum");
  expect_rejected(lossy(2, 2, ids_counts, good, {0}), "longer than its streams");  // extra byte
  expect_rejected(lossy(2, 2, ids_counts, {good[0], {std::uint64_t(1) << 21, 0, 0}}),
                  "invalid depth residual");  // q = 2^20 > 2^20 − 1
  expect_rejected(lossy(2, 2, ids_counts, {{0, 4094, 8190}, good[1]}),
                  "invalid normal residual");  // v = 4095 > 2^12 − 2
  // One pixel with two samples whose depths go backwards: q = 10, then 5.
  expect_rejected(lossy(1, 2, {3, 2}, {{20, 4094, 4094}, {9, 0, 0}}), "not sorted");

  // Lossy scalars (flag 2): bits, float lo and hi, then predicted codes. Two bits over [1, 3]:
  // codes 0, 1, 2 are 1, 2, 3 and code 3 is non-finite (NaN).
  auto with_scalars = [&](std::uint8_t bits, float lo, float hi, const Bytes& residuals) {
    Bytes payload = ids_counts;
    for (int k = 0; k < 3; ++k)
      for (const Sample& s : good)
        put_varint(payload, k == 0 ? s.depth_residual : k == 1 ? s.u_residual : s.v_residual);
    payload.push_back(bits);
    for (float x : {lo, hi})
      for (int k = 0; k < 4; ++k)
        payload.push_back(std::uint8_t(std::bit_cast<std::uint32_t>(x) >> (8 * k)));
    payload.insert(payload.end(), residuals.begin(), residuals.end());
    return sealed_fragment(2, 20, 12, 10, 0.0, 2.0, 2, 2, payload);
  };
  f = decoded(with_scalars(2, 1.0f, 3.0f, {0, 4}));  // q = 0, then 0 + 2
  EXPECT_EQ(f.scalar, (std::vector<float>{1.0f, 3.0f}));
  f = decoded(with_scalars(2, 1.0f, 3.0f, {2, 1}));  // q = 1, then 1 − 1
  EXPECT_EQ(f.scalar, (std::vector<float>{2.0f, 1.0f}));
  f = decoded(with_scalars(2, 1.0f, 3.0f, {6, 5}));  // q = 3 (non-finite), then 3 − 3
  EXPECT_TRUE(std::isnan(f.scalar[0]));
  EXPECT_EQ(f.scalar[1], 1.0f);
  expect_rejected(with_scalars(2, 1.0f, 3.0f, {8, 0}), "invalid scalar residual");  // q = 4
  expect_rejected(with_scalars(1, 1.0f, 3.0f, {0, 0}), "invalid scalar range");  // 1 bit: lo = hi
  expect_rejected(with_scalars(2, 3.0f, 1.0f, {0, 0}), "invalid scalar range");  // lo > hi
  expect_rejected(with_scalars(25, 1.0f, 3.0f, {0, 0}), "invalid scalar range");
  expect_rejected(with_scalars(2, 1.0f, INFINITY, {0, 0}), "invalid scalar range");

  // Lossless: raw floats; a NaN depth and a zero normal are refused.
  auto lossless = [](float depth, glm::vec3 normal) {
    Bytes payload{3, 1};
    for (float x : {depth, normal.x, normal.y, normal.z})
      for (int k = 0; k < 4; ++k)
        payload.push_back(std::uint8_t(std::bit_cast<std::uint32_t>(x) >> (8 * k)));
    return sealed_fragment(1, 0, 0, 10, 0.0, 2.0, 1, 1, payload);
  };
  EXPECT_EQ(decoded(lossless(1.5f, {0, 1, 0})).depth, std::vector<float>{1.5f});
  expect_rejected(lossless(NAN, {0, 1, 0}), "non-finite depth");
  expect_rejected(lossless(1.5f, {0, 0, 0}), "invalid normal");
  expect_rejected(lossless(1.5f, {0, INFINITY, 0}), "invalid normal");
}

TEST(FragmentCodec, EncodeRejectsInvalidFragmentsAndSettings) {
  const LdiFragment good = edge_case_fragment(false);
  LdiFragment f = good;
  f.pixels[1] = 0;  // not strictly increasing
  EXPECT_THROW(encode_fragment(f), std::invalid_argument);
  f = good;
  f.counts[2] = 65;  // counts exceed the samples
  EXPECT_THROW(encode_fragment(f), std::invalid_argument);
  f = good;
  f.normal[3] = {0, 0, 0};
  EXPECT_THROW(encode_fragment(f), std::invalid_argument);
  f = good;
  f.normal[3].y = NAN;
  EXPECT_THROW(encode_fragment(f), std::invalid_argument);
  for (const FragmentEncoding& e :
       {FragmentEncoding{.depth_bits = 0}, FragmentEncoding{.depth_bits = 25},
        FragmentEncoding{.normal_bits = 1}, FragmentEncoding{.normal_bits = 17},
        FragmentEncoding{.scalar_bits = 1}, FragmentEncoding{.scalar_bits = 25},
        FragmentEncoding{.zstd_level = 1000}})
    EXPECT_THROW(encode_fragment(good, e), std::invalid_argument);
}

}  // namespace
}  // namespace ldimesh

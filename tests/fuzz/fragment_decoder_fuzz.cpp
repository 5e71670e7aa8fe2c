// libFuzzer target for decode_fragment (scripts/fuzz.sh builds and runs it with ASan and UBSan).
// Any input must be decoded or refused without a crash, an out-of-bounds read or undefined
// behaviour; a fragment the decoder accepts must be accepted by the encoder and survive a
// lossless round trip bit for bit (decode_fragment's contract).
//
// With LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes a seed corpus of valid encodings
// (lossy and lossless, with and without scalar, empty) into DIR and exits. The fuzzing build
// defines FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION: the decoder then skips its checksum
// comparisons, so that mutations get past them to the zstd frame and the streams.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <zstd.h>

#include "ldimesh/transport/fragment_codec.hpp"

#include "fuzz_seeds.hpp"

namespace {

using ldimesh::FragmentEncoding;
using ldimesh::LdiFragment;

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// A 24 × 24 view of two concentric spheres (radii 0.9 and 0.5 in [−1, 1]³): up to four layers
// per pixel with smooth depths and normals, like a ray-cast LDI.
LdiFragment spheres_fragment(bool with_scalar) {
  LdiFragment f;
  const int n = 24;
  f.view = 1;
  f.pixel_count = n * n;
  f.depth_hi = 2.0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = -1 + (i + 0.5) * 2.0 / n, y = -1 + (j + 0.5) * 2.0 / n;
      std::uint32_t count = 0;
      for (double sign : {-1.0, 1.0})
        for (double r : sign < 0 ? std::vector<double>{0.9, 0.5} : std::vector<double>{0.5, 0.9}) {
          const double h2 = r * r - x * x - y * y;
          if (h2 <= 0) continue;
          const double z = sign * std::sqrt(h2);
          f.depth.push_back(float(1.0 + z));
          f.normal.push_back(glm::normalize(glm::vec3(float(x), float(y), float(z))));
          if (with_scalar) f.scalar.push_back(float(r + 0.01 * i));
          ++count;
        }
      if (count > 0) {
        f.pixels.push_back(std::uint32_t(j * n + i));
        f.counts.push_back(count);
      }
    }
  return f;
}

// `message` with its zstd frame rewritten as one raw (stored) block (RFC 8878): mutations then
// hit the streams themselves instead of zstd's entropy coding. The checksums go stale, which
// the fuzzing build does not check; the sizes in the header are kept right.
std::vector<std::uint8_t> with_raw_frame(std::vector<std::uint8_t> message) {
  constexpr std::size_t kHeader = 76, kCompressedSizeOffset = 60;
  const std::uint8_t* frame = message.data() + kHeader;
  const std::size_t frame_size = message.size() - kHeader;
  std::vector<std::uint8_t> payload(std::size_t(ZSTD_getFrameContentSize(frame, frame_size)));
  if (ZSTD_isError(ZSTD_decompress(payload.data(), payload.size(), frame, frame_size)) ||
      payload.size() >= (1u << 17))
    std::abort();
  message.resize(kHeader);
  const std::uint32_t size = std::uint32_t(payload.size()), block = 1u | (size << 3);
  message.insert(message.end(),
                 {0x28, 0xB5, 0x2F, 0xFD, 0xA0,  // magic, single segment
                  std::uint8_t(size), std::uint8_t(size >> 8), std::uint8_t(size >> 16),
                  std::uint8_t(size >> 24), std::uint8_t(block), std::uint8_t(block >> 8),
                  std::uint8_t(block >> 16)});
  message.insert(message.end(), payload.begin(), payload.end());
  for (int k = 0; k < 8; ++k)
    message[kCompressedSizeOffset + k] = std::uint8_t((message.size() - kHeader) >> (8 * k));
  return message;
}

}  // namespace

void ldimesh::fuzz::write_seeds(const std::string& dir) {
  const FragmentEncoding lossy, lossless{.lossless = true},
      coarse{.depth_bits = 16, .normal_bits = 10};
  LdiFragment empty;
  empty.pixel_count = 64;
  empty.depth_hi = 1.0;
  const LdiFragment plain = spheres_fragment(false), scalar = spheres_fragment(true);
  write_file(dir + "/seed-lossy", encode_fragment(plain, lossy));
  write_file(dir + "/seed-lossy-scalar", encode_fragment(scalar, lossy));
  write_file(dir + "/seed-lossy-16-10", encode_fragment(plain, coarse));
  write_file(dir + "/seed-lossless", encode_fragment(plain, lossless));
  write_file(dir + "/seed-lossless-scalar", encode_fragment(scalar, lossless));
  write_file(dir + "/seed-empty-lossy", encode_fragment(empty, lossy));
  write_file(dir + "/seed-empty-lossless", encode_fragment(empty, lossless));
  write_file(dir + "/seed-raw-lossy-scalar", with_raw_frame(encode_fragment(scalar, lossy)));
  write_file(dir + "/seed-raw-lossless", with_raw_frame(encode_fragment(plain, lossless)));
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  LdiFragment f;
  if (!ldimesh::decode_fragment({data, size}, f)) return 0;
  // Accepted: encode_fragment must not throw (an exception here aborts: a finding).
  LdiFragment g;
  if (!ldimesh::decode_fragment(encode_fragment(f, {.lossless = true}), g)) __builtin_trap();
  if (g.pixels != f.pixels || g.counts != f.counts || !same_bits(g.depth, f.depth) ||
      !same_bits(g.normal, f.normal) || !same_bits(g.scalar, f.scalar))
    __builtin_trap();
  if (!ldimesh::decode_fragment(encode_fragment(f, {}), g)) __builtin_trap();
  return 0;
}

// libFuzzer target for the adaptor's options parser (scripts/fuzz.sh options builds and runs it
// with ASan and UBSan): the options document comes from a solver's input deck or the user. Any
// input must be read or refused with an invalid_options Status, without a crash, an exception
// or undefined behaviour (a number out of an integer's range included); an accepted document
// must give values within the documented ranges (finite numbers).
//
// With LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes a seed corpus into DIR and exits:
// documents from docs/adaptor.md's examples and the tests, every key present.
#include <cmath>
#include <string>
#include <string_view>

#include "../../adaptor/src/options.hpp"

#include "fuzz_seeds.hpp"

void ldimesh::fuzz::write_seeds(const std::string& dir) {
  const char* seeds[] = {
      "{}",
      R"({"isovalues": [0.25, 0.5], "views": "xz", "resolution": 512, "r": 0.5})",
      R"({"cadence": {"every_steps": 10, "every_seconds": 2.5}, "busy": "coalesce"})",
      R"({"server": {"enabled": true, "bind": "0.0.0.0", "allow_remote": true, "port": 8080, "token": "abc"},
          "output_dir": "out/steps", "keep": 4, "memory_mb": 256})",
      R"({"encoding": {"lossless": false, "depth_bits": 16, "normal_bits": 10},
          "glb": {"compression_level": 3, "normal_bits": 8, "scalar_bits": 9}, "log": false, "background": true,
          "merging": true, "refinement": false})",
      R"({"testing": {"slow_root_seconds": 0.5,
                      "fault": {"kind": "corrupt_message", "step": 3, "rank": 1}}})",
  };
  int k = 0;
  for (const char* seed : seeds)
    write_file(dir + "/seed-" + std::to_string(k++) + ".json", seed);
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  ldimesh::AdaptorOptions o;
  const ldimesh::Status s =
      ldimesh::parse_adaptor_options({reinterpret_cast<const char*>(data), size}, o);
  if (!s) {
    if (s.code() != ldimesh::StatusCode::invalid_options) __builtin_trap();
    return 0;
  }
  bool finite = true;
  for (double v : o.isovalues)
    finite = finite && std::isfinite(v);
  const bool in_range =
      finite && !o.isovalues.empty() && o.isovalues.size() <= 8 && !o.views.empty() &&
      o.resolution >= 2 && o.resolution <= 8192 && o.r >= 0.0 && o.r <= 1.0 && o.every_steps >= 1 &&
      o.every_seconds >= 0.0 && std::isfinite(o.every_seconds) && o.port >= 0 && o.port <= 65535 &&
      o.keep >= 1 && o.memory_mb >= 1 && o.encoding.depth_bits >= 1 &&
      o.encoding.depth_bits <= 24 && o.encoding.normal_bits >= 2 && o.encoding.normal_bits <= 16 &&
      o.glb.compression_level >= 0 && o.glb.compression_level <= 10 && o.glb.normal_bits >= 2 &&
      o.glb.normal_bits <= 16 && o.glb.scalar_bits >= 1 && o.glb.scalar_bits <= 16;
  if (!in_range) __builtin_trap();
  return 0;
}

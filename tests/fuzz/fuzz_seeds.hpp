// What the fuzz targets share (one target per binary, so this header is included once): with
// LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes its seed corpus into DIR and exits
// (scripts/fuzz.sh does it before fuzzing). Each target defines write_seeds.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include <unistd.h>

namespace ldimesh::fuzz {

// Writes the target's seeds into `dir`; exits non-zero on failure.
void write_seeds(const std::string& dir);

inline void write_file(const std::string& path, std::string_view bytes) {
  std::FILE* out = std::fopen(path.c_str(), "wb");
  if (!out || std::fwrite(bytes.data(), 1, bytes.size(), out) != bytes.size()) {
    std::fprintf(stderr, "fuzz: cannot write %s\n", path.c_str());
    std::exit(1);
  }
  std::fclose(out);
}
// A scratch file of this process for a target whose decoder reads a path: $TMPDIR (or /tmp)
// /ldimesh_fuzz_PID.`extension`.
inline std::string scratch_path(const std::string& extension) {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir && *dir ? dir : "/tmp") + "/ldimesh_fuzz_" + std::to_string(::getpid()) +
         extension;
}

inline void write_file(const std::string& path, const std::vector<unsigned char>& bytes) {
  write_file(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

}  // namespace ldimesh::fuzz

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("LDIMESH_FUZZ_WRITE_SEEDS")) {
    ldimesh::fuzz::write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

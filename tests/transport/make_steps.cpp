// Test-only: writes fake steps 1..N (fake_steps.hpp: valid GLB containers, typed metadata)
// into DIR as a job run would, for the ldimesh-serve / ldimesh-fetch shell test.
//
//   ldimesh_make_steps DIR N
#include <cstdio>
#include <cstdlib>

#include "fake_steps.hpp"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s DIR N\n", argv[0]);
    return 2;
  }
  const long count = std::strtol(argv[2], nullptr, 10);
  for (long step = 1; step <= count; ++step) {
    const auto snapshot = ldimesh::testing::fake_snapshot(static_cast<std::uint64_t>(step), 100);
    if (const ldimesh::Status s = ldimesh::write_step_files(argv[1], snapshot); !s) {
      std::fprintf(stderr, "ldimesh_make_steps: %s\n", s.message().c_str());
      return 1;
    }
  }
  return 0;
}

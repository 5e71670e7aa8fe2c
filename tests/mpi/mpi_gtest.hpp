// GoogleTest under mpiexec. Tests are collective: every rank runs every test, only rank 0
// prints, and checks use non-fatal EXPECT_* so that no rank returns early and leaves the others
// waiting in a collective call.
#pragma once

#include <mpi.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#if defined(__SANITIZE_THREAD__)
#include <tbb/global_control.h>
#endif

namespace ldimesh::testing {

inline int rank_of() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}

inline int ranks() {
  int n = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &n);
  return n;
}

// Collective: an empty folder <temp>/<prefix>_<name>_<ranks> (removed by rank 0 first; every
// rank returns once it is gone), for a test's output.
inline std::string fresh_temp_dir(const std::string& prefix, const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   (prefix + "_" + name + "_" + std::to_string(ranks()));
  if (rank_of() == 0) std::filesystem::remove_all(dir);
  MPI_Barrier(MPI_COMM_WORLD);
  return dir.string();
}

// The body of main(): initialises MPI (funneled, or MPI_THREAD_MULTIPLE when the first
// argument is --thread-multiple), runs the tests with only rank 0 printing, and returns failure
// on every rank if any rank failed. `before_tests` runs after MPI_Init; what it returns lives
// while the tests run (e.g. a tbb::global_control).
template <class Setup>
int run_mpi_tests(int argc, char** argv, Setup before_tests) {
  int provided = 0;
  const bool multiple = argc > 1 && std::string(argv[1]) == "--thread-multiple";
  MPI_Init_thread(&argc, &argv, multiple ? MPI_THREAD_MULTIPLE : MPI_THREAD_FUNNELED, &provided);
  // Asked for MPI_THREAD_MULTIPLE and not granted, the background-path tests would quietly test
  // the synchronous path: fail instead.
  if (multiple && provided < MPI_THREAD_MULTIPLE) {
    std::fprintf(stderr, "FAIL: --thread-multiple, but MPI granted thread level %d only\n",
                 provided);
    MPI_Finalize();
    return 1;
  }
  ::testing::InitGoogleTest(&argc, argv);
  if (rank_of() != 0) {
    auto& listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  int failed = 0;
  {
#if defined(__SANITIZE_THREAD__)
    // Under ThreadSanitizer (scripts/sanitize) TBB runs no worker threads: its scheduler is not
    // instrumented, so ThreadSanitizer would not see a task's writes happen before the wait that
    // ends parallel_for and would report them. The threads checked are ours (the adaptor's
    // caster and root worker, the HTTP server's); a parallel loop then runs on the thread that
    // calls it.
    const tbb::global_control serial(tbb::global_control::max_allowed_parallelism, 1);
#endif
    [[maybe_unused]] auto guard = before_tests();
    failed = RUN_ALL_TESTS();
  }
  int any = 0;
  MPI_Allreduce(&failed, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  MPI_Finalize();
  return any;
}

inline int run_mpi_tests(int argc, char** argv) {
  return run_mpi_tests(argc, argv, [] { return 0; });
}

}  // namespace ldimesh::testing

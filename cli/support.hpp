// What the ldimesh command's subcommands share: output paths checked before any work, and
// failures that reach every rank.
#pragma once

#include <functional>
#include <stdexcept>
#include <string>

#include <mpi.h>

#include "ldimesh/core/base/status.hpp"

namespace ldimesh::cli {

// Fails early, before any work, if `path` could not be written: it is a folder, or not
// writable, or the nearest existing folder above it is not writable (missing folders are made
// when the file is written). Creates nothing: a run that fails leaves the file system as it
// found it.
void check_writable(const std::string& path);

// Writes `path` through `write(temporary)`: the missing folders made, the file written beside it
// under a hidden temporary name with the same extension, and renamed over `path` once complete. A
// failure (a Status, or an exception from `write`) removes the temporary file and throws
// runtime_error; `path` is then as it was.
void write_atomically(const std::string& path,
                      const std::function<Status(const std::string& temporary)>& write);

// Whether `path` ends in `ext` (".ply"), in any letter case.
bool has_extension(const std::string& path, const std::string& ext);

// Runs `step` on every rank; if it throws on any, every rank throws the first failing rank's
// message (so that no rank waits in a collective call the others never reach).
template <class Step>
void on_all_ranks(MPI_Comm comm, Step step) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  std::string error;
  try {
    step();
  } catch (...) {
    error = ldimesh::status_from_current_exception("").message();
    if (error.empty()) error = "unknown error";
  }
  int failed = error.empty() ? size : rank, first = size;
  MPI_Allreduce(&failed, &first, 1, MPI_INT, MPI_MIN, comm);
  if (first == size) return;
  int length = int(error.size());
  MPI_Bcast(&length, 1, MPI_INT, first, comm);
  error.resize(std::size_t(length));
  MPI_Bcast(error.data(), length, MPI_CHAR, first, comm);
  throw std::runtime_error(size > 1 && first != 0 ? "rank " + std::to_string(first) + ": " + error
                                                  : error);
}

}  // namespace ldimesh::cli

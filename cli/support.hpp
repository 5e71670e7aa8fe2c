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
// writable, or the folder it is in (the nearest existing one above it, where the missing ones
// are made when the file is written) is not writable. A symbolic link is checked, and written,
// as its target. Creates nothing: a run that fails leaves the file system as it found it.
void check_writable(const std::string& path);
// The same for a folder files are written into (made when they are written).
void check_writable_folder(const std::string& path);

// Writes `path` (a symbolic link's target) through `write(temporary)`: the missing folders made,
// the file written beside it under a unique hidden name with the same extension, then renamed
// over `path` once complete, with the permissions of the file it replaces. A failure (a Status,
// or an exception from `write`) removes the temporary file and the folders it made and throws
// runtime_error; `path` is then as it was. `before_rename` (if any) runs once the temporary is
// complete: what else the run writes, so that its failure leaves `path` untouched too.
void write_atomically(const std::string& path,
                      const std::function<Status(const std::string& temporary)>& write,
                      const std::function<void()>& before_rename = {});

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

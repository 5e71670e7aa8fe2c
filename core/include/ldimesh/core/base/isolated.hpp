// Work on untrusted input in a child process: a reader or decoder that a hostile file can crash
// or keep busy (Draco's, VTK's) runs in a forked child whose CPU time may be limited; what it
// produces comes back as bytes through a pipe. Linux (fork, prctl, close_range).
#pragma once

#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <type_traits>
#include <vector>

#include "ldimesh/core/base/status.hpp"

namespace ldimesh {

// What the child's work is, for the limits and the errors.
struct IsolatedTask {
  std::string prefix;   // of every error: "glb: ", "'file.vtu': "
  std::string process;  // "the decoder process": "… died of signal 8", "… ran out of memory"
  // Why a child stopped at its CPU limit is an error of the input (after "took more than N s
  // of CPU and was stopped"), and why one that died of a signal is ("died of signal N (NAME)").
  std::string over_cpu, died;
  std::string doing;  // the work, as in "decoding took more than N s of CPU"
  // RLIMIT_CPU of the child, rounded up to whole seconds, in [1, 10⁶]; a child that uses no CPU
  // (blocked, e.g. on a lock another thread held at the fork) is killed after four times that
  // in wall time, plus 10 s.
  double cpu_seconds = 10.0;
};

// Runs `work` in a forked child and gives what it wrote into `out` (replaced), or its error
// Status (code and message as the child returned them). The child resets its signals, keeps no
// descriptor but its pipe, ends with its parent, writes no core dump, is the first the system's
// out-of-memory killer takes (oom_score_adj 1000), has the CPU limit (never
// above a hard limit it inherited), runs `work` only and leaves with _exit (no exit handlers, no
// destructors). The calling thread alone goes on in the child: meant for a multithreaded caller
// too, where no other thread holds a lock `work` needs at the fork (glibc's fork resets its
// allocator's); the wall-time limit ends a child that would wait on one. Errors, each starting
// with task.prefix: corrupt_input where the CPU limit stopped the child or it died of a signal,
// out_of_memory where it (or the parent, for its output) ran out of memory, io where no process
// can be started or limited, internal where it made no progress or its output is truncated.
// `out` changes only on success. cpu_seconds outside [1, 10⁶] is invalid_argument.
Status run_isolated(const IsolatedTask& task,
                    const std::function<Status(std::vector<std::uint8_t>& out)>& work,
                    std::vector<std::uint8_t>& out);

// What crosses the pipe: trivially copyable values as their bytes, vectors as a 64-bit element
// count and their elements.
class ByteWriter {
 public:
  explicit ByteWriter(std::vector<std::uint8_t>& out) : out_(out) {}
  template <class T>
  void put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto* p = reinterpret_cast<const std::uint8_t*>(&value);
    out_.insert(out_.end(), p, p + sizeof value);
  }
  template <class T>
  void put_vector(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    put(std::uint64_t(v.size()));
    const auto* p = reinterpret_cast<const std::uint8_t*>(v.data());
    out_.insert(out_.end(), p, p + v.size() * sizeof(T));
  }

 private:
  std::vector<std::uint8_t>& out_;
};

// Reads what ByteWriter wrote, every count checked against the bytes there are; false where
// they run out. done(): every byte read.
class ByteReader {
 public:
  explicit ByteReader(const std::vector<std::uint8_t>& in) : in_(in) {}
  template <class T>
  bool get(T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    return get_bytes(&value, sizeof value);
  }
  template <class T>
  bool get_vector(std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    std::uint64_t n = 0;
    if (!get(n) || n > (in_.size() - at_) / sizeof(T)) return false;
    v.resize(std::size_t(n));
    return get_bytes(v.data(), std::size_t(n) * sizeof(T));
  }
  bool done() const { return at_ == in_.size(); }
  std::size_t position() const { return at_; }  // the bytes read so far

 private:
  bool get_bytes(void* data, std::size_t n) {
    if (n > in_.size() - at_) return false;
    if (n) std::memcpy(data, in_.data() + at_, n);
    at_ += n;
    return true;
  }
  const std::vector<std::uint8_t>& in_;
  std::size_t at_ = 0;
};

}  // namespace ldimesh

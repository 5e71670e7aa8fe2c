// decode_glb_isolated: decode_glb in a child process whose CPU time is limited (glb.hpp).
#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "ldimesh/transport/glb.hpp"

namespace ldimesh {
namespace {

// What the child sends: the total length of the rest (8 bytes), the Status (code, message),
// then the mesh's arrays and GlbInfo's fields, each array as a 64-bit element count and its
// bytes.
void put_bytes(std::vector<std::uint8_t>& out, const void* data, std::size_t n) {
  const auto* p = static_cast<const std::uint8_t*>(data);
  out.insert(out.end(), p, p + n);
}
template <class T>
void put(std::vector<std::uint8_t>& out, const T& value) {
  static_assert(std::is_trivially_copyable_v<T>);
  put_bytes(out, &value, sizeof value);
}
template <class T>
void put_vector(std::vector<std::uint8_t>& out, const std::vector<T>& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  put(out, std::uint64_t(v.size()));
  put_bytes(out, v.data(), v.size() * sizeof(T));
}

// Reads what put/put_vector wrote, every count checked against the bytes there are.
struct Reader {
  const std::vector<std::uint8_t>& in;
  std::size_t at = 0;
  bool get_bytes(void* data, std::size_t n) {
    if (n > in.size() - at) return false;
    if (n) std::memcpy(data, in.data() + at, n);
    at += n;
    return true;
  }
  template <class T>
  bool get(T& value) {
    return get_bytes(&value, sizeof value);
  }
  template <class T>
  bool get_vector(std::vector<T>& v) {
    std::uint64_t n = 0;
    if (!get(n) || n > (in.size() - at) / sizeof(T)) return false;
    v.resize(std::size_t(n));
    return get_bytes(v.data(), std::size_t(n) * sizeof(T));
  }
};

bool write_all(int fd, const std::vector<std::uint8_t>& bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += std::size_t(n);
  }
  return true;
}

// Exit statuses of the child other than 0.
constexpr int kNoLimit = 3;    // setrlimit failed
constexpr int kNoMemory = 4;   // an allocation failed
constexpr int kNoPipe = 5;     // the parent stopped reading
constexpr int kNoSignals = 6;  // the signal set-up failed

// The child: signals as a fresh process has them, no descriptor but the pipe's, the CPU limit
// (never above a hard limit it inherited), no core dump; decode, send, and leave without running
// the parent's exit handlers or destructors.
[[noreturn]] void decode_in_child(int fd, std::span<const std::uint8_t> glb, double cpu_seconds) {
  sigset_t none;
  sigemptyset(&none);
  if (::sigprocmask(SIG_SETMASK, &none, nullptr) != 0) ::_exit(kNoSignals);
  for (const int sig : {SIGINT, SIGTERM, SIGXCPU, SIGHUP})
    ::signal(sig, SIG_DFL);
  ::signal(SIGPIPE, SIG_IGN);              // a parent that stops reading: EPIPE, not a signal
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);      // ends with the parent
  if (::getppid() == 1) ::_exit(kNoPipe);  // the parent died before the line above
  ::prctl(PR_SET_DUMPABLE, 0);             // no core dump, not even through a pipe handler
  if (fd < 3) ::_exit(kNoPipe);
  ::close_range(3, unsigned(fd) - 1, 0);
  ::close_range(unsigned(fd) + 1, ~0U, 0);
  rlimit cpu{};
  if (::getrlimit(RLIMIT_CPU, &cpu) != 0) ::_exit(kNoLimit);
  rlim_t soft = rlim_t(std::ceil(cpu_seconds)), hard = soft + 1;  // SIGXCPU, then SIGKILL
  if (cpu.rlim_max != RLIM_INFINITY) {
    hard = std::min(hard, cpu.rlim_max);
    soft = std::min(soft, hard);
  }
  cpu.rlim_cur = soft;
  cpu.rlim_max = hard;
  const rlimit no_core{0, 0};
  if (::setrlimit(RLIMIT_CPU, &cpu) != 0 || ::setrlimit(RLIMIT_CORE, &no_core) != 0)
    ::_exit(kNoLimit);
  std::vector<std::uint8_t> out;
  try {
    Mesh mesh;
    GlbInfo info;
    const Status s = decode_glb(glb, mesh, &info);
    put(out, std::uint64_t(0));  // the length, below
    put(out, std::int32_t(s.code()));
    put_vector(out, std::vector<char>(s.message().begin(), s.message().end()));
    if (s) {
      put_vector(out, mesh.positions);
      put_vector(out, mesh.normals);
      put_vector(out, mesh.scalars);
      put_vector(out, mesh.quads);
      put_vector(out, mesh.triangles);
      put_vector(out, mesh.quad_view);
      put_vector(out, mesh.triangle_view);
      put_vector(out, mesh.view_dirs);
      put(out, std::uint64_t(info.triangles));
      put(out, std::uint64_t(info.vertices));
      put(out, std::uint8_t(info.has_scalar));
      put(out, info.scalar_min);
      put(out, info.scalar_max);
    }
    const std::uint64_t length = out.size() - sizeof(std::uint64_t);
    std::memcpy(out.data(), &length, sizeof length);
  } catch (...) {
    ::_exit(kNoMemory);
  }
  ::_exit(write_all(fd, out) ? 0 : kNoPipe);
}

// Reads the child's output from `fd` into `bytes` until EOF or `deadline`. Returns 0, an errno,
// or ETIMEDOUT; std::bad_alloc propagates.
int read_until(int fd, std::vector<std::uint8_t>& bytes,
               std::chrono::steady_clock::time_point deadline) {
  std::uint8_t chunk[1 << 16];
  std::uint64_t announced = 0;
  while (true) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return ETIMEDOUT;
    pollfd p{fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, int(std::min<long long>(left.count(), 1000)));
    if (ready < 0 && errno == EINTR) continue;
    if (ready < 0) return errno;
    if (ready == 0) continue;
    const ssize_t n = ::read(fd, chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return errno;
    if (n == 0) return 0;
    const bool had_length = bytes.size() >= sizeof announced;
    bytes.insert(bytes.end(), chunk, chunk + n);
    if (!had_length && bytes.size() >= sizeof announced) {  // room for all of it at once
      std::memcpy(&announced, bytes.data(), sizeof announced);
      bytes.reserve(std::size_t(std::min<std::uint64_t>(announced, std::uint64_t(1) << 40)) +
                    sizeof announced);
    }
  }
}

}  // namespace

double glb_decode_cpu_limit(std::size_t glb_bytes) {
  return 2.0 + std::floor(5.0 * double(glb_bytes) / double(1 << 20));
}

Status decode_glb_isolated(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info,
                           double cpu_seconds) {
  if (cpu_seconds == 0.0) cpu_seconds = glb_decode_cpu_limit(glb.size());
  if (!(cpu_seconds >= 1.0 && cpu_seconds <= 1e6))
    return Status::invalid_argument("glb: the decoder's CPU limit must lie in [1, 1e6] s");
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return Status::io(std::string("glb: cannot create a pipe: ") + std::strerror(errno));
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int e = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    return Status::io(std::string("glb: cannot start the decoder process: ") + std::strerror(e));
  }
  if (pid == 0) {
    ::close(fds[0]);
    decode_in_child(fds[1], glb, cpu_seconds);
  }
  ::close(fds[1]);
  // Everything the child sends, read while it writes (a pipe holds only 64 KiB). A child that
  // uses no CPU (blocked, e.g. on a lock another thread held at the fork) is killed after four
  // times its CPU limit in wall time, plus 10 s.
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(4.0 * std::ceil(cpu_seconds) + 10.0));
  std::vector<std::uint8_t> bytes;
  int read_error = 0;
  bool out_of_memory = false;
  try {
    read_error = read_until(fds[0], bytes, deadline);
  } catch (...) {
    out_of_memory = true;
  }
  ::close(fds[0]);  // a child still writing gets EPIPE and ends
  if (read_error || out_of_memory) ::kill(pid, SIGKILL);
  // (Where the caller ignores SIGCHLD the child is reaped without a status: its output decides.)
  int status = 0;
  rusage used{};
  while (::wait4(pid, &status, 0, &used) < 0 && errno == EINTR) {
  }
  if (out_of_memory)
    return Status::out_of_memory("glb: no memory for the decoder process's output");
  if (read_error == ETIMEDOUT)
    return Status::internal("glb: the decoder process made no progress (stopped after " +
                            std::to_string(int(4.0 * std::ceil(cpu_seconds) + 10.0)) + " s)");
  if (read_error)
    return Status::io(std::string("glb: cannot read the decoder process's output: ") +
                      std::strerror(read_error));
  char limit_text[32];
  std::snprintf(limit_text, sizeof limit_text, "%.0f", std::ceil(cpu_seconds));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    const double cpu = double(used.ru_utime.tv_sec + used.ru_stime.tv_sec) +
                       1e-6 * double(used.ru_utime.tv_usec + used.ru_stime.tv_usec);
    if (sig == SIGXCPU || (sig == SIGKILL && cpu >= std::ceil(cpu_seconds)))
      return Status::corrupt_input(std::string("glb: decoding took more than ") + limit_text +
                                   " s of CPU and was stopped (a damaged or hostile Draco "
                                   "stream: Draco's decoder can spend seconds on a few bytes)");
    return Status::corrupt_input(std::string("glb: the decoder process died of signal ") +
                                 std::to_string(sig) + " (" + ::strsignal(sig) + ")");
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == kNoMemory)
    return Status::out_of_memory("glb: the decoder process ran out of memory");
  if (WIFEXITED(status) && WEXITSTATUS(status) == kNoLimit)
    return Status::io("glb: cannot limit the decoder process's CPU time (setrlimit)");
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    return Status::internal("glb: the decoder process failed (exit status " +
                            std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")");
  Reader r{bytes};
  std::uint64_t length = 0;
  std::int32_t code = 0;
  std::vector<char> message;
  if (!r.get(length) || length != bytes.size() - sizeof length || !r.get(code) ||
      !r.get_vector(message))
    return Status::internal("glb: the decoder process's output is truncated");
  if (code != std::int32_t(StatusCode::ok))
    return Status::error(code >= 0 && code <= std::int32_t(StatusCode::internal)
                             ? StatusCode(code)
                             : StatusCode::internal,
                         std::string(message.begin(), message.end()));
  Mesh mesh;
  std::uint64_t triangles = 0, vertices = 0;
  std::uint8_t has_scalar = 0;
  GlbInfo decoded;
  if (!r.get_vector(mesh.positions) || !r.get_vector(mesh.normals) || !r.get_vector(mesh.scalars) ||
      !r.get_vector(mesh.quads) || !r.get_vector(mesh.triangles) || !r.get_vector(mesh.quad_view) ||
      !r.get_vector(mesh.triangle_view) || !r.get_vector(mesh.view_dirs) || !r.get(triangles) ||
      !r.get(vertices) || !r.get(has_scalar) || !r.get(decoded.scalar_min) ||
      !r.get(decoded.scalar_max) || r.at != bytes.size())
    return Status::internal("glb: the decoder process's output is truncated");
  decoded.triangles = std::size_t(triangles);
  decoded.vertices = std::size_t(vertices);
  decoded.has_scalar = has_scalar != 0;
  out = std::move(mesh);
  if (info) *info = decoded;
  return Status::ok();
}

}  // namespace ldimesh

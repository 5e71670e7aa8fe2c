// decode_glb_isolated: decode_glb in a child process whose CPU time is limited (glb.hpp).
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "ldimesh/transport/glb.hpp"

namespace ldimesh {
namespace {

// What the child sends: the Status (code, message), then the mesh's arrays and GlbInfo, each
// array as a 64-bit element count and its bytes.
void put_bytes(std::vector<std::uint8_t>& out, const void* data, std::size_t n) {
  const auto* p = static_cast<const std::uint8_t*>(data);
  out.insert(out.end(), p, p + n);
}
template <class T>
void put_vector(std::vector<std::uint8_t>& out, const std::vector<T>& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  const std::uint64_t n = v.size();
  put_bytes(out, &n, sizeof n);
  put_bytes(out, v.data(), v.size() * sizeof(T));
}

// Reads what put_bytes/put_vector wrote, every count checked against the bytes there are.
struct Reader {
  const std::vector<std::uint8_t>& in;
  std::size_t at = 0;
  bool get(void* data, std::size_t n) {
    if (n > in.size() - at) return false;
    if (n) std::memcpy(data, in.data() + at, n);
    at += n;
    return true;
  }
  template <class T>
  bool get_vector(std::vector<T>& v) {
    std::uint64_t n = 0;
    if (!get(&n, sizeof n) || n > (in.size() - at) / sizeof(T)) return false;
    v.resize(std::size_t(n));
    return get(v.data(), std::size_t(n) * sizeof(T));
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

// The child: decode, send, leave without running the parent's exit handlers or destructors.
[[noreturn]] void decode_in_child(int fd, std::span<const std::uint8_t> glb, double cpu_seconds) {
  const rlim_t limit = rlim_t(std::ceil(cpu_seconds));
  const rlimit cpu{limit, limit + 1};  // SIGXCPU at the limit, SIGKILL a second later
  const rlimit no_core{0, 0};
  if (::setrlimit(RLIMIT_CPU, &cpu) != 0 || ::setrlimit(RLIMIT_CORE, &no_core) != 0) ::_exit(3);
  std::vector<std::uint8_t> out;
  try {
    Mesh mesh;
    GlbInfo info;
    const Status s = decode_glb(glb, mesh, &info);
    const std::int32_t code = std::int32_t(s.code());
    put_bytes(out, &code, sizeof code);
    std::vector<char> message(s.message().begin(), s.message().end());
    put_vector(out, message);
    if (s) {
      put_vector(out, mesh.positions);
      put_vector(out, mesh.normals);
      put_vector(out, mesh.scalars);
      put_vector(out, mesh.quads);
      put_vector(out, mesh.triangles);
      put_vector(out, mesh.quad_view);
      put_vector(out, mesh.triangle_view);
      put_vector(out, mesh.view_dirs);
      put_bytes(out, &info, sizeof info);
    }
  } catch (...) {
    ::_exit(4);  // allocation failure: the parent reports it
  }
  ::_exit(write_all(fd, out) ? 0 : 5);
}

}  // namespace

double glb_decode_cpu_limit(std::size_t glb_bytes) {
  return 2.0 + std::floor(5.0 * double(glb_bytes) / double(1 << 20));
}

Status decode_glb_isolated(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info,
                           double cpu_seconds) {
  static_assert(std::is_trivially_copyable_v<GlbInfo>);
  if (cpu_seconds == 0.0) cpu_seconds = glb_decode_cpu_limit(glb.size());
  if (!(cpu_seconds >= 1.0 && cpu_seconds <= 1e6))
    return Status::invalid_argument("glb: the decoder's CPU limit must lie in [1, 1e6] s");
  int fds[2];
  if (::pipe(fds) != 0)
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
  // Everything the child sends, read while it writes (a pipe holds only 64 KiB).
  std::vector<std::uint8_t> bytes;
  bool read_failed = false;
  try {
    std::uint8_t chunk[1 << 16];
    while (true) {
      const ssize_t n = ::read(fds[0], chunk, sizeof chunk);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) read_failed = true;
      if (n <= 0) break;
      bytes.insert(bytes.end(), chunk, chunk + n);
    }
  } catch (...) {
    read_failed = true;
  }
  ::close(fds[0]);  // a child still writing gets EPIPE and ends
  // (Where the caller ignores SIGCHLD the child is reaped without a status: its output decides.)
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  char limit_text[32];
  std::snprintf(limit_text, sizeof limit_text, "%.0f", std::ceil(cpu_seconds));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    if (sig == SIGXCPU || sig == SIGKILL)
      return Status::corrupt_input(std::string("glb: decoding took more than ") + limit_text +
                                   " s of CPU and was stopped (a damaged or hostile Draco stream: "
                                   "Draco's decoder can spend seconds on a few bytes)");
    return Status::corrupt_input(std::string("glb: the decoder process died of signal ") +
                                 std::to_string(sig) + " (" + ::strsignal(sig) + ")");
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 4)
    return Status::out_of_memory("glb: the decoder process ran out of memory");
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    return Status::internal("glb: the decoder process failed (exit status " +
                            std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")");
  if (read_failed) return Status::io("glb: cannot read the decoder process's output");
  Reader r{bytes};
  std::int32_t code = 0;
  std::vector<char> message;
  if (!r.get(&code, sizeof code) || !r.get_vector(message))
    return Status::internal("glb: the decoder process's output is truncated");
  if (code != std::int32_t(StatusCode::ok))
    return Status::error(code >= 0 && code <= std::int32_t(StatusCode::internal)
                             ? StatusCode(code)
                             : StatusCode::internal,
                         std::string(message.begin(), message.end()));
  Mesh mesh;
  GlbInfo decoded;
  if (!r.get_vector(mesh.positions) || !r.get_vector(mesh.normals) || !r.get_vector(mesh.scalars) ||
      !r.get_vector(mesh.quads) || !r.get_vector(mesh.triangles) || !r.get_vector(mesh.quad_view) ||
      !r.get_vector(mesh.triangle_view) || !r.get_vector(mesh.view_dirs) ||
      !r.get(&decoded, sizeof decoded) || r.at != bytes.size())
    return Status::internal("glb: the decoder process's output is truncated");
  out = std::move(mesh);
  if (info) *info = decoded;
  return Status::ok();
}

}  // namespace ldimesh

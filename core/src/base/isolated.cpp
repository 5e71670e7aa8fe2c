// run_isolated: work on untrusted input in a child process (isolated.hpp).
#include "ldimesh/core/base/isolated.hpp"

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
#include <string>

namespace ldimesh {
namespace {

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
// (never above a hard limit it inherited), no core dump, first in line for the out-of-memory
// killer; the work, its output sent as the total
// length of the rest (8 bytes), the Status (code, message) and what the work wrote; then _exit.
[[noreturn]] void run_in_child(int fd, double cpu_seconds,
                               const std::function<Status(std::vector<std::uint8_t>&)>& work) {
  sigset_t none;
  sigemptyset(&none);
  if (::sigprocmask(SIG_SETMASK, &none, nullptr) != 0) ::_exit(kNoSignals);
  // The parent's handlers too (MPI's print a stack trace on SIGSEGV or SIGFPE): a crash ends
  // the child quietly, and the parent tells what it was.
  for (const int sig : {SIGINT, SIGTERM, SIGXCPU, SIGHUP, SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT})
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
  // The child, not the parent, is what the system's out-of-memory killer takes first.
  if (const int oom = ::open("/proc/self/oom_score_adj", O_WRONLY | O_CLOEXEC); oom >= 0) {
    [[maybe_unused]] const ssize_t written = ::write(oom, "1000", 4);
    ::close(oom);
  }
  std::vector<std::uint8_t> header, result;
  try {
    const Status s = work(result);
    if (!s) result.clear();
    ByteWriter w(header);
    w.put(std::uint64_t(0));  // the length, below
    w.put(std::int32_t(s.code()));
    w.put_vector(std::vector<char>(s.message().begin(), s.message().end()));
    const std::uint64_t length = header.size() - sizeof(std::uint64_t) + result.size();
    std::memcpy(header.data(), &length, sizeof length);
  } catch (...) {
    ::_exit(kNoMemory);
  }
  ::_exit(write_all(fd, header) && write_all(fd, result) ? 0 : kNoPipe);
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

Status run_isolated(const IsolatedTask& task,
                    const std::function<Status(std::vector<std::uint8_t>& out)>& work,
                    std::vector<std::uint8_t>& out) {
  const std::string& prefix = task.prefix;
  const double cpu_seconds = task.cpu_seconds;
  if (!(cpu_seconds >= 1.0 && cpu_seconds <= 1e6))
    return Status::invalid_argument(prefix + "the CPU limit of " + task.process +
                                    " must lie in [1, 1e6] s");
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return Status::io(prefix + "cannot create a pipe: " + std::strerror(errno));
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int e = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    return Status::io(prefix + "cannot start " + task.process + ": " + std::strerror(e));
  }
  if (pid == 0) {
    ::close(fds[0]);
    run_in_child(fds[1], cpu_seconds, work);
  }
  ::close(fds[1]);
  // Everything the child sends, read while it writes (a pipe holds only 64 KiB), until the
  // wall-time limit.
  const double wall = 4.0 * std::ceil(cpu_seconds) + 10.0;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(wall));
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
    return Status::out_of_memory(prefix + "no memory for the output of " + task.process);
  if (read_error == ETIMEDOUT)
    return Status::internal(prefix + task.process + " made no progress (stopped after " +
                            std::to_string(int(wall)) + " s)");
  if (read_error)
    return Status::io(prefix + "cannot read the output of " + task.process + ": " +
                      std::strerror(read_error));
  char limit_text[32];
  std::snprintf(limit_text, sizeof limit_text, "%.0f", std::ceil(cpu_seconds));
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    const double cpu = double(used.ru_utime.tv_sec + used.ru_stime.tv_sec) +
                       1e-6 * double(used.ru_utime.tv_usec + used.ru_stime.tv_usec);
    if (sig == SIGXCPU || (sig == SIGKILL && cpu >= std::ceil(cpu_seconds)))
      return Status::corrupt_input(prefix + task.doing + " took more than " + limit_text +
                                   " s of CPU and was stopped (" + task.over_cpu + ")");
    return Status::corrupt_input(prefix + task.process + " died of signal " + std::to_string(sig) +
                                 " (" + ::strsignal(sig) + ")" +
                                 (task.died.empty() ? "" : ": " + task.died));
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == kNoMemory)
    return Status::out_of_memory(prefix + task.process + " ran out of memory");
  if (WIFEXITED(status) && WEXITSTATUS(status) == kNoLimit)
    return Status::io(prefix + "cannot limit the CPU time of " + task.process + " (setrlimit)");
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    return Status::internal(prefix + task.process + " failed (exit status " +
                            std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + ")");
  ByteReader r(bytes);
  std::uint64_t length = 0;
  std::int32_t code = 0;
  std::vector<char> message;
  if (!r.get(length) || length != bytes.size() - sizeof length || !r.get(code) ||
      !r.get_vector(message))
    return Status::internal(prefix + "the output of " + task.process + " is truncated");
  if (code != std::int32_t(StatusCode::ok))
    return Status::error(code >= 0 && code <= std::int32_t(StatusCode::internal)
                             ? StatusCode(code)
                             : StatusCode::internal,
                         std::string(message.begin(), message.end()));
  // The payload in place (no second copy of what may be gigabytes).
  bytes.erase(bytes.begin(), bytes.begin() + std::ptrdiff_t(r.position()));
  out = std::move(bytes);
  return Status::ok();
}

}  // namespace ldimesh

// libFuzzer target for the job's HTTP server (scripts/fuzz.sh http builds and runs it with ASan
// and UBSan): what a browser, ldimesh-fetch or anyone who can reach the port sends. A real
// HttpServer listens on loopback over a store of three steps, with the viewer's files in a
// folder beside a secret file (and a symlink pointing at it; binary, so that httplib never
// compresses it and the check below sees its bytes); each input is sent as the raw bytes
// of one connection (several requests when it holds several, keep-alive), the sending side is
// then shut so that the server sees the end of the request, and the whole answer is read. The
// server must answer every input that holds a request line with HTTP responses
// (`HTTP/1.1 NNN`), never 500 (an exception or an internal error), and never the secret's
// bytes; a sanitizer report, a crash or a hang is a finding too.
//
// Long polls and event streams would hold an input for their whole wait: the store is shut down
// once its steps are in, so that they answer at once (204, or the stream's end), as at a job's
// end. cpp-httplib's own parser is Debian's library, not instrumented: coverage guides through
// its calls into our handler (paths, query strings, headers, the token, the limits).
//
// With LDIMESH_FUZZ_WRITE_SEEDS=DIR set, the binary writes its seed corpus into DIR and exits:
// requests of docs/api.md with and without the token, the viewer's files, traversal attempts,
// long polls and event streams, bodies, oversized and malformed requests.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <string_view>

#include "../transport/fake_steps.hpp"
#include "ldimesh/transport/http_server.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

#include "fuzz_seeds.hpp"

namespace {

namespace fs = std::filesystem;

constexpr std::string_view kToken = "fuzz-token";
constexpr std::string_view kSecret = "SECRET-7f3a9c-NEVER-SERVED";

struct Server {
  fs::path root;
  ldimesh::SnapshotStore store{{.max_snapshots = 4}};
  std::unique_ptr<ldimesh::HttpServer> server;
  int port = 0;

  Server() {
    root = fs::temp_directory_path() / ("ldimesh_http_fuzz_" + std::to_string(::getpid()));
    fs::create_directories(root / "web");
    fs::create_directories(root / "three/build");
    std::ofstream(root / "web/index.html") << "<html>viewer</html>";
    std::ofstream(root / "web/viewer.js") << "export {};";
    std::ofstream(root / "three/build/three.module.js") << "export const REVISION = '0';";
    std::ofstream(root / "secret.bin") << kSecret;
    std::error_code ec;
    fs::create_symlink("../secret.bin", root / "web/escape", ec);
    for (std::uint64_t step = 1; step <= 3; ++step)
      if (!store.publish(ldimesh::testing::fake_snapshot(step, 100 * step))) std::abort();
    store.shutdown();  // long polls and streams answer at once

    ldimesh::HttpServerOptions o;
    o.token = std::string(kToken);
    o.static_dir = root / "web";
    o.vendor_three_dir = root / "three";
    o.requests_per_second = 0;  // one client, as fast as it can
    o.read_timeout = std::chrono::seconds(1);
    o.write_timeout = std::chrono::seconds(1);
    o.keep_alive_timeout = std::chrono::seconds(1);
    server = std::make_unique<ldimesh::HttpServer>(store, o);
    if (const ldimesh::Status s = server->start(); !s) {
      std::fprintf(stderr, "fuzz: the server does not start: %s\n", s.message().c_str());
      std::exit(1);
    }
    port = server->port();
  }
  ~Server() {
    server.reset();
    std::error_code ec;
    fs::remove_all(root, ec);
  }
};

// Sends `bytes` on a fresh connection, shuts the sending side and returns all the server said.
std::string exchange(int port, std::string_view bytes) {
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(std::uint16_t(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  // Thousands of connections a second can run this machine out of local ports for a moment
  // (EADDRNOTAVAIL, the fuzzer's side): wait and try again, for at most 10 s. Any other failure
  // (the server no longer listening) is a finding.
  int fd = -1;
  for (int attempt = 0;; ++attempt) {
    fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) std::abort();
    if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) break;
    const int error = errno;
    ::close(fd);
    if ((error != EADDRNOTAVAIL && error != EAGAIN && error != EINTR) || attempt == 1000) {
      std::fprintf(stderr, "fuzz: cannot connect to the server: %s\n", std::strerror(error));
      __builtin_trap();
    }
    ::usleep(10000);
  }
  timeval timeout{5, 0};  // longer than any server timeout: a silent server is a hang
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  std::size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;  // the server closed early (a refused request): read what it said
    sent += std::size_t(n);
  }
  ::shutdown(fd, SHUT_WR);
  std::string answer;
  char buffer[16384];
  for (;;) {
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
      std::fprintf(stderr, "fuzz: the server said nothing for 5 s\n");
      __builtin_trap();
    }
    if (n <= 0) break;
    answer.append(buffer, std::size_t(n));
  }
  ::close(fd);
  return answer;
}

Server& server() {
  static Server s;
  return s;
}

}  // namespace

void ldimesh::fuzz::write_seeds(const std::string& dir) {
  const std::string t(kToken);
  const std::string seeds[] = {
      "GET / HTTP/1.1\r\nHost: localhost\r\n\r\n",
      "GET /viewer/viewer.js HTTP/1.1\r\n\r\nGET /vendor/three/build/three.module.js "
      "HTTP/1.1\r\nConnection: close\r\n\r\n",
      "GET /api/v1/steps?token=" + t + " HTTP/1.1\r\n\r\n",
      "GET /api/v1/latest HTTP/1.1\r\nAuthorization: Bearer " + t + "\r\n\r\n",
      "GET /api/v1/steps/2 HTTP/1.1\r\nAuthorization: Bearer " + t + "\r\n\r\n",
      "HEAD /api/v1/steps/3/mesh.glb?token=" + t + " HTTP/1.1\r\nRange: bytes=0-9\r\n\r\n",
      "GET /api/v1/steps/3/mesh.glb HTTP/1.1\r\nAuthorization: bearer  " + t + " \r\n\r\n",
      "GET /api/v1/latest?after=3&wait=2&token=" + t + " HTTP/1.1\r\n\r\n",
      "GET /api/v1/events?token=" + t + " HTTP/1.1\r\nLast-Event-ID: 1\r\n\r\n",
      "GET /api/v1/steps HTTP/1.1\r\n\r\n",
      "GET /viewer/../secret.bin HTTP/1.1\r\n\r\nGET /viewer/escape HTTP/1.1\r\n\r\n",
      "GET /viewer/%2e%2e/secret.bin HTTP/1.1\r\n\r\nGET /vendor/three/..%2f..%2fsecret.bin "
      "HTTP/1.1\r\n\r\n",
      "POST /api/v1/steps?token=" + t + " HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello",
      "GET /api/v1/steps HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
      "GET /api/v1/steps/99999999999999999999?token=" + t + " HTTP/1.1\r\n\r\n",
      "GET /api/v2/x?token=" + t + "&token=" + t + " HTTP/1.0\r\n\r\n",
      "GET / HTTP/1.1\r\nX-Long: " + std::string(20000, 'a') + "\r\n\r\n",
      "BREW /pot HTTP/1.1\r\n\r\n",
      "GET\r\n\r\n",
  };
  int k = 0;
  for (const std::string& seed : seeds)
    write_file(dir + "/seed-" + std::to_string(k++) + ".http", seed);
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const std::string answer = exchange(server().port, input);
  if (answer.find(kSecret) != std::string::npos) {
    std::fprintf(stderr, "fuzz: the secret file was served\n");
    __builtin_trap();
  }
  // Every answer the server gives is a sequence of HTTP responses; none is an internal error.
  // (The search looks into bodies too: none served here holds that text or echoes a request.)
  if (!answer.empty() && answer.rfind("HTTP/1.1 ", 0) != 0) {
    std::fprintf(stderr, "fuzz: not an HTTP response: %.80s\n", answer.c_str());
    __builtin_trap();
  }
  for (std::size_t at = answer.find("HTTP/1.1 "); at != std::string::npos;
       at = answer.find("HTTP/1.1 ", at + 1))
    if (answer.compare(at, 12, "HTTP/1.1 500") == 0) {
      std::fprintf(stderr, "fuzz: internal error: %.200s\n", answer.c_str() + at);
      __builtin_trap();
    }
  return 0;
}

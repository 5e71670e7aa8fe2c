// The job's HTTP server: serves the steps of a SnapshotStore with the API of docs/api.md, and
// the web viewer's static files. It runs on its own threads (cpp-httplib's pool) and only
// reads the store, so the publisher never waits for it; docs/method.md, "The job's HTTP
// server", explains the threads, limits and defences.
#pragma once

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh {

struct HttpServerOptions {
  // The address to listen on. The default keeps the server off the network: remote people
  // come through an SSH tunnel. An address that is not loopback (is_loopback_address) is
  // refused unless allow_remote is set: the server speaks plain HTTP, so the token, the only
  // protection then, travels over the network unencrypted (callers print a warning).
  std::string bind_address = "127.0.0.1";
  bool allow_remote = false;
  // 0 = any free port (HttpServer::port() tells which).
  int port = 0;
  // The access token every /api/ request must carry; empty = a random 128-bit token (32 hex
  // digits). A given token must be URL-safe: letters, digits and "-._~".
  std::string token;
  // The viewer's files (viewer/web: index.html, viewer.js, style.css), served at "/",
  // "/index.html" and "/viewer/…"; empty = no viewer (those paths answer 404).
  std::filesystem::path static_dir;
  // three.js (node_modules/three), served at "/vendor/three/…"; empty = none.
  std::filesystem::path vendor_three_dir;
  // Worker threads = connections served at once; further connections wait for a worker.
  int threads = 8;
  // Long polls and event streams open at once (each holds a worker), 1 ≤ max_streams <
  // threads so that plain requests always find a worker; further ones get 503.
  int max_streams = 4;
  // The largest request: headers (431 beyond) and body (413 beyond). The API takes no body.
  std::size_t max_request_bytes = 16 * 1024;
  // API requests without a valid token (a 401 each), per client (rate_limit_key: an IPv4
  // address, an IPv6 /64): at most request_burst
  // at once, refilled at requests_per_second; beyond, 429 with Retry-After for that address's
  // requests without the token. Requests with the token and the viewer's files are never
  // limited. 0 for either = no limit.
  int requests_per_second = 10;
  int request_burst = 100;
  // Per read or write on a connection: a stalled client holds a worker at most this long.
  std::chrono::seconds read_timeout{5};
  std::chrono::seconds write_timeout{5};
  // How long an idle keep-alive connection holds its worker (and delays stop()).
  std::chrono::seconds keep_alive_timeout{2};
  // The interval of keep-alive comments on event streams (proxies drop silent connections).
  std::chrono::milliseconds event_keep_alive{15000};
};

// Where the web viewer's files lie: viewer/web (with index.html) and node_modules/three, each
// from the first of these folders that has it — share/ldimesh beside the running program's bin/
// (an installed program), share/ldimesh under the install prefix configured at build time, the
// checkout the library was built in (first instead for a program run from the build tree); or
// only $LDIMESH_DATA_DIR where that is set. Empty paths (the API works without the viewer) when
// none has them.
struct ViewerFiles {
  std::filesystem::path static_dir, vendor_three_dir;
};
ViewerFiles find_viewer_files();

// Serves `store` over HTTP. start() and stop() from one thread; port(), token() and url() from
// any thread after start().
class HttpServer {
 public:
  // `store` must outlive the server. Nothing is opened before start().
  explicit HttpServer(const SnapshotStore& store, HttpServerOptions options = {});
  // Stops the server (see stop()).
  ~HttpServer();

  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Checks the options, binds the port and starts the listening thread and the worker pool;
  // returns once the server accepts connections. Errors (nothing keeps running): invalid
  // options (a bad token, a static directory that does not exist, thread counts), the port in
  // use ("… port 8080 is in use …"), an address that cannot be bound, or already started.
  // Sets SIGPIPE aside only in the server's own threads: the host's handler is left as it was.
  Status start();

  // Stops accepting, ends long polls and event streams at once (streams end with a clean
  // final chunk) and joins every thread. Returns within the longest of keep_alive_timeout,
  // read_timeout and write_timeout (a connection that is idle, half-sent or not draining), at
  // once when no connection is open. A no-op when not running. The store is left as it is.
  void stop();

  bool running() const;
  // The port it listens on (the free one picked for port 0); 0 before start().
  int port() const;
  // The access token (the generated one when options.token was empty).
  const std::string& token() const;
  // "http://ADDR:PORT/?token=TOKEN", the URL to open in a browser or give ldimesh-fetch.
  std::string url() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Whether `address` (as given to bind_address) is a loopback address: 127.0.0.0/8, ::1 (also
// written out or as ::ffff:127.x.y.z) or "localhost".
bool is_loopback_address(std::string_view address);

// Whose requests the rate limit (HttpServerOptions::requests_per_second) counts together, for a
// client's `address` as the server sees it: an IPv4 address itself (also written as an
// IPv4-mapped IPv6 one), an IPv6 address's /64 prefix ("2001:db8:1:2::/64": one host or
// network usually holds a whole /64 and can take any address in it; a link-local address's zone,
// "%eth0", is left out), anything else as given.
std::string rate_limit_key(std::string_view address);

// The warning a program prints when its server listens on a non-loopback `address`
// (allow_remote), one line ending in a newline.
std::string remote_server_warning(std::string_view address);

// A random 128-bit token as 32 lowercase hex digits, from std::random_device (throws
// std::runtime_error, as std::random_device does, where the system has no entropy source).
std::string random_token();

// Whether `given` equals `expected`, in a time that depends only on expected.size() (no early
// exit on the first differing byte, so response times do not reveal a prefix of the token).
bool tokens_equal(std::string_view given, std::string_view expected);

}  // namespace ldimesh

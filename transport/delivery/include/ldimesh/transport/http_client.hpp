// The client side of docs/api.md: list, metadata, GLB and long polls against a job's server
// (or `ldimesh-serve`), each call returning a Status whose message a person can act on.
//
// Status codes: a bad URL and a step the server does not have are invalid_argument; a server
// that cannot be reached, refuses the token, times out or closes the connection is io; what a
// server sends that is not what docs/api.md says (bad JSON, a GLB larger than the limit, shorter
// or longer than announced, or not a glTF binary) is corrupt_input. Only the constructor throws.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh {

// A server's address and token, from the URL it printed.
struct ServerUrl {
  std::string host;  // name or address; IPv6 without brackets
  int port = 80;
  std::string token;  // from "?token=…", empty when the URL has none
  // "http://HOST:PORT", for messages.
  std::string base() const;
};

// Parses "http://HOST[:PORT][/PATH][?…token=T…]" (the URL a server prints; the path is
// ignored, the API lives at /api/v1/). Errors for another scheme (https is not served: use an
// SSH tunnel), a missing host or a port outside 1..65535.
Status parse_server_url(std::string_view url, ServerUrl& out);

// One step as the server describes it: parsed, and the JSON text as served.
struct RemoteStep {
  StepMetadata metadata;
  std::string json;
};

struct HttpClientOptions {
  std::chrono::seconds connect_timeout{5};
  // Per read: a server that says nothing for this long fails the call (long polls add their
  // wait to it).
  std::chrono::seconds read_timeout{30};
  // A larger GLB is refused while it downloads (a hostile or broken server cannot make the
  // client allocate without bound).
  std::size_t max_glb_bytes = std::size_t{4} << 30;
  // A request the server answers with 503 or 429 and a Retry-After in seconds (too many long
  // polls open; too many requests without the token: docs/api.md) is asked again after those
  // seconds (at least 1, at most 10), up to this many times; then the call fails with the
  // server's message. A 503 without Retry-After (the server is stopping) fails at once. (List,
  // metadata and long polls; not a GLB download, which the server never refuses that way.)
  int retries = 5;
};

// Talks to one server. One call at a time (not thread-safe), except cancel(). The calls write
// to sockets with SIGPIPE blocked in the calling thread (one they raise is discarded): a server
// closing mid-request, or cancel(), gives an error, never the signal.
// Error messages: "cannot connect to http://…: connection refused (…)", "the server refused
// the token …", "step 42 is not on the server (it keeps steps 10 to 25)", "step 42: corrupt
// download: …".
class HttpClient {
 public:
  // `url` as for parse_server_url; a non-empty `token` replaces the URL's. Throws
  // std::invalid_argument for a URL parse_server_url rejects.
  HttpClient(std::string_view url, std::string token = {}, HttpClientOptions options = {});
  ~HttpClient();

  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;

  // The steps the server keeps, oldest first.
  Status list_steps(std::vector<RemoteStep>& out);
  // The newest step's metadata; an error when the server has none yet.
  Status latest(RemoteStep& out);
  // The metadata of `step`.
  Status step(std::uint64_t step, RemoteStep& out);
  // The GLB of `step` into `out` (replaced), checked: the Content-Length, `expected_bytes`
  // (the metadata's "bytes") when given, and the glTF binary header (check_glb_header).
  Status mesh(std::uint64_t step, std::vector<std::uint8_t>& out,
              std::optional<std::uint64_t> expected_bytes = std::nullopt);
  // Long poll: waits up to `wait` (at most 60 s) for a step newer than `after` (any step when
  // empty). `out` gets the newest step, or is empty when none came within the wait.
  Status wait_for_newer(std::optional<std::uint64_t> after, std::chrono::seconds wait,
                        std::optional<RemoteStep>& out);

  // From any thread (a signal handler's thread): makes the call in progress, if any, fail
  // promptly with an error. The client stays usable.
  void cancel();

  // "http://HOST:PORT".
  std::string base_url() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ldimesh

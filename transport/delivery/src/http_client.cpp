#include "ldimesh/transport/http_client.hpp"

#include <netdb.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <charconv>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <utility>

#include <httplib.h>
#include <nlohmann/json.hpp>

namespace ldimesh {

namespace {

constexpr std::size_t kMaxErrorBody = 64 * 1024;

std::string percent_decode(std::string_view s) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size()) {
      int value = 0;
      const auto [end, ec] = std::from_chars(s.data() + i + 1, s.data() + i + 3, value, 16);
      if (ec == std::errc() && end == s.data() + i + 3) {
        out += static_cast<char>(value);
        i += 2;
        continue;
      }
    }
    out += s[i] == '+' ? ' ' : s[i];
  }
  return out;
}

// The "error" member of a server's JSON error body, or empty.
std::string server_message(std::string_view body) {
  const auto j = nlohmann::json::parse(body, nullptr, /*allow_exceptions=*/false);
  if (j.is_object() && j.contains("error") && j["error"].is_string())
    return j["error"].get<std::string>();
  return {};
}

Status parse_step(std::string body, RemoteStep& out) {
  RemoteStep step;
  if (Status s = metadata_from_json(body, step.metadata); !s)
    return Status::corrupt_input("the server sent bad " + s.message());
  step.json = std::move(body);
  out = std::move(step);
  return Status::ok();
}

}  // namespace

std::string ServerUrl::base() const {
  const bool ipv6 = host.find(':') != std::string::npos;
  return "http://" + (ipv6 ? "[" + host + "]" : host) + ":" + std::to_string(port);
}

Status parse_server_url(std::string_view url, ServerUrl& out) {
  ServerUrl parsed;
  std::string_view rest = url;
  if (const std::size_t scheme = rest.find("://"); scheme != std::string_view::npos) {
    std::string name(rest.substr(0, scheme));
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (name == "https")
      return Status::invalid_argument(
          "https is not served: the server speaks http (use an SSH tunnel)");
    if (name != "http")
      return Status::invalid_argument("'" + std::string(url) + "' is not an http:// URL");
    rest.remove_prefix(scheme + 3);
  }
  const std::size_t authority_end = std::min(rest.find_first_of("/?#"), rest.size());
  std::string_view authority = rest.substr(0, authority_end);
  std::string_view port_text;
  if (authority.starts_with("[")) {
    const std::size_t close = authority.find(']');
    if (close == std::string_view::npos)
      return Status::invalid_argument("'" + std::string(url) + "': unclosed [ in the address");
    parsed.host = std::string(authority.substr(1, close - 1));
    const std::string_view after = authority.substr(close + 1);
    if (!after.empty()) {
      if (after.front() != ':')
        return Status::invalid_argument("'" + std::string(url) + "': bad address");
      port_text = after.substr(1);
    }
  } else {
    const std::size_t colon = authority.rfind(':');
    parsed.host = std::string(authority.substr(0, colon));
    if (colon != std::string_view::npos) port_text = authority.substr(colon + 1);
  }
  if (parsed.host.empty())
    return Status::invalid_argument("'" + std::string(url) + "' names no host");
  if (!port_text.empty() || authority.ends_with(":")) {
    int port = 0;
    const auto [end, ec] =
        std::from_chars(port_text.data(), port_text.data() + port_text.size(), port);
    if (ec != std::errc() || end != port_text.data() + port_text.size() || port < 1 ||
        port > 65535) {
      return Status::invalid_argument("'" + std::string(url) + "': the port is not in 1..65535");
    }
    parsed.port = port;
  }
  rest.remove_prefix(authority_end);
  rest = rest.substr(0, std::min(rest.find('#'), rest.size()));
  if (const std::size_t query = rest.find('?'); query != std::string_view::npos) {
    std::string_view params = rest.substr(query + 1);
    while (!params.empty()) {
      const std::size_t amp = std::min(params.find('&'), params.size());
      const std::string_view param = params.substr(0, amp);
      if (param.starts_with("token=")) parsed.token = percent_decode(param.substr(6));
      params.remove_prefix(std::min(amp + 1, params.size()));
    }
  }
  out = std::move(parsed);
  return Status::ok();
}

// While a request runs, SIGPIPE is blocked in the calling thread, and one its writes raised is
// taken off before the thread's mask is restored. Debian's libcpp-httplib sends without
// MSG_NOSIGNAL, so a write to a socket the server closed, or that cancel() shut down (it stops
// the request from another thread), raised SIGPIPE and killed a process that does not ignore it
// (seen in the test of cancel(): Http.ClientCancelEndsALongPollInFlight died of SIGPIPE). A
// SIGPIPE raised by a write is directed at the writing thread.
class SigpipeBlocked {
 public:
  SigpipeBlocked() {
    sigemptyset(&pipe_);
    sigaddset(&pipe_, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipe_, &old_);
    sigset_t pending;
    was_pending_ = sigpending(&pending) == 0 && sigismember(&pending, SIGPIPE) == 1;
  }
  ~SigpipeBlocked() {
    sigset_t pending;
    if (!was_pending_ && sigpending(&pending) == 0 && sigismember(&pending, SIGPIPE) == 1) {
      const timespec now{0, 0};
      sigtimedwait(&pipe_, nullptr, &now);
    }
    pthread_sigmask(SIG_SETMASK, &old_, nullptr);
  }
  SigpipeBlocked(const SigpipeBlocked&) = delete;
  SigpipeBlocked& operator=(const SigpipeBlocked&) = delete;

 private:
  sigset_t pipe_, old_;
  bool was_pending_ = false;
};

struct HttpClient::Impl {
  Impl(ServerUrl u, HttpClientOptions o)
      : url(std::move(u)), options(o), client(url.host, url.port) {
    client.set_connection_timeout(options.connect_timeout);
    client.set_read_timeout(options.read_timeout);
    client.set_write_timeout(options.read_timeout);
    // One connection per call: nothing to go stale between the polls of `--follow`.
    client.set_keep_alive(false);
    if (!url.token.empty()) client.set_bearer_token_auth(url.token);
  }

  ServerUrl url;
  HttpClientOptions options;
  httplib::Client client;
  std::atomic<bool> canceled{false};    // cancel(): no further retry
  std::atomic<bool> requesting{false};  // a request in flight, which cancel() stops

  // Marks a request in flight; false where cancel() came first. cancel() sets `canceled`, then
  // reads `requesting`; this sets `requesting`, then reads `canceled` (sequentially consistent):
  // one of the two sees the other, so a cancel() that lands just before the request starts
  // is not lost.
  bool begin_request() {
    requesting = true;
    if (!canceled) return true;
    requesting = false;
    return false;
  }

  Status transport_error(httplib::Error error, const std::string& what) const;
  Status http_error(int status, const std::string& body, const std::string& what);
  Status get(const std::string& path, const std::string& what, std::string& body, int& status);
  Status not_found(std::uint64_t step);
};

Status HttpClient::Impl::transport_error(httplib::Error error, const std::string& what) const {
  const std::string base = url.base();
  switch (error) {
    case httplib::Error::Connection: {
      // httplib reports a name that does not resolve like a refused connection.
      addrinfo hints{};
      hints.ai_socktype = SOCK_STREAM;
      addrinfo* found = nullptr;
      if (::getaddrinfo(url.host.c_str(), nullptr, &hints, &found) != 0)
        return Status::io("cannot connect to " + base + ": unknown host '" + url.host + "'");
      ::freeaddrinfo(found);
      return Status::io("cannot connect to " + base +
                        ": connection refused (is the server running? is the SSH tunnel up?)");
    }
    case httplib::Error::ConnectionTimeout:
      return Status::io("cannot connect to " + base + ": timed out after " +
                        std::to_string(options.connect_timeout.count()) + " s");
    case httplib::Error::Read:
      return Status::io(base + ": the connection broke or timed out while reading " + what);
    case httplib::Error::Write:
      return Status::io(base + ": the connection broke while asking for " + what);
    case httplib::Error::Canceled:
      return Status::io(base + ": " + what + ": interrupted");
    default:
      return Status::io(base + ": " + what + ": " + httplib::to_string(error));
  }
}

Status HttpClient::Impl::http_error(int status, const std::string& body, const std::string& what) {
  if (status == 401) {
    return Status::io(url.token.empty()
                          ? "the server wants a token: use the URL it printed (…/?token=…)"
                          : "the server refused the token (use the one in the URL it printed)");
  }
  const std::string said = server_message(body);
  return Status::io(url.base() + ": " + what + ": HTTP " + std::to_string(status) +
                    (said.empty() ? "" : " (" + said + ")"));
}

Status HttpClient::Impl::get(const std::string& path, const std::string& what, std::string& body,
                             int& status) {
  canceled = false;  // a cancel() before this call ended the one before
  for (int attempt = 0;; ++attempt) {
    if (!begin_request()) return transport_error(httplib::Error::Canceled, what);
    const SigpipeBlocked no_sigpipe;
    auto result = client.Get(path);
    requesting = false;
    // A request cancel() stopped fails as a read or write on the closed socket: "interrupted".
    if (!result) return transport_error(canceled ? httplib::Error::Canceled : result.error(), what);
    status = result->status;
    body = std::move(result->body);
    if ((status != 503 && status != 429) || attempt >= options.retries) return Status::ok();
    // Busy (503) or rate-limited (429) with a Retry-After in seconds: wait as the server asks
    // (1 to 10 s), in slices that cancel() ends. Without one (a server that is stopping) the
    // answer stands.
    const std::string after = result->get_header_value("Retry-After");
    int seconds = -1;
    const auto [end, ec] = std::from_chars(after.data(), after.data() + after.size(), seconds);
    if (after.empty() || ec != std::errc() || end != after.data() + after.size() || seconds < 0)
      return Status::ok();
    seconds = std::clamp(seconds, 1, 10);
    for (int slice = 0; slice < seconds * 10; ++slice) {
      if (canceled) return transport_error(httplib::Error::Canceled, what);
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (canceled) return transport_error(httplib::Error::Canceled, what);
  }
}

Status HttpClient::Impl::not_found(std::uint64_t step) {
  // Say which steps there are, so that the person can pick one.
  std::string body;
  int status = 0;
  std::string kept = "…";
  if (get("/api/v1/steps", "the list of steps", body, status) && status == 200) {
    const auto j = nlohmann::json::parse(body, nullptr, false);
    std::vector<std::uint64_t> steps;
    if (j.is_object() && j.contains("steps") && j["steps"].is_array()) {
      for (const auto& s : j["steps"]) {
        if (s.is_object() && s.contains("step") && s["step"].is_number_unsigned())
          steps.push_back(s["step"].get<std::uint64_t>());
      }
    }
    if (steps.empty())
      kept = "it has no step yet";
    else if (steps.size() == 1)
      kept = "it keeps step " + std::to_string(steps.front());
    else
      kept =
          "it keeps steps " + std::to_string(steps.front()) + " to " + std::to_string(steps.back());
  }
  return Status::invalid_argument("step " + std::to_string(step) + " is not on the server (" +
                                  kept + ")");
}

HttpClient::HttpClient(std::string_view url, std::string token, HttpClientOptions options) {
  ServerUrl parsed;
  if (Status s = parse_server_url(url, parsed); !s) throw std::invalid_argument(s.message());
  if (!token.empty()) parsed.token = std::move(token);
  impl_ = std::make_unique<Impl>(std::move(parsed), options);
}

HttpClient::~HttpClient() = default;

std::string HttpClient::base_url() const {
  return impl_->url.base();
}

void HttpClient::cancel() {
  impl_->canceled = true;
  // Only a request in flight needs stopping (a retry's wait ends on the flag; begin_request sees
  // one that comes before the request). httplib's stop() locks inside libcpp-httplib.so and
  // unlocks inline here, which ThreadSanitizer reports (tsan.supp says why that is suppressed).
  if (impl_->requesting) impl_->client.stop();
}

Status HttpClient::list_steps(std::vector<RemoteStep>& out) {
  std::string body;
  int status = 0;
  const std::string what = "the list of steps";
  if (Status s = impl_->get("/api/v1/steps", what, body, status); !s) return s;
  if (status != 200) return impl_->http_error(status, body, what);
  const auto j = nlohmann::ordered_json::parse(body, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("steps") || !j["steps"].is_array())
    return Status::corrupt_input(impl_->url.base() + ": the list of steps is not {\"steps\": […]}");
  std::vector<RemoteStep> steps;
  for (const auto& s : j["steps"]) {
    RemoteStep step;
    if (Status st = parse_step(s.dump(), step); !st) return st;
    steps.push_back(std::move(step));
  }
  out = std::move(steps);
  return Status::ok();
}

Status HttpClient::latest(RemoteStep& out) {
  std::string body;
  int status = 0;
  const std::string what = "the latest step";
  if (Status s = impl_->get("/api/v1/latest", what, body, status); !s) return s;
  if (status == 404) return Status::io("the server has no step yet");
  if (status != 200) return impl_->http_error(status, body, what);
  return parse_step(std::move(body), out);
}

Status HttpClient::step(std::uint64_t step, RemoteStep& out) {
  std::string body;
  int status = 0;
  const std::string what = "step " + std::to_string(step);
  if (Status s = impl_->get("/api/v1/steps/" + std::to_string(step), what, body, status); !s)
    return s;
  if (status == 404) return impl_->not_found(step);
  if (status != 200) return impl_->http_error(status, body, what);
  return parse_step(std::move(body), out);
}

Status HttpClient::mesh(std::uint64_t step, std::vector<std::uint8_t>& out,
                        std::optional<std::uint64_t> expected_bytes) {
  const std::string what = "step " + std::to_string(step);
  const std::size_t limit = impl_->options.max_glb_bytes;
  int status = 0;
  std::optional<std::uint64_t> content_length;
  bool too_large = false;
  std::vector<std::uint8_t> glb;
  std::string error_body;
  impl_->canceled = false;  // a cancel() before this call ended the one before
  if (!impl_->begin_request())
    return impl_->transport_error(httplib::Error::Canceled, "the mesh of " + what);
  const SigpipeBlocked no_sigpipe;
  auto result = impl_->client.Get(
      "/api/v1/steps/" + std::to_string(step) + "/mesh.glb",
      [&](const httplib::Response& response) {
        status = response.status;
        if (response.has_header("Content-Length") && !response.has_header("Content-Encoding")) {
          const std::string text = response.get_header_value("Content-Length");
          std::uint64_t length = 0;
          const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), length);
          if (ec == std::errc() && end == text.data() + text.size()) content_length = length;
        }
        if (status == 200 && content_length && *content_length > limit) too_large = true;
        if (status == 200 && content_length && !too_large)
          glb.reserve(static_cast<std::size_t>(*content_length));
        return !too_large;
      },
      [&](const char* data, std::size_t size) {
        if (status != 200) {
          if (error_body.size() < kMaxErrorBody) error_body.append(data, size);
          return true;
        }
        if (glb.size() + size > limit) {
          too_large = true;
          return false;
        }
        glb.insert(glb.end(), data, data + size);
        return true;
      });
  impl_->requesting = false;
  if (too_large) {
    return Status::corrupt_input(what + ": corrupt download: larger than the limit of " +
                                 std::to_string(limit) + " bytes");
  }
  if (!result)
    return impl_->transport_error(impl_->canceled ? httplib::Error::Canceled : result.error(),
                                  "the mesh of " + what);
  if (status == 404) return impl_->not_found(step);
  if (status != 200) return impl_->http_error(status, error_body, "the mesh of " + what);
  if (content_length && *content_length != glb.size()) {
    return Status::corrupt_input(what + ": corrupt download: " + std::to_string(glb.size()) +
                                 " bytes, the Content-Length says " +
                                 std::to_string(*content_length));
  }
  if (expected_bytes && *expected_bytes != glb.size()) {
    return Status::corrupt_input(what + ": corrupt download: " + std::to_string(glb.size()) +
                                 " bytes, the metadata says " + std::to_string(*expected_bytes));
  }
  if (Status s = check_glb_header(glb); !s)
    return Status::corrupt_input(what + ": corrupt download: " + s.message());
  out = std::move(glb);
  return Status::ok();
}

Status HttpClient::wait_for_newer(std::optional<std::uint64_t> after, std::chrono::seconds wait,
                                  std::optional<RemoteStep>& out) {
  wait = std::clamp(wait, std::chrono::seconds(0), std::chrono::seconds(60));
  std::string path = "/api/v1/latest?wait=" + std::to_string(wait.count());
  if (after) path += "&after=" + std::to_string(*after);
  const std::string what = "the next step";
  // The server answers after up to `wait`: the read timeout must outlast it.
  impl_->client.set_read_timeout(impl_->options.read_timeout + wait);
  std::string body;
  int status = 0;
  Status s = impl_->get(path, what, body, status);
  impl_->client.set_read_timeout(impl_->options.read_timeout);
  if (!s) return s;
  if (status == 204 || (status == 404 && !after)) {
    out.reset();
    return Status::ok();
  }
  if (status != 200) return impl_->http_error(status, body, what);
  RemoteStep step;
  if (Status p = parse_step(std::move(body), step); !p) return p;
  out = std::move(step);
  return Status::ok();
}

}  // namespace ldimesh

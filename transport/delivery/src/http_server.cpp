#include "ldimesh/transport/http_server.hpp"

#include <arpa/inet.h>
#include <pthread.h>
#include <signal.h>
#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <optional>
#include <random>
#include <stop_token>
#include <thread>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include <httplib.h>
#include <nlohmann/json.hpp>

namespace ldimesh {

namespace fs = std::filesystem;

namespace {

using httplib::Request;
using httplib::Response;

constexpr std::size_t kMaxStaticFileBytes = std::size_t{64} << 20;
constexpr std::size_t kGlbWriteBlock = std::size_t{256} << 10;
constexpr std::uint64_t kMaxWaitSeconds = 60;  // docs/api.md: long polls wait at most 60 s

void set_error(Response& res, int status, const std::string& message) {
  res.status = status;
  res.set_content(nlohmann::json{{"error", message}}.dump(-1, ' ', false,
                                                          nlohmann::json::error_handler_t::replace),
                  "application/json");
}

std::optional<std::uint64_t> parse_u64(std::string_view text) {
  std::uint64_t value = 0;
  if (text.empty() ||
      !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::nullopt;
  }
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

bool is_url_safe_token(std::string_view token) {
  return !token.empty() && std::all_of(token.begin(), token.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ||
           c == '.' || c == '_' || c == '~';
  });
}

// A relative path that cannot leave its root by itself: segments that are not empty, "." or
// "..", no backslash, no control character. Symlinks are checked after resolution.
bool is_plain_relative_path(std::string_view rel) {
  if (rel.empty() || rel.front() == '/') return false;
  for (char c : rel) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f || c == '\\') return false;
  }
  std::size_t begin = 0;
  while (begin <= rel.size()) {
    const std::size_t end = std::min(rel.find('/', begin), rel.size());
    const std::string_view segment = rel.substr(begin, end - begin);
    if (segment.empty() || segment == "." || segment == "..") return false;
    begin = end + 1;
  }
  return true;
}

// Whether `path` is `root` or lies below it, component by component (a string prefix would
// let "/srv/web-secret" pass for the root "/srv/web").
bool is_within(const fs::path& root, const fs::path& path) {
  const auto [r, p] = std::mismatch(root.begin(), root.end(), path.begin(), path.end());
  return r == root.end();
}

std::string mime_type(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  // Module scripts and the Draco decoder's WebAssembly are refused under a wrong type.
  if (ext == ".html" || ext == ".htm") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json" || ext == ".map") return "application/json";
  if (ext == ".wasm") return "application/wasm";
  if (ext == ".svg") return "image/svg+xml";
  if (ext == ".png") return "image/png";
  if (ext == ".jpg" || ext == ".jpeg") return "image/jpeg";
  if (ext == ".ico") return "image/x-icon";
  if (ext == ".glb") return "model/gltf-binary";
  if (ext == ".gltf") return "model/gltf+json";
  if (ext == ".txt" || ext == ".md") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

// "event: step" with the metadata as data; a data: line per line of the JSON (one, as the
// store holds it, unless a step file was written pretty-printed). The id lets a reconnecting
// EventSource say, in Last-Event-ID, which step it has.
std::string step_event(const Snapshot& snapshot) {
  std::string event = "id: " + std::to_string(snapshot.step) + "\nevent: step\n";
  std::string_view json = snapshot.metadata_json;
  while (!json.empty()) {
    const std::size_t end = std::min(json.find('\n'), json.size());
    std::string_view line = json.substr(0, end);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    event += "data: ";
    event += line;
    event += '\n';
    json.remove_prefix(std::min(end + 1, json.size()));
  }
  event += '\n';
  return event;
}

// Requests without a valid token per client (rate_limit_key), as a token bucket each: `burst` at
// once, refilled at `rate` per second. Buckets that have refilled are forgotten once there are
// many, and all of them if that frees nothing (so many addresses cannot grow the map without bound;
// they get a fresh burst instead).
class RequestLimiter {
 public:
  RequestLimiter(int rate, int burst) : rate_(rate), burst_(burst) {}

  // Whether a request from `address` may go on now; takes one token when it may.
  bool allow(const std::string& address) {
    if (rate_ <= 0 || burst_ <= 0) return true;
    const std::lock_guard lock(mutex_);
    const auto now = std::chrono::steady_clock::now();  // under the lock: times only increase
    if (buckets_.size() >= kMaxAddresses) {
      forget_full(now);
      if (buckets_.size() >= kMaxAddresses) buckets_.clear();
    }
    auto [it, fresh] = buckets_.try_emplace(address, Bucket{double(burst_), now});
    Bucket& b = it->second;
    if (!fresh) b = Bucket{level(b, now), now};
    if (b.tokens < 1.0) return false;
    b.tokens -= 1.0;
    return true;
  }

 private:
  struct Bucket {
    double tokens;
    std::chrono::steady_clock::time_point last;
  };
  static constexpr std::size_t kMaxAddresses = 4096;

  double level(const Bucket& b, std::chrono::steady_clock::time_point now) const {
    const double seconds = std::chrono::duration<double>(now - b.last).count();
    return std::min(double(burst_), b.tokens + seconds * rate_);
  }
  void forget_full(std::chrono::steady_clock::time_point now) {
    std::erase_if(buckets_, [&](const auto& entry) { return level(entry.second, now) >= burst_; });
  }

  const int rate_, burst_;
  std::mutex mutex_;
  std::unordered_map<std::string, Bucket> buckets_;
};

std::string describe_kept_steps(const SnapshotStore& store) {
  const auto kept = store.list();
  if (kept.empty()) return "it has no step yet";
  if (kept.size() == 1) return "it keeps step " + std::to_string(kept.front()->step);
  return "it keeps steps " + std::to_string(kept.front()->step) + " to " +
         std::to_string(kept.back()->step);
}

}  // namespace

struct HttpServer::Impl {
  Impl(const SnapshotStore& s, HttpServerOptions o)
      : store(s),
        options(std::move(o)),
        limiter(options.requests_per_second, options.request_burst) {}

  const SnapshotStore& store;
  HttpServerOptions options;
  std::string token;
  fs::path static_root;  // canonical, or empty
  fs::path vendor_root;  // canonical, or empty
  std::unique_ptr<httplib::Server> server;
  std::thread listener;
  std::atomic<bool> listener_done{false};
  std::stop_source stop_source;  // ends long polls and event streams at stop()
  std::atomic<int> open_streams{0};
  std::atomic<int> port{0};
  RequestLimiter limiter;

  httplib::Server::HandlerResponse handle(const Request& req, Response& res);
  void dispatch(const Request& req, Response& res);
  bool authorized(const Request& req) const;
  void api(const Request& req, Response& res, std::string_view path);
  void list_steps(Response& res);
  void latest(const Request& req, Response& res);
  void step_metadata(std::uint64_t step, Response& res);
  void step_mesh(std::uint64_t step, Response& res);
  void events(const Request& req, Response& res);
  void serve_file(const fs::path& root, std::string_view rel, Response& res);
  bool acquire_stream();
  void release_stream() { open_streams.fetch_sub(1); }
};

httplib::Server::HandlerResponse HttpServer::Impl::handle(const Request& req, Response& res) {
  // Every request ends here (the pre-routing handler), so nothing reaches httplib's own
  // routing, whose std::regex matching recurses per character of the path.
  try {
    res.set_header("X-Content-Type-Options", "nosniff");
    dispatch(req, res);
  } catch (const std::exception& e) {
    set_error(res, 500, std::string("internal error: ") + e.what());
  } catch (...) {
    set_error(res, 500, "internal error");
  }
  return httplib::Server::HandlerResponse::Handled;
}

void HttpServer::Impl::dispatch(const Request& req, Response& res) {
  std::size_t header_bytes = req.target.size();
  for (const auto& [key, value] : req.headers)
    header_bytes += key.size() + value.size() + 4;
  if (header_bytes > options.max_request_bytes) {
    res.set_header("Connection", "close");
    return set_error(res, 431, "request headers too large");
  }
  if (req.has_header("Transfer-Encoding")) {
    res.set_header("Connection", "close");
    return set_error(res, 400, "requests take no body");
  }
  if (req.has_header("Content-Length")) {
    const auto length = parse_u64(req.get_header_value("Content-Length"));
    if (!length) return set_error(res, 400, "bad Content-Length");
    if (*length > options.max_request_bytes) {
      res.set_header("Connection", "close");
      return set_error(res, 413, "request too large");
    }
    if (*length > 0) {
      res.set_header("Connection", "close");
      return set_error(res, 400, "requests take no body");
    }
  }
  if (req.method != "GET" && req.method != "HEAD") {
    res.set_header("Allow", "GET, HEAD");
    return set_error(res, 405, "only GET and HEAD");
  }

  const std::string_view path = req.path;
  if (path == "/api" || path.starts_with("/api/")) {
    res.set_header("Cache-Control", "no-store");
    if (!authorized(req)) {
      // Guessing the token: requests without it are limited per address; the owner's, with
      // it, never are (everyone through an SSH tunnel comes from 127.0.0.1).
      if (!limiter.allow(rate_limit_key(req.remote_addr))) {
        res.set_header("Retry-After", "1");
        return set_error(res, 429, "too many requests without a valid token from this address");
      }
      res.set_header("WWW-Authenticate", "Bearer");
      return set_error(res, 401,
                       "missing or wrong token: open the URL the job printed (…/?token=…)");
    }
    return api(req, res, path);
  }
  res.set_header("Cache-Control", "no-cache");
  if (path == "/" || path == "/index.html") return serve_file(static_root, "index.html", res);
  if (path.starts_with("/viewer/")) return serve_file(static_root, path.substr(8), res);
  if (path.starts_with("/vendor/three/")) return serve_file(vendor_root, path.substr(14), res);
  set_error(res, 404, "not found");
}

bool HttpServer::Impl::authorized(const Request& req) const {
  const std::string header = req.get_header_value("Authorization");
  if (header.size() > 7 &&
      (header.compare(0, 7, "Bearer ") == 0 || header.compare(0, 7, "bearer ") == 0)) {
    std::string_view given(header);
    given.remove_prefix(7);
    while (!given.empty() && given.front() == ' ')
      given.remove_prefix(1);
    while (!given.empty() && given.back() == ' ')
      given.remove_suffix(1);
    if (tokens_equal(given, token)) return true;
  }
  return req.has_param("token") && tokens_equal(req.get_param_value("token"), token);
}

void HttpServer::Impl::api(const Request& req, Response& res, std::string_view path) {
  constexpr std::string_view v1 = "/api/v1/";
  if (!path.starts_with(v1)) return set_error(res, 404, "no such API path (try /api/v1/…)");
  std::string_view rest = path.substr(v1.size());
  if (rest == "steps") return list_steps(res);
  if (rest == "latest") return latest(req, res);
  if (rest == "events") return events(req, res);
  if (rest.starts_with("steps/")) {
    rest.remove_prefix(6);
    const std::size_t slash = std::min(rest.find('/'), rest.size());
    const auto step = parse_u64(rest.substr(0, slash));
    const std::string_view tail = rest.substr(slash);
    if (step && tail.empty()) return step_metadata(*step, res);
    if (step && tail == "/mesh.glb") return step_mesh(*step, res);
  }
  set_error(res, 404, "no such API path");
}

void HttpServer::Impl::list_steps(Response& res) {
  const auto kept = store.list();
  std::string body = "{\"steps\": [";
  for (std::size_t i = 0; i < kept.size(); ++i) {
    if (i) body += ", ";
    body += kept[i]->metadata_json;
  }
  body += "]}";
  res.set_content(body, "application/json");
}

bool HttpServer::Impl::acquire_stream() {
  if (open_streams.fetch_add(1) < options.max_streams) return true;
  open_streams.fetch_sub(1);
  return false;
}

void HttpServer::Impl::latest(const Request& req, Response& res) {
  std::optional<std::uint64_t> after;
  std::uint64_t wait = 0;
  if (req.has_param("after")) {
    after = parse_u64(req.get_param_value("after"));
    if (!after) return set_error(res, 400, "after must be a step number");
  }
  if (req.has_param("wait")) {
    const auto w = parse_u64(req.get_param_value("wait"));
    if (!w || *w > kMaxWaitSeconds) return set_error(res, 400, "wait must be 0 to 60 seconds");
    wait = *w;
  }

  // A step newer than `after` (any step without it) is the answer at once, wait or not.
  std::shared_ptr<const Snapshot> snapshot = store.latest();
  if (snapshot && after && snapshot->step <= *after) snapshot = nullptr;
  if (!snapshot && wait > 0) {
    // Waiting takes one of max_streams until the answer, even where the client has gone in
    // between (httplib 0.11 shows a handler nothing of its connection): a client that cancels a
    // long poll leaves its place taken for the rest of the wait.
    if (!acquire_stream()) {
      res.set_header("Retry-After", "1");
      return set_error(res, 503, "too many long polls and event streams open");
    }
    snapshot = store.wait_for_newer(after, std::chrono::seconds(wait), stop_source.get_token());
    release_stream();
  }

  if (snapshot) return res.set_content(snapshot->metadata_json, "application/json");
  if (stop_source.stop_requested()) return set_error(res, 503, "the server is stopping");
  if (!after && wait == 0) return set_error(res, 404, "no step has been published yet");
  if (wait > 0 && store.is_shut_down()) return set_error(res, 503, "the job is ending");
  res.status = 204;  // nothing newer within the wait
}

void HttpServer::Impl::step_metadata(std::uint64_t step, Response& res) {
  const auto snapshot = store.find(step);
  if (!snapshot) {
    return set_error(res, 404,
                     "step " + std::to_string(step) + " is not on the server (" +
                         describe_kept_steps(store) + ")");
  }
  res.set_content(snapshot->metadata_json, "application/json");
}

void HttpServer::Impl::step_mesh(std::uint64_t step, Response& res) {
  std::shared_ptr<const Snapshot> snapshot = store.find(step);
  if (!snapshot) {
    return set_error(res, 404,
                     "step " + std::to_string(step) + " is not on the server (" +
                         describe_kept_steps(store) + ")");
  }
  // The provider holds the snapshot: eviction during the download frees nothing it reads, and
  // the bytes go out from the snapshot itself, without a copy.
  const std::size_t size = snapshot->glb->size();
  res.set_content_provider(size, "model/gltf-binary",
                           [snapshot = std::move(snapshot)](std::size_t offset, std::size_t length,
                                                            httplib::DataSink& sink) {
                             const std::size_t n = std::min(length, kGlbWriteBlock);
                             return sink.write(
                                 reinterpret_cast<const char*>(snapshot->glb->data()) + offset, n);
                           });
}

void HttpServer::Impl::events(const Request& req, Response& res) {
  if (!acquire_stream()) {
    res.set_header("Retry-After", "1");
    return set_error(res, 503, "too many long polls and event streams open");
  }
  struct Stream {
    std::optional<std::uint64_t> after;  // the last step sent
    bool started = false;
  };
  auto stream = std::make_shared<Stream>();
  // A reconnecting EventSource sends the id of the last event it got: go on from there.
  if (req.has_header("Last-Event-ID"))
    stream->after = parse_u64(req.get_header_value("Last-Event-ID"));
  res.set_header("Cache-Control", "no-cache");
  res.set_chunked_content_provider(
      "text/event-stream",
      [this, stream, stop = stop_source.get_token()](std::size_t, httplib::DataSink& sink) {
        // Runs outside httplib's exception guard: nothing may escape.
        try {
          if (!stream->started) {
            stream->started = true;
            static constexpr std::string_view hello = "retry: 2000\n\n";
            return sink.write(hello.data(), hello.size());
          }
          const auto snapshot = store.wait_for_newer(stream->after, options.event_keep_alive, stop);
          if (stop.stop_requested() || (!snapshot && store.is_shut_down())) {
            sink.done();  // the final chunk: the client sees a clean end
            return true;
          }
          std::string chunk;
          if (snapshot) {
            stream->after = snapshot->step;
            chunk = step_event(*snapshot);
          } else {
            chunk = ": keep-alive\n\n";
          }
          // False once the client has gone: httplib then closes the connection.
          return sink.write(chunk.data(), chunk.size());
        } catch (...) {
          return false;
        }
      },
      [this](bool) { release_stream(); });
}

void HttpServer::Impl::serve_file(const fs::path& root, std::string_view rel, Response& res) {
  if (root.empty()) return set_error(res, 404, "no viewer files on this server");
  if (rel.empty()) return set_error(res, 404, "not found");  // a directory: no listings
  if (!is_plain_relative_path(rel)) return set_error(res, 400, "bad path");
  std::error_code ec;
  // weakly_canonical resolves symlinks: a link inside the root pointing out of it lands
  // outside and is refused like a "..".
  const fs::path resolved = fs::weakly_canonical(root / fs::path(rel), ec);
  if (ec || !is_within(root, resolved) || !fs::is_regular_file(resolved, ec))
    return set_error(res, 404, "not found");
  const auto size = fs::file_size(resolved, ec);
  if (ec || size > kMaxStaticFileBytes) return set_error(res, 404, "not found");
  std::string body(static_cast<std::size_t>(size), '\0');
  std::ifstream in(resolved, std::ios::binary);
  if (!in.read(body.data(), static_cast<std::streamsize>(body.size())))
    return set_error(res, 500, "cannot read the file");
  res.set_content(std::move(body), mime_type(resolved));
}

HttpServer::HttpServer(const SnapshotStore& store, HttpServerOptions options)
    : impl_(std::make_unique<Impl>(store, std::move(options))) {}

HttpServer::~HttpServer() {
  stop();
}

Status HttpServer::start() {
  Impl& m = *impl_;
  const HttpServerOptions& o = m.options;
  if (m.server) return Status::invalid_argument("the HTTP server is already running");
  if (o.threads < 2) return Status::invalid_argument("the HTTP server needs at least 2 threads");
  if (o.max_streams < 1 || o.max_streams >= o.threads)
    return Status::invalid_argument("max_streams must be at least 1 and less than threads");
  if (o.requests_per_second < 0 || o.request_burst < 0)
    return Status::invalid_argument("requests_per_second and request_burst must be ≥ 0");
  if (!o.allow_remote && !is_loopback_address(o.bind_address))
    return Status::invalid_argument(
        "refusing to listen on " + o.bind_address +
        ", which is not a loopback address: the server speaks plain HTTP, so its token would "
        "travel over the network unencrypted. Use 127.0.0.1 with an SSH tunnel, or allow it "
        "explicitly (server option \"allow_remote\": true, ldimesh serve --allow-remote)");
  if (o.max_request_bytes == 0 || o.read_timeout.count() <= 0 || o.write_timeout.count() <= 0 ||
      o.keep_alive_timeout.count() <= 0 || o.event_keep_alive.count() <= 0) {
    return Status::invalid_argument("the request size limit and the timeouts must be positive");
  }
  if (o.port < 0 || o.port > 65535)
    return Status::invalid_argument("port " + std::to_string(o.port) + " is not in 0..65535");
  if (!o.token.empty() && !is_url_safe_token(o.token))
    return Status::invalid_argument("the token may hold only letters, digits and -._~");
  m.token = o.token.empty() ? random_token() : o.token;
  for (const auto& [dir, root, what] :
       {std::tuple{&o.static_dir, &m.static_root, "viewer directory"},
        std::tuple{&o.vendor_three_dir, &m.vendor_root, "three.js directory"}}) {
    root->clear();
    if (dir->empty()) continue;
    std::error_code ec;
    *root = fs::canonical(*dir, ec);
    if (ec || !fs::is_directory(*root, ec))
      return Status::invalid_argument(std::string(what) + " '" + dir->string() +
                                      "' is not a directory");
  }

  // httplib::Server's constructor ignores SIGPIPE for the whole process; the host's handler
  // is put back, and the server's own threads block SIGPIPE instead (a write to a client that
  // has gone then fails with EPIPE, in that thread only).
  struct sigaction host_sigpipe {};
  ::sigaction(SIGPIPE, nullptr, &host_sigpipe);
  auto server = std::make_unique<httplib::Server>();
  ::sigaction(SIGPIPE, &host_sigpipe, nullptr);

  const auto threads = static_cast<std::size_t>(o.threads);
  server->new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  server->set_read_timeout(o.read_timeout);
  server->set_write_timeout(o.write_timeout);
  server->set_keep_alive_timeout(o.keep_alive_timeout.count());
  server->set_payload_max_length(o.max_request_bytes);
  // httplib's default sets SO_REUSEPORT, which lets a second job bind the same port and take
  // a share of the first one's connections. SO_REUSEADDR only allows a restart while old
  // connections linger in TIME_WAIT; a port in use stays an error.
  server->set_socket_options([](int sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  server->set_pre_routing_handler(
      [&m](const Request& req, Response& res) { return m.handle(req, res); });

  errno = 0;
  int port = o.port;
  if (port == 0) {
    port = server->bind_to_any_port(o.bind_address);
  } else if (!server->bind_to_port(o.bind_address, port)) {
    port = -1;
  }
  if (port <= 0) {
    const int err = errno;
    std::string why;
    if (err == EADDRINUSE)
      why = "port " + std::to_string(o.port) + " is in use (choose another port, or 0 for any)";
    else if (err == EADDRNOTAVAIL)
      why = "the address is not one of this machine's";
    else if (err == EACCES)
      why = "permission denied (ports below 1024 need privileges)";
    else
      why = err ? std::strerror(err) : "the address cannot be resolved or bound";
    return Status::io("cannot listen on " + o.bind_address + ":" + std::to_string(o.port) + ": " +
                      why);
  }

  m.server = std::move(server);
  m.port = port;
  m.stop_source = std::stop_source();
  m.listener_done = false;
  m.listener = std::thread([&m] {
    sigset_t pipe;
    sigemptyset(&pipe);
    sigaddset(&pipe, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipe, nullptr);  // inherited by the workers started below
    m.server->listen_after_bind();
    m.listener_done = true;
  });
  // stop() can only interrupt a server that has begun listening.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!m.server->is_running() && !m.listener_done &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (!m.server->is_running()) {
    stop();
    return Status::io("the HTTP server did not start listening");
  }
  return Status::ok();
}

void HttpServer::stop() {
  Impl& m = *impl_;
  if (!m.server) return;
  m.stop_source.request_stop();
  m.server->stop();
  if (m.listener.joinable()) m.listener.join();  // httplib joins its workers before returning
  m.server.reset();
  m.port = 0;
}

bool HttpServer::running() const {
  return impl_->server && impl_->server->is_running();
}

int HttpServer::port() const {
  return impl_->port;
}

const std::string& HttpServer::token() const {
  return impl_->token;
}

std::string HttpServer::url() const {
  const std::string& address = impl_->options.bind_address;
  const bool ipv6 = address.find(':') != std::string::npos;
  return "http://" + (ipv6 ? "[" + address + "]" : address) + ":" + std::to_string(port()) +
         "/?token=" + impl_->token;
}

bool is_loopback_address(std::string_view address) {
  if (address == "localhost") return true;
  const std::string text(address);
  in_addr v4{};
  if (::inet_pton(AF_INET, text.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  if (::inet_pton(AF_INET6, text.c_str(), &v6) == 1)
    return IN6_IS_ADDR_LOOPBACK(&v6) || (IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127);
  return false;
}

std::string rate_limit_key(std::string_view address) {
  const std::string text(address);
  // A link-local peer comes with its zone ("fe80::1%eth0"), which inet_pton does not read.
  const std::string bare = text.substr(0, text.find('%'));
  in6_addr v6{};
  if (::inet_pton(AF_INET6, bare.c_str(), &v6) != 1) return text;
  char buffer[INET6_ADDRSTRLEN];
  if (IN6_IS_ADDR_V4MAPPED(&v6))
    return ::inet_ntop(AF_INET, &v6.s6_addr[12], buffer, sizeof buffer) ? buffer : text;
  std::memset(&v6.s6_addr[8], 0, 8);
  return ::inet_ntop(AF_INET6, &v6, buffer, sizeof buffer) ? std::string(buffer) + "/64" : text;
}

std::string remote_server_warning(std::string_view address) {
  return "warning: the HTTP server listens on " + std::string(address) +
         ", reachable from the network in plain HTTP: anyone who sees the URL (with its token) "
         "or the traffic can fetch the meshes\n";
}

std::string random_token() {
  std::random_device device;
  static constexpr char hex[] = "0123456789abcdef";
  std::string token;
  for (int word = 0; word < 4; ++word) {
    std::uint32_t bits = device();
    for (int digit = 0; digit < 8; ++digit, bits >>= 4)
      token += hex[bits & 0xf];
  }
  return token;
}

bool tokens_equal(std::string_view given, std::string_view expected) {
  // Every byte of `expected` is compared against something, whatever `given` holds.
  unsigned difference = given.size() != expected.size();
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const unsigned char g = i < given.size() ? static_cast<unsigned char>(given[i]) : 0;
    difference |= g ^ static_cast<unsigned char>(expected[i]);
  }
  return difference == 0;
}

ViewerFiles find_viewer_files() {
  std::vector<fs::path> roots;
  std::error_code ec;
  if (const char* env = std::getenv("LDIMESH_DATA_DIR"); env && *env) {
    roots.emplace_back(env);  // the only place then
  } else {
    // A program run from the build tree takes the checkout's files (the ones being worked on);
    // an installed one (or a solver) those installed beside its bin/, then under the prefix
    // configured at build time, then the checkout.
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    const fs::path beside = ec ? fs::path() : exe.parent_path().parent_path() / "share" / "ldimesh";
    const bool in_build_tree =
        !ec && exe.string().rfind(std::string(LDIMESH_BINARY_DIR) + "/", 0) == 0;
    if (in_build_tree) roots.emplace_back(LDIMESH_SOURCE_DIR);
    if (!beside.empty()) roots.push_back(beside);
    roots.emplace_back(LDIMESH_INSTALL_DATA_DIR);
    if (!in_build_tree) roots.emplace_back(LDIMESH_SOURCE_DIR);
  }
  ViewerFiles files;
  for (const fs::path& root : roots) {
    if (files.static_dir.empty() && fs::is_regular_file(root / "viewer/web/index.html", ec))
      files.static_dir = root / "viewer" / "web";
    if (files.vendor_three_dir.empty() && fs::is_directory(root / "node_modules/three/build", ec))
      files.vendor_three_dir = root / "node_modules" / "three";
  }
  return files;
}

}  // namespace ldimesh

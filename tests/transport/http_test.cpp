// The snapshot store and the job's HTTP server as a viewer or ldimesh-fetch meets them: over
// loopback, driven by the client library, raw httplib and raw sockets.
#include "ldimesh/transport/http_server.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <httplib.h>

#include "fake_steps.hpp"
#include "ldimesh/transport/http_client.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing::fake_glb;
using testing::fake_metadata;
using testing::fake_snapshot;

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// A fresh directory under the system's temporary one, removed at the end of the test.
class TempDir {
 public:
  TempDir() {
    std::random_device device;
    path_ = fs::temp_directory_path() / ("ldimesh_http_test_" + std::to_string(device()));
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

void write_text(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

int connect_loopback(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval timeout{5, 0};  // no test waits for ever on a server that says nothing
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

bool send_all(int fd, const std::string& data) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    const ssize_t n = ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += static_cast<std::size_t>(n);
  }
  return true;
}

// Sends `request` as is (no client-side normalisation of the path) and returns the answer,
// read until the server closes the connection.
std::string raw_exchange(int port, const std::string& request) {
  const int fd = connect_loopback(port);
  if (fd < 0) return {};
  send_all(fd, request);
  std::string answer;
  char buffer[4096];
  for (ssize_t n; (n = ::recv(fd, buffer, sizeof buffer, 0)) > 0;)
    answer.append(buffer, static_cast<std::size_t>(n));
  ::close(fd);
  return answer;
}

std::string raw_get(int port, const std::string& target) {
  return raw_exchange(port, "GET " + target + " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
}

int status_of(const std::string& answer) {
  if (answer.size() < 12 || answer.compare(0, 5, "HTTP/") != 0) return 0;
  return std::stoi(answer.substr(9, 3));
}

// A port nothing listens on (bound, then released).
int closed_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address);
  socklen_t length = sizeof address;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
  ::close(fd);
  return ntohs(address.sin_port);
}

// ---------------------------------------------------------------------------------------------
// The store.

std::vector<std::uint64_t> kept_steps(const SnapshotStore& store) {
  std::vector<std::uint64_t> steps;
  for (const auto& s : store.list())
    steps.push_back(s->step);
  return steps;
}

TEST(SnapshotStore, KeepsTheLatestNSteps) {
  SnapshotStore store({.max_snapshots = 3});
  for (std::uint64_t step = 1; step <= 5; ++step)
    ASSERT_TRUE(store.publish(fake_snapshot(step)));
  EXPECT_EQ(kept_steps(store), (std::vector<std::uint64_t>{3, 4, 5}));
  EXPECT_EQ(store.find(2), nullptr);
  ASSERT_NE(store.find(4), nullptr);
  EXPECT_EQ(*store.find(4)->glb, fake_glb(4));
  EXPECT_EQ(store.latest()->step, 5u);
}

TEST(SnapshotStore, StaysUnderTheMemoryCapAndKeepsTheNewest) {
  // Room for three steps (the JSON of step 10 is a few bytes longer than step 1's), not four.
  const std::size_t cap = 3 * fake_snapshot(1, 100000).memory_bytes() + 100;
  SnapshotStore store({.max_snapshots = 100, .max_bytes = cap});
  for (std::uint64_t step = 1; step <= 10; ++step)
    ASSERT_TRUE(store.publish(fake_snapshot(step, 100000)));
  EXPECT_EQ(kept_steps(store), (std::vector<std::uint64_t>{8, 9, 10}));
  EXPECT_LE(store.memory_bytes(), cap);
  // A step larger than the whole cap evicts every other one, but is itself kept.
  ASSERT_TRUE(store.publish(fake_snapshot(11, 1000000)));
  EXPECT_EQ(kept_steps(store), (std::vector<std::uint64_t>{11}));
}

TEST(SnapshotStore, StepsMustIncrease) {
  SnapshotStore store;
  ASSERT_TRUE(store.publish(fake_snapshot(5)));
  const Status same = store.publish(fake_snapshot(5));
  EXPECT_FALSE(same);
  EXPECT_NE(same.message().find("not newer"), std::string::npos) << same.message();
  EXPECT_FALSE(store.publish(fake_snapshot(3)));
  EXPECT_EQ(kept_steps(store), (std::vector<std::uint64_t>{5}));
  EXPECT_TRUE(store.publish(fake_snapshot(6)));
}

TEST(SnapshotStore, RejectsSnapshotsThatDisagreeWithThemselves) {
  SnapshotStore store;
  Snapshot no_glb = fake_snapshot(1);
  no_glb.glb = nullptr;
  EXPECT_FALSE(store.publish(no_glb));
  Snapshot not_glb = fake_snapshot(1);
  auto bytes = *not_glb.glb;
  bytes[0] = 'x';
  not_glb.glb = std::make_shared<const std::vector<std::uint8_t>>(bytes);
  EXPECT_FALSE(store.publish(not_glb));
  Snapshot other_step = fake_snapshot(1);
  other_step.step = 2;
  EXPECT_FALSE(store.publish(other_step));
  Snapshot bad_json = fake_snapshot(1);
  bad_json.metadata_json = "{\"step\": 1,";
  EXPECT_FALSE(store.publish(bad_json));
  EXPECT_TRUE(store.list().empty());
}

TEST(SnapshotStore, AReaderKeepsAnEvictedSnapshotAlive) {
  SnapshotStore store({.max_snapshots = 1});
  ASSERT_TRUE(store.publish(fake_snapshot(1, 1000)));
  const auto held = store.latest();
  ASSERT_TRUE(store.publish(fake_snapshot(2, 1000)));
  EXPECT_EQ(store.find(1), nullptr);
  EXPECT_EQ(*held->glb, fake_glb(1, 1000));
}

TEST(SnapshotStore, WaitForNewerWakesOnPublishAndTimesOut) {
  SnapshotStore store;
  ASSERT_TRUE(store.publish(fake_snapshot(1)));
  // Already newer: at once.
  EXPECT_EQ(store.wait_for_newer(std::nullopt, 0ms)->step, 1u);
  EXPECT_EQ(store.wait_for_newer(0, 0ms)->step, 1u);
  std::shared_ptr<const Snapshot> got;
  std::thread waiter([&] { got = store.wait_for_newer(1, 10s); });
  std::this_thread::sleep_for(50ms);
  ASSERT_TRUE(store.publish(fake_snapshot(2)));
  waiter.join();
  ASSERT_NE(got, nullptr);
  EXPECT_EQ(got->step, 2u);
  const auto start = Clock::now();
  EXPECT_EQ(store.wait_for_newer(2, 100ms), nullptr);
  EXPECT_GE(seconds_since(start), 0.09);
}

TEST(SnapshotStore, ShutdownAndStopTokensReleaseWaiters) {
  SnapshotStore store;
  std::stop_source stop;
  std::atomic<int> released{0};
  const auto start = Clock::now();
  std::thread by_token([&] {
    EXPECT_EQ(store.wait_for_newer(std::nullopt, 30s, stop.get_token()), nullptr);
    ++released;
  });
  std::thread by_shutdown([&] {
    EXPECT_EQ(store.wait_for_newer(std::nullopt, 30s), nullptr);
    ++released;
  });
  std::this_thread::sleep_for(50ms);
  stop.request_stop();
  store.shutdown();
  by_token.join();
  by_shutdown.join();
  EXPECT_EQ(released, 2);
  EXPECT_LT(seconds_since(start), 5.0);
  EXPECT_EQ(store.wait_for_newer(std::nullopt, 30s), nullptr);  // at once after shutdown
  EXPECT_TRUE(store.publish(fake_snapshot(1)));                 // publishing still works
}

TEST(SnapshotStore, MetadataJsonIsTheDocumentedObjectAndRoundTrips) {
  StepMetadata m = fake_metadata(42);
  m.time = 0.42;
  m.bytes = 1234567;
  m.scalar = ScalarRange{"temperature", 0.0, 1.0};
  m.seconds = {{"glb", 0.1}, {"mesh", 0.04}, {"cast", 0.25}, {"encode", 0.03}, {"extra", 1.0}};
  m.skipped_steps = 3;
  m.nonfinite_values = 7;
  const std::string json = metadata_to_json(m);
  // docs/api.md's key order.
  EXPECT_EQ(json.rfind(R"({"step":42,"time":0.42,"isovalues":[0.5],"triangles":1042,)", 0), 0u)
      << json;
  EXPECT_NE(json.find(R"("views":[[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]],)"
                      R"("resolution":64,"r":0.5,)"
                      R"("scalar":{"name":"temperature","min":0.0,"max":1.0},)"
                      R"("seconds":{"cast":0.25,"encode":0.03,"mesh":0.04,"glb":0.1,"extra":1.0},)"
                      R"("skipped_steps":3,"nonfinite_values":7})"),
            std::string::npos)
      << json;
  EXPECT_EQ(json.find('\n'), std::string::npos);
  StepMetadata back;
  ASSERT_TRUE(metadata_from_json(json, back));
  EXPECT_EQ(back.step, 42u);
  EXPECT_EQ(back.time, 0.42);
  EXPECT_EQ(back.isovalues, m.isovalues);
  EXPECT_EQ(back.triangles, m.triangles);
  EXPECT_EQ(back.vertices, m.vertices);
  EXPECT_EQ(back.samples, m.samples);
  EXPECT_EQ(back.quads, m.quads);
  EXPECT_EQ(back.bytes, m.bytes);
  EXPECT_EQ(back.views, m.views);
  EXPECT_EQ(back.resolution, m.resolution);
  EXPECT_EQ(back.r, m.r);
  EXPECT_EQ(back.skipped_steps, 3u);
  EXPECT_EQ(back.nonfinite_values, 7u);
  ASSERT_TRUE(back.scalar);
  EXPECT_EQ(back.scalar->name, "temperature");
  EXPECT_EQ(back.scalar->max, 1.0);
  EXPECT_EQ(back.seconds, m.seconds);

  m.scalar.reset();
  EXPECT_EQ(metadata_to_json(m).find("scalar"), std::string::npos);

  // Surfaces coloured by different fields, or not at all: a field and range per isovalue, after
  // "scalar" (here absent).
  m.isovalues = {0.3, 0.5, 0.7};
  m.surface_scalars = {ScalarRange{"U", 0.25, 0.75}, std::nullopt, ScalarRange{"T", 300.0, 350.5}};
  const std::string mixed = metadata_to_json(m);
  EXPECT_NE(mixed.find(R"("r":0.5,"surface_scalars":[{"name":"U","min":0.25,"max":0.75},null,)"
                       R"({"name":"T","min":300.0,"max":350.5}],"seconds":)"),
            std::string::npos)
      << mixed;
  StepMetadata again;
  ASSERT_TRUE(metadata_from_json(mixed, again));
  EXPECT_FALSE(again.scalar);
  ASSERT_EQ(again.surface_scalars.size(), 3u);
  ASSERT_TRUE(again.surface_scalars[0] && again.surface_scalars[2]);
  EXPECT_FALSE(again.surface_scalars[1]);
  EXPECT_EQ(again.surface_scalars[0]->name, "U");
  EXPECT_EQ(again.surface_scalars[0]->min, 0.25);
  EXPECT_EQ(again.surface_scalars[2]->name, "T");
  EXPECT_EQ(again.surface_scalars[2]->max, 350.5);

  for (const char* bad :
       {"", "[]", "{\"time\": 1}", "{\"step\": -1}", "{\"step\": \"1\"}",
        "{\"step\": 1, \"views\": [[1, 0]]}", "{\"step\": 1, \"seconds\": 3}",
        "{\"step\": 1, \"surface_scalars\": {}}", "{\"step\": 1, \"surface_scalars\": [3]}",
        "{\"step\": 1, \"surface_scalars\": [{\"name\": 1, \"min\": 0, \"max\": 1}]}",
        "{\"step\": 1, \"isovalues\": [0.5], \"surface_scalars\": [null, null]}"}) {
    StepMetadata untouched;
    untouched.step = 7;
    const Status s = metadata_from_json(bad, untouched);
    EXPECT_FALSE(s) << bad;
    EXPECT_EQ(s.message().rfind("metadata: ", 0), 0u) << s.message();
    EXPECT_EQ(untouched.step, 7u);
  }
}

TEST(SnapshotStore, StepFilesRoundTripAndPartialFilesAreIgnored) {
  TempDir dir;
  ASSERT_TRUE(write_step_files(dir.path(), fake_snapshot(1)));
  ASSERT_TRUE(write_step_files(dir.path(), fake_snapshot(2, 500)));
  EXPECT_TRUE(fs::exists(dir.path() / "step_000001.glb"));
  EXPECT_TRUE(fs::exists(dir.path() / "step_000002.json"));
  // A writer's temporary, a .glb whose .json has not arrived, a corrupt step.
  write_text(dir.path() / ".step_000003.glb.tmp.1.0", "partial");
  const auto glb4 = fake_glb(4);
  std::ofstream(dir.path() / "step_000004.glb", std::ios::binary)
      .write(reinterpret_cast<const char*>(glb4.data()), static_cast<std::streamsize>(glb4.size()));
  write_text(dir.path() / "step_000005.glb", "not a glb");
  write_text(dir.path() / "step_000005.json", "{\"step\": 5}");
  write_text(dir.path() / "notes.txt", "hello");

  SnapshotStore store;
  DirectoryWatcher watcher(dir.path());
  std::size_t loaded = 0;
  ASSERT_TRUE(watcher.scan(store, &loaded));
  EXPECT_EQ(loaded, 2u);
  EXPECT_EQ(kept_steps(store), (std::vector<std::uint64_t>{1, 2}));
  EXPECT_EQ(*store.find(2)->glb, fake_glb(2, 500));
  EXPECT_EQ(store.find(2)->metadata_json, fake_snapshot(2, 500).metadata_json);
  const auto warnings = watcher.take_warnings();
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("step_000005"), std::string::npos) << warnings[0];

  // Step 4's .json arrives; step 5, unchanged, is not reported again.
  write_text(dir.path() / "step_000004.json", fake_snapshot(4).metadata_json);
  ASSERT_TRUE(watcher.scan(store, &loaded));
  EXPECT_EQ(loaded, 1u);
  EXPECT_EQ(store.latest()->step, 4u);
  EXPECT_TRUE(watcher.take_warnings().empty());
  // Repaired, step 5 loads.
  ASSERT_TRUE(write_step_files(dir.path(), fake_snapshot(5)));
  ASSERT_TRUE(watcher.scan(store, &loaded));
  EXPECT_EQ(loaded, 1u);
  EXPECT_EQ(store.latest()->step, 5u);

  EXPECT_FALSE(DirectoryWatcher(dir.path() / "missing").scan(store));
  EXPECT_FALSE(write_step_files("/proc/version/x", fake_snapshot(9)));
}

TEST(SnapshotStore, ScanLoadsOnlyTheNewestStepsTheStoreKeeps) {
  TempDir dir;
  for (std::uint64_t step = 1; step <= 10; ++step)
    ASSERT_TRUE(write_step_files(dir.path(), fake_snapshot(step)));
  SnapshotStore store({.max_snapshots = 3});
  std::size_t loaded = 0;
  ASSERT_TRUE(DirectoryWatcher(dir.path()).scan(store, &loaded));
  EXPECT_EQ(loaded, 3u);
  EXPECT_EQ(kept_steps(store), (std::vector<std::uint64_t>{8, 9, 10}));
}

// ---------------------------------------------------------------------------------------------
// The server.

class Http : public ::testing::Test {
 protected:
  void SetUp() override {
    write_text(dir_.path() / "web/index.html", "<html>viewer</html>");
    write_text(dir_.path() / "web/viewer.js", "export {};");
    write_text(dir_.path() / "three/build/three.module.js", "export const REVISION = '0';");
    write_text(dir_.path() / "secret.txt", "SECRET");
    fs::create_symlink("../secret.txt", dir_.path() / "web/escape");
    for (std::uint64_t step = 1; step <= 3; ++step)
      ASSERT_TRUE(store_.publish(fake_snapshot(step, 100 * step)));
    options_.static_dir = dir_.path() / "web";
    options_.vendor_three_dir = dir_.path() / "three";
    options_.event_keep_alive = 200ms;
    start();
  }

  void start() {
    server_ = std::make_unique<HttpServer>(store_, options_);
    const Status s = server_->start();
    ASSERT_TRUE(s) << s.message();
    port_ = server_->port();
  }

  std::string base() const { return "http://127.0.0.1:" + std::to_string(port_); }
  HttpClient client() const { return HttpClient(base(), server_->token()); }

  TempDir dir_;
  SnapshotStore store_{{.max_snapshots = 4}};
  HttpServerOptions options_;
  std::unique_ptr<HttpServer> server_;
  int port_ = 0;
};

TEST_F(Http, ListsStepsAndServesMetadataAndIdenticalGlbBytes) {
  HttpClient c = client();
  std::vector<RemoteStep> steps;
  ASSERT_TRUE(c.list_steps(steps));
  ASSERT_EQ(steps.size(), 3u);
  for (std::uint64_t i = 0; i < 3; ++i) {
    EXPECT_EQ(steps[i].metadata.step, i + 1);
    EXPECT_EQ(steps[i].json, store_.find(i + 1)->metadata_json);
  }
  RemoteStep two;
  ASSERT_TRUE(c.step(2, two));
  EXPECT_EQ(two.json, store_.find(2)->metadata_json);
  EXPECT_EQ(two.metadata.triangles, fake_metadata(2).triangles);
  EXPECT_EQ(two.metadata.bytes, fake_glb(2, 200).size());
  std::vector<std::uint8_t> glb;
  ASSERT_TRUE(c.mesh(2, glb, two.metadata.bytes));
  EXPECT_EQ(glb, fake_glb(2, 200));
  RemoteStep newest;
  ASSERT_TRUE(c.latest(newest));
  EXPECT_EQ(newest.metadata.step, 3u);

  httplib::Client raw("127.0.0.1", port_);
  raw.set_bearer_token_auth(server_->token());
  const auto res = raw.Get("/api/v1/steps/3/mesh.glb");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_EQ(res->get_header_value("Content-Type"), "model/gltf-binary");
  EXPECT_EQ(res->get_header_value("Content-Length"), std::to_string(fake_glb(3, 300).size()));
}

TEST_F(Http, UrlCarriesARandomToken) {
  const std::string& token = server_->token();
  EXPECT_EQ(token.size(), 32u);
  EXPECT_EQ(token.find_first_not_of("0123456789abcdef"), std::string::npos);
  EXPECT_EQ(server_->url(), base() + "/?token=" + token);
  EXPECT_NE(random_token(), random_token());
  EXPECT_TRUE(tokens_equal("abc", "abc"));
  EXPECT_FALSE(tokens_equal("abd", "abc"));
  EXPECT_FALSE(tokens_equal("ab", "abc"));
  EXPECT_FALSE(tokens_equal("abcd", "abc"));
  EXPECT_FALSE(tokens_equal("", "abc"));
  // The client takes the token from the printed URL.
  HttpClient from_url(server_->url());
  RemoteStep newest;
  EXPECT_TRUE(from_url.latest(newest));
}

TEST_F(Http, ApiNeedsTheToken) {
  const std::string& token = server_->token();
  httplib::Client raw("127.0.0.1", port_);
  EXPECT_EQ(raw.Get("/api/v1/steps")->status, 401);
  EXPECT_EQ(raw.Get("/api/v1/steps?token=" + token + "x")->status, 401);
  EXPECT_EQ(raw.Get("/api/v1/steps?token=")->status, 401);
  EXPECT_EQ(raw.Get("/api/v1/steps/1/mesh.glb")->status, 401);
  EXPECT_EQ(raw.Get("/api/v1/nothing")->status, 401);  // no hint of what exists
  EXPECT_EQ(raw.Get("/api/v1/steps", {{"Authorization", "Bearer wrong"}})->status, 401);
  EXPECT_EQ(raw.Get("/api/v1/steps", {{"Authorization", "Basic " + token}})->status, 401);
  EXPECT_EQ(raw.Get("/api/v1/steps?token=" + token)->status, 200);
  EXPECT_EQ(raw.Get("/api/v1/steps", {{"Authorization", "Bearer " + token}})->status, 200);
  // The viewer's files hold no data: no token.
  const auto index = raw.Get("/");
  ASSERT_TRUE(index);
  EXPECT_EQ(index->status, 200);
  EXPECT_EQ(index->body, "<html>viewer</html>");
  EXPECT_EQ(index->get_header_value("Content-Type"), "text/html; charset=utf-8");
  EXPECT_EQ(raw.Get("/viewer/viewer.js")->get_header_value("Content-Type"),
            "text/javascript; charset=utf-8");
  EXPECT_EQ(raw.Get("/vendor/three/build/three.module.js")->status, 200);

  HttpClient wrong(base(), "0123");
  std::vector<RemoteStep> steps;
  const Status refused = wrong.list_steps(steps);
  EXPECT_FALSE(refused);
  EXPECT_NE(refused.message().find("the server refused the token"), std::string::npos)
      << refused.message();
}

TEST_F(Http, UnknownStepsAndPathsAre404) {
  HttpClient c = client();
  RemoteStep step;
  Status missing = c.step(42, step);
  EXPECT_FALSE(missing);
  EXPECT_EQ(missing.message(), "step 42 is not on the server (it keeps steps 1 to 3)");
  std::vector<std::uint8_t> glb;
  missing = c.mesh(42, glb);
  EXPECT_EQ(missing.message(), "step 42 is not on the server (it keeps steps 1 to 3)");

  httplib::Client raw("127.0.0.1", port_);
  raw.set_bearer_token_auth(server_->token());
  for (const char* path : {"/api/v1/steps/42", "/api/v1/steps/42/mesh.glb", "/api/v1/steps/x",
                           "/api/v1/steps/1/mesh.png", "/api/v1/steps/", "/api/v2/steps",
                           "/api/v1/steps/99999999999999999999999", "/nothing", "/viewer/none.js",
                           "/viewer/", "/vendor/three/"}) {
    const auto res = raw.Get(path);
    ASSERT_TRUE(res) << path;
    EXPECT_EQ(res->status, 404) << path;
  }
  EXPECT_EQ(raw.Post("/api/v1/steps", "", "text/plain")->status, 405);
}

TEST_F(Http, LatestBeforeTheFirstStepIs404) {
  SnapshotStore empty;
  HttpServer server(empty);
  ASSERT_TRUE(server.start());
  HttpClient c(server.url());
  RemoteStep step;
  const Status s = c.latest(step);
  EXPECT_FALSE(s);
  EXPECT_EQ(s.message(), "the server has no step yet");
  EXPECT_EQ(c.step(1, step).message(), "step 1 is not on the server (it has no step yet)");
}

TEST_F(Http, LongPollReturnsOnPublishAnd204OnTimeout) {
  HttpClient c = client();
  std::optional<RemoteStep> got;
  // Already newer than 2: at once.
  ASSERT_TRUE(c.wait_for_newer(2, 5s, got));
  ASSERT_TRUE(got);
  EXPECT_EQ(got->metadata.step, 3u);

  const auto start = Clock::now();
  std::thread publisher([&] {
    std::this_thread::sleep_for(200ms);
    EXPECT_TRUE(store_.publish(fake_snapshot(4)));
  });
  Status s = c.wait_for_newer(3, 10s, got);
  publisher.join();
  ASSERT_TRUE(s) << s.message();
  ASSERT_TRUE(got);
  EXPECT_EQ(got->metadata.step, 4u);
  EXPECT_LT(seconds_since(start), 5.0);

  httplib::Client raw("127.0.0.1", port_);
  raw.set_bearer_token_auth(server_->token());
  const auto before = Clock::now();
  const auto timeout = raw.Get("/api/v1/latest?after=4&wait=1");
  ASSERT_TRUE(timeout);
  EXPECT_EQ(timeout->status, 204);
  EXPECT_GE(seconds_since(before), 0.9);
  EXPECT_EQ(raw.Get("/api/v1/latest?after=4")->status, 204);  // no wait: at once
  EXPECT_EQ(raw.Get("/api/v1/latest?after=3")->status, 200);
  EXPECT_EQ(raw.Get("/api/v1/latest?after=4&wait=61")->status, 400);
  EXPECT_EQ(raw.Get("/api/v1/latest?after=x&wait=1")->status, 400);
  EXPECT_EQ(raw.Get("/api/v1/latest?after=4&wait=-1")->status, 400);
}

// Reads the event stream with a raw client until `done` says so; returns what came.
std::string read_events(int port, const std::string& token,
                        const std::function<bool(const std::string&)>& done) {
  httplib::Client raw("127.0.0.1", port);
  raw.set_read_timeout(5, 0);
  std::string stream;
  raw.Get("/api/v1/events?token=" + token, [&](const char* data, std::size_t size) {
    stream.append(data, size);
    return !done(stream);
  });
  return stream;
}

TEST_F(Http, EventsSendTheNewestStepThenEachNewOne) {
  std::atomic<bool> published{false};
  std::thread publisher;
  const std::string stream = read_events(port_, server_->token(), [&](const std::string& s) {
    if (s.find("\"step\":3,") != std::string::npos && !published.exchange(true)) {
      publisher = std::thread([&] { EXPECT_TRUE(store_.publish(fake_snapshot(4))); });
    }
    return s.find("\"step\":4,") != std::string::npos;
  });
  if (publisher.joinable()) publisher.join();
  // The newest step first (not the older ones), then the new one, each a complete event.
  EXPECT_EQ(stream.find("\"step\":1,"), std::string::npos);
  const std::size_t three =
      stream.find("id: 3\nevent: step\ndata: " + store_.find(3)->metadata_json + "\n\n");
  const std::size_t four =
      stream.find("id: 4\nevent: step\ndata: " + store_.find(4)->metadata_json + "\n\n");
  EXPECT_NE(three, std::string::npos) << stream;
  EXPECT_NE(four, std::string::npos) << stream;
  EXPECT_LT(three, four);
}

TEST_F(Http, EventsKeepAliveWithComments) {
  const std::string stream = read_events(port_, server_->token(), [](const std::string& s) {
    return s.find(": keep-alive\n\n") != std::string::npos;
  });
  EXPECT_NE(stream.find(": keep-alive\n\n"), std::string::npos);
}

TEST_F(Http, ConcurrentDownloadsAreNeverTorn) {
  // Steps are published and evicted while 8 clients download; every GLB that arrives must be
  // exactly the one published under its step number.
  std::mutex mutex;
  std::map<std::uint64_t, std::vector<std::uint8_t>> published;
  for (std::uint64_t step = 1; step <= 3; ++step)
    published[step] = *store_.find(step)->glb;
  std::atomic<bool> stop{false};
  std::atomic<int> downloads{0};
  std::atomic<int> evicted{0};
  std::vector<std::thread> clients;
  for (int t = 0; t < 8; ++t) {
    clients.emplace_back([&] {
      HttpClient c = client();
      while (!stop) {
        RemoteStep newest;
        if (!c.latest(newest)) continue;
        std::vector<std::uint8_t> glb;
        const Status s = c.mesh(newest.metadata.step, glb, newest.metadata.bytes);
        if (!s) {
          EXPECT_NE(s.message().find("is not on the server"), std::string::npos) << s.message();
          ++evicted;
          continue;
        }
        std::lock_guard lock(mutex);
        EXPECT_EQ(glb, published.at(newest.metadata.step));
        ++downloads;
      }
    });
  }
  for (std::uint64_t step = 4; step <= 60; ++step) {
    Snapshot s = fake_snapshot(step, 5000 * (step % 7));
    {
      std::lock_guard lock(mutex);
      published[step] = *s.glb;
    }
    ASSERT_TRUE(store_.publish(std::move(s)));
    std::this_thread::sleep_for(10ms);
  }
  stop = true;
  for (auto& c : clients)
    c.join();
  EXPECT_GT(downloads, 20);
  EXPECT_EQ(kept_steps(store_), (std::vector<std::uint64_t>{57, 58, 59, 60}));
}

TEST_F(Http, AClientLeavingMidDownloadHarmsNothing) {
  ASSERT_TRUE(store_.publish(fake_snapshot(4, 8 << 20)));  // 8 MiB: far beyond socket buffers
  const std::string request =
      "GET /api/v1/steps/4/mesh.glb?token=" + server_->token() + " HTTP/1.1\r\nHost: x\r\n\r\n";
  for (int i = 0; i < 10; ++i) {
    const int fd = connect_loopback(port_);
    ASSERT_GE(fd, 0);
    ASSERT_TRUE(send_all(fd, request));
    char head[1000];
    EXPECT_GT(::recv(fd, head, sizeof head, 0), 0);
    ::close(fd);
  }
  // The publisher is not held up, and the server serves the whole step to the next client.
  ASSERT_TRUE(store_.publish(fake_snapshot(5)));
  HttpClient c = client();
  std::vector<std::uint8_t> glb;
  ASSERT_TRUE(c.mesh(4, glb));
  EXPECT_EQ(glb, fake_glb(4, 8 << 20));
}

TEST_F(Http, ADownloadOutlivesTheEvictionOfItsStep) {
  ASSERT_TRUE(store_.publish(fake_snapshot(4, 8 << 20)));
  const int fd = connect_loopback(port_);
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(send_all(fd, "GET /api/v1/steps/4/mesh.glb?token=" + server_->token() +
                               " HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"));
  char buffer[65536];
  const ssize_t first = ::recv(fd, buffer, 1000, 0);
  ASSERT_GT(first, 0);
  std::string answer(buffer, static_cast<std::size_t>(first));
  // Steps 5 to 8 push step 4 out of the store (it keeps 4) while its download is under way.
  for (std::uint64_t step = 5; step <= 8; ++step)
    ASSERT_TRUE(store_.publish(fake_snapshot(step)));
  ASSERT_EQ(store_.find(4), nullptr);
  for (ssize_t n; (n = ::recv(fd, buffer, sizeof buffer, 0)) > 0;)
    answer.append(buffer, static_cast<std::size_t>(n));
  ::close(fd);
  const std::size_t body = answer.find("\r\n\r\n");
  ASSERT_NE(body, std::string::npos);
  const auto expected = fake_glb(4, 8 << 20);
  ASSERT_EQ(answer.size() - body - 4, expected.size());
  EXPECT_TRUE(std::equal(expected.begin(), expected.end(),
                         reinterpret_cast<const std::uint8_t*>(answer.data() + body + 4)));
}

TEST_F(Http, PathTraversalNeverReachesAFileOutsideTheRoots) {
  for (const char* target : {"/../secret.txt",
                             "/../CMakeLists.txt",
                             "/viewer/../secret.txt",
                             "/viewer/../../secret.txt",
                             "/viewer/%2e%2e/secret.txt",
                             "/viewer/%2E%2E/%2e%2e/secret.txt",
                             "/%2e%2e/%2e%2e/etc/passwd",
                             "/vendor/three/../../secret.txt",
                             "/vendor/three/../../CMakeLists.txt",
                             "/vendor/three/%2e%2e/%2e%2e/secret.txt",
                             "/vendor/three/..%2f..%2fsecret.txt",
                             "//etc/passwd",
                             "/viewer//etc/passwd",
                             "/viewer/%2fetc%2fpasswd",
                             "/vendor/three//etc/passwd",
                             "/viewer/escape",
                             "/viewer/./escape",
                             "/viewer/..\\secret.txt",
                             "/viewer/%00secret.txt",
                             "/viewer/%5c..%5csecret.txt",
                             "/viewer/index.html/..",
                             "/viewer/.."}) {
    const std::string answer = raw_get(port_, target);
    const int status = status_of(answer);
    EXPECT_TRUE(status == 400 || status == 403 || status == 404) << target << ": " << status;
    EXPECT_EQ(answer.find("SECRET"), std::string::npos) << target;
    EXPECT_EQ(answer.find("root:"), std::string::npos) << target;
  }
  EXPECT_EQ(status_of(raw_get(port_, "/viewer/viewer.js")), 200);
}

TEST_F(Http, HugeRequestsAreRefused) {
  const std::string big_body =
      raw_exchange(port_,
                   "GET /api/v1/steps HTTP/1.1\r\nHost: x\r\nContent-Length: 1000000000\r\n"
                   "Connection: close\r\n\r\nabc");
  EXPECT_EQ(status_of(big_body), 413) << big_body.substr(0, 100);
  std::string headers = "GET / HTTP/1.1\r\nHost: x\r\nConnection: close\r\n";
  for (int i = 0; i < 40; ++i)
    headers += "X-Filler-" + std::to_string(i) + ": " + std::string(1000, 'f') + "\r\n";
  const std::string big_headers = raw_exchange(port_, headers + "\r\n");
  const int status = status_of(big_headers);
  EXPECT_TRUE(status == 431 || status == 413 || status == 400) << status;
  // Still serving.
  EXPECT_EQ(status_of(raw_get(port_, "/")), 200);
}

TEST_F(Http, ClientCancelEndsALongPollInFlight) {
  // cancel() from another thread stops the request on the wire (httplib's stop()): a long poll
  // that would wait 30 s returns at once, "interrupted"; the client then works again. The first
  // cancel() at different moments, then one every 20 ms until the call returns (a cancel()
  // before the call began belongs to the call before, and is reset), for ThreadSanitizer's sake
  // too. The long polls stay open on the server until stop() (docs/api.md).
  HttpClient c = client();
  for (const auto first : {0ms, 1ms, 50ms, 300ms}) {
    SCOPED_TRACE("first cancel after " + std::to_string(first.count()) + " ms");
    std::optional<RemoteStep> got;
    std::atomic<bool> returned{false};
    const auto start = Clock::now();
    std::thread canceller([&] {
      std::this_thread::sleep_for(first);
      while (!returned) {
        c.cancel();
        std::this_thread::sleep_for(20ms);
      }
    });
    const Status s = c.wait_for_newer(3, 30s, got);
    returned = true;
    canceller.join();
    EXPECT_FALSE(s);
    EXPECT_NE(s.message().find("interrupted"), std::string::npos) << s.message();
    EXPECT_LT(seconds_since(start), 10.0);
    EXPECT_FALSE(got.has_value());
  }
  // A step newer than `after` is answered at once, though the cancelled polls that reached the
  // server hold its long-poll places (four) until their 30 s end.
  std::optional<RemoteStep> got;
  const Status s = c.wait_for_newer(2, 5s, got);
  ASSERT_TRUE(s) << s.message();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->metadata.step, 3u);
}

TEST_F(Http, StopIsPromptWithOpenStreamsAndLongPolls) {
  options_.event_keep_alive = 15s;
  server_.reset();
  start();
  std::thread stream(
      [&] { read_events(port_, server_->token(), [](const std::string&) { return false; }); });
  std::thread poll([&] {
    HttpClient c = client();
    std::optional<RemoteStep> got;
    c.wait_for_newer(3, 30s, got);  // ends with the server, not after 30 s
  });
  std::this_thread::sleep_for(300ms);
  const auto start = Clock::now();
  server_->stop();
  EXPECT_LT(seconds_since(start), 3.0);
  stream.join();
  poll.join();
  EXPECT_FALSE(server_->running());
  EXPECT_EQ(status_of(raw_get(port_, "/")), 0);  // nothing listens any more
}

TEST_F(Http, TooManyStreamsGet503) {
  options_.threads = 3;
  options_.max_streams = 1;
  server_.reset();
  start();
  // Another client keeps the one stream open, poll after poll (however slowly its thread
  // starts, e.g. under ThreadSanitizer); a second long poll meets it within a few tries. (That
  // client does not wait out the 503s it gets in turn: it asks again at once.)
  std::atomic<bool> done{false};
  std::thread poll([&] {
    HttpClient c(base(), server_->token(), {.retries = 0});
    while (!done) {
      std::optional<RemoteStep> got;
      c.wait_for_newer(3, 1s, got);
    }
  });
  httplib::Client raw("127.0.0.1", port_);
  raw.set_bearer_token_auth(server_->token());
  int status = 0;
  for (const auto deadline = Clock::now() + 20s; status != 503 && Clock::now() < deadline;)
    status = raw.Get("/api/v1/latest?after=3&wait=1")->status;
  EXPECT_EQ(status, 503);
  EXPECT_EQ(raw.Get("/api/v1/steps")->status, 200);  // plain requests still served
  done = true;
  poll.join();
}

// The client asks again after a 503 or 429 as Retry-After says (a server whose long polls are all
// taken answers 503, Retry-After: 1), up to HttpClientOptions::retries times.
TEST_F(Http, ClientRetriesWhatTheServerRefusesForNow) {
  httplib::Server fake;
  std::atomic<int> asked{0};
  fake.Get("/api/v1/latest", [&](const httplib::Request&, httplib::Response& res) {
    const int n = ++asked;
    if (n <= 2) {  // busy twice, rate-limited once (Retry-After 0: waits 1 s), then a step
      res.status = 503;
      res.set_header("Retry-After", "1");
      res.set_content(R"({"error": "too many long polls and event streams open"})",
                      "application/json");
    } else if (n == 3) {
      res.status = 429;
      res.set_header("Retry-After", "0");
    } else {
      res.set_content(R"({"step": 4, "time": 0.5, "bytes": 100})", "application/json");
    }
  });
  fake.Get("/api/v1/steps", [&](const httplib::Request&, httplib::Response& res) {
    ++asked;
    res.status = 503;
    res.set_content(R"({"error": "the server is stopping"})", "application/json");
  });
  const int port = fake.bind_to_any_port("127.0.0.1");
  std::thread serving([&] { fake.listen_after_bind(); });
  while (!fake.is_running())
    std::this_thread::sleep_for(1ms);
  const std::string url = "http://127.0.0.1:" + std::to_string(port);

  HttpClient patient(url, "t");
  std::optional<RemoteStep> got;
  Status s = patient.wait_for_newer(3, 1s, got);
  ASSERT_TRUE(s) << s.message();
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(got->metadata.step, 4u);
  EXPECT_EQ(asked, 4);
  // With fewer retries than refusals: the server's message.
  asked = 0;
  HttpClient hasty(url, "t", {.retries = 1});
  s = hasty.wait_for_newer(3, 1s, got);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("HTTP 503 (too many long polls and event streams open)"),
            std::string::npos)
      << s.message();
  EXPECT_EQ(asked, 2);
  // cancel() ends the wait between tries.
  asked = 0;
  HttpClient cancelled(url, "t");
  std::thread canceller([&] {
    std::this_thread::sleep_for(300ms);
    cancelled.cancel();
  });
  s = cancelled.wait_for_newer(3, 1s, got);
  canceller.join();
  EXPECT_NE(s.message().find("interrupted"), std::string::npos) << s.message();
  EXPECT_EQ(asked, 1);
  // A 503 without Retry-After (a server that is stopping) stands.
  asked = 0;
  std::vector<RemoteStep> steps;
  s = patient.list_steps(steps);
  EXPECT_NE(s.message().find("HTTP 503 (the server is stopping)"), std::string::npos)
      << s.message();
  EXPECT_EQ(asked, 1);
  fake.stop();
  serving.join();
}

TEST_F(Http, RequestsWithoutTheTokenBeyondAnAddressRateGet429) {
  options_.requests_per_second = 2;
  options_.request_burst = 10;
  server_.reset();
  start();
  httplib::Client guesser("127.0.0.1", port_), owner("127.0.0.1", port_);
  guesser.set_bearer_token_auth("a-guess");
  owner.set_bearer_token_auth(server_->token());
  const auto begin = Clock::now();
  // The burst: each wrong token is told so, then the rate holds the guesses back.
  for (int i = 0; i < 10; ++i)
    ASSERT_EQ(guesser.Get("/api/v1/steps")->status, 401) << "request " << i;
  int told = 10, refused = 0;
  for (int i = 0; i < 20; ++i) {
    const auto res = guesser.Get(i % 2 ? "/api/v1/steps" : "/api/v1/steps/1/mesh.glb");
    ASSERT_TRUE(res);
    if (res->status == 401) {
      ++told;
    } else {
      ASSERT_EQ(res->status, 429);
      EXPECT_EQ(res->get_header_value("Retry-After"), "1");
      EXPECT_NE(res->body.find("too many requests without a valid token"), std::string::npos)
          << res->body;
      ++refused;
    }
  }
  // At most the burst and what the rate refilled meanwhile.
  EXPECT_LE(told, 10 + int(2.0 * seconds_since(begin)) + 1);
  EXPECT_GE(refused, 1);
  // The owner, from the same address, and the viewer's files are not held back.
  for (int i = 0; i < 30; ++i) {
    ASSERT_EQ(owner.Get("/api/v1/steps")->status, 200) << "request " << i;
    ASSERT_EQ(guesser.Get("/")->status, 200) << "request " << i;
  }
  std::this_thread::sleep_for(1200ms);  // two guesses back
  EXPECT_EQ(guesser.Get("/api/v1/steps")->status, 401);
}

// The rate limit counts an IPv6 client by its /64 (one host can take any address in it), an IPv4
// one by its address, however written.
TEST(RateLimitKey, IPv4ByAddressIPv6ByItsSlash64) {
  EXPECT_EQ(rate_limit_key("10.1.2.3"), "10.1.2.3");
  EXPECT_EQ(rate_limit_key("::ffff:10.1.2.3"), "10.1.2.3");
  EXPECT_EQ(rate_limit_key("2001:db8:1:2:aaaa:bbbb:cccc:dddd"), "2001:db8:1:2::/64");
  EXPECT_EQ(rate_limit_key("2001:db8:1:2::1"), rate_limit_key("2001:db8:1:2:ffff::7"));
  EXPECT_NE(rate_limit_key("2001:db8:1:2::1"), rate_limit_key("2001:db8:1:3::1"));
  EXPECT_EQ(rate_limit_key("::1"), "::/64");
  EXPECT_EQ(rate_limit_key("fe80::1%eth0"), "fe80::/64");  // a link-local peer, with its zone
  EXPECT_EQ(rate_limit_key("fe80::1%eth0"), rate_limit_key("fe80::2:3:4:5%eth1"));
  EXPECT_EQ(rate_limit_key("not an address"), "not an address");
  EXPECT_EQ(rate_limit_key(""), "");
}

TEST_F(Http, ANonLoopbackAddressIsRefusedUnlessAllowed) {
  for (const char* address :
       {"127.0.0.1", "127.1.2.3", "::1", "0:0:0:0:0:0:0:1", "::ffff:127.0.0.1", "localhost"})
    EXPECT_TRUE(is_loopback_address(address)) << address;
  for (const char* address :
       {"0.0.0.0", "::", "10.0.0.1", "128.0.0.1", "::ffff:10.0.0.1", "example.org", ""})
    EXPECT_FALSE(is_loopback_address(address)) << address;

  HttpServerOptions any = options_;
  any.bind_address = "0.0.0.0";
  any.token = "known-token";
  HttpServer refused(store_, any);
  const Status s = refused.start();
  EXPECT_FALSE(s);
  EXPECT_FALSE(refused.running());
  EXPECT_NE(s.message().find("not a loopback address"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("allow_remote"), std::string::npos) << s.message();
  EXPECT_EQ(s.message().find("known-token"), std::string::npos);

  any.allow_remote = true;
  HttpServer allowed(store_, any);
  ASSERT_TRUE(allowed.start());
  httplib::Client raw("127.0.0.1", allowed.port());  // 0.0.0.0 takes loopback too
  raw.set_bearer_token_auth(allowed.token());
  EXPECT_EQ(raw.Get("/api/v1/steps")->status, 200);
  EXPECT_NE(remote_server_warning("0.0.0.0").find("0.0.0.0"), std::string::npos);
}

TEST_F(Http, StartReportsAPortInUseAndBadOptions) {
  HttpServerOptions same = options_;
  same.port = port_;
  HttpServer second(store_, same);
  const Status s = second.start();
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("port " + std::to_string(port_) + " is in use"), std::string::npos)
      << s.message();
  HttpServerOptions bad_token;
  bad_token.token = "has space";
  EXPECT_FALSE(HttpServer(store_, bad_token).start());
  HttpServerOptions bad_dir;
  bad_dir.static_dir = dir_.path() / "missing";
  EXPECT_FALSE(HttpServer(store_, bad_dir).start());
  HttpServerOptions given_token;
  given_token.token = "my-token";
  HttpServer third(store_, given_token);
  ASSERT_TRUE(third.start());
  EXPECT_EQ(third.token(), "my-token");
  EXPECT_FALSE(third.start());  // already running
}

TEST_F(Http, ClientReportsConnectionRefusedAndBadUrls) {
  const int port = closed_port();
  HttpClient c("http://127.0.0.1:" + std::to_string(port), "t");
  RemoteStep step;
  const Status s = c.latest(step);
  EXPECT_FALSE(s);
  EXPECT_EQ(
      s.message().rfind(
          "cannot connect to http://127.0.0.1:" + std::to_string(port) + ": connection refused", 0),
      0u)
      << s.message();

  ServerUrl url;
  ASSERT_TRUE(parse_server_url("http://127.0.0.1:8080/?token=abc", url));
  EXPECT_EQ(url.host, "127.0.0.1");
  EXPECT_EQ(url.port, 8080);
  EXPECT_EQ(url.token, "abc");
  ASSERT_TRUE(parse_server_url("http://[::1]:81/x?a=1&token=t%7E", url));
  EXPECT_EQ(url.host, "::1");
  EXPECT_EQ(url.port, 81);
  EXPECT_EQ(url.token, "t~");
  ASSERT_TRUE(parse_server_url("localhost", url));
  EXPECT_EQ(url.port, 80);
  EXPECT_FALSE(parse_server_url("https://host:1", url));
  EXPECT_FALSE(parse_server_url("ftp://host:1", url));
  EXPECT_FALSE(parse_server_url("http://:80", url));
  EXPECT_FALSE(parse_server_url("http://host:99999", url));
  EXPECT_FALSE(parse_server_url("http://host:x", url));
  EXPECT_THROW(HttpClient("http://host:0"), std::invalid_argument);
}

TEST_F(Http, ClientDetectsCorruptDownloads) {
  // A server that answers like ours but sends bytes that are not the step's GLB.
  httplib::Server fake;
  const auto good = fake_glb(1);
  fake.Get("/api/v1/steps/1/mesh.glb", [](const httplib::Request&, httplib::Response& res) {
    res.set_content("this is not a glb", "model/gltf-binary");
  });
  fake.Get("/api/v1/steps/2/mesh.glb", [&](const httplib::Request&, httplib::Response& res) {
    auto bytes = good;
    bytes[8] ^= 1;  // the header's length field
    res.set_content(reinterpret_cast<const char*>(bytes.data()), bytes.size(), "model/gltf-binary");
  });
  fake.Get("/api/v1/steps/3/mesh.glb", [&](const httplib::Request&, httplib::Response& res) {
    res.set_content(reinterpret_cast<const char*>(good.data()), good.size(), "model/gltf-binary");
  });
  const int port = fake.bind_to_any_port("127.0.0.1");
  std::thread serving([&] { fake.listen_after_bind(); });
  while (!fake.is_running())
    std::this_thread::sleep_for(1ms);

  HttpClient c("http://127.0.0.1:" + std::to_string(port), "t");
  std::vector<std::uint8_t> glb;
  Status s = c.mesh(1, glb);
  EXPECT_NE(s.message().find("step 1: corrupt download: not a glTF binary"), std::string::npos)
      << s.message();
  s = c.mesh(2, glb);
  EXPECT_NE(s.message().find("step 2: corrupt download: not a glTF binary: the header says"),
            std::string::npos)
      << s.message();
  s = c.mesh(3, glb, good.size() + 1);
  EXPECT_NE(s.message().find("step 3: corrupt download: " + std::to_string(good.size()) +
                             " bytes, the metadata says"),
            std::string::npos)
      << s.message();
  EXPECT_TRUE(c.mesh(3, glb, good.size()));
  EXPECT_EQ(glb, good);
  HttpClient tiny("http://127.0.0.1:" + std::to_string(port), "t", {.max_glb_bytes = 10});
  s = tiny.mesh(3, glb);
  EXPECT_NE(s.message().find("larger than the limit"), std::string::npos) << s.message();
  fake.stop();
  serving.join();
}

}  // namespace
}  // namespace ldimesh

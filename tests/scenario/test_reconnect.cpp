// Clients that outlive their server's troubles: the back-off policy (backoff.h), irradcast-view
// against a listener that resets its connections and against a server that starts late, and
// irradcast-load users across a kill -9 and restart of irradcast-server.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <asio.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <map>
#include <set>
#include <sstream>

#include "irradcast/client/backoff.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/frame.h"
#include "process.h"
#include "service_fixture.h"

namespace irradcast::test_reconnect {

using asio::ip::tcp;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

using test::command;
using test::free_port;

fs::path temp_path(const std::string& name) {
  return fs::temp_directory_path() /
         ("irradcast_reconnect_" + std::to_string(::getpid()) + "_" + name);
}

// An in-process server for `port`: cornell, small lightmaps, final after 2 updates.
struct LocalServer {
  explicit LocalServer(std::uint16_t port) {
    host = std::make_unique<EngineHost>(make_cornell_box(), "cornell", test::small_host(2));
    ServerOptions so = test::loopback();
    so.port = port;
    so.io_threads = 1;
    server = std::make_unique<Server>(*host, so);
    server->start();
    host->start();
  }
  ~LocalServer() {
    server->stop();
    host->stop();
  }
  std::unique_ptr<EngineHost> host;
  std::unique_ptr<Server> server;
};

std::vector<std::string> viewer_args(std::uint16_t port, const fs::path& out, int timeout_s) {
  return command(IRRADCAST_VIEW_EXE,
                 "--connect 127.0.0.1:" + std::to_string(port) + " --out " + out.string() +
                     " --json " + out.string() + ".json --until-converged --timeout " +
                     std::to_string(timeout_s) + " --width 32 --height 24 --cache-dir none");
}

// A listener that misbehaves: accepts connections and ends them the ways a dying server does.
class FlakyListener {
 public:
  FlakyListener() : acceptor_(io_) {
    acceptor_.open(tcp::v4());
    acceptor_.set_option(tcp::acceptor::reuse_address(true));
    acceptor_.bind(tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
    acceptor_.listen();
  }
  std::uint16_t port() const { return acceptor_.local_endpoint().port(); }
  void close() { acceptor_.close(); }

  // The next connection, or nullopt after `limit`.
  std::optional<tcp::socket> accept(std::chrono::milliseconds limit = 10000ms) {
    std::optional<tcp::socket> got;
    acceptor_.async_accept([&](std::error_code ec, tcp::socket s) {
      if (!ec) got = std::move(s);
    });
    run_for(limit, [&] { acceptor_.cancel(); });
    return got;
  }
  // The next frame on `s`, or nullopt at EOF / an error / after `limit`.
  std::optional<wire::Envelope> read(tcp::socket& s, std::chrono::milliseconds limit = 5000ms) {
    wire::FrameDecoder decoder;
    std::array<char, 4096> buf{};
    wire::Envelope e;
    const auto deadline = Clock::now() + limit;
    while (decoder.next(e) != wire::DecodeStatus::Frame) {
      if (Clock::now() >= deadline) return std::nullopt;
      std::error_code result = asio::error::would_block;
      std::size_t n = 0;
      s.async_read_some(asio::buffer(buf), [&](std::error_code ec, std::size_t got) {
        result = ec;
        n = got;
      });
      run_for(std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()),
              [&] { s.cancel(); });
      if (result) return std::nullopt;
      decoder.feed(buf.data(), n);
    }
    return e;
  }
  // Close with SO_LINGER 0: the peer gets a RST ("Connection reset by peer").
  static void reset(tcp::socket& s) {
    s.set_option(asio::socket_base::linger(true, 0));
    s.close();
  }

 private:
  template <class Cancel>
  void run_for(std::chrono::milliseconds limit, Cancel cancel) {
    io_.restart();
    io_.run_for(std::max(limit, 1ms));
    if (!io_.stopped()) {
      cancel();
      io_.restart();
      io_.run();
    }
  }

  asio::io_context io_;
  tcp::acceptor acceptor_;
};

}  // namespace

TEST(Backoff, DelaysAreJitteredUnderACappedExponentialCeiling) {
  BackoffPolicy p;
  p.initial = 100ms;
  p.cap = 2000ms;
  p.factor = 2.0;
  Backoff b(p, 42);
  const std::vector<std::chrono::milliseconds> ceilings = {100ms,  200ms,  400ms, 800ms,
                                                           1600ms, 2000ms, 2000ms};
  for (std::size_t k = 0; k < ceilings.size(); ++k) {
    EXPECT_EQ(b.ceiling(), ceilings[k]) << "attempt " << k;
    const Clock::duration d = b.next();
    EXPECT_GE(d.count(), 0);
    EXPECT_LE(d, ceilings[k]) << "attempt " << k;
  }
  // At the cap: uniform in [0, 2 s] (full jitter), never above it, all different.
  std::set<Clock::duration::rep> seen;
  double sum = 0.0, lo = 1e9, hi = 0.0;
  const int n = 2000;
  for (int i = 0; i < n; ++i) {
    const double s = std::chrono::duration<double>(b.next()).count();
    EXPECT_LE(s, 2.0);
    sum += s;
    lo = std::min(lo, s);
    hi = std::max(hi, s);
    seen.insert(static_cast<Clock::duration::rep>(s * 1e9));
  }
  EXPECT_GT(seen.size(), static_cast<std::size_t>(n * 99 / 100)) << "not jittered";
  EXPECT_NEAR(sum / n, 1.0, 0.06) << "the mean of uniform [0, 2 s]";
  EXPECT_LT(lo, 0.05);
  EXPECT_GT(hi, 1.95);
  // reset() starts again from the initial ceiling.
  b.reset();
  EXPECT_EQ(b.ceiling(), 100ms);
  EXPECT_LE(b.next(), 100ms);
  // Seeded: the same seed gives the same delays, another seed others.
  Backoff a1(p, 7), a2(p, 7), c(p, 8);
  int same = 0;
  for (int i = 0; i < 20; ++i) {
    const auto d1 = a1.next(), d2 = a2.next(), d3 = c.next();
    EXPECT_EQ(d1, d2);
    same += d1 == d3;
  }
  EXPECT_LT(same, 2);
}

TEST(Backoff, NeverSleepsPastTheDeadline) {
  BackoffPolicy p;  // the defaults: 100 ms, x2, capped at 2 s
  for (std::uint64_t seed = 1; seed <= 50; ++seed) {
    Backoff b(p, seed);
    const Clock::time_point start{};
    const Clock::time_point deadline = start + 3500ms;
    Clock::time_point t = start;  // virtual time: sleep = advance
    int attempts = 0;
    while (auto d = b.next_before(t, deadline)) {
      ASSERT_GE(d->count(), 0);
      ASSERT_LE(t + *d, deadline) << "seed " << seed << ", attempt " << attempts;
      t += *d;
      ASSERT_LT(++attempts, 1000);
    }
    // The last delay ends exactly at the deadline (a last attempt there), then no more.
    EXPECT_EQ(t, deadline) << "seed " << seed;
    EXPECT_FALSE(b.next_before(deadline + 1ms, deadline));
  }
}

TEST(Backoff, BadPoliciesAndTheErrorsThatMeanTryAgain) {
  BackoffPolicy p;
  p.initial = 0ms;
  EXPECT_THROW(Backoff(p, 1), Error);
  p.initial = 500ms;
  p.cap = 100ms;
  EXPECT_THROW(Backoff(p, 1), Error);
  p.cap = 1000ms;
  p.factor = 0.5;
  EXPECT_THROW(Backoff(p, 1), Error);
  EXPECT_TRUE(server_error_is_transient(wire::SERVER_SHUTDOWN));
  EXPECT_TRUE(server_error_is_transient(wire::IDLE_TIMEOUT));
  EXPECT_TRUE(server_error_is_transient(wire::INTERNAL));
  EXPECT_TRUE(server_error_is_transient(wire::REFUSED));  // e.g. "the server is full"
  EXPECT_FALSE(server_error_is_transient(wire::UNSUPPORTED_VERSION));
  EXPECT_FALSE(server_error_is_transient(wire::BAD_FRAME));
  EXPECT_FALSE(server_error_is_transient(wire::UNEXPECTED_MESSAGE));
}

// The viewer meets a dying server in every phase before the real one takes the port: resets at
// once, after its Hello, an Error SERVER_SHUTDOWN instead of a Welcome, and a reset in the middle
// of the scene download. Each is another attempt, and the viewer ends with its image.
TEST(Reconnect, ViewerRidesOutResetConnectionsAndGetsItsImage) {
  FlakyListener flaky;
  const std::uint16_t port = flaky.port();
  const fs::path out = temp_path("flaky.png");
  fs::remove(out);
  test::Process viewer(viewer_args(port, out, 60), temp_path("flaky_view.log"));

  {  // 1. Reset at once.
    auto s = flaky.accept();
    ASSERT_TRUE(s) << "the viewer never connected\n" << viewer.output();
    FlakyListener::reset(*s);
  }
  {  // 2. Reset after reading the Hello.
    auto s = flaky.accept();
    ASSERT_TRUE(s) << "the viewer gave up after a reset\n" << viewer.output();
    auto hello = flaky.read(*s);
    ASSERT_TRUE(hello && hello->has_hello());
    FlakyListener::reset(*s);
  }
  {  // 3. A server shutting down: Error SERVER_SHUTDOWN instead of a Welcome, then close.
    auto s = flaky.accept();
    ASSERT_TRUE(s) << "the viewer gave up after a reset during the handshake\n" << viewer.output();
    auto hello = flaky.read(*s);
    ASSERT_TRUE(hello && hello->has_hello());
    const std::string frame =
        wire::encode_frame(wire::make_error(wire::SERVER_SHUTDOWN, "the server is shutting down"));
    asio::write(*s, asio::buffer(frame));
    s->shutdown(tcp::socket::shutdown_send);
    flaky.read(*s, 3000ms);  // until the viewer closes
  }
  {  // 4. A Welcome, then a reset during the scene download.
    auto s = flaky.accept();
    ASSERT_TRUE(s) << "the viewer gave up after SERVER_SHUTDOWN\n" << viewer.output();
    auto hello = flaky.read(*s);
    ASSERT_TRUE(hello && hello->has_hello());
    wire::Envelope welcome;
    wire::Welcome* w = welcome.mutable_welcome();
    w->set_protocol_version(wire::kProtocolVersion);
    w->set_session(1);
    w->set_scene_id("dying");
    w->set_scene_hash(std::string(32, 'x'));
    w->set_scene_bytes(4096);
    w->set_tile_size(16);
    w->set_idle_timeout_ms(10000);
    w->set_tile_epoch(1);
    asio::write(*s, asio::buffer(wire::encode_frame(welcome)));
    auto request = flaky.read(*s);
    ASSERT_TRUE(request && request->has_scene_request()) << viewer.output();
    FlakyListener::reset(*s);
  }
  // The real server takes the port.
  flaky.close();
  LocalServer server(port);
  const std::optional<int> status = viewer.wait_for(60s);
  ASSERT_TRUE(status) << "the viewer did not finish\n" << viewer.output();
  EXPECT_EQ(*status, 0) << viewer.output();
  EXPECT_NE(viewer.output().find("converged image after"), std::string::npos) << viewer.output();
  EXPECT_TRUE(fs::exists(out));
  std::ifstream jf(out.string() + ".json");
  const nlohmann::json j = nlohmann::json::parse(jf);
  EXPECT_EQ(j["connections"], 1) << "one session: the flaky connections never set one up";
  EXPECT_GE(j.value("connect_attempts", 0), 5);
  fs::remove(out);
  fs::remove(out.string() + ".json");
}

// A server that accepts and then says nothing is as gone as one that resets: no Welcome, or a
// scene download that stalls, within the reply timeout is another attempt (the library, with a
// short reply timeout).
TEST(Reconnect, ClientRetriesAHandshakeOrDownloadThatTimesOut) {
  FlakyListener flaky;
  const std::uint16_t port = flaky.port();
  ViewClientOptions vo;
  vo.port = port;
  vo.name = "patient";
  vo.reply_timeout = 300ms;
  vo.deadline = Clock::now() + 60s;
  vo.backoff_seed = 3;
  ViewClient client(vo);
  auto connected = std::async(std::launch::async, [&] { client.connect(); });
  {  // 1. Reads the Hello and never answers.
    auto s = flaky.accept();
    ASSERT_TRUE(s);
    ASSERT_TRUE(flaky.read(*s));
    auto next = flaky.accept();
    ASSERT_TRUE(next) << "no new attempt after a Welcome that never came";
    // 2. A Welcome, then nothing of the scene.
    ASSERT_TRUE(flaky.read(*next));
    wire::Envelope welcome;
    wire::Welcome* w = welcome.mutable_welcome();
    w->set_protocol_version(wire::kProtocolVersion);
    w->set_scene_hash(std::string(32, 'y'));
    w->set_scene_bytes(4096);
    w->set_tile_size(16);
    asio::write(*next, asio::buffer(wire::encode_frame(welcome)));
    auto request = flaky.read(*next);
    ASSERT_TRUE(request && request->has_scene_request());
    auto third = flaky.accept();
    ASSERT_TRUE(third) << "no new attempt after a stalled download";
    FlakyListener::reset(*third);
  }
  flaky.close();
  LocalServer server(port);
  ASSERT_EQ(connected.wait_for(30s), std::future_status::ready);
  ASSERT_NO_THROW(connected.get());
  EXPECT_EQ(client.counters().connections, 1u);
  EXPECT_GE(client.counters().connect_attempts, 4u);
  const auto until = Clock::now() + 30s;
  while (!client.all_tiles_received() && Clock::now() < until) client.poll(50ms);
  EXPECT_TRUE(client.all_tiles_received());
  client.close();
}

// What reconnecting would not cure still ends the viewer at once, with a clear message: a frame
// that does not parse, and a server of another protocol version.
TEST(Reconnect, ViewerStillFailsClearlyOnProtocolErrors) {
  struct Case {
    std::string name, says;
    std::function<void(FlakyListener&, tcp::socket&)> answer;
  };
  const std::vector<Case> cases = {
      {"bad_frame", "bad frame",
       [](FlakyListener&, tcp::socket& s) {
         std::string junk("\x10\x00\x00\x00", 4);
         for (int i = 0; i < 16; ++i) junk += static_cast<char>(0xF7 ^ (i * 37));
         asio::write(s, asio::buffer(junk));
       }},
      {"version", "protocol 99",
       [](FlakyListener&, tcp::socket& s) {
         wire::Envelope welcome;
         welcome.mutable_welcome()->set_protocol_version(99);
         asio::write(s, asio::buffer(wire::encode_frame(welcome)));
       }},
  };
  for (const Case& c : cases) {
    FlakyListener flaky;
    const fs::path out = temp_path(c.name + ".png");
    test::Process viewer(viewer_args(flaky.port(), out, 60), temp_path(c.name + "_view.log"));
    auto s = flaky.accept();
    ASSERT_TRUE(s) << viewer.output();
    auto hello = flaky.read(*s);
    ASSERT_TRUE(hello && hello->has_hello());
    c.answer(flaky, *s);
    const std::optional<int> status = viewer.wait_for(10s);
    ASSERT_TRUE(status) << c.name << ": the viewer retries a protocol error\n" << viewer.output();
    EXPECT_EQ(*status, 1) << viewer.output();
    EXPECT_NE(viewer.output().find(c.says), std::string::npos) << viewer.output();
    EXPECT_FALSE(flaky.accept(300ms)) << c.name << ": the viewer connected again";
  }
}

// A server that comes up later than the old 10 s connect limit: the viewer keeps trying (with
// back-off, capped at 2 s) until its --timeout.
TEST(Reconnect, ViewerWaitsForAServerThatStartsTwelveSecondsLate) {
  const std::uint16_t port = free_port();
  const fs::path out = temp_path("late.png");
  fs::remove(out);
  test::Process viewer(viewer_args(port, out, 90), temp_path("late_view.log"));
  const std::optional<int> early = viewer.wait_for(12s);
  ASSERT_FALSE(early) << "the viewer gave up on a server that is not there yet (exit " << *early
                      << ")\n"
                      << viewer.output();
  LocalServer server(port);
  const std::optional<int> status = viewer.wait_for(60s);
  ASSERT_TRUE(status) << "the viewer did not finish\n" << viewer.output();
  EXPECT_EQ(*status, 0) << viewer.output();
  EXPECT_NE(viewer.output().find("converged image after"), std::string::npos) << viewer.output();
  fs::remove(out);
  fs::remove(out.string() + ".json");
}

// kill -9 of irradcast-server in the middle of a load test, and a restart on the same port: every
// user reconnects (with back-off), resumes, and finishes the run; the report counts the
// reconnects.
TEST(Reconnect, LoadUsersReconnectAfterTheServerIsKilledAndRestarted) {
  const std::uint16_t port = free_port();
  const std::vector<std::string> server_args = command(
      IRRADCAST_SERVER_EXE, "--scene cornell --bind 127.0.0.1 --port " + std::to_string(port) +
                                " --texels-per-scene 48 --tile-size 16 --max-updates 3 --threads 1 "
                                "--io-threads 1 --log-level warn");
  auto server = std::make_unique<test::Process>(server_args, temp_path("load_server1.log"));
  // Wait until it listens.
  ViewClientOptions vo;
  vo.port = port;
  vo.name = "watcher";
  vo.connect_timeout = 30000ms;
  {
    ViewClient probe(vo);
    ASSERT_NO_THROW(probe.connect()) << server->output();
    probe.close();
  }
  const int users = 4;
  const fs::path json = temp_path("load.json");
  fs::remove(json);
  test::Process load(command(IRRADCAST_LOAD_EXE, "--connect 127.0.0.1:" + std::to_string(port) +
                                                     " --users " + std::to_string(users) +
                                                     " --duration 10 --threads 1 --camera-hz 5 "
                                                     "--quiet --json " +
                                                     json.string()),
                     temp_path("load.log"));
  {  // Every user has a session (4 + this watcher).
    ViewClient watcher(vo);
    watcher.connect();
    bool all = false;
    for (int i = 0; i < 100 && !all; ++i) {
      auto s = watcher.request_stats(2s);
      all = s && s->clients() >= static_cast<std::uint32_t>(users + 1);
      if (!all) std::this_thread::sleep_for(100ms);
    }
    ASSERT_TRUE(all) << load.output();
    watcher.close();
  }
  std::this_thread::sleep_for(500ms);
  server->signal(SIGKILL);
  ASSERT_TRUE(server->wait_for(5s));
  std::this_thread::sleep_for(500ms);
  server = std::make_unique<test::Process>(server_args, temp_path("load_server2.log"));
  const std::optional<int> status = load.wait_for(60s);
  ASSERT_TRUE(status) << load.output();
  EXPECT_EQ(*status, 0) << load.output();
  std::ifstream f(json);
  const nlohmann::json rep = nlohmann::json::parse(f);
  EXPECT_EQ(rep["users"]["connected"], users);
  EXPECT_EQ(rep["users"]["failed"], 0) << rep.dump(2);
  EXPECT_GE(rep["users"].value("reconnects", 0), users) << rep.dump(2);
  for (const auto& u : rep["per_user"]) {
    EXPECT_EQ(u["failure"], "");
    EXPECT_GE(u.value("reconnects", 0), 1);
  }
  EXPECT_NE(load.output().find("reconnects"), std::string::npos) << load.output();
  server->signal(SIGINT);
  server->wait_for(10s);
  fs::remove(json);
}

}  // namespace irradcast::test_reconnect

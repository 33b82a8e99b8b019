// Clients that fail over (--connect A,B,...): the address list and its hostile forms, a viewer
// that moves from a killed irradcast-server to a second one and still converges to that server's
// image (resuming when the tile epoch is the same, receiving every tile again when it is not),
// a dead first address, load users spread over the list, and irradcast-edit past a dead address.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "cli.h"
#include "irradcast/client/host_port.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "process.h"
#include "service_fixture.h"

namespace irradcast::test_failover {

using namespace std::chrono_literals;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

fs::path temp_path(const std::string& name) {
  return fs::temp_directory_path() /
         ("irradcast_failover_" + std::to_string(::getpid()) + "_" + name);
}

// An in-process server of the cornell box (small lightmaps, final after 2 updates).
struct LocalServer {
  explicit LocalServer(EngineHostOptions ho = test::small_host(2), const std::string& token = "") {
    host = std::make_unique<EngineHost>(make_cornell_box(), "cornell", ho);
    ServerOptions so = test::loopback();
    so.io_threads = 1;
    so.control_token = token;
    server = std::make_unique<Server>(*host, so);
    server->start();
    host->start();
  }
  ~LocalServer() { stop(); }
  void stop() {
    if (!server) return;
    server->stop();
    host->stop();
    server.reset();
  }
  HostPort address() const { return {"127.0.0.1", port}; }
  std::unique_ptr<EngineHost> host;
  std::unique_ptr<Server> server;
  std::uint16_t port = 0;
};

std::unique_ptr<LocalServer> start_server(EngineHostOptions ho = test::small_host(2),
                                          const std::string& token = "") {
  auto s = std::make_unique<LocalServer>(ho, token);
  s->port = s->server->port();
  return s;
}

// Waits until the engine published its final tiles.
void wait_idle(const EngineHost& host) {
  const auto deadline = Clock::now() + 60s;
  while (!host.stats().idle && Clock::now() < deadline) std::this_thread::sleep_for(20ms);
  ASSERT_TRUE(host.stats().idle);
}

ViewClientOptions viewer(std::vector<HostPort> servers, const std::string& name) {
  ViewClientOptions o;
  o.servers = std::move(servers);
  o.name = name;
  o.connect_timeout = 20000ms;
  o.backoff_seed = 7;
  return o;
}

// Polls until every tile of `v` has arrived and `done` holds (or 30 s).
template <class Done>
void poll_until(ViewClient& v, Done done) {
  const auto deadline = Clock::now() + 30s;
  while (!(v.all_tiles_received() && done()) && Clock::now() < deadline) v.poll(50ms);
}

// Polls until the viewer holds every tile and its server's engine is idle (final tiles).
void poll_until_final(ViewClient& v) {
  poll_until(v, [&] {
    auto s = v.request_stats(2s);
    return s && s->engine_idle() && s->queue_depth() == 0;
  });
  v.poll(200ms);
}

// The lightmaps of a viewer connected only to `server` once it has every final tile.
std::vector<Lightmap> direct_lightmaps(const HostPort& server) {
  ViewClient v(viewer({server}, "direct"));
  v.connect();
  poll_until_final(v);
  std::vector<Lightmap> maps = v.lightmaps();
  v.close();
  return maps;
}

bool same_lightmaps(const std::vector<Lightmap>& a, const std::vector<Lightmap>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].width != b[i].width || a[i].height != b[i].height || a[i].texels != b[i].texels)
      return false;
  return true;
}

}  // namespace

TEST(HostList, ParsesListsAndRejectsHostileOnes) {
  const std::vector<HostPort> one = parse_host_list("127.0.0.1:7450");
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0].host, "127.0.0.1");
  EXPECT_EQ(one[0].port, 7450);
  const std::vector<HostPort> three = parse_host_list("a:1,::1:7450,gw.example:65535");
  ASSERT_EQ(three.size(), 3u);
  EXPECT_EQ(three[1].host, "::1");
  EXPECT_EQ(three[1].port, 7450);
  EXPECT_EQ(three[2].text(), "gw.example:65535");
  std::string sixteen = "h:1";
  for (int i = 2; i <= 16; ++i) sixteen += ",h:" + std::to_string(i);
  EXPECT_EQ(parse_host_list(sixteen).size(), kMaxServerAddresses);

  auto error_of = [](const std::string& spec) {
    try {
      parse_host_list(spec);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(error_of(""), "--connect: no address (HOST:PORT[,HOST:PORT...])");
  EXPECT_NE(error_of("a:1,,b:2").find("address 2 is empty"), std::string::npos);
  EXPECT_NE(error_of("a:1,").find("address 2 is empty"), std::string::npos);
  EXPECT_NE(error_of(",a:1").find("address 1 is empty"), std::string::npos);
  EXPECT_NE(error_of("a:1,b:0").find("'0' is not a port number"), std::string::npos);
  EXPECT_NE(error_of("a:1,b:65536").find("'65536' is not a port number"), std::string::npos);
  EXPECT_NE(error_of("a:1, b:2").find("' b' is not a host name"), std::string::npos);
  EXPECT_NE(error_of("a:1,b\x01:2").find("is not a host name"), std::string::npos);
  EXPECT_NE(error_of("a:1,b").find("'b' is not HOST:PORT"), std::string::npos);
  EXPECT_NE(error_of("a:1,b:2\n").find("is not a port number"), std::string::npos)
      << error_of("a:1,b:2\n");
  EXPECT_EQ(error_of(sixteen + ",h:17"), "--connect: more than 16 addresses");
  // A huge list stops at the limit, long before its end.
  std::string huge;
  for (int i = 0; i < 100000; ++i) huge += "h:1,";
  EXPECT_EQ(error_of(huge), "--connect: more than 16 addresses");
  // The programs say the same on their command line.
  const test::CliResult r =
      test::run_cli(IRRADCAST_VIEW_EXE, "--connect 127.0.0.1:1,,127.0.0.1:2 --out x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--connect: address 2 is empty"), std::string::npos) << r.output;
}

// Two servers of the same scene and parameters: kill A and the viewer moves to B. Both are
// deterministic, so B's tile epoch and versions are A's: the viewer resumes without receiving a
// tile again, and its lightmaps are those of a viewer of B alone, bit for bit.
TEST(Failover, KilledServerMovesTheViewerToTheNextWhichResumes) {
  const std::string args =
      "--scene cornell --bind 127.0.0.1 --texels-per-scene 48 --tile-size 16 --max-updates 2 "
      "--threads 1 --io-threads 1 --log-level warn --port ";
  const std::uint16_t port_a = test::free_port(), port_b = test::free_port();
  test::Process a(test::command(IRRADCAST_SERVER_EXE, args + std::to_string(port_a)),
                  temp_path("a.log"));
  test::Process b(test::command(IRRADCAST_SERVER_EXE, args + std::to_string(port_b)),
                  temp_path("b.log"));
  const HostPort addr_a{"127.0.0.1", port_a}, addr_b{"127.0.0.1", port_b};
  const std::vector<Lightmap> reference = direct_lightmaps(addr_b);  // B's final tiles

  ViewClient v(viewer({addr_a, addr_b}, "failover"));
  v.connect();
  EXPECT_EQ(v.server().port, port_a);
  poll_until_final(v);  // A's final tiles
  ASSERT_TRUE(v.all_tiles_received());
  EXPECT_TRUE(same_lightmaps(v.lightmaps(), reference)) << "A and B differ: not deterministic?";
  const std::uint64_t tiles_before = v.counters().tiles_applied;

  a.signal(SIGKILL);
  ASSERT_TRUE(a.wait_for(5s));
  const auto deadline = Clock::now() + 30s;
  while (v.counters().connections < 2 && Clock::now() < deadline) v.poll(50ms);
  v.poll(300ms);
  const ViewClientCounters c = v.counters();
  EXPECT_EQ(c.connections, 2u);
  EXPECT_EQ(c.connections_lost, 1u);
  EXPECT_GE(c.failovers, 1u);
  EXPECT_EQ(v.server().port, port_b);
  EXPECT_EQ(c.tiles_applied, tiles_before) << "B sent tiles the viewer held (no resume)";
  EXPECT_TRUE(same_lightmaps(v.lightmaps(), reference));
  v.close();
}

// B has another engine parameter (another seed), so another tile epoch: its versions are not
// comparable with A's. The viewer must take every tile B sends, even where B's version number is
// lower than the one it holds from A, and end with B's image.
TEST(Failover, AnotherTileEpochGetsEveryTileAgain) {
  EngineHostOptions ho_a = test::small_host(3);  // A refines further: higher versions
  EngineHostOptions ho_b = test::small_host(1);
  ho_b.engine.seed = ho_a.engine.seed + 1;
  auto a = start_server(ho_a);
  auto b = start_server(ho_b);
  wait_idle(*b->host);
  ASSERT_NE(a->host->tile_epoch(), b->host->tile_epoch());
  const std::vector<Lightmap> reference = direct_lightmaps(b->address());

  ViewClient v(viewer({a->address(), b->address()}, "epochs"));
  v.connect();
  wait_idle(*a->host);
  poll_until(v, [] { return true; });
  v.poll(300ms);
  ASSERT_TRUE(v.all_tiles_received());
  EXPECT_FALSE(same_lightmaps(v.lightmaps(), reference)) << "A and B agree: the test shows nothing";
  const std::uint64_t tiles_before = v.counters().tiles_applied;

  a->stop();
  const auto deadline = Clock::now() + 30s;
  while (v.counters().connections < 2 && Clock::now() < deadline) v.poll(50ms);
  poll_until(v, [] { return true; });
  v.poll(300ms);
  EXPECT_EQ(v.server().port, b->port);
  EXPECT_EQ(v.counters().tiles_applied - tiles_before, v.tile_count());
  EXPECT_TRUE(same_lightmaps(v.lightmaps(), reference));
  v.close();
}

// irradcast-view --connect DEAD,B: the refused first address costs one attempt; the viewer gets
// its image from B.
TEST(Failover, ViewerWithADeadFirstAddressConnectsToTheSecond) {
  auto b = start_server();
  const fs::path out = temp_path("dead_first.png");
  const test::CliResult r = test::run_cli(
      IRRADCAST_VIEW_EXE, "--connect 127.0.0.1:" + std::to_string(test::free_port()) +
                              ",127.0.0.1:" + std::to_string(b->port) + " --out " + out.string() +
                              " --json " + out.string() +
                              ".json --until-converged --timeout 30 --width 32 --height 24 "
                              "--cache-dir none");
  EXPECT_EQ(r.status, 0) << r.output;
  std::ifstream f(out.string() + ".json");
  ASSERT_TRUE(f) << r.output;
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["converged"], true);
  EXPECT_EQ(j["connections"], 1);
  EXPECT_EQ(j["connect_attempts"], 2);
  EXPECT_EQ(j["failovers"], 1);
  fs::remove(out);
  fs::remove(out.string() + ".json");
}

// Load users spread their first connection over the list (user i on server i mod n), and a
// user whose first address is dead goes on to the next.
TEST(Failover, LoadUsersSpreadOverTheList) {
  auto a = start_server();
  auto b = start_server();
  LoadOptions lo;
  lo.servers = {a->address(), b->address(), {"127.0.0.1", test::free_port()}};
  lo.users = 6;
  lo.duration_s = 2.0;
  lo.threads = 1;
  lo.camera_hz = 2.0;
  const LoadReport r = run_load(lo);
  EXPECT_EQ(r.connected, 6);
  EXPECT_EQ(r.failed, 0) << r.text();
  // Users 0 and 3 start on A, 1 and 4 on B, 2 and 5 on the dead address and go on to A.
  EXPECT_EQ(a->server->stats().connections, 4u);
  EXPECT_EQ(b->server->stats().connections, 2u);
  EXPECT_NE(r.text().find(b->address().text()), std::string::npos) << r.text();
}

// irradcast-edit --connect DEAD,A: the edit is applied on A.
TEST(Failover, EditorSkipsADeadAddress) {
  auto a = start_server(test::quick_host(), "failover-token-0123456789");
  const test::CliResult r = test::run_cli(
      IRRADCAST_EDIT_EXE, "--connect 127.0.0.1:" + std::to_string(test::free_port()) +
                              ",127.0.0.1:" + std::to_string(a->port) +
                              " --token failover-token-0123456789 --hide short_block");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("revision 1 applied"), std::string::npos) << r.output;
  EXPECT_EQ(a->host->stats().revision, 1u);
  // Every address dead: one clear line naming each.
  const std::string dead1 = std::to_string(test::free_port()), dead2 = "1";
  const test::CliResult none =
      test::run_cli(IRRADCAST_EDIT_EXE, "--connect 127.0.0.1:" + dead1 + ",127.0.0.1:" + dead2 +
                                            " --token t --hide short_block");
  EXPECT_EQ(none.status, 1) << none.output;
  EXPECT_NE(none.output.find("no server of --connect answered"), std::string::npos) << none.output;
  EXPECT_NE(none.output.find("127.0.0.1:" + dead1), std::string::npos) << none.output;
}

// A server lost between two edits of a script: the second goes to the next server of the list.
TEST(Failover, EditorMovesToTheNextServerBetweenEdits) {
  const std::string token = "failover-token-0123456789";
  auto a = start_server(test::quick_host(), token);
  auto b = start_server(test::quick_host(), token);
  const fs::path script = temp_path("script.json");
  {
    std::ofstream f(script);
    f << R"([{"op": "hide", "node": "short_block"},
             {"after_ms": 1500, "op": "hide", "node": "tall_block"}])";
  }
  test::Process edit(test::command(IRRADCAST_EDIT_EXE, "--connect " + a->address().text() + "," +
                                                           b->address().text() + " --token " +
                                                           token + " --script " + script.string()),
                     temp_path("edit.log"));
  // The first edit applied on A and the editor told so: stop A while the editor waits for the
  // second. (Stopping A once its host has the edit but before the editor read "applied" makes
  // the editor report the first edit as not applied, rightly.)
  const auto deadline = Clock::now() + 20s;
  while (edit.output().find("revision 1 applied") == std::string::npos && Clock::now() < deadline)
    std::this_thread::sleep_for(10ms);
  ASSERT_EQ(a->host->stats().revision, 1u) << edit.output();
  ASSERT_NE(edit.output().find("revision 1 applied"), std::string::npos) << edit.output();
  a->stop();
  const std::optional<int> status = edit.wait_for(30s);
  ASSERT_TRUE(status) << edit.output();
  EXPECT_EQ(*status, 0) << edit.output();
  EXPECT_EQ(b->host->stats().revision, 1u);  // the second edit, and only it
  EXPECT_NE(edit.output().find("trying the next server"), std::string::npos) << edit.output();
  fs::remove(script);
}

}  // namespace irradcast::test_failover

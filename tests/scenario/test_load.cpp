// irradcast-load, driven as a user would, against an in-process server; and its camera paths.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <asio.hpp>

#include <filesystem>
#include <fstream>
#include <future>
#include <thread>

#include "cli.h"
#include "irradcast/client/camera_path.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "service_fixture.h"

namespace irradcast::test_load {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

using test::loopback;
using test::small_host;

// The server's tile versions in the clients' layout order, as irradcast-load digests them.
std::uint64_t server_digest(const TileStore& store) {
  std::vector<std::uint64_t> v;
  for (std::uint32_t m = 0; m < store.lightmap_count(); ++m)
    for (int ty = 0; ty < store.tiles_y(m); ++ty)
      for (int tx = 0; tx < store.tiles_x(m); ++tx)
        v.push_back(store.version(static_cast<std::uint32_t>(
            store.index(m, static_cast<std::uint32_t>(tx), static_cast<std::uint32_t>(ty)))));
  return versions_digest(v);
}

fs::path temp_file(const std::string& name) {
  return fs::temp_directory_path() / ("irradcast_load_" + name);
}

nlohmann::json read_json(const fs::path& p) {
  std::ifstream f(p);
  return nlohmann::json::parse(f);
}

}  // namespace

// The acceptance test: 32 thin users for a few seconds; every user connects, loads the
// scene, holds every tile at the server's final version, and nothing goes wrong. The engine
// starts after the users connected, so every version is computed while they are subscribed
// (live tiles with a latency).
TEST(Load, ThirtyTwoThinUsersGetEveryTileVersionWithoutErrors) {
  EngineHost host(make_cornell_box(), "cornell", small_host(3));
  Server server(host, loopback());
  server.start();
  const fs::path json = temp_file("32.json");
  fs::remove(json);
  auto load = std::async(std::launch::async, [&] {
    return test::run_cli(IRRADCAST_LOAD_EXE,
                         "--connect 127.0.0.1:" + std::to_string(server.port()) +
                             " --users 32 --duration 6 --camera-hz 5 "
                             "--threads 2 --quiet --json " +
                             json.string());
  });
  // Wait until every user has subscribed (or give up after 20 s), then start refining.
  for (int i = 0; i < 200 && server.stats().clients < 32; ++i) std::this_thread::sleep_for(100ms);
  std::this_thread::sleep_for(500ms);
  host.start();
  const test::CliResult r = load.get();
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("32 connected, 0 failed"), std::string::npos) << r.output;
  ASSERT_TRUE(host.stats().idle) << "the engine should have finished its 3 updates";
  const nlohmann::json rep = read_json(json);
  EXPECT_EQ(rep["users"]["total"], 32);
  EXPECT_EQ(rep["users"]["connected"], 32);
  EXPECT_EQ(rep["users"]["failed"], 0);
  EXPECT_EQ(rep["users"]["scene_loaded"], 32);
  EXPECT_EQ(rep["users"]["full_image"], 32);
  EXPECT_TRUE(rep["errors"].empty()) << rep["errors"].dump();
  const std::uint64_t digest = server_digest(host.tiles());
  const auto tiles = static_cast<std::uint64_t>(host.tiles().tile_count());
  ASSERT_EQ(rep["per_user"].size(), 32u);
  std::uint64_t applied = 0;
  for (const auto& u : rep["per_user"]) {
    EXPECT_EQ(u["tiles_held"].get<std::uint64_t>(), tiles);
    EXPECT_EQ(u["versions_digest"].get<std::string>(), std::to_string(digest))
        << "a user does not hold the server's final version of every tile";
    EXPECT_EQ(u["failure"], "");
    EXPECT_GE(u["tiles_applied"].get<std::uint64_t>(), tiles);
    applied += u["tiles_applied"].get<std::uint64_t>();
  }
  // Every tile a user applied was computed after it subscribed, so each has a latency.
  EXPECT_EQ(rep["tile_latency_ms"]["count"].get<std::uint64_t>(), applied);
  EXPECT_EQ(rep["totals"]["tiles_live"].get<std::uint64_t>(), applied);
  EXPECT_GT(rep["totals"]["camera_updates"].get<std::uint64_t>(), 32u);
  // The server saw the same traffic.
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.connections, 32u);
  EXPECT_EQ(ss.tiles_sent, applied);
  EXPECT_EQ(ss.errors_sent, 0u);
  RecordProperty("tile_latency_p99_ms",
                 std::to_string(rep["tile_latency_ms"]["p99"].get<double>()));
  server.stop();
  host.stop();
}

// Render mode composes frames; the library API gives the same report without the CLI.
TEST(Load, RenderModeUsersComposeFrames) {
  EngineHost host(make_cornell_box(), "cornell", small_host(2));
  Server server(host, loopback());
  server.start();
  host.start();
  LoadOptions o = test::load_of(server.port(), 3, 3.0);
  o.render = true;
  o.width = 48;
  o.height = 32;
  o.fps = 20.0;
  o.camera_path = "random-walk";
  o.threads = 2;
  int progress_calls = 0;
  const LoadReport r = run_load(o, [&](const LoadProgress& p) {
    ++progress_calls;
    EXPECT_EQ(p.users, 3);
  });
  EXPECT_GE(progress_calls, 2);
  EXPECT_EQ(r.connected, 3);
  EXPECT_EQ(r.failed, 0);
  EXPECT_EQ(r.full_image, 3);
  ASSERT_EQ(r.per_user.size(), 3u);
  for (const LoadUserResult& u : r.per_user) {
    EXPECT_GT(u.frames, 5u);
    EXPECT_LE(u.frames, 62u) << "the frame cap of 20/s over 3 s";
  }
  EXPECT_EQ(r.frames_per_s.count, 3u);
  EXPECT_NE(r.text().find("frames/s per user"), std::string::npos);
  const nlohmann::json j = nlohmann::json::parse(r.json());
  EXPECT_EQ(j["options"]["mode"], "render");
  EXPECT_EQ(j["totals"]["frames"].get<std::uint64_t>(), r.frames);
  server.stop();
  host.stop();
}

TEST(Load, NoServerMeansFailedUsersAndExitThree) {
  // A port nobody listens on: bind one, close it, use it.
  std::uint16_t port = 0;
  {
    asio::io_context io;
    asio::ip::tcp::acceptor a(io, asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
    port = a.local_endpoint().port();
  }
  const LoadOptions o = test::load_of(port, 4, 1.0);
  const LoadReport r = run_load(o);
  EXPECT_EQ(r.connected, 0);
  EXPECT_EQ(r.failed, 4);
  ASSERT_EQ(r.errors.count("connect"), 1u);
  EXPECT_EQ(r.errors.at("connect"), 4u);
  const test::CliResult cli =
      test::run_cli(IRRADCAST_LOAD_EXE,
                    "--connect 127.0.0.1:" + std::to_string(port) + " --users 2 --duration 1");
  EXPECT_EQ(cli.status, 3) << cli.output;
  EXPECT_NE(cli.output.find("0 connected, 2 failed"), std::string::npos) << cli.output;
}

// More users than the server admits from one address: the users over the limit get REFUSED,
// fail once each (no reconnect loop against the same limit), and the report says what to do.
TEST(Load, UsersOverThePerAddressLimitAreRefusedOnceWithAHint) {
  EngineHost host(make_cornell_box(), "cornell", small_host(1));
  ServerOptions so = loopback();
  so.max_clients_per_peer = 2;
  Server server(host, so);
  server.start();
  host.start();
  const test::CliResult r =
      test::run_cli(IRRADCAST_LOAD_EXE, "--connect 127.0.0.1:" + std::to_string(server.port()) +
                                            " --users 5 --duration 2 --threads 1 --quiet");
  EXPECT_EQ(r.status, 3) << r.output;
  EXPECT_NE(r.output.find("5 connected, 3 failed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("server REFUSED: 3"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("INTERNAL"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--max-clients-per-peer 0"), std::string::npos) << r.output;
  EXPECT_EQ(server.stats().peer_refused, 3u);
  server.stop();
  host.stop();
}

TEST(Load, BadArgumentsGetAClearMessage) {
  struct Case {
    std::string args, message;
  };
  const std::vector<Case> cases = {
      {"--connect nohost --users 1", "HOST:PORT"},
      {"--connect 127.0.0.1:99999 --users 1", "not a port number"},
      {"--connect 127.0.0.1:1 --mode fast", "--mode must be thin or render"},
      {"--connect 127.0.0.1:1 --camera-path /nonexistent/path.txt",
       "cannot read the camera path file"},
      {"--connect 127.0.0.1:1 --users 0", "--users"},
  };
  for (const Case& c : cases) {
    const test::CliResult r = test::run_cli(IRRADCAST_LOAD_EXE, c.args);
    EXPECT_NE(r.status, 0) << c.args;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.args << "\n" << r.output;
  }
}

TEST(CameraPath, KeyframeFilesAreCheckedLineByLine) {
  const fs::path p = temp_file("path.txt");
  auto write = [&](const std::string& text) { std::ofstream(p) << text; };
  write("# t ex ey ez tx ty tz\n0 0 0 0 0 0 -1\n2 2 0 0 2 0 -1 60\n");
  const std::vector<CameraKeyframe> k = load_camera_keyframes(p.string());
  ASSERT_EQ(k.size(), 2u);
  const CameraPath path = CameraPath::keyframes(k, 0.0);
  EXPECT_NEAR(path.at(1.0).eye.x, 1.0f, 1e-5f);  // halfway
  EXPECT_NEAR(path.at(3.0).eye.x, 1.0f, 1e-5f);  // loops over its 2 s
  EXPECT_NEAR(path.at(0.5).forward.z, -1.0f, 1e-5f);

  const std::vector<std::pair<std::string, std::string>> bad = {
      {"0 0 0 0 0 0 -1\n1 1 1 1 x 0 0\n", ":2: not a number"},
      {"0 0 0 0 0 0\n", ":1: expected 't ex ey ez tx ty tz [yfov_deg]', got 6"},
      {"1 0 0 0 0 0 -1\n1 1 0 0 0 0 -1\n", ":2: times must increase"},
      {"0 1 1 1 1 1 1\n", "the eye and the target are the same point"},
      {"0 0 0 0 0 0 -1 190\n", "yfov must be in (0, 180)"},
      {"# nothing\n\n", "has no keyframes"},
  };
  for (const auto& [text, message] : bad) {
    write(text);
    try {
      load_camera_keyframes(p.string());
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  }
}

TEST(CameraPath, OrbitAndRandomWalkStayInsideTheBoundsAndDifferPerUser) {
  Bounds b;
  b.extend(glm::vec3(0.0f));
  b.extend(glm::vec3(4.0f, 3.0f, 8.0f));
  const CameraPath o1 = CameraPath::orbit(b, 10.0, 0.0), o2 = CameraPath::orbit(b, 10.0, 0.5);
  const CameraPath w1 = CameraPath::random_walk(b, 1), w2 = CameraPath::random_walk(b, 2);
  double apart_orbit = 0.0, apart_walk = 0.0;
  for (double t = 0.0; t < 30.0; t += 0.37) {
    for (const CameraPath* p : {&o1, &o2, &w1, &w2}) {
      const CameraPose c = p->at(t);
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(c.eye[a], b.lo[a]);
        EXPECT_LE(c.eye[a], b.hi[a]);
      }
      EXPECT_NEAR(glm::length(c.forward), 1.0f, 1e-4f);
    }
    apart_orbit += glm::length(o1.at(t).eye - o2.at(t).eye);
    apart_walk += glm::length(w1.at(t).eye - w2.at(t).eye);
  }
  EXPECT_GT(apart_orbit, 10.0);
  EXPECT_GT(apart_walk, 10.0);
  // An orbit comes back to where it started after its period.
  EXPECT_NEAR(glm::length(o1.at(0.0).eye - o1.at(10.0).eye), 0.0f, 1e-4f);
}

}  // namespace irradcast::test_load

// The service end to end over loopback TCP: an in-process engine host and server, real viewer
// clients, and raw sockets that misbehave.
#include <gtest/gtest.h>

#include <asio.hpp>

#include <filesystem>
#include <future>
#include <thread>

#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/frame.h"
#include "service_fixture.h"

namespace irradcast::test_service {

using asio::ip::tcp;
using namespace std::chrono_literals;

namespace {

using test::client_of;
using test::small_host;

ServerOptions loopback(std::chrono::milliseconds idle = 5000ms) {
  ServerOptions o = test::loopback(idle);
  o.scene_chunk_bytes = 512;  // many chunks, so a download can be cut in the middle
  return o;
}

// Polls until every tile is current and the engine is done, or the deadline.
bool run_until_final(ViewClient& c, std::chrono::seconds limit = 60s) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < deadline) {
    c.poll(50ms);
    auto s = c.request_stats(5s);
    if (s && s->engine_idle() && s->queue_depth() == 0 && c.all_tiles_received()) return true;
  }
  return false;
}

// A raw connection for the robustness tests.
struct Raw : test::RawConnection {
  using RawConnection::RawConnection;
  // Reads until the server closes the connection; returns the first Error frame's code.
  std::optional<wire::ErrorCode> error_then_close(std::chrono::milliseconds limit = 5000ms) {
    const std::optional<wire::Error> error = RawConnection::error_then_close(limit);
    EXPECT_TRUE(eof) << "the server should close the connection";
    if (!error) return std::nullopt;
    return error->code();
  }
};

wire::Envelope hello(std::uint32_t version = wire::kProtocolVersion) {
  return test::hello_frame("raw", version);
}

}  // namespace

// Bound: every pixel of a client's frame within 0.5% of its largest channel (+1e-6) of the frame
// composed straight from the server's lightmaps. Why: RGB9E5 keeps 9 mantissa bits per channel
// under the texel's largest channel (error <= 2^-9 of it, about 0.2%); the compositor is linear
// in E (bilinear weights summing to 1, times albedo / pi, plus emission that both sides add
// exactly), so a pixel's error is a weighted mean of its texels' errors; neighbouring texels of
// different brightness give the 2.5x margin.
TEST(Service, EightClientsMatchTheServersLightmapsWithinTheTileEncodingError) {
  EngineHost host(make_cornell_box(), "cornell", small_host(3));
  Server server(host, loopback());
  server.start();
  host.start();
  const std::vector<std::string> cameras = {
      // the box spans 0..0.556 m
      "",
      "eye=0.278,0.273,-0.4:target=0.278,0.273,0:fov=50",
      "eye=0.1,0.1,-0.3:target=0.3,0.2,0.3:fov=60",
      "eye=0.45,0.45,-0.2:target=0.2,0,0.3:fov=45",
      "eye=0.278,0.1,0.1:target=0.278,0.1,0.5:fov=70",
      "eye=0.05,0.27,0.05:target=0.5,0.1,0.5:fov=80",
      "eye=0.5,0.05,0.05:target=0,0.3,0.5:fov=80",
      "eye=0.278,0.5,0.278:target=0.278,0,0.278:fov=90:up=0,0,1"};
  const int w = 64, h = 64;
  struct Result {
    bool final = false;
    ImageRGB image;
    CameraPose camera;
    std::uint64_t bytes = 0;
  };
  std::vector<std::future<Result>> futures;
  for (std::size_t i = 0; i < cameras.size(); ++i)
    futures.push_back(std::async(std::launch::async, [&, i] {
      Result r;
      ViewClient c(client_of(server, "viewer" + std::to_string(i)));
      c.connect();
      r.camera = default_camera(c.scene(), c.world());
      if (!cameras[i].empty()) r.camera = parse_camera(cameras[i], r.camera);
      c.send_camera(r.camera);
      r.final = run_until_final(c);
      r.image = c.compose(r.camera, w, h);
      r.bytes = c.counters().bytes_received;
      c.close();
      return r;
    }));
  std::vector<Result> results;
  for (auto& f : futures) results.push_back(f.get());
  const std::vector<Lightmap> maps = host.tiles().published();
  RayScene rays(host.world());
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < results.size(); ++i) {
    const Result& r = results[i];
    ASSERT_TRUE(r.final) << "client " << i << " never got the final tiles";
    const ImageRGB direct = compose(host.world(), rays, host.atlas(), maps, r.camera, w, h);
    double lit = 0.0;
    for (std::size_t p = 0; p < direct.pixels.size(); ++p) {
      const glm::vec3 a = r.image.pixels[p], b = direct.pixels[p];
      const float m = std::max(b.x, std::max(b.y, b.z));
      lit += m;
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(a[c], b[c], 5e-3f * m + 1e-6f) << "client " << i << " pixel " << p;
    }
    EXPECT_GT(lit, 0.0) << "client " << i << " sees nothing lit";
    total += r.bytes;
  }
  const ServerStats ss = server.stats();
  RecordProperty("bytes_received_by_8_clients", std::to_string(total));
  RecordProperty("bytes_per_texel", std::to_string(host.tiles().bytes_per_texel()));
  EXPECT_GE(ss.bytes_sent, total);
  EXPECT_EQ(ss.connections, 8u);
  server.stop();
  host.stop();
}

TEST(Service, BadInputGetsAnErrorAndLeavesTheServerAndOtherClientsAlone) {
  EngineHost host(make_cornell_box(), "cornell", small_host(2));
  Server server(host, loopback(700ms));
  server.start();
  host.start();
  // A well-behaved client, on its own thread, stays connected through everything below.
  std::atomic<bool> done{false};
  auto good = std::async(std::launch::async, [&] {
    ViewClient c(client_of(server, "good"));
    c.connect();
    while (!done) c.poll(20ms);
    const bool final = run_until_final(c);
    return std::make_pair(final, c.counters().connections);
  });

  {  // A frame announcing more than the size cap.
    Raw r(server.port());
    r.write(std::string("\xff\xff\xff\x7f", 4));
    EXPECT_EQ(r.error_then_close(), wire::FRAME_TOO_LARGE);
  }
  {  // Random bytes that fit the cap but do not parse.
    Raw r(server.port());
    std::string junk("\x10\x00\x00\x00", 4);
    for (int i = 0; i < 16; ++i) junk += static_cast<char>(0xF7 ^ (i * 37));
    r.write(junk);
    EXPECT_EQ(r.error_then_close(), wire::BAD_FRAME);
  }
  {  // Wrong protocol version.
    Raw r(server.port());
    r.send(hello(99));
    EXPECT_EQ(r.error_then_close(), wire::UNSUPPORTED_VERSION);
  }
  {  // Anything but Hello first.
    Raw r(server.port());
    wire::Envelope ping;
    ping.mutable_ping()->set_nonce(1);
    r.send(ping);
    EXPECT_EQ(r.error_then_close(), wire::UNEXPECTED_MESSAGE);
  }
  {  // An unknown message type (a newer peer's field 99): Error, and the session goes on.
    Raw r(server.port());
    r.send(hello());
    auto welcome = r.read();
    ASSERT_TRUE(welcome && welcome->has_welcome());
    r.write(std::string("\x03\x00\x00\x00\x98\x06\x01", 7));  // field 99, varint 1
    auto err = r.read();
    ASSERT_TRUE(err && err->has_error());
    EXPECT_EQ(err->error().code(), wire::UNEXPECTED_MESSAGE);
    wire::Envelope ping;
    ping.mutable_ping()->set_nonce(77);
    r.send(ping);
    auto pong = r.read();
    ASSERT_TRUE(pong && pong->has_pong());
    EXPECT_EQ(pong->pong().nonce(), 77u);
  }
  {  // A truncated frame, then the client vanishes.
    Raw r(server.port());
    r.send(hello());
    std::string frame = wire::encode_frame(hello());
    r.write(frame.substr(0, frame.size() / 2));
  }
  {  // A client that connects and never speaks: dropped after the idle timeout.
    Raw r(server.port());
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_EQ(r.error_then_close(3000ms), wire::IDLE_TIMEOUT);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 2500ms);
  }
  {  // A client that disconnects in the middle of the scene download.
    Raw r(server.port());
    r.send(hello());
    auto welcome = r.read();
    ASSERT_TRUE(welcome && welcome->has_welcome());
    ASSERT_GT(welcome->welcome().scene_bytes(), 1024u);
    wire::Envelope req;
    req.mutable_scene_request()->set_offset(0);
    r.send(req);
    auto chunk = r.read();
    ASSERT_TRUE(chunk && chunk->has_scene_chunk());
  }
  // The server is unaffected: a new client downloads the scene and gets every tile, and the
  // good client is still on its first connection.
  ViewClient fresh(client_of(server, "fresh"));
  fresh.connect();
  EXPECT_TRUE(run_until_final(fresh));
  EXPECT_FALSE(fresh.counters().scene_from_cache);
  done = true;
  auto [good_final, good_connections] = good.get();
  EXPECT_TRUE(good_final);
  EXPECT_EQ(good_connections, 1u) << "the good client had to reconnect";
  // Wait for the server to notice the vanished clients.
  fresh.close();
  for (int i = 0; i < 100 && server.stats().clients > 0; ++i) std::this_thread::sleep_for(20ms);
  EXPECT_EQ(server.stats().clients, 0u);
  server.stop();
  host.stop();
}

TEST(Service, ViewerResumesAfterAServerRestartWithoutGettingTilesAgain) {
  const auto cache = std::filesystem::temp_directory_path() /
                     ("irradcast-test-cache-" + std::to_string(::getpid()));
  std::filesystem::remove_all(cache);
  auto host = std::make_unique<EngineHost>(make_cornell_box(), "cornell", small_host(2));
  auto server = std::make_unique<Server>(*host, loopback());
  server->start();
  host->start();
  ViewClientOptions vo = client_of(*server, "resumer");
  vo.cache_dir = cache.string();
  const std::uint16_t port = server->port();
  ViewClient c(vo);
  c.connect();
  ASSERT_TRUE(run_until_final(c));
  const std::uint64_t first_bytes = c.counters().bytes_received;
  const std::uint64_t tiles = c.counters().tiles_applied;
  // Restart: same scene and parameters on the same port (the engine is deterministic, so the
  // restarted server reaches the same tile versions).
  server->stop();
  host->stop();
  server.reset();
  host = std::make_unique<EngineHost>(make_cornell_box(), "cornell", small_host(2));
  host->start();
  host->wait_for_updates(2);
  ServerOptions so = loopback();
  so.port = port;
  server = std::make_unique<Server>(*host, so);
  server->start();
  ASSERT_TRUE(run_until_final(c));
  EXPECT_EQ(c.counters().connections, 2u);
  EXPECT_EQ(c.counters().tiles_applied, tiles) << "tiles with unchanged versions came again";
  const std::uint64_t resumed_bytes = c.counters().bytes_received - first_bytes;
  RecordProperty("first_session_bytes", std::to_string(first_bytes));
  RecordProperty("resumed_session_bytes", std::to_string(resumed_bytes));
  EXPECT_LT(resumed_bytes, first_bytes / 20);
  // A restart with another seed is another lineage of versions (another tile_epoch): every tile
  // comes again, though the scene (same hash) is not downloaded again.
  server->stop();
  host->stop();
  server.reset();
  EngineHostOptions reseeded = small_host(2);
  reseeded.engine.seed = 2;
  host = std::make_unique<EngineHost>(make_cornell_box(), "cornell", reseeded);
  host->start();
  server = std::make_unique<Server>(*host, so);
  server->start();
  const std::uint64_t scene_bytes = c.counters().scene_bytes_downloaded;
  ASSERT_TRUE(run_until_final(c));
  EXPECT_EQ(c.counters().connections, 3u);
  EXPECT_GE(c.counters().tiles_applied, tiles + c.tile_count());
  EXPECT_EQ(c.counters().scene_bytes_downloaded, scene_bytes);
  // A second viewer gets the scene from the cache.
  ViewClient second(vo);
  second.connect();
  EXPECT_TRUE(second.counters().scene_from_cache);
  second.close();
  c.close();
  server->stop();
  host->stop();
  std::filesystem::remove_all(cache);
}

}  // namespace irradcast::test_service

// Distribution through NATS on loopback (docs/DISTRIBUTION.md): a nats-server with JetStream, an
// origin (EngineHost + NatsOrigin + Server) and gateways (NatsGateway + Server) in the process,
// viewers (ViewClient) of each. Viewers of gateways get exactly what a viewer of the origin
// gets; an edit sent through a gateway reaches every viewer; a gateway serves on while NATS is
// down and catches up after; NATS and the origin restarted lose nothing viewers hold; a gateway
// started while the origin is down gets the state from JetStream alone; malformed messages and
// requests are refused.
#include <gtest/gtest.h>

#include <nats/nats.h>

#include <chrono>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"
#include "dynamic_scenes.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/camera.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast/wire/tile_codec.h"
#include "irradcast_nats.pb.h"
#include "nats_fixture.h"

namespace irradcast::test_nats {

using namespace std::chrono_literals;

namespace {

const std::string kToken = "secret-token-for-nats-tests";

using test::converge;
using test::expect_same_image;
using test::same_versions;
using test::view_of;

ViewClientOptions viewer_of(const Server& s, const std::string& name) {
  ViewClientOptions o = test::client_of(s, name);
  o.connect_timeout = 10000ms;
  return o;
}

}  // namespace

TEST(NatsSubjects, SceneIdsBecomeDistinctSubjectTokens) {
  const NatsSubjects c = nats_subjects("cornell");
  EXPECT_EQ(c.token, "cornell");
  EXPECT_EQ(c.stream, "IRRADCAST_cornell");
  EXPECT_EQ(c.tile(7), "irradcast.cornell.s.tile.7");
  EXPECT_EQ(c.filter, "irradcast.cornell.s.>");
  EXPECT_EQ(c.submit, "irradcast.cornell.req.edit");
  const NatsSubjects r = nats_subjects("rooms:2");
  const NatsSubjects u = nats_subjects("rooms_2");
  EXPECT_EQ(u.token, "rooms_2");
  EXPECT_EQ(r.token.rfind("rooms_2-", 0), 0u) << r.token;
  EXPECT_NE(r.token, u.token);
  for (const std::string& id :
       {std::string("/data/a b.gltf"), std::string("x.*>"), std::string()}) {
    const std::string t = nats_subjects(id).token;
    EXPECT_EQ(
        t.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-"),
        std::string::npos)
        << t;
  }
}

TEST(NatsTileStore, InstallKeepsTheNewestVersionAndRefusesBadPayloads) {
  TileStore origin({{40, 20}}, TileStoreOptions{16});
  Lightmap m(40, 20, glm::vec3(0.25f, 0.5f, 1.0f));
  m.texels[5] = glm::vec3(3.0f, 2.0f, 1.0f);
  origin.publish({m}, 1234);
  TileStore copy({{40, 20}}, TileStoreOptions{16});
  for (std::uint32_t i = 0; i < origin.tile_count(); ++i) {
    const auto s = origin.snapshot(i, wire::TILE_RGB9E5_ZSTD);
    EXPECT_TRUE(copy.install(i, s.version, s.time_us, s.payload));
    EXPECT_FALSE(copy.install(i, s.version, s.time_us, s.payload));  // not newer
    EXPECT_EQ(*copy.snapshot(i, wire::TILE_RGB9E5_ZSTD).payload, *s.payload);
    // The half-float encoding comes from the decoded texels: the same as the origin's.
    EXPECT_EQ(*copy.snapshot(i, wire::TILE_HALF_ZSTD).payload,
              *origin.snapshot(i, wire::TILE_HALF_ZSTD).payload);
  }
  EXPECT_DOUBLE_EQ(copy.bytes_per_texel(), origin.bytes_per_texel());
  const auto good = origin.snapshot(0, wire::TILE_RGB9E5_ZSTD).payload;
  auto junk = std::make_shared<const std::string>("not a tile");
  EXPECT_THROW(copy.install(0, 9, 0, junk), Error);
  EXPECT_THROW(copy.install(99, 9, 0, good), Error);
  // Tile 1 is 16 x 16, tile 2 is 8 x 16: another tile's payload does not fit.
  EXPECT_THROW(copy.install(2, 9, 0, good), Error);
  EXPECT_EQ(copy.version(2), 1u);
  // A forced install (a new lineage) takes a lower version.
  EXPECT_TRUE(copy.install(0, 1, 0, good, true));
}

TEST(Nats, ViewersOfTwoGatewaysSeeExactlyWhatAViewerOfTheOriginSees) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 3);
  test::NatsGatewayNode a(nats.url()), b(nats.url());
  ASSERT_TRUE(origin.settle());
  const TileStore& want = origin.host.tiles();
  ASSERT_TRUE(test::eventually([&] {
    return same_versions(want, a.gateway.tiles()) && same_versions(want, b.gateway.tiles());
  }));
  EXPECT_EQ(a.gateway.package()->hash, origin.host.package()->hash);
  EXPECT_EQ(a.gateway.tile_epoch(), origin.host.tile_epoch());

  ViewClient direct(viewer_of(origin.server, "direct"));
  ViewClient via_a(viewer_of(*a.server, "via-a"));
  ViewClient via_b(viewer_of(*b.server, "via-b"));
  for (ViewClient* v : {&direct, &via_a, &via_b}) {
    v->connect();
    ASSERT_TRUE(converge(*v, want));
    EXPECT_EQ(v->scene_hash(), origin.host.package()->hash);
  }
  const ImageRGB reference = view_of(direct);
  expect_same_image(view_of(via_a), reference, "gateway a");
  expect_same_image(view_of(via_b), reference, "gateway b");
  // A viewer's camera goes to the origin through the gateway.
  via_a.send_camera(default_camera(via_a.scene(), via_a.world()));
  EXPECT_TRUE(test::eventually([&] {
    via_a.poll(10ms);
    return origin.origin.nats_stats().camera_requests >= 1;
  }));
  // The gateways' Stats carry the origin's engine stats.
  auto stats = via_a.request_stats(5s);
  ASSERT_TRUE(stats);
  EXPECT_TRUE(test::eventually([&] { return a.gateway.stats().updates == 3; }));
  EXPECT_EQ(a.gateway.backend_name(), origin.host.backend_name());
  const NatsGatewayStats gs = a.gateway.nats_stats();
  EXPECT_TRUE(gs.connected);
  EXPECT_GE(gs.tiles_installed, want.tile_count());
  EXPECT_EQ(gs.bad_messages, 0u);
  const std::string metrics = format_nats_gateway_metrics(gs);
  EXPECT_NE(metrics.find("irradcast_gateway_nats_connected 1\n"), std::string::npos) << metrics;
}

TEST(Nats, AnEditSentThroughAGatewayReachesEveryViewer) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 2, kToken);
  test::NatsGatewayNode a(nats.url(), kToken), b(nats.url(), kToken);
  ASSERT_TRUE(origin.settle());
  ViewClient direct(viewer_of(origin.server, "direct"));
  ViewClient via_b(viewer_of(*b.server, "via-b"));
  direct.connect();
  via_b.connect();
  const std::string hash_before = origin.host.package()->hash;

  // The editor talks to gateway a: its acknowledgement carries the origin's revision.
  test::RawConnection editor(a.server->port());
  ASSERT_TRUE(editor.join("editor"));
  const std::optional<wire::Envelope> ack = editor.edit(
      test::edit_frame(R"({"op": "move", "node": "tall_block", "by": [0.05, 0, 0]})", kToken, 5));
  ASSERT_TRUE(ack && ack->has_scene_edit())
      << (ack && ack->has_error() ? ack->error().message() : std::string("no answer"));
  EXPECT_EQ(ack->scene_edit().revision(), 1u);
  EXPECT_EQ(ack->scene_edit().request_id(), 5u);
  EXPECT_FALSE(ack->scene_edit().applied());

  // Every viewer applies it, and ends with the origin's package.
  for (ViewClient* v : {&direct, &via_b}) {
    const auto deadline = std::chrono::steady_clock::now() + 15s;
    while (v->scene_revision() < 1 && std::chrono::steady_clock::now() < deadline) v->poll(20ms);
    EXPECT_EQ(v->scene_revision(), 1u);
    EXPECT_EQ(v->counters().edits_applied, 1u);
  }
  std::optional<wire::Envelope> applied;
  while ((applied = editor.read(10000ms)) && !applied->has_scene_edit()) {
  }
  ASSERT_TRUE(applied);
  EXPECT_TRUE(applied->scene_edit().applied());
  EXPECT_NE(origin.host.package()->hash, hash_before);
  EXPECT_EQ(applied->scene_edit().scene_hash(), origin.host.package()->hash);
  EXPECT_TRUE(test::eventually([&] { return b.gateway.revision() == 1; }));
  EXPECT_EQ(b.gateway.package()->hash, origin.host.package()->hash);
  // A viewer that joins gateway b now gets the edited scene in its Welcome.
  ViewClient late(viewer_of(*b.server, "late"));
  late.connect();
  EXPECT_EQ(late.scene_revision(), 1u);
  EXPECT_EQ(late.scene_hash(), origin.host.package()->hash);
  EXPECT_EQ(origin.origin.nats_stats().edit_requests, 1u);
}

// Dynamic objects behind a gateway (docs/DYNAMIC.md): the gateway serves the origin's probe
// volume (its chunks reassembled and checked) and the origin's poses, and a pose streamed through
// the gateway reaches the origin, which takes it, and every viewer.
TEST(Nats, GatewaysServeTheProbeVolumeAndThePoses) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 2, kToken, {}, test::cornell_with_prop());
  test::NatsGatewayNode gw(nats.url(), kToken);
  ASSERT_TRUE(origin.settle());
  ViewClient direct(viewer_of(origin.server, "direct"));
  ViewClient via(viewer_of(*gw.server, "via"));
  direct.connect();
  via.connect();
  const auto wanted = origin.host.probe_volume();
  ASSERT_NE(wanted, nullptr);
  for (ViewClient* v : {&direct, &via}) {
    EXPECT_TRUE(test::eventually([&] {
      v->poll(20ms);
      return v->probe_volume().lit() && v->probe_volume().epoch == wanted->epoch &&
             v->probe_volume().version == wanted->version;
    })) << (v == &direct ? "direct" : "via")
        << ": " << v->probe_volume().version << " of " << wanted->version << "; the gateway got "
        << gw.gateway.nats_stats().volumes_received << " volumes, "
        << "the origin published " << origin.origin.nats_stats().volumes_published;
  }
  ASSERT_TRUE(via.probe_volume().lit() && direct.probe_volume().lit());
  // The same volume, bit for bit, through NATS.
  const IrradianceVolume& a = direct.probe_volume().volume;
  const IrradianceVolume& b = via.probe_volume().volume;
  ASSERT_EQ(a.sh.size(), b.sh.size());
  ASSERT_EQ(a.grid.counts, b.grid.counts);
  for (float x : {0.1f, 0.25f, 0.4f})
    for (const glm::vec3 n : {glm::vec3(0, 1, 0), glm::vec3(0, -1, 0), glm::vec3(1, 0, 0)}) {
      const glm::vec3 p(x, 0.2f, 0.3f);
      EXPECT_EQ(a.irradiance(p, n), b.irradiance(p, n)) << x;
      EXPECT_EQ(a.irradiance(p, n, false), b.irradiance(p, n, false)) << x;
      EXPECT_GT(a.irradiance(p, n).x, 0.0f);
    }
  EXPECT_GE(gw.gateway.nats_stats().volumes_received, 1u);

  // A pose streamed to the gateway: the origin takes it, both viewers show it.
  test::RawConnection editor(gw.server->port());
  ASSERT_TRUE(editor.join("editor"));
  const wire::Envelope e =
      test::edit_frame(R"({"op": "move", "node": "prop", "by": [0.1, 0, 0]})", kToken, 3, true);
  editor.send(e);
  const auto prop = static_cast<std::size_t>(make_cornell_box().nodes.size()) + 1;
  for (ViewClient* v : {&direct, &via})
    EXPECT_TRUE(test::eventually([&] {
      v->poll(20ms);
      return v->pose_sequence() >= 1 && std::abs(v->scene().nodes[prop].local[3].x - 0.1f) < 1e-6f;
    }));
  EXPECT_EQ(origin.host.poses()->sequence(), 1u);
  EXPECT_EQ(origin.host.revision(), 0u);
  // A viewer joining the gateway now gets the pose in its first Poses.
  ViewClient late(viewer_of(*gw.server, "late"));
  late.connect();
  EXPECT_TRUE(test::eventually([&] {
    late.poll(20ms);
    return std::abs(late.scene().nodes[prop].local[3].x - 0.1f) < 1e-6f;
  }));
}

// An origin that comes back on the same stream with a scene without dynamic nodes clears what the
// last one left there: its poses (which name nodes this scene does not pose: a gateway serving
// them would have every viewer refuse them as a protocol error and drop) and its probe volume.
TEST(Nats, AnOriginWithoutDynamicNodesClearsTheLastOnesPosesAndVolume) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  {
    test::NatsOriginNode first(nats.url(), 2, kToken, {}, test::cornell_with_prop());
    ASSERT_TRUE(first.settle());
    test::RawConnection editor(first.server.port());
    ASSERT_TRUE(editor.join("editor"));
    const wire::Envelope e =
        test::edit_frame(R"({"op": "move", "node": "prop", "by": [0.1, 0, 0]})", kToken, 1, true);
    editor.send(e);
    ASSERT_TRUE(test::eventually([&] {
      return first.origin.nats_stats().poses_published >= 1 &&
             first.origin.nats_stats().volumes_published >= 1;
    }));
    ASSERT_TRUE(first.origin.flush(std::chrono::seconds(10)));
  }
  test::NatsOriginNode second(nats.url(), 1, kToken);
  ASSERT_TRUE(second.settle());
  test::NatsGatewayNode gw(nats.url(), kToken);
  ViewClient via(viewer_of(*gw.server, "via"));
  via.connect();
  EXPECT_TRUE(test::converge(via, second.host.tiles()));
  std::this_thread::sleep_for(500ms);
  for (int i = 0; i < 10; ++i) via.poll(20ms);
  EXPECT_EQ(via.counters().connections_lost, 0u) << "the viewer was sent poses it refused";
  EXPECT_EQ(via.counters().connections, 1u);
  EXPECT_FALSE(via.probe_volume().lit()) << "the gateway served the last origin's volume";
  EXPECT_EQ(gw.gateway.nats_stats().bad_messages, 0u);
  via.close();
}

namespace {

// What the origin answers an edit submitted through `gw` that it must refuse (a failure, and
// "", when it takes it).
std::string refusal(test::NatsGatewayNode& gw, const std::string& json) {
  try {
    gw.gateway.submit_edit(parse_edit_json(json));
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "the origin took " << json;
  return "";
}

}  // namespace

// The control token never crosses NATS: a gateway's session checks it and forwards the edit
// without it (a listener on req.edit sees no token); the origin applies edits from NATS only when
// it takes edits at all, and refuses one that carries a token.
TEST(Nats, EditsCrossNatsWithoutTheToken) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 1, kToken);
  test::NatsGatewayNode gw(nats.url(), kToken);
  natsConnection* spy = nullptr;
  ASSERT_EQ(natsConnection_ConnectTo(&spy, nats.url().c_str()), NATS_OK);
  natsSubscription* sub = nullptr;
  ASSERT_EQ(natsConnection_SubscribeSync(&sub, spy, nats_subjects("cornell").submit.c_str()),
            NATS_OK);
  ASSERT_EQ(natsConnection_Flush(spy), NATS_OK);
  {  // A viewer of the gateway edits with the token.
    test::RawConnection editor(gw.server->port());
    ASSERT_TRUE(editor.join("editor"));
    const std::optional<wire::Envelope> ack = editor.edit(
        test::edit_frame(R"({"op": "move", "node": "tall_block", "by": [0, 0.01, 0]})", kToken));
    ASSERT_TRUE(ack && ack->has_scene_edit())
        << (ack && ack->has_error() ? ack->error().message() : "no answer");
    EXPECT_EQ(ack->scene_edit().revision(), 1u);
  }
  natsMsg* seen = nullptr;
  ASSERT_EQ(natsSubscription_NextMsg(&seen, sub, 5000), NATS_OK);
  wire::SceneEdit forwarded;
  ASSERT_TRUE(forwarded.ParseFromArray(natsMsg_GetData(seen), natsMsg_GetDataLength(seen)));
  EXPECT_TRUE(forwarded.token().empty());
  EXPECT_EQ(
      std::string(natsMsg_GetData(seen), static_cast<std::size_t>(natsMsg_GetDataLength(seen)))
          .find(kToken),
      std::string::npos);
  natsMsg_Destroy(seen);
  natsSubscription_Destroy(sub);
  natsConnection_Destroy(spy);
  EXPECT_TRUE(test::eventually([&] { return origin.host.revision() == 1; }));
  // An invalid edit: the origin's validation message comes back.
  EXPECT_NE(refusal(gw, R"({"op": "move", "node": "no_such_node", "by": [0, 1, 0]})")
                .find("no_such_node"),
            std::string::npos);
  // An origin without a control token takes no edits from NATS either.
  test::NatsProcess nats2;
  test::NatsOriginNode closed(nats2.url(), 1);
  test::NatsGatewayNode gw2(nats2.url(), kToken);
  EXPECT_NE(refusal(gw2, R"({"op": "move", "node": "tall_block", "by": [0, 1, 0]})")
                .find("takes no edits"),
            std::string::npos);
  EXPECT_EQ(closed.host.revision(), 0u);
}

TEST(Nats, AGatewayServesWhileNatsIsDownAndCatchesUpAfter) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  auto origin = std::make_unique<test::NatsOriginNode>(nats.url(), 2, kToken);
  test::NatsGatewayNode gw(nats.url(), kToken);
  ASSERT_TRUE(origin->settle());
  ASSERT_TRUE(
      test::eventually([&] { return same_versions(origin->host.tiles(), gw.gateway.tiles()); }));
  ViewClient viewer(viewer_of(*gw.server, "viewer"));
  viewer.connect();
  ASSERT_TRUE(converge(viewer, origin->host.tiles()));

  nats.stop();
  ASSERT_TRUE(test::eventually([&] { return !gw.gateway.nats_stats().connected; }));
  // A new viewer joins and gets everything from the gateway alone.
  ViewClient newcomer(viewer_of(*gw.server, "newcomer"));
  newcomer.connect();
  ASSERT_TRUE(converge(newcomer, origin->host.tiles()));
  expect_same_image(view_of(newcomer), view_of(viewer), "viewer that joined while NATS was down");
  // An edit cannot reach the origin: a clear refusal, nothing changes.
  try {
    gw.gateway.submit_edit(
        parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [0.05, 0, 0]})"));
    ADD_FAILURE() << "an edit went through without NATS";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("NATS"), std::string::npos) << e.what();
  }
  // The origin applies an edit of its own meanwhile (its viewers' edit): after NATS returns the
  // gateway catches up and its viewers get the edit.
  origin->host.submit_edit(
      parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [0.05, 0, 0]})"));
  nats.start();
  ASSERT_TRUE(test::eventually([&] { return gw.gateway.revision() == 1; }, 15000ms));
  // It read the stream again after the reconnection (a catch-up).
  EXPECT_TRUE(test::eventually([&] { return gw.gateway.nats_stats().subscriptions >= 2; }));
  EXPECT_EQ(gw.gateway.package()->hash, origin->host.package()->hash);
  const auto deadline = std::chrono::steady_clock::now() + 15s;
  while (viewer.scene_revision() < 1 && std::chrono::steady_clock::now() < deadline)
    viewer.poll(20ms);
  EXPECT_EQ(viewer.scene_revision(), 1u);
  ViewClient after(viewer_of(*gw.server, "after"));
  after.connect();
  EXPECT_EQ(after.scene_hash(), origin->host.package()->hash);
  EXPECT_EQ(after.scene_revision(), 1u);
}

// NATS and the origin both restart: the gateway keeps what it has (and a gateway that starts
// while the origin is still down gets it from JetStream's storage alone); the new origin, with
// the same inputs, reaches the same versions, so viewers lose nothing and get nothing twice.
TEST(Nats, RestartingNatsAndTheOriginLosesNothingViewersHold) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  auto origin = std::make_unique<test::NatsOriginNode>(nats.url(), 3);
  test::NatsGatewayNode gw(nats.url());
  ASSERT_TRUE(origin->settle());
  ASSERT_TRUE(
      test::eventually([&] { return same_versions(origin->host.tiles(), gw.gateway.tiles()); }));
  ViewClient viewer(viewer_of(*gw.server, "viewer"));
  viewer.connect();
  ASSERT_TRUE(converge(viewer, origin->host.tiles()));
  const ImageRGB before = view_of(viewer);
  const std::string hash = origin->host.package()->hash;
  std::vector<std::uint64_t> versions;
  for (std::uint32_t i = 0; i < gw.gateway.tiles().tile_count(); ++i)
    versions.push_back(gw.gateway.tiles().version(i));
  const std::uint64_t tiles_before = viewer.counters().tiles_applied;

  origin.reset();
  nats.stop();
  nats.start();
  // The origin is down: a late gateway reads the whole state from JetStream.
  test::NatsGatewayNode late(nats.url());
  ASSERT_TRUE(
      test::eventually([&] { return same_versions(gw.gateway.tiles(), late.gateway.tiles()); }));
  ViewClient late_viewer(viewer_of(*late.server, "late-viewer"));
  late_viewer.connect();
  ASSERT_TRUE(converge(late_viewer, gw.gateway.tiles()));
  expect_same_image(view_of(late_viewer), before,
                    "viewer of a gateway started while the origin was down");

  origin = std::make_unique<test::NatsOriginNode>(nats.url(), 3);
  ASSERT_TRUE(origin->settle());
  EXPECT_EQ(origin->host.package()->hash, hash);
  ASSERT_TRUE(test::eventually([&] { return gw.gateway.nats_stats().subscriptions >= 2; }));
  ASSERT_TRUE(
      test::eventually([&] { return same_versions(origin->host.tiles(), gw.gateway.tiles()); }));
  for (std::uint32_t i = 0; i < versions.size(); ++i)
    EXPECT_EQ(gw.gateway.tiles().version(i), versions[i]) << "tile " << i;
  viewer.poll(300ms);
  EXPECT_EQ(viewer.counters().tiles_applied, tiles_before) << "tiles sent again";
  expect_same_image(view_of(viewer), before, "viewer after the restarts");
}

// Bytes on the scene's subjects or requests that are not what an origin or gateway sends are
// counted and ignored; the gateway goes on serving what it has.
TEST(Nats, MalformedMessagesAndRequestsAreRefused) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 1, kToken);
  test::NatsGatewayNode gw(nats.url(), kToken);
  ASSERT_TRUE(origin.settle());
  ASSERT_TRUE(
      test::eventually([&] { return same_versions(origin.host.tiles(), gw.gateway.tiles()); }));
  const NatsSubjects s = nats_subjects("cornell");
  natsConnection* nc = nullptr;
  ASSERT_EQ(natsConnection_ConnectTo(&nc, nats.url().c_str()), NATS_OK);
  jsCtx* js = nullptr;
  ASSERT_EQ(natsConnection_JetStream(&js, nc, nullptr), NATS_OK);
  // One at a time: messages on one subject replace each other in the stream, so one that is
  // replaced before the gateway got it is never delivered (the stream keeps the latest).
  auto put = [&](const std::string& subject, const std::string& bytes) {
    const std::uint64_t bad = gw.gateway.nats_stats().bad_messages;
    EXPECT_EQ(js_Publish(nullptr, js, subject.c_str(), bytes.data(), static_cast<int>(bytes.size()),
                         nullptr, nullptr),
              NATS_OK)
        << subject;
    EXPECT_TRUE(test::eventually([&] { return gw.gateway.nats_stats().bad_messages > bad; }))
        << subject << " was not refused";
  };

  put(s.tile(0), "garbage");
  wire::NatsTile t;  // parses, but its payload is not a tile
  t.set_index(1);
  t.set_version(1000);
  t.set_payload("zzzz");
  put(s.tile(1), t.SerializeAsString());
  t.set_index(1u << 30);  // not in the layout
  put(s.tile(2), t.SerializeAsString());
  put(s.state, "\xff\xff\xff");
  wire::NatsSceneState st;  // parses, but announces nothing usable
  st.set_package_chunks(1);
  st.set_scene_hash(std::string(32, 'x'));
  put(s.state, st.SerializeAsString());
  put(s.stats, "\x08");
  put(s.filter.substr(0, s.filter.size() - 1) + "other", "?");
  // The probe volume and the poses (docs/DYNAMIC.md): refused whole, nothing served from them.
  put(s.volume, "\xff\xff");
  wire::NatsVolume vol;  // parses, but announces no chunk
  vol.set_hash(std::string(32, 'h'));
  vol.set_bytes(3);
  put(s.volume, vol.SerializeAsString());
  const auto announce = [&](const std::string& frame) {
    wire::NatsVolumeChunk c;
    c.set_hash(wire::sha256(frame));
    c.set_data(frame);
    const std::string chunk = c.SerializeAsString();
    // A refused announcement drops its chunks: each comes with its own.
    const auto publish_chunk = [&] {
      EXPECT_EQ(js_Publish(nullptr, js, s.volume_chunk(0).c_str(), chunk.data(),
                           static_cast<int>(chunk.size()), nullptr, nullptr),
                NATS_OK);
    };
    wire::NatsVolume v;
    v.set_hash(wire::sha256(frame));
    v.set_bytes(frame.size() + 1);  // not the chunks' size
    v.set_chunks(1);
    publish_chunk();
    put(s.volume, v.SerializeAsString());
    v.set_bytes(frame.size());  // the right size, but not a ProbeVolume with its layout
    publish_chunk();
    put(s.volume, v.SerializeAsString());
  };
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(1);
  announce(wire::encode_frame(ping));
  wire::NatsPoses poses;
  wire::NodePose* pose = poses.mutable_poses()->add_poses();
  for (int i = 0; i < 15; ++i) pose->add_matrix(1.0f);
  put(s.poses, poses.SerializeAsString());  // 15 values
  pose->add_matrix(std::numeric_limits<float>::quiet_NaN());
  put(s.poses, poses.SerializeAsString());  // not finite
  EXPECT_EQ(gw.gateway.nats_stats().bad_messages, 13u);
  EXPECT_EQ(gw.gateway.probe_volume(), nullptr);
  EXPECT_EQ(gw.gateway.poses()->sequence(), 0u);
  EXPECT_EQ(gw.gateway.tiles().version(1), origin.host.tiles().version(1));
  // Requests to the origin that do not parse get an answer that says so.
  for (const std::string& subject : {s.submit, s.cameras}) {
    natsMsg* reply = nullptr;
    ASSERT_EQ(natsConnection_Request(&reply, nc, subject.c_str(), "\xff\xff", 2, 5000), NATS_OK);
    wire::NatsReply r;
    EXPECT_TRUE(r.ParseFromArray(natsMsg_GetData(reply), natsMsg_GetDataLength(reply)));
    EXPECT_EQ(r.code(), wire::BAD_REQUEST) << subject;
    natsMsg_Destroy(reply);
  }
  // An edit that carries a token on NATS is refused (gateways forward edits without it).
  wire::SceneEdit edit;
  wire::to_proto(parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [0, 1, 0]})"),
                 &edit);
  edit.set_token(kToken);
  const std::string bytes = edit.SerializeAsString();
  natsMsg* reply = nullptr;
  ASSERT_EQ(natsConnection_Request(&reply, nc, s.submit.c_str(), bytes.data(),
                                   static_cast<int>(bytes.size()), 5000),
            NATS_OK);
  wire::NatsReply r;
  EXPECT_TRUE(r.ParseFromArray(natsMsg_GetData(reply), natsMsg_GetDataLength(reply)));
  EXPECT_EQ(r.code(), wire::BAD_REQUEST);
  EXPECT_NE(r.error().find("carries a token"), std::string::npos) << r.error();
  natsMsg_Destroy(reply);
  EXPECT_EQ(origin.host.revision(), 0u);
  // The gateway still serves its viewers the origin's tiles.
  ViewClient v(viewer_of(*gw.server, "after"));
  v.connect();
  EXPECT_TRUE(converge(v, origin.host.tiles()));
  jsCtx_Destroy(js);
  natsConnection_Destroy(nc);
}

// The programs: irradcast-server --nats and irradcast-gateway, as an operator runs them.
TEST(NatsPrograms, TheGatewayProgramServesWhatTheOriginProgramComputes) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  const std::uint16_t origin_port = test::free_loopback_port();
  const std::uint16_t gateway_port = test::free_loopback_port();
  const auto tmp = std::filesystem::temp_directory_path();
  const std::string pid = std::to_string(::getpid());
  const std::string common = "--bind 127.0.0.1 --io-threads 1 --status-every 0 --log-level warn";
  auto args = [](const std::string& exe, const std::string& line) {
    std::vector<std::string> v = {exe};
    std::istringstream ss(line);
    for (std::string w; ss >> w;) v.push_back(w);
    return v;
  };
  test::Process origin(
      args(IRRADCAST_SERVER_EXE,
           "--scene cornell --texels-per-scene 48 --tile-size 16 --max-updates 3 "
           "--threads 1 --nats " +
               nats.url() + " --port " + std::to_string(origin_port) + " " + common),
      tmp / ("irradcast_nats_origin_" + pid + ".log"));
  test::Process gateway(
      args(IRRADCAST_GATEWAY_EXE, "--nats " + nats.url() + " --scene cornell --port " +
                                      std::to_string(gateway_port) + " " + common),
      tmp / ("irradcast_nats_gateway_" + pid + ".log"));
  ViewClientOptions vo;
  vo.connect_timeout = 30000ms;
  vo.port = origin_port;
  ViewClient direct(vo);
  vo.port = gateway_port;
  ViewClient via(vo);
  direct.connect();
  via.connect();
  // Until the origin's engine is final and both viewers hold the same versions of every tile.
  bool same = false;
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (!same && std::chrono::steady_clock::now() < deadline) {
    direct.poll(50ms);
    via.poll(50ms);
    auto s = direct.request_stats(2s);
    same = s && s->engine_idle() && direct.all_tiles_received();
    for (std::uint32_t m = 0; same && m < direct.lightmaps().size(); ++m)
      for (std::uint32_t ty = 0;
           same && ty * 16 < static_cast<std::uint32_t>(direct.lightmaps()[m].height); ++ty)
        for (std::uint32_t tx = 0;
             same && tx * 16 < static_cast<std::uint32_t>(direct.lightmaps()[m].width); ++tx)
          same = direct.tile_version(m, tx, ty) == via.tile_version(m, tx, ty);
  }
  ASSERT_TRUE(same) << origin.output() << gateway.output();
  EXPECT_EQ(via.scene_hash(), direct.scene_hash());
  expect_same_image(view_of(via), view_of(direct), "viewer of irradcast-gateway");
  direct.close();
  via.close();
  gateway.signal(SIGTERM);
  EXPECT_EQ(gateway.wait_for(10s), 0) << gateway.output();
  origin.signal(SIGTERM);
  EXPECT_EQ(origin.wait_for(10s), 0) << origin.output();
  // Bad arguments: one clear line, exit status 1.
  const test::CliResult bad =
      test::run_cli(IRRADCAST_GATEWAY_EXE, "--nats http://127.0.0.1:1 --port 0");
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.output.find("irradcast-gateway: error: --nats: 'http://127.0.0.1:1' is not a "
                            "nats:// or tls://HOST:PORT "
                            "URL"),
            std::string::npos)
      << bad.output;
}

}  // namespace irradcast::test_nats

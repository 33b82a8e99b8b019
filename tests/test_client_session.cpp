// ClientSession, the client's protocol core, without sockets: frames in, frames out. A small
// scene package stands in for the server's; the tests check what the core answers (Hello,
// SceneRequest, Subscribe), the state it keeps (scene, tiles, epoch, revision, counters), how it
// resumes, and that bad input fails with a clear error.
#include <gtest/gtest.h>

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "dynamic_scenes.h"
#include "irradcast/client/client_session.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast::test_client_session {

using Event = ClientStep::Event;
using Phase = ClientSession::Phase;

namespace {

constexpr std::uint32_t kTile = 32;

// What a server would hold: the package and the Welcome describing it.
struct FakeServer {
  explicit FakeServer(const Scene& scene = make_cornell_box()) {
    const World world = World::build(scene);
    AtlasOptions ao;
    ao.texels_per_scene = 48.0f;
    atlas = build_atlas(world, ao);
    package = wire::make_scene_package(scene, atlas);
  }

  wire::Envelope welcome(std::uint64_t epoch = 7, std::uint64_t session = 1) const {
    wire::Envelope e;
    wire::Welcome* w = e.mutable_welcome();
    w->set_protocol_version(wire::kProtocolVersion);
    w->set_session(session);
    w->set_scene_id("cornell");
    w->set_scene_hash(package.hash);
    w->set_scene_bytes(package.bytes.size());
    w->set_tile_size(kTile);
    w->set_tile_epoch(epoch);
    w->set_idle_timeout_ms(900);
    for (const ObjectLightmap& o : atlas.objects) {
      wire::LightmapInfo* li = w->add_lightmaps();
      li->set_width(static_cast<std::uint32_t>(o.width));
      li->set_height(static_cast<std::uint32_t>(o.height));
      li->set_tiles_x(static_cast<std::uint32_t>(wire::tiles_along(o.width, kTile)));
      li->set_tiles_y(static_cast<std::uint32_t>(wire::tiles_along(o.height, kTile)));
    }
    return e;
  }

  // The package in chunks of `size` bytes.
  std::vector<wire::Envelope> chunks(std::size_t size) const {
    std::vector<wire::Envelope> out;
    std::uint64_t offset = 0;
    for (const std::string& piece : wire::chunk(package.bytes, size)) {
      wire::Envelope e;
      wire::SceneChunk* c = e.mutable_scene_chunk();
      c->set_scene_hash(package.hash);
      c->set_offset(offset);
      c->set_total(package.bytes.size());
      c->set_data(piece);
      offset += piece.size();
      out.push_back(e);
    }
    return out;
  }

  wire::Envelope tile(std::uint32_t lightmap, std::uint64_t version) const {
    const ObjectLightmap& o = atlas.objects[lightmap];
    const wire::TileRect r = wire::tile_rect(o.width, o.height, kTile, 0, 0);
    Lightmap map(o.width, o.height);
    for (glm::vec3& t : map.texels) t = glm::vec3(0.25f * static_cast<float>(version));
    wire::Envelope e;
    wire::TileUpdate* t = e.mutable_tile_update();
    t->set_lightmap(lightmap);
    t->set_version(version);
    t->set_encoding(wire::TILE_RGB9E5_ZSTD);
    t->set_width(static_cast<std::uint32_t>(r.w));
    t->set_height(static_cast<std::uint32_t>(r.h));
    t->set_payload(wire::encode_tile(map, r, wire::TILE_RGB9E5_ZSTD));
    return e;
  }

  static wire::Envelope edit(std::uint64_t revision, const std::string& node, bool applied) {
    SceneEdit edit;
    EditOp op;
    op.kind = EditOp::Kind::Move;
    op.target = node;
    op.vector = glm::vec3(0.05f, 0.0f, 0.0f);
    edit.ops.push_back(op);
    wire::Envelope e;
    wire::to_proto(edit, e.mutable_scene_edit());
    e.mutable_scene_edit()->set_revision(revision);
    e.mutable_scene_edit()->set_applied(applied);
    return e;
  }

  Atlas atlas;
  wire::ScenePackage package;
};

ClientSessionOptions options() {
  ClientSessionOptions o;
  o.name = "unit";
  o.encoding = wire::TILE_HALF_ZSTD;
  o.max_bytes_per_s = 12345;
  return o;
}

// "kind: what" of the ClientSessionFailure that f() throws.
std::string failure_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const ClientSessionFailure& e) {
    return e.kind() + ": " + e.what();
  }
  return "no failure";
}

std::string kind_of(const std::function<void()>& f) {
  const std::string failure = failure_of(f);
  return failure.substr(0, failure.find(':'));
}

// Hello, Welcome, download in chunks: the session is ready; returns the last step.
ClientStep connect_and_download(ClientSession& s, const FakeServer& server) {
  s.hello();
  EXPECT_EQ(s.on_frame(server.welcome()).event, Event::NeedScene);
  EXPECT_TRUE(s.download().has_scene_request());
  ClientStep last;
  for (const wire::Envelope& c : server.chunks(512)) last = s.on_frame(c);
  return last;
}

}  // namespace

TEST(ClientSession, FirstConnectionDownloadsTheSceneAndSubscribes) {
  const FakeServer server;
  ClientSession s(options());
  const wire::Envelope hello = s.hello();
  ASSERT_TRUE(hello.has_hello());
  EXPECT_EQ(hello.hello().protocol_version(), wire::kProtocolVersion);
  EXPECT_EQ(hello.hello().client_name(), "unit");
  EXPECT_TRUE(hello.hello().cached_scene_hash().empty());  // nothing to resume
  EXPECT_EQ(hello.hello().known_size(), 0);
  EXPECT_EQ(s.phase(), Phase::AwaitWelcome);

  const ClientStep welcome = s.on_frame(server.welcome());
  EXPECT_EQ(welcome.event, Event::NeedScene);
  EXPECT_TRUE(welcome.send.empty());
  EXPECT_EQ(s.session(), 1u);
  EXPECT_EQ(s.tile_epoch(), 7u);
  EXPECT_EQ(s.ping_interval(), std::chrono::milliseconds(300));  // a third of the idle timeout
  const wire::Envelope request = s.download();
  ASSERT_TRUE(request.has_scene_request());
  EXPECT_EQ(request.scene_request().offset(), 0u);

  const std::vector<wire::Envelope> chunks = server.chunks(512);
  ASSERT_GT(chunks.size(), 1u);
  for (std::size_t i = 0; i + 1 < chunks.size(); ++i)
    EXPECT_EQ(s.on_frame(chunks[i]).event, Event::Downloading);
  EXPECT_FALSE(s.has_scene());
  const ClientStep ready = s.on_frame(chunks.back());
  EXPECT_EQ(ready.event, Event::SessionReady);
  EXPECT_TRUE(ready.scene_loaded);
  ASSERT_EQ(ready.send.size(), 1u);
  ASSERT_TRUE(ready.send[0].has_subscribe());
  EXPECT_TRUE(ready.send[0].subscribe().all());
  EXPECT_EQ(ready.send[0].subscribe().encoding(), wire::TILE_HALF_ZSTD);
  EXPECT_EQ(ready.send[0].subscribe().max_bytes_per_s(), 12345u);

  EXPECT_EQ(s.phase(), Phase::Streaming);
  EXPECT_EQ(s.scene_hash(), server.package.hash);
  EXPECT_EQ(s.downloaded_package(), server.package.bytes);
  EXPECT_EQ(s.scene().unpacked.atlas.objects.size(), server.atlas.objects.size());
  EXPECT_GT(s.tiles().tile_count(), 0u);
  EXPECT_FALSE(s.tiles().all_received());
  EXPECT_EQ(s.counters().scene_bytes_downloaded, server.package.bytes.size());
  EXPECT_EQ(s.counters().frames_received, 1 + chunks.size());
  EXPECT_FALSE(s.counters().scene_from_cache);
}

TEST(ClientSession, AppliesNewerTilesAndSkipsStaleOnes) {
  const FakeServer server;
  ClientSession s(options());
  connect_and_download(s, server);
  EXPECT_EQ(s.on_frame(server.tile(0, 3)).event, Event::TileApplied);
  EXPECT_EQ(s.tiles().version(0, 0, 0), 3u);
  EXPECT_NEAR(s.tiles().lightmaps()[0].texels[0].x, 0.75f, 0.01f);
  EXPECT_EQ(s.on_frame(server.tile(0, 2)).event, Event::None);  // older: nothing changes
  EXPECT_EQ(s.tiles().version(0, 0, 0), 3u);
  EXPECT_EQ(s.counters().tiles_applied, 1u);
}

// Sessions that share a TileDecodeCache (irradcast-load's users) decode byte-identical tiles
// once: the second session copies the texels; different bytes under the same tile and version,
// or a broken payload, are decoded (or rejected) by the session itself.
TEST(ClientSession, SessionsSharingDecodesGetTheSameTexelsFromOneDecode) {
  const FakeServer server;
  auto shared = std::make_shared<TileDecodeCache>();
  ClientSessionOptions o = options();
  o.shared_decodes = shared;
  ClientSession a(o), b(o), c(o), d(o);
  for (ClientSession* s : {&a, &b, &c, &d}) connect_and_download(*s, server);
  EXPECT_EQ(a.on_frame(server.tile(0, 3)).event, Event::TileApplied);
  EXPECT_EQ(b.on_frame(server.tile(0, 3)).event, Event::TileApplied);
  EXPECT_EQ(shared->hits(), 1u);
  EXPECT_EQ(b.tiles().lightmaps()[0].texels, a.tiles().lightmaps()[0].texels);
  EXPECT_NEAR(b.tiles().lightmaps()[0].texels[0].x, 0.75f, 0.01f);
  // Same tile and version, other bytes: decoded, not copied.
  wire::Envelope other = server.tile(0, 2);
  other.mutable_tile_update()->set_version(3);
  EXPECT_EQ(c.on_frame(other).event, Event::TileApplied);
  EXPECT_EQ(shared->hits(), 1u);
  EXPECT_NEAR(c.tiles().lightmaps()[0].texels[0].x, 0.5f, 0.01f);
  // A broken payload is rejected by each session and never shared.
  wire::Envelope broken = server.tile(0, 4);
  broken.mutable_tile_update()->set_payload("not zstd");
  EXPECT_EQ(kind_of([&] { d.on_frame(broken); }), "bad tile");
  EXPECT_EQ(kind_of([&] { a.on_frame(broken); }), "bad tile");
  EXPECT_EQ(shared->hits(), 1u);
}

// irradcast-load's thin users keep a reference to the shared decode instead of copying it:
// the same texels as a session that decodes itself, no lightmaps, and bad tiles still rejected.
TEST(ClientSession, ThinSessionsHoldReferencesToTheSharedDecode) {
  const FakeServer server;
  auto shared = std::make_shared<TileDecodeCache>();
  ClientSessionOptions by_ref = options();
  by_ref.shared_decodes = shared;
  by_ref.shared_texels = SharedTexels::Reference;
  ClientSession own(options()), a(by_ref), b(by_ref);
  for (ClientSession* s : {&own, &a, &b}) connect_and_download(*s, server);
  for (ClientSession* s : {&own, &a, &b})
    EXPECT_EQ(s->on_frame(server.tile(0, 3)).event, Event::TileApplied);
  EXPECT_EQ(shared->hits(), 1u);  // a decoded, b found a's decode
  const std::vector<glm::vec3> expect = own.tiles().tile_texels(0, 0, 0);
  ASSERT_FALSE(expect.empty());
  EXPECT_EQ(a.tiles().tile_texels(0, 0, 0), expect);
  EXPECT_EQ(b.tiles().tile_texels(0, 0, 0), expect);
  EXPECT_TRUE(a.tiles().tile_texels(0, 1, 0).empty());  // never received
  EXPECT_THROW((void)a.tiles().lightmaps(), Error);
  // A newer version replaces the reference; an older one changes nothing.
  EXPECT_EQ(a.on_frame(server.tile(0, 4)).event, Event::TileApplied);
  EXPECT_EQ(a.on_frame(server.tile(0, 2)).event, Event::None);
  EXPECT_EQ(a.tiles().version(0, 0, 0), 4u);
  EXPECT_EQ(own.on_frame(server.tile(0, 4)).event, Event::TileApplied);
  EXPECT_EQ(a.tiles().tile_texels(0, 0, 0), own.tiles().tile_texels(0, 0, 0));
  // Broken bytes and deltas (which need the client's own texels) are rejected.
  wire::Envelope broken = server.tile(0, 5);
  broken.mutable_tile_update()->set_payload("not zstd");
  EXPECT_EQ(kind_of([&] { b.on_frame(broken); }), "bad tile");
  wire::Envelope delta = server.tile(0, 6);
  delta.mutable_tile_update()->set_encoding(wire::TILE_RGB9E5_DELTA_ZSTD);
  EXPECT_EQ(kind_of([&] { a.on_frame(delta); }), "bad tile");
  EXPECT_EQ(a.tiles().version(0, 0, 0), 4u);
}

TEST(ClientSession, ResumesWithItsSceneAndTileVersions) {
  const FakeServer server;
  ClientSession s(options());
  connect_and_download(s, server);
  s.on_frame(server.tile(1, 5));
  s.disconnect();
  EXPECT_EQ(s.phase(), Phase::Idle);

  const wire::Envelope hello = s.hello();
  EXPECT_EQ(hello.hello().cached_scene_hash(), server.package.hash);
  EXPECT_EQ(hello.hello().known_epoch(), 7u);
  ASSERT_EQ(hello.hello().known_size(), 1);
  EXPECT_EQ(hello.hello().known(0).lightmap(), 1u);
  EXPECT_EQ(hello.hello().known(0).version(), 5u);

  // The same scene and epoch: subscribed at once, versions kept.
  const ClientStep resumed = s.on_frame(server.welcome(7, 2));
  EXPECT_EQ(resumed.event, Event::SessionReady);
  EXPECT_FALSE(resumed.scene_loaded);
  ASSERT_EQ(resumed.send.size(), 1u);
  EXPECT_TRUE(resumed.send[0].has_subscribe());
  EXPECT_EQ(s.session(), 2u);
  EXPECT_EQ(s.tiles().version(1, 0, 0), 5u);

  // Another epoch: the versions are forgotten (any version is news), the scene is kept.
  s.disconnect();
  s.hello();
  EXPECT_EQ(s.on_frame(server.welcome(8, 3)).event, Event::SessionReady);
  EXPECT_EQ(s.tiles().version(1, 0, 0), 0u);
  EXPECT_EQ(s.on_frame(server.tile(1, 1)).event, Event::TileApplied);
}

TEST(ClientSession, TakesACachedPackageAndRejectsADamagedOne) {
  const FakeServer server;
  ClientSession s(options());
  s.hello();
  ASSERT_EQ(s.on_frame(server.welcome()).event, Event::NeedScene);
  ClientStep step;
  std::string why;
  std::string damaged = server.package.bytes;
  damaged[damaged.size() / 2] ^= 0x5a;
  EXPECT_FALSE(s.use_cached_package(damaged, step, &why));
  EXPECT_NE(why.find("hash mismatch"), std::string::npos) << why;
  EXPECT_EQ(s.phase(), Phase::NeedScene);
  ASSERT_TRUE(s.use_cached_package(server.package.bytes, step, &why));
  EXPECT_EQ(step.event, Event::SessionReady);
  EXPECT_TRUE(step.send[0].has_subscribe());
  EXPECT_TRUE(s.counters().scene_from_cache);
  EXPECT_EQ(s.counters().scene_bytes_downloaded, 0u);
  EXPECT_TRUE(s.downloaded_package().empty());
}

TEST(ClientSession, FollowsBroadcastEditsInOrder) {
  const FakeServer server;
  ClientSession s(options());
  s.hello();
  s.on_frame(server.welcome());
  s.download();
  const std::vector<wire::Envelope> chunks = server.chunks(512);
  s.on_frame(chunks[0]);
  // An edit during the download waits for the scene; an acknowledgement is not for viewers.
  s.on_frame(FakeServer::edit(1, "tall_block", true));
  s.on_frame(FakeServer::edit(2, "tall_block", false));
  for (std::size_t i = 1; i < chunks.size(); ++i) s.on_frame(chunks[i]);
  EXPECT_EQ(s.revision(), 1u);
  EXPECT_EQ(s.counters().edits_applied, 1u);
  s.on_frame(FakeServer::edit(1, "tall_block", true));  // already held
  EXPECT_EQ(s.counters().edits_applied, 1u);
  s.on_frame(FakeServer::edit(2, "tall_block", true));
  EXPECT_EQ(s.revision(), 2u);
  EXPECT_FALSE(s.take_reload());
  // A gap, or an edit that does not apply: reload the scene (once).
  s.on_frame(FakeServer::edit(4, "tall_block", true));
  EXPECT_EQ(s.revision(), 2u);
  EXPECT_TRUE(s.take_reload());
  EXPECT_FALSE(s.take_reload());
  s.on_frame(FakeServer::edit(3, "no_such_node", true));
  EXPECT_EQ(s.revision(), 2u);
  EXPECT_TRUE(s.take_reload());
}

// Poses (docs/DYNAMIC.md#poses): applied as they come; a complete set puts every node posed
// before and not in it back where the package places it; a hostile pose fails the session and
// leaves the scene as it was.
TEST(ClientSession, FollowsPosesAndACompleteSetPutsTheRestBack) {
  const FakeServer server(test::cornell_with_prop());
  ClientSession s(options());
  ASSERT_EQ(connect_and_download(s, server).event, Event::SessionReady);
  const auto prop = static_cast<std::size_t>(make_cornell_box().nodes.size()) + 1;
  const Node loaded = s.scene().unpacked.scene.nodes[prop];
  const auto poses = [](std::uint64_t sequence, bool complete, std::vector<wire::NodePose> list) {
    wire::Envelope e;
    e.mutable_poses()->set_sequence(sequence);
    e.mutable_poses()->set_complete(complete);
    for (const wire::NodePose& p : list) *e.mutable_poses()->add_poses() = p;
    return e;
  };
  glm::mat4 moved = loaded.local;
  moved[3].x += 0.3f;
  s.on_frame(poses(4, false, {wire::node_pose_to_proto(prop, moved, false)}));
  EXPECT_EQ(s.pose_sequence(), 4u);
  EXPECT_FLOAT_EQ(s.scene().unpacked.scene.nodes[prop].local[3].x, moved[3].x);
  EXPECT_FALSE(s.scene().unpacked.scene.nodes[prop].visible);
  EXPECT_EQ(s.revision(), 0u);  // not a revision
  // The prop's object (and its child's) moved in the client's world.
  const World expected = World::build(s.scene().unpacked.scene);
  ASSERT_EQ(s.scene().world.objects.size(), expected.objects.size());
  for (std::size_t o = 0; o < expected.objects.size(); ++o) {
    EXPECT_EQ(s.scene().world.objects[o].transform, expected.objects[o].transform) << o;
    EXPECT_EQ(s.scene().world.objects[o].visible, expected.objects[o].visible) << o;
  }
  // Hostile: a static node, a NaN: the session fails, the scene stays.
  EXPECT_EQ(
      kind_of([&] { s.on_frame(poses(5, false, {wire::node_pose_to_proto(0, moved, true)})); }),
      "protocol");
  glm::mat4 nan = moved;
  nan[3].y = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(
      kind_of([&] { s.on_frame(poses(5, false, {wire::node_pose_to_proto(prop, nan, true)})); }),
      "protocol");
  EXPECT_FLOAT_EQ(s.scene().unpacked.scene.nodes[prop].local[3].x, moved[3].x);
  EXPECT_FALSE(s.scene().unpacked.scene.nodes[prop].visible);
  EXPECT_EQ(s.pose_sequence(), 4u);
  // A new server's complete set without the prop: back as the package places it.
  s.on_frame(poses(1, true, {}));
  EXPECT_EQ(s.scene().unpacked.scene.nodes[prop].local, loaded.local);
  EXPECT_TRUE(s.scene().unpacked.scene.nodes[prop].visible);
  EXPECT_EQ(s.pose_sequence(), 1u);
}

TEST(ClientSession, IgnoresEditsWhenNotFollowing) {
  const FakeServer server;
  ClientSessionOptions o = options();
  o.follow_edits = false;
  ClientSession s(o);
  connect_and_download(s, server);
  s.on_frame(FakeServer::edit(5, "tall_block", true));
  EXPECT_EQ(s.revision(), 0u);
  EXPECT_FALSE(s.take_reload());
}

TEST(ClientSession, ReportsServerErrorsStatsAndBye) {
  const FakeServer server;
  ClientSession s(options());
  s.hello();
  wire::Envelope error;
  error.mutable_error()->set_code(wire::SERVER_SHUTDOWN);
  error.mutable_error()->set_message("going away");
  EXPECT_EQ(s.on_frame(error).event, Event::ServerError);
  EXPECT_EQ(s.counters().errors_received, 1u);
  wire::Envelope stats;
  stats.mutable_stats()->set_queue_depth(3);
  EXPECT_EQ(s.on_frame(stats).event, Event::Stats);
  ASSERT_TRUE(s.last_stats());
  EXPECT_EQ(s.last_stats()->queue_depth(), 3u);
  EXPECT_EQ(s.on_frame(wire::make_bye("done")).event, Event::Bye);
  const wire::Envelope ping = ClientSession::ping(4, 99);
  EXPECT_EQ(ping.ping().nonce(), 4u);
  EXPECT_EQ(ping.ping().time_us(), 99u);
}

TEST(ClientSession, RejectsMessagesOutOfOrder) {
  const FakeServer server;
  ClientSession s(options());
  s.hello();
  EXPECT_EQ(failure_of([&] { s.on_frame(server.tile(0, 1)); }),
            "protocol: a TileUpdate before the subscription");
  EXPECT_EQ(failure_of([&] { s.on_frame(server.chunks(512)[0]); }),
            "protocol: a SceneChunk outside a download");
  wire::Envelope old = server.welcome();
  old.mutable_welcome()->set_protocol_version(wire::kProtocolVersion + 1);
  EXPECT_EQ(failure_of([&] { s.on_frame(old); }),
            "protocol: the server speaks protocol " + std::to_string(wire::kProtocolVersion + 1) +
                ", this client " + std::to_string(wire::kProtocolVersion));
  s.on_frame(server.welcome());
  EXPECT_EQ(failure_of([&] { s.on_frame(server.welcome()); }), "protocol: an unexpected Welcome");
}

TEST(ClientSession, RejectsBadChunksScenesAndTiles) {
  const FakeServer server;
  {  // a chunk that skips bytes
    ClientSession s(options());
    s.hello();
    s.on_frame(server.welcome());
    s.download();
    const std::vector<wire::Envelope> chunks = server.chunks(512);
    EXPECT_EQ(kind_of([&] { s.on_frame(chunks[1]); }), "bad scene");
  }
  {  // a package whose bytes do not hash to the Welcome's
    ClientSession s(options());
    s.hello();
    wire::Envelope w = server.welcome();
    w.mutable_welcome()->set_scene_hash(std::string(32, 'x'));
    s.on_frame(w);
    s.download();
    std::vector<wire::Envelope> chunks = server.chunks(1u << 20);
    ASSERT_EQ(chunks.size(), 1u);
    chunks[0].mutable_scene_chunk()->set_scene_hash(std::string(32, 'x'));
    try {
      s.on_frame(chunks[0]);
      ADD_FAILURE() << "a package that does not match its hash was taken";
    } catch (const ClientSessionFailure& e) {
      EXPECT_EQ(e.kind(), "bad scene");
      EXPECT_NE(std::string(e.what()).find("hash mismatch"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(s.has_scene());
  }
  {  // a layout that does not match the package's atlas
    ClientSession s(options());
    s.hello();
    wire::Envelope w = server.welcome();
    w.mutable_welcome()->mutable_lightmaps(0)->set_width(3);
    s.on_frame(w);
    s.download();
    const std::vector<wire::Envelope> chunks = server.chunks(1u << 20);
    EXPECT_EQ(kind_of([&] { s.on_frame(chunks[0]); }), "bad scene");
  }
  {  // tiles outside the layout or with a broken payload
    ClientSession s(options());
    connect_and_download(s, server);
    wire::Envelope t = server.tile(0, 1);
    t.mutable_tile_update()->set_lightmap(100000);
    EXPECT_EQ(kind_of([&] { s.on_frame(t); }), "bad tile");
    t = server.tile(0, 1);
    t.mutable_tile_update()->set_payload("not zstd");
    EXPECT_EQ(kind_of([&] { s.on_frame(t); }), "bad tile");
    EXPECT_EQ(s.counters().tiles_applied, 0u);
  }
}

}  // namespace irradcast::test_client_session

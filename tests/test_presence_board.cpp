// Presence (irradcast-server --presence, docs/DYNAMIC.md#presence): the board of avatars and the
// nearest-K choice, a session's Avatars without sockets, the viewer's avatar nodes against
// hostile lists, the capsule, and end to end on loopback: a viewer draws another where it stands
// and a load test's users see each other at most presence_hz times a second.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/client/avatars.h"
#include "irradcast/client/camera_message.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/shapes.h"
#include "presence_board.h"
#include "service_fixture.h"
#include "session_driver.h"
#include "session_protocol.h"

namespace irradcast::test_presence_board {

using namespace std::chrono_literals;

namespace {

CameraPose camera_at(glm::vec3 eye, glm::vec3 forward = {0.0f, 0.0f, 1.0f}) {
  CameraPose c;
  c.eye = eye;
  c.forward = forward;
  return c;
}

wire::Envelope camera_update(glm::vec3 eye) {
  return irradcast::camera_update(camera_at(eye, {1.0f, 0.0f, 0.0f}));
}

}  // namespace

TEST(PresenceBoard, ChangesAreTakenOnceAndTheNearestComeFirstWithoutSelf) {
  PresenceBoard b;
  EXPECT_EQ(b.take_changed(), nullptr);
  b.place(1, camera_at({0, 0, 0}));
  b.place(2, camera_at({5, 0, 0}, {1, 0, 0}));
  b.place(3, camera_at({1, 0, 0}));
  b.place(4, camera_at({0, 3, 0}));
  const auto all = b.take_changed();
  ASSERT_NE(all, nullptr);
  EXPECT_EQ(all->size(), 4u);
  EXPECT_EQ(b.take_changed(), nullptr) << "nothing moved since";
  b.place(3, camera_at({1, 0, 0}));
  EXPECT_EQ(b.take_changed(), nullptr) << "the same place is no change";
  const std::vector<AvatarState> near = nearest_avatars(*all, 1, {0, 0, 0}, 2);
  ASSERT_EQ(near.size(), 2u);
  EXPECT_EQ(near[0].id, 3u);
  EXPECT_EQ(near[1].id, 4u);
  const std::vector<AvatarState> every = nearest_avatars(*all, 9, {6, 0, 0}, 32);
  ASSERT_EQ(every.size(), 4u);
  EXPECT_EQ(every[0].id, 2u);
  EXPECT_NEAR(every[0].heading, 0.5f * 3.14159265f, 1e-5f) << "looking down +x";
  EXPECT_EQ(every[0].eye, glm::vec3(5, 0, 0));
  // Out of the world, and leaving: gone from the next snapshot.
  b.place(2, camera_at({2e7f, 0, 0}));
  b.remove(4);
  const auto after = b.take_changed();
  ASSERT_NE(after, nullptr);
  EXPECT_EQ(after->size(), 2u);
}

// Other servers' avatars (NATS): each (source, id) gets an id of the board's own, kept while it
// stays listed; what is no place is left out; the local avatars and their version stay apart.
TEST(PresenceBoard, OtherServersAvatarsGetIdsOfTheirOwnAndBadOnesAreLeftOut) {
  PresenceBoard b;
  b.set_height(1.7f);
  b.place(1, camera_at({0, 0, 0}));
  std::uint64_t local_version = 0;
  ASSERT_EQ(b.local(&local_version).size(), 1u);
  b.take_changed();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  b.set_group(77, {{1, {1, 0, 0}, 0.0f},  // the same id as session 1: another source's
                   {2, {2, 0, 0}, 0.0f},
                   {3, {nan, 0, 0}, 0.0f},   // not finite
                   {4, {3e7f, 0, 0}, 0.0f},  // beyond kMaxCoordinate
                   {0, {1, 1, 1}, 0.0f},     // no id
                   {2, {9, 9, 9}, 0.0f},     // repeated
                   {5, {1, 1, 1}, nan}});    // heading not finite
  auto all = b.take_changed();
  ASSERT_NE(all, nullptr);
  ASSERT_EQ(all->size(), 3u) << "session 1 and the group's two valid avatars";
  std::map<std::uint64_t, glm::vec3> at;
  for (const AvatarState& a : *all) at[a.id] = a.eye;
  ASSERT_EQ(at.size(), 3u) << "every id distinct";
  EXPECT_EQ(at.at(1), glm::vec3(0, 0, 0)) << "the session keeps its id";
  std::uint64_t id_of_2 = 0;
  for (const auto& [id, eye] : at)
    if (eye == glm::vec3(2, 0, 0)) id_of_2 = id;
  EXPECT_GE(id_of_2, PresenceBoard::kFirstGroupId);
  // The source's avatar 2 moves: it keeps the id; the groups come back with the source's ids.
  b.set_group(77, {{2, {2.5f, 0, 0}, 0.0f}, {1, {1, 0, 0}, 0.0f}});
  all = b.take_changed();
  ASSERT_NE(all, nullptr);
  int moved = 0;
  for (const AvatarState& a : *all) {
    if (a.eye != glm::vec3(2.5f, 0, 0)) continue;
    ++moved;
    EXPECT_EQ(a.id, id_of_2);
  }
  EXPECT_EQ(moved, 1);
  const PresenceBoard::Groups groups = b.groups();
  ASSERT_EQ(groups.size(), 1u);
  ASSERT_EQ(groups.at(77).size(), 2u);
  EXPECT_EQ(groups.at(77)[0].id, 1u);
  EXPECT_EQ(groups.at(77)[1].id, 2u);
  std::uint64_t v = 0;
  b.local(&v);
  EXPECT_EQ(v, local_version) << "other servers' avatars are no local change";
  // Replacing all groups drops those not named; an unchanged set is no change.
  b.set_group(78, {{1, {4, 0, 0}, 0.0f}});
  b.replace_groups({{78, {{1, {4, 0, 0}, 0.0f}}}});
  EXPECT_EQ(b.size(), 2u);
  b.take_changed();
  b.replace_groups({{78, {{1, {4, 0, 0}, 0.0f}}}});
  EXPECT_EQ(b.take_changed(), nullptr);
  // The height another server decides wins while it is set.
  EXPECT_FLOAT_EQ(b.height(), 1.7f);
  b.set_shared_height(0.14f);
  EXPECT_FLOAT_EQ(b.height(), 0.14f);
  EXPECT_NE(b.take_changed(), nullptr) << "a new height is a change";
  b.set_shared_height(0.0f);
  EXPECT_FLOAT_EQ(b.height(), 1.7f);
  // At most kMaxGroupAvatars of one source.
  std::vector<AvatarState> many;
  for (std::uint64_t i = 1; i <= PresenceBoard::kMaxGroupAvatars + 10; ++i)
    many.push_back({i, {0, 0, 0}, 0.0f});
  b.set_group(79, many);
  EXPECT_EQ(b.groups().at(79).size(), PresenceBoard::kMaxGroupAvatars);
}

// A session over a real engine host with the server's board, as the server ticks it.
class PresenceSessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    host.emplace(make_cornell_box(), "cornell", test::quick_host(1));
    host->step();
    options.presence = true;
    options.presence_nearest = 2;
    options.presence_height = 0.14f;
    make_context(true);
  }
  void make_context(bool presence) {
    board.set_height(options.presence_height);  // as the Server does
    context.emplace(SessionContext{*host, options, counters, peers, [] { return ServerStats{}; },
                                   options.max_hello_frame, nullptr, presence ? &board : nullptr});
  }
  SessionProtocol& session(bool presence) {
    sessions.push_back(test::joined(*context, sessions.size() + 1, true, presence));
    return *sessions.back();
  }
  // The server's presence tick.
  void tick() {
    if (auto avatars = board.take_changed())
      for (const auto& s : sessions) s->presence_changed(avatars);
  }
  static void feed(SessionProtocol& s, const wire::Envelope& e) { test::feed(s, e); }
  // What the session writes now, tiles, the Welcome and the volume left out.
  static std::vector<wire::Envelope> written(SessionProtocol& s) {
    return test::frames_written(s, [](const wire::Envelope& e) {
      return !e.has_tile_update() && !e.has_welcome() && !e.has_probe_volume();
    });
  }
  static std::vector<std::uint64_t> ids(const wire::Envelope& e) {
    std::vector<std::uint64_t> out;
    for (const wire::Avatar& a : e.avatars().avatars()) out.push_back(a.id());
    return out;
  }

  std::optional<EngineHost> host;
  ServerOptions options;
  ServerCounters counters;
  PeerTable peers{options};
  PresenceBoard board;
  std::optional<SessionContext> context;
  std::vector<std::unique_ptr<SessionProtocol>> sessions;
};

TEST_F(PresenceSessionTest, EachViewerGetsTheNearestOthersOnlyWhenTheyChanged) {
  SessionProtocol& a = session(true);
  SessionProtocol& b = session(true);
  SessionProtocol& c = session(true);
  SessionProtocol& d = session(true);
  SessionProtocol& watcher = session(false);  // not shown, and sent none
  std::vector<wire::Envelope> first = written(a);
  ASSERT_EQ(first.size(), 1u) << "the first Avatars, empty: nobody has a camera yet";
  EXPECT_EQ(first[0].avatars().avatars_size(), 0);
  EXPECT_FLOAT_EQ(first[0].avatars().height(), 0.14f);
  for (SessionProtocol* s : {&b, &c, &d}) written(*s);
  feed(a, camera_update({0.0f, 0.2f, 0.0f}));
  feed(b, camera_update({0.1f, 0.2f, 0.0f}));
  feed(c, camera_update({0.3f, 0.2f, 0.0f}));
  feed(d, camera_update({0.5f, 0.2f, 0.0f}));
  feed(watcher, camera_update({0.0f, 0.2f, 0.0f}));
  tick();
  const std::vector<wire::Envelope> to_a = written(a);
  ASSERT_EQ(to_a.size(), 1u);
  EXPECT_EQ(ids(to_a[0]), (std::vector<std::uint64_t>{2, 3})) << "the 2 nearest, nearest first";
  EXPECT_FLOAT_EQ(to_a[0].avatars().avatars(0).eye().x(), 0.1f);
  EXPECT_EQ(ids(written(d)[0]), (std::vector<std::uint64_t>{3, 2}));
  EXPECT_TRUE(written(watcher).empty()) << "a viewer without presence gets no Avatars";
  // D moves far away: A's nearest two are the same and unchanged, so A is sent nothing; C's
  // change.
  feed(d, camera_update({3.0f, 0.2f, 0.0f}));
  tick();
  EXPECT_TRUE(written(a).empty());
  // B leaves: A's set changes.
  b.close(CloseReason::Bye);
  tick();
  const std::vector<wire::Envelope> after = written(a);
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(ids(after[0]), (std::vector<std::uint64_t>{3, 4}));
  // A slow viewer: many ticks unread, one Avatars with the newest.
  for (int i = 1; i <= 20; ++i) {
    feed(c, camera_update({0.3f + 0.01f * static_cast<float>(i), 0.2f, 0.0f}));
    tick();
  }
  const std::vector<wire::Envelope> newest = written(a);
  ASSERT_EQ(newest.size(), 1u);
  EXPECT_FLOAT_EQ(newest[0].avatars().avatars(0).eye().x(), 0.5f);
  EXPECT_GE(counters.avatar_frames_sent.load(), 6u);
}

TEST_F(PresenceSessionTest, AServerWithoutPresenceSaysSoAndSubscribesTheRest) {
  make_context(false);
  SessionProtocol& s = session(true);
  bool error = false, tiles = false;
  for (const wire::Envelope& e :
       test::frames_written(s, [](const wire::Envelope&) { return true; })) {
    if (e.has_error()) {
      error = true;
      EXPECT_EQ(e.error().code(), wire::BAD_REQUEST);
      EXPECT_NE(e.error().message().find("--presence"), std::string::npos);
    }
    tiles = tiles || e.has_tile_update();
    EXPECT_FALSE(e.has_avatars());
  }
  EXPECT_TRUE(error);
  EXPECT_TRUE(tiles);
  EXPECT_FALSE(s.closed());
  // A NaN camera is refused as before, and places nothing.
  wire::Envelope bad = camera_update({0.0f, 0.0f, 0.0f});
  bad.mutable_camera_update()->mutable_eye()->set_x(std::numeric_limits<float>::quiet_NaN());
  feed(s, bad);
  EXPECT_EQ(board.size(), 0u);
}

TEST(Capsule, IsClosedOutwardAndAsTallAsAsked) {
  const Mesh m = capsule("c", 0.2f, 0.6f, 12, 24, 0);
  float lo = 1e9f, hi = -1e9f;
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const glm::vec3 p = m.positions[i];
    lo = std::min(lo, p.y);
    hi = std::max(hi, p.y);
    // The normal points away from the axis segment's nearest point, at the radius.
    const glm::vec3 axis(0.0f, std::clamp(p.y, -0.3f, 0.3f), 0.0f);
    EXPECT_NEAR(glm::length(p - axis), 0.2f, 1e-5f);
    EXPECT_GT(glm::dot(p - axis, m.normals[i]), 0.19f);
  }
  EXPECT_NEAR(lo, -0.5f, 1e-6f);
  EXPECT_NEAR(hi, 0.5f, 1e-6f);
  // Outward winding: the signed volume is positive and near the capsule's.
  double volume = 0.0;
  for (const glm::uvec3& t : m.triangles)
    volume += glm::dot(glm::dvec3(m.positions[t.x]),
                       glm::cross(glm::dvec3(m.positions[t.y]), glm::dvec3(m.positions[t.z]))) /
              6.0;
  const double exact = 3.14159265 * 0.04 * 0.6 + 4.0 / 3.0 * 3.14159265 * 0.008;
  EXPECT_NEAR(volume, exact, 0.03 * exact);
  EXPECT_THROW(capsule("c", 0.2f, 0.6f, 11, 24, 0), Error);
  EXPECT_THROW(capsule("c", 0.2f, -1.0f, 12, 24, 0), Error);
}

TEST(AvatarNodes, KeepTheirAvatarAndRefuseWhatIsNotAPlace) {
  wire::UnpackedScene u;
  u.scene = make_cornell_box();
  const std::size_t objects = u.scene.objects().size();
  u.atlas.objects.resize(objects);
  const int first = add_avatar_nodes(u, 2);
  EXPECT_EQ(u.scene.objects().size(), objects + 2);
  EXPECT_EQ(u.atlas.objects.size(), objects + 2);
  EXPECT_TRUE(u.scene.nodes[first].dynamic);
  EXPECT_FALSE(u.scene.nodes[first + 1].visible);
  World world = World::build(u.scene);
  AvatarNodes nodes(first, 2);
  auto avatar = [](wire::Avatars& m, std::uint64_t id, float x) {
    wire::Avatar* a = m.add_avatars();
    a->set_id(id);
    a->mutable_eye()->set_x(x);
    a->mutable_eye()->set_y(0.2f);
    a->mutable_eye()->set_z(0.2f);
  };
  wire::Avatars m;
  m.set_height(0.14f);
  avatar(m, 7, 0.1f);
  avatar(m, 8, 0.2f);
  avatar(m, 9, 0.3f);  // past the two nodes
  SceneEdit e = nodes.place(m, world.bounds);
  apply_edit(u.scene, e);
  EXPECT_EQ(nodes.shown(), 2);
  EXPECT_TRUE(u.scene.nodes[first].visible);
  EXPECT_FLOAT_EQ(u.scene.nodes[first].local[3].x, 0.1f);
  EXPECT_FLOAT_EQ(u.scene.nodes[first].local[1].y, 0.14f) << "scaled to the height";
  // 7 leaves, 8 stays on its node, 9 takes 7's.
  wire::Avatars next;
  next.set_height(0.14f);
  avatar(next, 9, 0.3f);
  avatar(next, 8, 0.25f);
  apply_edit(u.scene, nodes.place(next, world.bounds));
  EXPECT_FLOAT_EQ(u.scene.nodes[first + 1].local[3].x, 0.25f) << "8 kept its node";
  EXPECT_FLOAT_EQ(u.scene.nodes[first].local[3].x, 0.3f);
  // Hostile: NaN, out of the world, a repeated id, id 0: none shown; a bad height throws.
  wire::Avatars bad;
  bad.set_height(0.14f);
  avatar(bad, 3, std::numeric_limits<float>::quiet_NaN());
  avatar(bad, 4, 1e30f);
  avatar(bad, 0, 0.1f);
  avatar(bad, 5, 0.1f);
  avatar(bad, 5, 0.2f);
  SceneEdit hidden = nodes.place(bad, world.bounds);
  apply_edit(u.scene, hidden);
  EXPECT_EQ(nodes.shown(), 1);
  EXPECT_FLOAT_EQ(u.scene.nodes[first].local[3].x, 0.1f) << "5's first place";
  EXPECT_FALSE(u.scene.nodes[first + 1].visible);
  bad.set_height(std::numeric_limits<float>::infinity());
  EXPECT_THROW(nodes.place(bad, world.bounds), Error);
  bad.set_height(0.0f);
  EXPECT_THROW(nodes.place(bad, world.bounds), Error);
}

// Two viewers on loopback: the one looking into the box draws the other where its camera stands
// (the left front, by the red wall), in the pixels around it, and nowhere else.
TEST(Presence, AViewerDrawsAnotherAtItsCamera) {
  EngineHostOptions ho = test::small_host(4);
  ho.avatars = true;
  EngineHost host(make_cornell_box(), "cornell", ho);
  ServerOptions so = test::loopback();
  so.presence = true;
  so.presence_height = 0.14f;
  Server server(host, so);
  server.start();
  host.start();
  ASSERT_TRUE(test::eventually([&] { return host.stats().idle; }, 60s));
  ViewClientOptions vo = test::client_of(server, "a");
  vo.presence = true;
  ViewClient a(vo);
  vo.name = "b";
  ViewClient b(vo);
  a.connect();
  b.connect();
  const CameraPose cam = default_camera(a.scene(), a.world());
  a.send_camera(cam);
  b.send_camera(camera_at({0.42f, 0.15f, 0.12f}, {-1.0f, 0.0f, 1.0f}));
  ASSERT_TRUE(test::eventually([&] {
    a.poll(20ms);
    b.poll(1ms);
    return a.counters().avatars_shown == 1 && a.all_tiles_received() &&
           a.probe_volume().lit() != nullptr;
  })) << "A shows B";
  EXPECT_EQ(b.counters().avatars_shown, 0u) << "B has not polled its Avatars yet, or A's";
  const ImageRGB with = a.compose(cam, 96, 96);
  b.close();
  ASSERT_TRUE(test::eventually([&] {
    a.poll(20ms);
    return a.counters().avatars_shown == 0;
  })) << "B left";
  const ImageRGB without = a.compose(cam, 96, 96);
  // Where B's eye projects: the pixels that changed lie around it, and there are some.
  int changed = 0, far = 0;
  const glm::vec3 fwd = glm::normalize(cam.forward);
  const glm::vec3 right = glm::normalize(glm::cross(fwd, cam.up)), up = glm::cross(right, fwd);
  const glm::vec3 d = glm::vec3(0.42f, 0.08f, 0.12f) - cam.eye;  // the avatar's middle
  const float t = std::tan(0.5f * cam.yfov);
  const float px = 48.0f + 48.0f * glm::dot(d, right) / glm::dot(d, fwd) / t;
  const float py = 48.0f - 48.0f * glm::dot(d, up) / glm::dot(d, fwd) / t;
  for (int y = 0; y < 96; ++y)
    for (int x = 0; x < 96; ++x) {
      const glm::vec3 p = with.at(x, y), q = without.at(x, y);
      if (glm::length(p - q) <= 0.02f * (glm::length(q) + 0.01f)) continue;
      ++changed;
      if (std::abs(x - px) > 12.0f || std::abs(y - py) > 16.0f) ++far;
    }
  EXPECT_GT(changed, 10) << "the avatar is drawn";
  EXPECT_LT(far, changed / 10 + 2) << "and where B stands (" << px << ", " << py << ")";
  server.stop();
  host.stop();
}

// irradcast-load --presence: every user sees the others (3 users, nearest 2), at most
// presence_hz Avatars a second, and the report says so.
TEST(Presence, LoadUsersSeeEachOtherAtMostPresenceHzTimesASecond) {
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  ServerOptions so = test::loopback();
  so.presence = true;
  so.presence_hz = 5.0;
  Server server(host, so);
  server.start();
  host.start();
  LoadOptions o = test::load_of(server.port(), 3, 3.0);
  o.camera_hz = 20.0;
  o.camera_path = "random-walk";
  o.presence = true;
  o.threads = 1;
  const LoadReport r = run_load(o);
  EXPECT_EQ(r.connected, 3);
  EXPECT_EQ(r.failed, 0);
  EXPECT_GT(r.avatar_messages, 3u * 3u);
  EXPECT_NEAR(r.avatars_per_message, 2.0, 0.5) << "the other two, once they have cameras";
  for (const LoadUserResult& u : r.per_user)
    EXPECT_LE(static_cast<double>(u.avatar_messages), 5.0 * 3.0 + 2.0) << "presence_hz over 3 s";
  EXPECT_NE(r.text().find("avatar bytes/s"), std::string::npos);
  const nlohmann::json j = nlohmann::json::parse(r.json());
  EXPECT_EQ(j["avatars"]["messages"].get<std::uint64_t>(), r.avatar_messages);
  server.stop();
  host.stop();
}

}  // namespace irradcast::test_presence_board

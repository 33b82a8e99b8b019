// Presence across NATS (docs/DYNAMIC.md#presence): the origin and its gateways, each with
// --presence, show every viewer that asks to every other, whichever server it is connected to;
// a viewer that leaves, or a gateway that stops, takes its avatars away; what a forged camera
// request or a forged s.presence holds that is no place is not shown.
#include <gtest/gtest.h>

#include <nats/nats.h>

#include <chrono>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/client/camera_message.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast/wire/frame.h"
#include "irradcast_nats.pb.h"
#include "nats_fixture.h"

namespace irradcast::test_nats_presence {

using namespace std::chrono_literals;

namespace {

// A viewer on the wire that shows itself (Subscribe.presence, no tiles) and keeps the newest
// Avatars it was sent.
struct PresenceViewer {
  PresenceViewer(std::uint16_t port, const std::string& name) : c(port) {
    EXPECT_TRUE(c.join(name));
    wire::Envelope s;
    s.mutable_subscribe()->set_presence(true);
    c.send(s);
  }
  void stand_at(glm::vec3 eye) {
    CameraPose pose;
    pose.eye = eye;
    c.send(camera_update(pose));
  }
  // Reads what came; the eyes of the avatars last listed, by id.
  const std::map<std::uint64_t, glm::vec3>& poll() {
    while (auto e = c.read(20ms)) {
      if (e->has_error()) ADD_FAILURE() << "error: " << e->error().message();
      if (!e->has_avatars()) continue;
      shown.clear();
      for (const wire::Avatar& a : e->avatars().avatars())
        shown[a.id()] = {a.eye().x(), a.eye().y(), a.eye().z()};
      height = e->avatars().height();
    }
    return shown;
  }
  // Whether it shows exactly avatars at `eyes` (any order, one each).
  bool shows(const std::vector<glm::vec3>& eyes) {
    poll();
    if (shown.size() != eyes.size()) return false;
    for (const glm::vec3& want : eyes) {
      bool found = false;
      for (const auto& [id, eye] : shown) found = found || glm::length(eye - want) < 1e-6f;
      if (!found) return false;
    }
    return true;
  }
  test::RawConnection c;
  std::map<std::uint64_t, glm::vec3> shown;
  float height = 0.0f;
};

std::string describe(const std::map<std::uint64_t, glm::vec3>& shown) {
  std::string out = std::to_string(shown.size()) + " avatars:";
  for (const auto& [id, e] : shown)
    out +=
        " (" + std::to_string(e.x) + ", " + std::to_string(e.y) + ", " + std::to_string(e.z) + ")";
  return out;
}

}  // namespace

TEST(NatsPresence, ViewersOfTheOriginAndOfTwoGatewaysSeeEachOther) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 1, "", {}, make_cornell_box(), true);
  test::NatsGatewayNode gw1(nats.url(), "", {}, true);
  std::optional<test::NatsGatewayNode> gw2(std::in_place, nats.url(), "", NatsCredentials{}, true);
  std::optional<PresenceViewer> viewer_o(std::in_place, origin.server.port(), "o");
  PresenceViewer& o = *viewer_o;
  PresenceViewer a(gw1.server->port(), "a");
  PresenceViewer b(gw2->server->port(), "b");
  const glm::vec3 at_o(0.1f, 0.2f, 0.1f), at_a(0.3f, 0.2f, 0.2f), at_b(0.45f, 0.25f, 0.4f);
  o.stand_at(at_o);
  a.stand_at(at_a);
  b.stand_at(at_b);
  EXPECT_TRUE(test::eventually([&] { return o.shows({at_a, at_b}); }, 15s)) << describe(o.shown);
  EXPECT_TRUE(test::eventually([&] { return a.shows({at_o, at_b}); }, 15s)) << describe(a.shown);
  EXPECT_TRUE(test::eventually([&] { return b.shows({at_o, at_a}); }, 15s)) << describe(b.shown);
  for (const PresenceViewer* v : {&o, &a, &b})
    EXPECT_FLOAT_EQ(v->height, 0.14f) << "every viewer is shown the origin's avatar height";
  EXPECT_GE(origin.origin.nats_stats().presence_published, 1u);
  EXPECT_GE(gw1.gateway.nats_stats().presence_received, 1u);

  // B moves: the others see it where it went, with the id it had.
  const std::uint64_t b_at_a = [&] {
    for (const auto& [id, eye] : a.shown)
      if (glm::length(eye - at_b) < 1e-6f) return id;
    return std::uint64_t{0};
  }();
  const glm::vec3 moved(0.4f, 0.3f, 0.3f);
  b.stand_at(moved);
  EXPECT_TRUE(test::eventually([&] { return a.shows({at_o, moved}); }, 15s)) << describe(a.shown);
  EXPECT_TRUE(a.shown.contains(b_at_a)) << "an avatar keeps its id while it moves";
  EXPECT_TRUE(test::eventually([&] { return o.shows({at_a, moved}); }, 15s)) << describe(o.shown);

  // O's viewer leaves: the gateways' viewers see only each other.
  viewer_o.reset();
  EXPECT_TRUE(test::eventually([&] { return a.shows({moved}); }, 15s)) << describe(a.shown);
  EXPECT_TRUE(test::eventually([&] { return b.shows({at_a}); }, 15s)) << describe(b.shown);

  // Gateway 2 stops with B still connected: it tells the origin (which would otherwise keep B's
  // avatar a minute here), and A sees nobody.
  gw2.reset();
  EXPECT_TRUE(test::eventually([&] { return a.shows({}); }, 15s)) << describe(a.shown);
  EXPECT_EQ(origin.origin.nats_stats().avatars_refused, 0u);
}

// What another server sends is checked as a client's: a forged camera request's avatars that are
// no place (not finite, out of range, no id, repeated) are not shown, the rest are; a forged
// s.presence that is too large or has no height is refused whole, its bad avatars left out.
TEST(NatsPresence, ForgedAvatarsAreLeftOutOrRefused) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 1, "", {}, make_cornell_box(), true);
  test::NatsGatewayNode gw(nats.url(), "", {}, true);
  PresenceViewer o(origin.server.port(), "o");
  PresenceViewer a(gw.server->port(), "a");
  o.stand_at({0.1f, 0.2f, 0.1f});
  a.stand_at({0.2f, 0.2f, 0.1f});
  ASSERT_TRUE(test::eventually([&] { return o.shows({{0.2f, 0.2f, 0.1f}}); }, 15s));

  const NatsSubjects s = nats_subjects("cornell");
  natsConnection* nc = nullptr;
  ASSERT_EQ(natsConnection_ConnectTo(&nc, nats.url().c_str()), NATS_OK);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  auto avatar = [](google::protobuf::RepeatedPtrField<wire::Avatar>* list, std::uint64_t id,
                   glm::vec3 eye) {
    wire::Avatar* w = list->Add();
    w->set_id(id);
    w->mutable_eye()->set_x(eye.x);
    w->mutable_eye()->set_y(eye.y);
    w->mutable_eye()->set_z(eye.z);
  };
  wire::NatsCameras forged;
  forged.set_gateway(12345);
  avatar(forged.mutable_avatars(), 1, {0.3f, 0.2f, 0.1f});
  avatar(forged.mutable_avatars(), 2, {nan, 0.2f, 0.1f});
  avatar(forged.mutable_avatars(), 3, {1e30f, 0.2f, 0.1f});
  avatar(forged.mutable_avatars(), 0, {0.3f, 0.3f, 0.1f});
  avatar(forged.mutable_avatars(), 1, {0.4f, 0.2f, 0.1f});
  const std::string bytes = forged.SerializeAsString();
  natsMsg* reply = nullptr;
  ASSERT_EQ(natsConnection_Request(&reply, nc, s.cameras.c_str(), bytes.data(),
                                   static_cast<int>(bytes.size()), 5000),
            NATS_OK);
  natsMsg_Destroy(reply);
  EXPECT_TRUE(test::eventually(
      [&] {
        return o.shows({{0.2f, 0.2f, 0.1f}, {0.3f, 0.2f, 0.1f}});
      },
      15s))
      << describe(o.shown);
  EXPECT_EQ(origin.origin.nats_stats().avatars_refused, 4u);
  EXPECT_TRUE(test::eventually(
      [&] {
        return a.shows({{0.1f, 0.2f, 0.1f}, {0.3f, 0.2f, 0.1f}});
      },
      15s))
      << "the gateway's viewer sees the forged gateway's valid avatar too: " << describe(a.shown);

  // s.presence as only an origin may publish it (NATS's permissions, deploy/nats/nats.conf).
  jsCtx* js = nullptr;
  ASSERT_EQ(natsConnection_JetStream(&js, nc, nullptr), NATS_OK);
  auto put = [&](const wire::NatsPresence& m) {
    const std::string data = m.SerializeAsString();
    EXPECT_EQ(js_Publish(nullptr, js, s.presence.c_str(), data.data(),
                         static_cast<int>(data.size()), nullptr, nullptr),
              NATS_OK);
  };
  const std::uint64_t bad = gw.gateway.nats_stats().bad_messages;
  wire::NatsPresence big;
  big.set_height(1.0f);
  for (int g = 0; g < 5000; ++g) big.add_groups()->set_source(static_cast<std::uint64_t>(g) + 1);
  put(big);
  EXPECT_TRUE(
      test::eventually([&] { return gw.gateway.nats_stats().bad_messages >= bad + 1; }, 15s));
  wire::NatsPresence tall;
  tall.set_height(std::numeric_limits<float>::infinity());
  put(tall);
  EXPECT_TRUE(
      test::eventually([&] { return gw.gateway.nats_stats().bad_messages >= bad + 2; }, 15s));
  // One with a NaN avatar among good ones: the good ones are shown (until the origin's next
  // set, within 50 ms, replaces them).
  const std::uint64_t refused = gw.gateway.nats_stats().avatars_refused;
  wire::NatsPresence mixed;
  mixed.set_height(0.14f);
  wire::NatsAvatarGroup* g = mixed.add_groups();
  g->set_source(999);
  avatar(g->mutable_avatars(), 1, {nan, 0.0f, 0.0f});
  avatar(g->mutable_avatars(), 2, {0.25f, 0.2f, 0.1f});
  put(mixed);
  EXPECT_TRUE(test::eventually(
      [&] { return gw.gateway.nats_stats().avatars_refused >= refused + 1; }, 15s));
  // The origin's sets go on: A sees what the origin knows.
  EXPECT_TRUE(test::eventually(
      [&] {
        return a.shows({{0.1f, 0.2f, 0.1f}, {0.3f, 0.2f, 0.1f}});
      },
      15s))
      << describe(a.shown);
  jsCtx_Destroy(js);
  natsConnection_Destroy(nc);
}

}  // namespace irradcast::test_nats_presence

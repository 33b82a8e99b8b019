// A failover viewer across gateways (docs/DISTRIBUTION.md, docs/DEPLOY-CLUSTER.md): a viewer
// connected with a list of two gateways of one origin (nats-server with JetStream, an origin and
// two gateways in the process, tests/nats_fixture.h) loses its gateway, moves to the other one,
// resumes there with the tiles it holds (both gateways carry the origin's tile epoch and
// versions), follows what the origin computes next, and ends with exactly the image of a viewer
// of the origin.
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>

#include "irradcast/client/host_port.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/scene_edit.h"
#include "nats_fixture.h"

namespace irradcast::test_nats_failover {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

HostPort address_of(const Server& s) {
  return {"127.0.0.1", s.port()};
}

}  // namespace

TEST(NatsFailover, KillingAGatewayMovesAFailoverViewerToTheOtherWhichConverges) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 3);
  auto a = std::make_unique<test::NatsGatewayNode>(nats.url());
  test::NatsGatewayNode b(nats.url());
  ASSERT_TRUE(origin.settle());
  ASSERT_TRUE(test::eventually([&] {
    return test::same_versions(origin.host.tiles(), a->gateway.tiles()) &&
           test::same_versions(origin.host.tiles(), b.gateway.tiles());
  }));

  ViewClientOptions vo;
  vo.servers = {address_of(*a->server), address_of(*b.server)};  // --connect A,B
  vo.name = "failover";
  vo.connect_timeout = 20000ms;
  vo.backoff_seed = 7;
  ViewClient v(vo);
  v.connect();
  EXPECT_EQ(v.server().port, a->server->port());
  ASSERT_TRUE(test::converge(v, origin.host.tiles()));
  const std::uint64_t tiles_before = v.counters().tiles_applied;
  const std::uint16_t port_b = b.server->port();

  // Gateway a goes away (its server and its NATS connection): the viewer moves to b and resumes
  // there without a tile sent again (b has the origin's tile epoch and the same versions).
  a.reset();
  const auto deadline = Clock::now() + 20s;
  while (v.counters().connections < 2 && Clock::now() < deadline) v.poll(50ms);
  v.poll(300ms);
  ViewClientCounters c = v.counters();
  ASSERT_EQ(c.connections, 2u);
  EXPECT_EQ(c.connections_lost, 1u);
  EXPECT_GE(c.failovers, 1u);
  EXPECT_EQ(v.server().port, port_b);
  EXPECT_EQ(c.tiles_applied, tiles_before) << "gateway b sent tiles the viewer held (no resume)";

  // The origin computes more (an edit of its own viewers): through gateway b the viewer gets the
  // edit and the new tiles, and ends with what a viewer of the origin sees, pixel for pixel.
  const std::uint64_t updates_before = origin.host.stats().updates;
  origin.host.submit_edit(
      parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [0.05, 0, 0]})"));
  ASSERT_TRUE(test::eventually([&] { return origin.host.stats().updates > updates_before; }, 15s));
  ASSERT_TRUE(origin.settle());
  ASSERT_TRUE(test::eventually(
      [&] { return test::same_versions(origin.host.tiles(), b.gateway.tiles()); }, 15s));
  ASSERT_TRUE(test::converge(v, origin.host.tiles()));
  EXPECT_EQ(v.scene_revision(), 1u);
  EXPECT_GT(v.counters().tiles_applied, tiles_before);

  ViewClientOptions direct_options = test::client_of(origin.server, "direct");
  direct_options.connect_timeout = 10000ms;
  ViewClient direct(direct_options);
  direct.connect();
  ASSERT_TRUE(test::converge(direct, origin.host.tiles()));
  test::expect_same_image(test::view_of(v), test::view_of(direct), "the failover viewer");
  v.close();
  direct.close();
}

}  // namespace irradcast::test_nats_failover

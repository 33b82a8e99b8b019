// An origin's edits across restarts with NATS (issue 31 part 3): with --state-dir a restarted
// origin resumes its edited scene and publishes that revision again; an origin without the folder
// (or on another machine) finds a newer revision from another origin in the stream and publishes
// nothing over it, so the gateways keep the edits, unless told to replace it.
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>

#include "irradcast/common/scene_edit.h"
#include "nats_fixture.h"

namespace irradcast::test_nats_state {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// An EngineHost and its NatsOrigin (no viewer server: the gateways serve).
struct Origin {
  Origin(const std::string& url, const std::string& state_dir, bool replace_newer = false)
      : host(make_cornell_box(), "cornell",
             [&] {
               EngineHostOptions o = test::small_host(1);
               o.state_dir = state_dir;
               return o;
             }()),
        origin(host, [&] {
          NatsOriginOptions o;
          o.url = url;
          o.replace_newer = replace_newer;
          return o;
        }()) {
    host.start();
  }
  ~Origin() { host.stop(); }
  EngineHost host;
  NatsOrigin origin;
};

TEST(NatsState, ARestartedOriginKeepsItsEditsAndNoOriginRollsTheStreamBack) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  const fs::path dir = fs::path(::testing::TempDir()) / "nats_state_origin";
  fs::remove_all(dir);
  std::string edited_hash;
  {
    Origin a(nats.url(), dir.string());
    EXPECT_EQ(a.origin.check_stream(10s), "");
    a.host.submit_edit(parse_edit_json(R"({"op": "hide", "node": "short_block"})"));
    ASSERT_TRUE(test::eventually([&] { return a.host.revision() == 1; }));
    a.host.wait_for_updates(~std::uint64_t{0});
    ASSERT_TRUE(a.origin.flush(10s));
    edited_hash = a.host.package()->hash;
  }
  test::NatsGatewayNode gateway(nats.url());
  ASSERT_TRUE(test::eventually([&] { return gateway.gateway.revision() == 1; }));

  {  // Another origin without the folder: at revision 0, it must not publish over revision 1.
    Origin b(nats.url(), "");
    const std::string refusal = b.origin.check_stream(10s);
    EXPECT_NE(refusal.find("holds revision 1"), std::string::npos) << refusal;
    EXPECT_NE(refusal.find("--state-dir"), std::string::npos) << refusal;
    EXPECT_TRUE(b.origin.nats_stats().refused_newer_stream);
    b.host.wait_for_updates(~std::uint64_t{0});
    std::this_thread::sleep_for(500ms);
    EXPECT_EQ(b.origin.nats_stats().tiles_published, 0u);
    EXPECT_EQ(b.origin.nats_stats().packages_published, 0u);
  }
  EXPECT_EQ(gateway.gateway.revision(), 1u);
  EXPECT_EQ(gateway.gateway.package()->hash, edited_hash);

  {  // The origin again on its folder: revision 1, the same package, published again.
    Origin a(nats.url(), dir.string());
    EXPECT_EQ(a.host.revision(), 1u);
    EXPECT_EQ(a.host.package()->hash, edited_hash);
    EXPECT_EQ(a.origin.check_stream(10s), "");
    a.host.wait_for_updates(~std::uint64_t{0});
    ASSERT_TRUE(a.origin.flush(10s));
    EXPECT_GE(a.origin.nats_stats().packages_published, 1u);
    // The gateway follows the new epoch of the same revision.
    EXPECT_TRUE(
        test::eventually([&] { return gateway.gateway.tile_epoch() == a.host.tile_epoch(); }));
    EXPECT_EQ(gateway.gateway.package()->hash, edited_hash);
  }

  {  // Told to, an origin without the folder replaces the stream's revision.
    Origin c(nats.url(), "", true);
    EXPECT_EQ(c.origin.check_stream(10s), "");
    c.host.wait_for_updates(~std::uint64_t{0});
    ASSERT_TRUE(c.origin.flush(10s));
    EXPECT_FALSE(c.origin.nats_stats().refused_newer_stream);
    EXPECT_TRUE(test::eventually([&] { return gateway.gateway.revision() == 0; }));
  }
}

}  // namespace
}  // namespace irradcast::test_nats_state

// The protocol side of a server session without sockets: a SessionProtocol over a real engine
// host, fed frames as a client would send them; the test reads what it writes back and the
// events it asks its connection for.
#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <vector>

#include "irradcast/common/builtin.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "session_protocol.h"

namespace irradcast::test_session_protocol {

using namespace std::chrono_literals;

namespace {

const std::string kToken = "secret-token-for-tests";

// One engine host for the suite, stepped once so that every tile has a version.
class SessionProtocolTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Progress::set_enabled(false);
    log::set_level(log::Level::Warn);
    EngineHostOptions o;
    o.atlas.texels_per_scene = 32.0f;
    o.tiles.tile_size = 16;
    o.max_updates = 1;
    host_ = new EngineHost(make_cornell_box(), "cornell", o);
    host_->step();
  }
  static void TearDownTestSuite() {
    delete host_;
    host_ = nullptr;
  }

  void SetUp() override {
    options.control_token = kToken;
    options.max_control_frames = 8;
    options.max_pending_edits = 2;
    options.token_failure_delay = 100ms;
    options.max_token_failures = 3;
  }

  // A session of this test's server (options as the test left them).
  SessionProtocol& session() {
    if (!context)
      context.emplace(SessionContext{*host_, options, counters, peers, [] { return ServerStats{}; },
                                     options.max_hello_frame});
    sessions.push_back(std::make_unique<SessionProtocol>(*context, sessions.size() + 1, "10.0.0.1",
                                                         "10.0.0.1:5000"));
    return *sessions.back();
  }

  // Feeds one frame and handles what it decodes to.
  static void feed(SessionProtocol& s, const wire::Envelope& e) { feed(s, wire::encode_frame(e)); }
  static void feed(SessionProtocol& s, const std::string& bytes) {
    s.receive(bytes.data(), bytes.size());
    wire::Envelope env;
    while (s.next_frame(env)) s.handle(env);
  }

  // The frames the session writes now, in order (until it has nothing, must wait or closes).
  static std::vector<wire::Envelope> written(SessionProtocol& s,
                                             SessionWrite::Kind* last = nullptr) {
    std::vector<wire::Envelope> out;
    for (;;) {
      const SessionWrite w = s.next_write(std::chrono::steady_clock::now());
      if (!w.frame) {
        if (last) *last = w.kind;
        return out;
      }
      wire::FrameDecoder d;
      d.feed(w.frame->data(), w.frame->size());
      wire::Envelope e;
      EXPECT_EQ(d.next(e), wire::DecodeStatus::Frame);
      out.push_back(e);
    }
  }

  static wire::Envelope hello(std::uint32_t version = wire::kProtocolVersion) {
    wire::Envelope e;
    e.mutable_hello()->set_protocol_version(version);
    e.mutable_hello()->set_client_name("test");
    return e;
  }
  static wire::Envelope subscribe_all(std::uint64_t max_bytes_per_s = 0) {
    wire::Envelope e;
    e.mutable_subscribe()->set_all(true);
    e.mutable_subscribe()->set_encoding(wire::TILE_RGB9E5_ZSTD);
    e.mutable_subscribe()->set_max_bytes_per_s(max_bytes_per_s);
    return e;
  }
  static wire::Envelope edit(const std::string& token) {
    wire::Envelope e;
    wire::to_proto(parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [0.01, 0, 0]})"),
                   e.mutable_scene_edit());
    e.mutable_scene_edit()->set_token(token);
    e.mutable_scene_edit()->set_request_id(7);
    return e;
  }
  std::uint64_t closed(CloseReason r) const {
    return counters.sessions_closed[static_cast<std::size_t>(r)].load();
  }

  // The session failed: it asks for the grace timer, writes one Error with `code`, then closes
  // and counts `reason`. The Error.
  wire::Error expect_failed(SessionProtocol& s, wire::ErrorCode code, CloseReason reason) {
    EXPECT_TRUE(s.take_events().closing);
    SessionWrite::Kind last{};
    const auto out = written(s, &last);
    EXPECT_EQ(last, SessionWrite::Kind::Close) << "the session closes once the Error is written";
    const std::uint64_t before = closed(reason);
    s.close(CloseReason::Disconnect);
    EXPECT_EQ(closed(reason), before + 1) << "the failure's reason counts";
    if (out.size() != 1 || !out[0].has_error()) {
      ADD_FAILURE() << out.size() << " frames written, expected one Error";
      return {};
    }
    EXPECT_EQ(out[0].error().code(), code);
    return out[0].error();
  }

  static EngineHost* host_;
  ServerOptions options;
  ServerCounters counters;
  PeerTable peers{options};
  std::optional<SessionContext> context;
  std::vector<std::unique_ptr<SessionProtocol>> sessions;
};
EngineHost* SessionProtocolTest::host_ = nullptr;

TEST_F(SessionProtocolTest, HelloIsAnsweredWithAWelcomeDescribingTheSceneAndTheLimits) {
  SessionProtocol& s = session();
  EXPECT_TRUE(s.awaiting_hello());
  feed(s, hello());
  EXPECT_TRUE(s.take_events().welcomed);
  EXPECT_FALSE(s.awaiting_hello());
  const auto out = written(s);
  ASSERT_EQ(out.size(), 1u);
  ASSERT_TRUE(out[0].has_welcome());
  const wire::Welcome& w = out[0].welcome();
  EXPECT_EQ(w.session(), 1u);
  EXPECT_EQ(w.scene_id(), "cornell");
  EXPECT_EQ(w.scene_hash(), host_->package()->hash);
  EXPECT_EQ(w.scene_bytes(), host_->package()->bytes.size());
  EXPECT_EQ(w.tile_epoch(), host_->tile_epoch());
  EXPECT_EQ(static_cast<std::size_t>(w.lightmaps_size()), host_->tiles().lightmap_count());
  EXPECT_EQ(w.max_frame_bytes(), options.max_frame);
  EXPECT_EQ(w.idle_timeout_ms(), options.idle_timeout.count());
}

TEST_F(SessionProtocolTest, AnotherProtocolVersionGetsAnErrorAndCloses) {
  SessionProtocol& s = session();
  feed(s, hello(wire::kProtocolVersion + 1));
  expect_failed(s, wire::UNSUPPORTED_VERSION, CloseReason::UnsupportedVersion);
  EXPECT_EQ(closed(CloseReason::Disconnect), 0u);
  EXPECT_EQ(counters.errors_sent.load(), 1u);
}

TEST_F(SessionProtocolTest, AFrameBeforeHelloIsUnexpected) {
  SessionProtocol& s = session();
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(1);
  feed(s, ping);
  EXPECT_TRUE(s.closing());
  const wire::Error e = expect_failed(s, wire::UNEXPECTED_MESSAGE, CloseReason::UnexpectedMessage);
  EXPECT_NE(e.message().find("expected hello"), std::string::npos);
}

TEST_F(SessionProtocolTest, AFrameOverTheHelloCapIsTooLargeBeforeHelloButNotAfter) {
  // A frame header announcing more than max_hello_frame (+32 per tile, here 0).
  const std::uint32_t n = static_cast<std::uint32_t>(options.max_hello_frame) + 100;
  const std::string header{static_cast<char>(n & 0xff), static_cast<char>((n >> 8) & 0xff),
                           static_cast<char>((n >> 16) & 0xff), static_cast<char>(n >> 24)};
  SessionProtocol& early = session();
  feed(early, header);
  expect_failed(early, wire::FRAME_TOO_LARGE, CloseReason::FrameTooLarge);

  // After Hello the cap is max_frame: the same header only means "more bytes to come".
  SessionProtocol& late = session();
  feed(late, hello());
  feed(late, header);
  EXPECT_FALSE(late.closing());
  EXPECT_TRUE(late.account_partial());
}

TEST_F(SessionProtocolTest, AResumeWithTheSameSceneAndEpochSendsOnlyNewerTiles) {
  const TileStore& tiles = host_->tiles();
  ASSERT_GT(tiles.tile_count(), 2u);
  // A client that holds every tile at its version, but tile 0 one version behind.
  auto resume = [&](std::uint64_t epoch) {
    wire::Envelope h = hello();
    h.mutable_hello()->set_cached_scene_hash(host_->package()->hash);
    h.mutable_hello()->set_known_epoch(epoch);
    for (std::uint32_t t = 0; t < tiles.tile_count(); ++t) {
      const TileStore::Tile& tile = tiles.tile(t);
      wire::TileVersion* k = h.mutable_hello()->add_known();
      k->set_lightmap(tile.lightmap);
      k->set_tile_x(tile.tx);
      k->set_tile_y(tile.ty);
      k->set_version(tiles.version(t) - (t == 0 ? 1 : 0));
    }
    return h;
  };
  SessionProtocol& same = session();
  feed(same, resume(host_->tile_epoch()));
  feed(same, subscribe_all());
  auto out = written(same);
  ASSERT_EQ(out.size(), 2u) << "the Welcome and tile 0";
  EXPECT_TRUE(out[0].has_welcome());
  ASSERT_TRUE(out[1].has_tile_update());
  EXPECT_EQ(out[1].tile_update().tile_x(), tiles.tile(0).tx);
  EXPECT_EQ(out[1].tile_update().version(), tiles.version(0));

  // Another epoch: the versions mean nothing, every tile comes again.
  SessionProtocol& other = session();
  feed(other, resume(host_->tile_epoch() + 1));
  feed(other, subscribe_all());
  out = written(other);
  EXPECT_EQ(out.size(), 1 + tiles.tile_count());
  EXPECT_EQ(other.queue_depth(), 0u);
}

TEST_F(SessionProtocolTest, TheByteRateCapMakesTilesWait) {
  SessionProtocol& s = session();
  feed(s, hello());
  feed(s, subscribe_all(1000));  // a 64 KiB burst, then 1000 bytes/s
  SessionWrite::Kind last{};
  std::size_t sent = written(s, &last).size() - 1;  // the Welcome, then tiles
  EXPECT_EQ(sent, host_->tiles().tile_count()) << "the first tiles fit in the burst";
  // New versions of every tile until the burst is spent.
  std::vector<std::uint32_t> all(host_->tiles().tile_count());
  for (std::uint32_t t = 0; t < all.size(); ++t) all[t] = t;
  for (int i = 0; i < 50 && last != SessionWrite::Kind::Wait; ++i) {
    host_->step();
    s.tiles_changed(all);
    sent += written(s, &last).size();
  }
  ASSERT_EQ(last, SessionWrite::Kind::Wait) << sent << " tiles sent";
  EXPECT_GT(s.queue_depth(), 0u);
  const auto now = std::chrono::steady_clock::now();
  const SessionWrite wait = s.next_write(now);
  ASSERT_EQ(wait.kind, SessionWrite::Kind::Wait);
  EXPECT_GT(wait.wait.count(), 0);
  EXPECT_FALSE(wait.frame);
  // Once the cap has refilled enough, the held tile goes.
  const SessionWrite tile = s.next_write(now + wait.wait + 1ms);
  EXPECT_EQ(tile.kind, SessionWrite::Kind::Tile);
}

TEST_F(SessionProtocolTest, AWrongTokenIsAnsweredAfterADelayAndBansAfterTooMany) {
  SessionProtocol& s = session();
  feed(s, hello());
  written(s);
  feed(s, edit("wrong-token-wrong-token"));
  SessionEvents ev = s.take_events();
  ASSERT_TRUE(ev.penalty);
  EXPECT_EQ(*ev.penalty, 100ms);
  EXPECT_FALSE(ev.banned);
  EXPECT_TRUE(s.paused()) << "nothing else is handled while the answer waits";
  EXPECT_TRUE(written(s).empty());
  s.penalty_ended();
  s.answer_token_failure(ev.banned);
  auto out = written(s);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].error().code(), wire::PERMISSION_DENIED);
  EXPECT_FALSE(s.closing());

  feed(s, edit("wrong-token-wrong-token"));
  ev = s.take_events();
  EXPECT_EQ(*ev.penalty, 200ms) << "the delay doubles per failure of the address";
  s.penalty_ended();
  s.answer_token_failure(ev.banned);
  written(s);
  feed(s, edit("wrong-token-wrong-token"));
  ev = s.take_events();
  EXPECT_TRUE(ev.banned) << "the third failure bans the address";
  s.penalty_ended();
  s.answer_token_failure(ev.banned);
  expect_failed(s, wire::PERMISSION_DENIED, CloseReason::TokenFailures);
  EXPECT_EQ(counters.token_failures.load(), 3u);
  EXPECT_EQ(peers.admit("10.0.0.1", [] { return std::size_t{0}; }), PeerTable::Admission::Banned);
  EXPECT_EQ(peers.admit("10.0.0.2", [] { return std::size_t{0}; }), PeerTable::Admission::Ok);
}

TEST_F(SessionProtocolTest, EditsNeedAServerWithAToken) {
  options.control_token.clear();
  SessionProtocol& s = session();
  feed(s, hello());
  written(s);
  feed(s, edit(kToken));
  EXPECT_FALSE(s.take_events().penalty);
  const auto out = written(s);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].error().code(), wire::PERMISSION_DENIED);
  EXPECT_NE(out[0].error().message().find("takes no edits"), std::string::npos);
}

TEST_F(SessionProtocolTest, EditBroadcastsPastThePendingLimitDropTheOldest) {
  SessionProtocol& s = session();
  s.edit_applied(std::make_shared<const std::string>("before hello"));
  feed(s, hello());
  written(s);
  for (int i = 0; i < 5; ++i)
    s.edit_applied(std::make_shared<const std::string>("edit " + std::to_string(i)));
  EXPECT_EQ(counters.edits_dropped.load(), 3u);
  std::vector<std::string> frames;
  for (SessionWrite w; (w = s.next_write(std::chrono::steady_clock::now())).frame;) {
    EXPECT_EQ(w.kind, SessionWrite::Kind::Edit);
    frames.push_back(*w.frame);
  }
  EXPECT_EQ(frames, (std::vector<std::string>{"edit 3", "edit 4"}));
}

TEST_F(SessionProtocolTest, AClientThatDoesNotReadItsRepliesPausesThenIsDropped) {
  SessionProtocol& s = session();
  feed(s, hello());
  written(s);
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(9);
  for (int i = 0; i < 4; ++i) s.handle(ping);
  EXPECT_TRUE(s.paused()) << "half the control frame cap queued: reading waits";
  wire::Envelope env;
  EXPECT_FALSE(s.next_frame(env));
  for (int i = 0; i < 4; ++i) s.handle(ping);
  EXPECT_FALSE(s.closing());
  s.handle(ping);  // the ninth reply does not fit
  EXPECT_TRUE(s.closing());
  const auto out = written(s);
  ASSERT_EQ(out.size(), 9u);
  EXPECT_EQ(out.back().error().code(), wire::BAD_REQUEST);
  s.close(CloseReason::Disconnect);
  EXPECT_EQ(closed(CloseReason::SlowClient), 1u);
}

TEST_F(SessionProtocolTest, HelloTimeoutClosesAtOnceDuringTheHandshakeOrWithAnErrorAfter) {
  SessionProtocol& handshaking = session();
  handshaking.hello_timed_out(true);
  EXPECT_EQ(handshaking.take_events().close, CloseReason::HelloTimeout);
  EXPECT_TRUE(written(handshaking).empty());

  SessionProtocol& silent = session();
  silent.hello_timed_out(false);
  expect_failed(silent, wire::IDLE_TIMEOUT, CloseReason::HelloTimeout);

  SessionProtocol& greeted = session();
  feed(greeted, hello());
  greeted.hello_timed_out(false);
  EXPECT_FALSE(greeted.closing()) << "a late timer after Hello does nothing";
}

TEST_F(SessionProtocolTest, ByeClosesWithoutAnError) {
  SessionProtocol& s = session();
  feed(s, hello());
  written(s);
  wire::Envelope bye;
  bye.mutable_bye()->set_reason("done");
  feed(s, bye);
  EXPECT_EQ(s.take_events().close, CloseReason::Bye);
  EXPECT_TRUE(written(s).empty());
}

}  // namespace

}  // namespace irradcast::test_session_protocol

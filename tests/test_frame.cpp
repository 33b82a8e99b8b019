// Framing: every message type round-trips, the incremental decoder handles any split of the
// byte stream, and hostile input (oversized, truncated, garbage, unknown messages) is reported,
// never crashes.
#include <gtest/gtest.h>

#include <google/protobuf/util/message_differencer.h>

#include <cstring>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "irradcast/common/error.h"
#include "irradcast/wire/frame.h"

namespace irradcast::test_frame {

using namespace irradcast::wire;
using google::protobuf::util::MessageDifferencer;

namespace {

// One Envelope of every message type, with every field set to a non-default value.
std::vector<Envelope> all_messages() {
  std::vector<Envelope> out;
  {
    Envelope e;
    Hello* m = e.mutable_hello();
    m->set_protocol_version(kProtocolVersion);
    m->set_client_name("viewer-7");
    m->set_cached_scene_hash(std::string(32, '\xab'));
    TileVersion* k = m->add_known();
    k->set_lightmap(3);
    k->set_tile_x(1);
    k->set_tile_y(2);
    k->set_version(99);
    m->set_known_epoch(1700000000123456ULL);
    out.push_back(e);
  }
  {
    Envelope e;
    Welcome* m = e.mutable_welcome();
    m->set_protocol_version(kProtocolVersion);
    m->set_session(0x123456789abcdefULL);
    m->set_scene_id("cornell");
    m->set_scene_hash(std::string("\x00\x01\x02\xff", 4));
    m->set_scene_bytes(123456);
    m->set_tile_size(32);
    m->add_capabilities("tiles.rgb9e5");
    m->add_capabilities("tiles.half");
    LightmapInfo* l = m->add_lightmaps();
    l->set_width(100);
    l->set_height(60);
    l->set_tiles_x(4);
    l->set_tiles_y(2);
    m->set_max_frame_bytes(kDefaultMaxFrame);
    m->set_idle_timeout_ms(kDefaultIdleTimeoutMs);
    m->set_tile_epoch(1700000000123456ULL);
    out.push_back(e);
  }
  {
    Envelope e;
    e.mutable_scene_request()->set_offset(4096);
    out.push_back(e);
  }
  {
    Envelope e;
    SceneChunk* m = e.mutable_scene_chunk();
    m->set_scene_hash("hash");
    m->set_offset(1 << 20);
    m->set_total(3 << 20);
    m->set_data(std::string(1000, '\0') + "tail");
    out.push_back(e);
  }
  {
    Envelope e;
    Subscribe* m = e.mutable_subscribe();
    m->set_all(true);
    m->add_lightmaps(0);
    m->add_lightmaps(7);
    m->set_max_bytes_per_s(1 << 20);
    m->set_encoding(TILE_HALF_ZSTD);
    m->set_presence(true);
    out.push_back(e);
  }
  {
    Envelope e;
    CameraUpdate* m = e.mutable_camera_update();
    m->mutable_eye()->set_x(1.5f);
    m->mutable_eye()->set_y(-2.0f);
    m->mutable_eye()->set_z(3.25f);
    m->mutable_forward()->set_z(-1.0f);
    m->mutable_up()->set_y(1.0f);
    m->set_yfov(0.69f);
    out.push_back(e);
  }
  {
    Envelope e;
    TileUpdate* m = e.mutable_tile_update();
    m->set_lightmap(5);
    m->set_tile_x(3);
    m->set_tile_y(4);
    m->set_version(17);
    m->set_encoding(TILE_RGB9E5_DELTA_ZSTD);
    m->set_width(32);
    m->set_height(20);
    m->set_payload(std::string("\x28\xb5\x2f\xfd payload", 12));
    m->set_server_time_us(1700000000000000ULL);
    m->set_base_version(16);
    out.push_back(e);
  }
  {
    Envelope e;
    e.mutable_stats_request();
    out.push_back(e);
  }
  {
    Envelope e;
    Stats* m = e.mutable_stats();
    m->set_clients(12);
    m->set_bytes_sent(1ULL << 40);
    m->set_tiles_sent(5000);
    m->set_tiles_coalesced(40);
    m->set_updates(300);
    m->set_rays_per_s(2.5e8);
    m->set_convergence(0.0125);
    m->set_engine_update_ms(41.5);
    m->set_queue_depth(7);
    m->set_uptime_ms(90000);
    m->set_bytes_received(4096);
    m->set_frames_received(88);
    m->set_errors_sent(1);
    m->set_engine_idle(true);
    m->set_bytes_per_texel(2.3);
    PassTime* p = m->add_pass_times();
    p->set_pass("scatter");
    p->set_bounce(2);
    p->set_ms(12.5);
    p->set_rays(1000000);
    p->set_seconds_total(3.75);
    p->set_rays_total(300000000);
    m->add_pass_times()->set_pass("direct");
    m->set_update_rate(23.5);
    m->set_queue_depth_total(70);
    m->set_queue_depth_max(30);
    m->set_connections(99);
    m->set_clients_refused(2);
    m->set_scene_bytes_sent(123456);
    m->set_tile_bytes_sent(1ULL << 39);
    m->set_tiles_published(8000);
    m->set_engine_seconds_total(88.25);
    m->set_rays_total(1ULL << 45);
    SessionsClosed* c = m->add_sessions_closed();
    c->set_reason("idle_timeout");
    c->set_sessions(3);
    m->add_sessions_closed()->set_reason("bye");
    m->set_tiles(480);
    m->set_texels(118000);
    m->set_backend("vulkan on llvmpipe (CPU, Vulkan 1.3.230)");
    m->set_scene_revision(3);
    m->set_last_edit_ms(12.75);
    m->set_stale_texels(4096);
    out.push_back(e);
  }
  {
    Envelope e;
    e.mutable_ping()->set_nonce(42);
    e.mutable_ping()->set_time_us(1234567);
    out.push_back(e);
  }
  {
    Envelope e;
    e.mutable_pong()->set_nonce(42);
    e.mutable_pong()->set_time_us(1234567);
    out.push_back(e);
  }
  {
    Envelope e;
    wire::SceneEdit* m = e.mutable_scene_edit();
    m->set_token("secret");
    wire::EditOp* op = m->add_ops();
    op->set_kind(wire::EditOp::SET_TRANSFORM);
    op->set_target("tall_block");
    op->mutable_vector()->set_x(0.05f);
    op->set_value(30.0f);
    for (int i = 0; i < 16; ++i) op->add_matrix(i % 5 == 0 ? 1.0f : 0.0f);
    m->set_request_id(7);
    m->set_revision(2);
    m->set_scene_hash(std::string(32, '\x5a'));
    m->set_applied(true);
    m->set_applied_us(1700000000000001ULL);
    m->set_stream(true);
    m->set_pose_sequence(11);
    out.push_back(e);
  }
  {
    Envelope e;
    Poses* m = e.mutable_poses();
    m->set_sequence(12);
    NodePose* p = m->add_poses();
    p->set_node(3);
    for (int i = 0; i < 16; ++i) p->add_matrix(i % 5 == 0 ? 1.0f : 0.0f);
    p->set_hidden(true);
    m->set_complete(true);
    m->set_posed_us(1700000000000002ULL);
    out.push_back(e);
  }
  {
    Envelope e;
    Avatars* m = e.mutable_avatars();
    Avatar* a = m->add_avatars();
    a->set_id(5);
    a->mutable_eye()->set_x(1.5f);
    a->mutable_eye()->set_y(1.6f);
    a->mutable_eye()->set_z(-2.0f);
    a->set_heading(0.25f);
    m->set_height(1.7f);
    m->set_time_us(1700000000000003ULL);
    out.push_back(e);
  }
  {
    Envelope e;
    e.mutable_scene_export_request()->set_token("secret");
    e.mutable_scene_export_request()->set_request_id(9);
    out.push_back(e);
  }
  {
    Envelope e;
    e.mutable_scene_export()->set_request_id(9);
    e.mutable_scene_export()->set_scene_hash(std::string(32, '\x3c'));
    e.mutable_scene_export()->set_scene_bytes(123456);
    e.mutable_scene_export()->mutable_poses()->set_sequence(4);
    out.push_back(e);
  }
  {
    Envelope e;
    ProbeVolume* v = e.mutable_probe_volume();
    v->set_epoch(2);
    v->set_version(5);
    for (int a = 0; a < 3; ++a) {
      v->add_origin(-1.0f + a);
      v->add_counts(4);
    }
    v->set_spacing(0.5f);
    v->set_layout(std::string(40, '\x11'));
    v->set_sh(std::string(30, '\x22'));
    v->set_emitted(std::string(30, '\x33'));
    out.push_back(e);
  }
  out.push_back(make_error(UNSUPPORTED_VERSION, "protocol version 9 is not supported"));
  out.back().mutable_error()->set_request_id(13);
  out.push_back(make_bye("viewer closed"));
  return out;
}

std::string stream_of(const std::vector<Envelope>& msgs) {
  std::string s;
  for (const Envelope& e : msgs) s += encode_frame(e);
  return s;
}

std::string le32(std::uint32_t v) {
  std::string s(4, '\0');
  for (int i = 0; i < 4; ++i) s[i] = static_cast<char>((v >> (8 * i)) & 0xFF);
  return s;
}

}  // namespace

TEST(Frame, EveryMessageTypeIsCovered) {
  // One per oneof case: a new message type must be added to all_messages().
  std::vector<Envelope> msgs = all_messages();
  std::set<int> cases;
  for (const Envelope& e : msgs) cases.insert(e.msg_case());
  EXPECT_EQ(cases.size(), msgs.size());
  EXPECT_EQ(static_cast<int>(cases.size()),
            Envelope::descriptor()->FindOneofByName("msg")->field_count());
  EXPECT_EQ(cases.count(Envelope::MSG_NOT_SET), 0u);
  // Every field of every message is set, so the round trip below covers them all.
  for (const Envelope& e : msgs) {
    const google::protobuf::Reflection* r = e.GetReflection();
    const google::protobuf::FieldDescriptor* f = e.GetDescriptor()->FindFieldByNumber(e.msg_case());
    ASSERT_NE(f, nullptr);
    const google::protobuf::Message& m = r->GetMessage(e, f);
    std::vector<const google::protobuf::FieldDescriptor*> set;
    m.GetReflection()->ListFields(m, &set);
    EXPECT_EQ(static_cast<int>(set.size()), m.GetDescriptor()->field_count()) << message_name(e);
  }
}

TEST(Frame, EveryMessageTypeRoundTrips) {
  for (const Envelope& e : all_messages()) {
    SCOPED_TRACE(message_name(e));
    std::string frame = encode_frame(e);
    ASSERT_GE(frame.size(), 4u);
    std::uint32_t len = static_cast<unsigned char>(frame[0]) |
                        (static_cast<unsigned char>(frame[1]) << 8) |
                        (static_cast<unsigned char>(frame[2]) << 16) |
                        (static_cast<std::uint32_t>(static_cast<unsigned char>(frame[3])) << 24);
    EXPECT_EQ(len, frame.size() - 4);
    EXPECT_EQ(len, e.ByteSizeLong());
    FrameDecoder d;
    d.feed(frame.data(), frame.size());
    Envelope out;
    ASSERT_EQ(d.next(out), DecodeStatus::Frame) << d.error();
    EXPECT_TRUE(MessageDifferencer::Equals(e, out)) << out.DebugString();
    EXPECT_EQ(out.msg_case(), e.msg_case());
    EXPECT_EQ(d.buffered(), 0u);
    EXPECT_EQ(d.next(out), DecodeStatus::NeedMore);
  }
}

TEST(Frame, LengthPrefixIsLittleEndian) {
  Envelope e;
  e.mutable_scene_chunk()->set_data(std::string(0x0102, 'x'));
  std::string frame = encode_frame(e);
  const std::size_t len = frame.size() - 4;
  EXPECT_EQ(static_cast<unsigned char>(frame[0]), len & 0xFF);
  EXPECT_EQ(static_cast<unsigned char>(frame[1]), (len >> 8) & 0xFF);
  EXPECT_EQ(frame[2], 0);
  EXPECT_EQ(frame[3], 0);
}

TEST(Frame, ByteAtATimeFeedingDecodesEveryFrame) {
  std::vector<Envelope> msgs = all_messages();
  std::string s = stream_of(msgs);
  FrameDecoder d;
  std::vector<Envelope> got;
  Envelope out;
  for (char c : s) {
    d.feed(&c, 1);
    DecodeStatus st;
    while ((st = d.next(out)) == DecodeStatus::Frame) got.push_back(out);
    ASSERT_EQ(st, DecodeStatus::NeedMore) << d.error();
  }
  ASSERT_EQ(got.size(), msgs.size());
  for (std::size_t i = 0; i < msgs.size(); ++i)
    EXPECT_TRUE(MessageDifferencer::Equals(msgs[i], got[i])) << i;
  EXPECT_EQ(d.buffered(), 0u);
  EXPECT_EQ(d.frames(), msgs.size());
}

TEST(Frame, RandomSplitsDecodeEveryFrame) {
  std::vector<Envelope> msgs = all_messages();
  std::string s = stream_of(msgs) + stream_of(msgs);
  std::mt19937 rng(7);
  for (int trial = 0; trial < 50; ++trial) {
    FrameDecoder d;
    std::size_t pos = 0, count = 0;
    Envelope out;
    while (pos < s.size()) {
      std::size_t n = std::min<std::size_t>(s.size() - pos, rng() % 300);
      d.feed(s.data() + pos, n);
      pos += n;
      while (d.next(out) == DecodeStatus::Frame) {
        EXPECT_TRUE(MessageDifferencer::Equals(msgs[count % msgs.size()], out));
        ++count;
      }
    }
    EXPECT_EQ(count, 2 * msgs.size());
  }
}

TEST(Frame, TwoFramesInOneFeed) {
  Envelope a, b;
  a.mutable_ping()->set_nonce(1);
  b.mutable_pong()->set_nonce(2);
  std::string s = encode_frame(a) + encode_frame(b);
  FrameDecoder d;
  d.feed(s.data(), s.size());
  Envelope out;
  ASSERT_EQ(d.next(out), DecodeStatus::Frame);
  ASSERT_TRUE(out.has_ping());
  EXPECT_EQ(out.ping().nonce(), 1u);
  ASSERT_EQ(d.next(out), DecodeStatus::Frame);
  ASSERT_TRUE(out.has_pong());
  EXPECT_EQ(out.pong().nonce(), 2u);
  EXPECT_EQ(d.next(out), DecodeStatus::NeedMore);
}

TEST(Frame, OversizedLengthIsTooLargeAndStaysBroken) {
  FrameDecoder d(1024);
  std::string s = le32(1025);
  d.feed(s.data(), s.size());
  Envelope out;
  EXPECT_EQ(d.next(out), DecodeStatus::TooLarge);
  EXPECT_NE(d.error().find("1025"), std::string::npos) << d.error();
  EXPECT_NE(d.error().find("1024"), std::string::npos) << d.error();
  // The stream is unusable: even a valid frame afterwards is not decoded.
  std::string ok = encode_frame(make_bye("x"));
  d.feed(ok.data(), ok.size());
  EXPECT_EQ(d.next(out), DecodeStatus::TooLarge);
  EXPECT_EQ(d.buffered(), 0u);
}

TEST(Frame, TooLargeIsReportedFromTheHeaderAlone) {
  // The decoder must not wait for (or buffer) 4 GiB before refusing.
  FrameDecoder d;
  std::string s = le32(0xFFFFFFFFu);
  d.feed(s.data(), s.size());
  Envelope out;
  EXPECT_EQ(d.next(out), DecodeStatus::TooLarge);
  FrameDecoder exact(kDefaultMaxFrame);
  s = le32(static_cast<std::uint32_t>(kDefaultMaxFrame + 1));
  exact.feed(s.data(), s.size());
  EXPECT_EQ(exact.next(out), DecodeStatus::TooLarge);
}

TEST(Frame, FrameAtTheCapIsAccepted) {
  Envelope e;
  e.mutable_scene_chunk()->set_data(std::string(1000, 'z'));
  const std::size_t size = e.ByteSizeLong();
  std::string frame = encode_frame(e, size);
  FrameDecoder d(size);
  d.feed(frame.data(), frame.size());
  Envelope out;
  EXPECT_EQ(d.next(out), DecodeStatus::Frame) << d.error();
  EXPECT_THROW(encode_frame(e, size - 1), irradcast::Error);
}

TEST(Frame, GarbagePayloadIsMalformed) {
  // 0xFF... is not a valid protobuf tag/varint sequence.
  std::string payload(16, '\xff');
  std::string s = le32(static_cast<std::uint32_t>(payload.size())) + payload;
  FrameDecoder d;
  d.feed(s.data(), s.size());
  Envelope out;
  EXPECT_EQ(d.next(out), DecodeStatus::Malformed);
  EXPECT_FALSE(d.error().empty());
  EXPECT_EQ(d.next(out), DecodeStatus::Malformed);
}

TEST(Frame, TruncatedMessageInsideFrameIsMalformed) {
  // A complete frame whose payload is a cut-off Envelope (a length-delimited field running past
  // the end of the frame).
  std::string full = encode_frame(make_error(BAD_REQUEST, "a message of some length"));
  std::string payload = full.substr(4, full.size() - 4 - 5);
  std::string s = le32(static_cast<std::uint32_t>(payload.size())) + payload;
  FrameDecoder d;
  d.feed(s.data(), s.size());
  Envelope out;
  EXPECT_EQ(d.next(out), DecodeStatus::Malformed);
}

TEST(Frame, TruncatedStreamNeedsMore) {
  std::string frame = encode_frame(make_error(INTERNAL, "boom"));
  for (std::size_t cut = 0; cut < frame.size(); ++cut) {
    FrameDecoder d;
    d.feed(frame.data(), cut);
    Envelope out;
    EXPECT_EQ(d.next(out), DecodeStatus::NeedMore) << cut;
    EXPECT_EQ(d.buffered(), cut);
  }
}

TEST(Frame, UnknownMessageTypeDecodesWithNoMessageSet) {
  // A newer peer's message: oneof field 100, length-delimited, 3 bytes. Tag = (100 << 3) | 2.
  std::string payload;
  payload += static_cast<char>(0xA2);  // varint 802 = 0x322 -> 0xA2 0x06
  payload += static_cast<char>(0x06);
  payload += static_cast<char>(3);
  payload += "abc";
  std::string s = le32(static_cast<std::uint32_t>(payload.size())) + payload;
  Envelope ping;
  ping.mutable_ping()->set_nonce(5);
  s += encode_frame(ping);
  FrameDecoder d;
  d.feed(s.data(), s.size());
  Envelope out;
  ASSERT_EQ(d.next(out), DecodeStatus::Frame) << d.error();
  EXPECT_EQ(out.msg_case(), Envelope::MSG_NOT_SET);
  EXPECT_STREQ(message_name(out), "unknown");
  // The stream stays usable.
  ASSERT_EQ(d.next(out), DecodeStatus::Frame);
  EXPECT_EQ(out.ping().nonce(), 5u);
}

TEST(Frame, EmptyFrameIsAnEnvelopeWithNoMessage) {
  std::string s = le32(0);
  FrameDecoder d;
  d.feed(s.data(), s.size());
  Envelope out;
  out.mutable_ping()->set_nonce(1);  // must be cleared by next()
  ASSERT_EQ(d.next(out), DecodeStatus::Frame);
  EXPECT_EQ(out.msg_case(), Envelope::MSG_NOT_SET);
  EXPECT_EQ(encode_frame(Envelope()), s);
}

TEST(Frame, RandomBytesNeverCrash) {
  std::mt19937 rng(1234);
  int frames = 0, broken = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    std::string s(rng() % 64, '\0');
    for (char& c : s) c = static_cast<char>(rng());
    if (s.size() >= 4 && trial % 2 == 0) {  // a plausible length, so payloads get parsed
      std::uint32_t len = static_cast<std::uint32_t>(rng() % (s.size() - 3));
      std::memcpy(s.data(), le32(len).data(), 4);
    }
    FrameDecoder d(256);
    d.feed(s.data(), s.size());
    Envelope out;
    for (int k = 0; k < 64; ++k) {
      DecodeStatus st = d.next(out);
      if (st == DecodeStatus::Frame) {
        ++frames;
        continue;
      }
      if (st != DecodeStatus::NeedMore) {
        ++broken;
        EXPECT_FALSE(d.error().empty());
      }
      break;
    }
  }
  EXPECT_GT(frames, 0);
  EXPECT_GT(broken, 0);
}

TEST(Frame, MakeErrorSetsCodeAndMessage) {
  Envelope e = make_error(FRAME_TOO_LARGE, "too big");
  ASSERT_TRUE(e.has_error());
  EXPECT_EQ(e.error().code(), FRAME_TOO_LARGE);
  EXPECT_EQ(e.error().message(), "too big");
  EXPECT_STREQ(message_name(e), "error");
  EXPECT_EQ(ErrorCode_Name(IDLE_TIMEOUT), "IDLE_TIMEOUT");
  // The numbering is part of the protocol.
  EXPECT_EQ(ERROR_UNSPECIFIED, 0);
  EXPECT_EQ(BAD_FRAME, 1);
  EXPECT_EQ(INTERNAL, 8);
  EXPECT_EQ(REFUSED, 10);
  EXPECT_EQ(TILE_RGB9E5_ZSTD, 0);
  EXPECT_EQ(TILE_HALF_ZSTD, 1);
  EXPECT_EQ(TILE_RGB9E5_DELTA_ZSTD, 2);
}

TEST(Frame, ConsumedBytesAreReleased) {
  // A long-lived connection must not accumulate the bytes of frames already decoded.
  Envelope e;
  e.mutable_scene_chunk()->set_data(std::string(10000, 'q'));
  std::string frame = encode_frame(e);
  FrameDecoder d;
  Envelope out;
  for (int i = 0; i < 200; ++i) {
    d.feed(frame.data(), frame.size() / 2);
    EXPECT_EQ(d.next(out), DecodeStatus::NeedMore);
    d.feed(frame.data() + frame.size() / 2, frame.size() - frame.size() / 2);
    ASSERT_EQ(d.next(out), DecodeStatus::Frame);
    EXPECT_EQ(d.buffered(), 0u);
  }
}

}  // namespace irradcast::test_frame

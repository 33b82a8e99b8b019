// wire::FrameChannel without sockets: the protocol port's channel passes bytes and frames through
// as they are; the web port's answers HTTP, upgrades, turns each binary message into one frame
// (its length prepended) and each frame into one message, refuses a message above the cap and a
// text message, holds the bytes of an incomplete message, and ends with one close frame.
#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <vector>

#include "irradcast/wire/frame.h"
#include "irradcast/wire/frame_channel.h"
#include "irradcast/wire/websocket.h"

namespace irradcast::test_frame_channel {
namespace {

using wire::FrameChannel;
using State = FrameChannel::State;

std::string concat(const std::vector<asio::const_buffer>& buffers) {
  std::string out;
  for (const auto& b : buffers) out.append(static_cast<const char*>(b.data()), b.size());
  return out;
}

wire::Envelope ping(std::uint64_t nonce) {
  wire::Envelope e;
  e.mutable_ping()->set_nonce(nonce);
  return e;
}

TEST(FrameChannel, ThePlainChannelPassesBytesAndFramesAsTheyAre) {
  auto ch = FrameChannel::plain();
  const std::string a = wire::encode_frame(ping(1)), b = wire::encode_frame(ping(2));
  std::string got;
  ch->receive(a.data(), 3, [&](const char* d, std::size_t n) { got.append(d, n); });
  ch->receive(a.data() + 3, a.size() - 3, [&](const char* d, std::size_t n) { got.append(d, n); });
  EXPECT_EQ(got, a);
  EXPECT_EQ(ch->state(), State::Open);
  EXPECT_TRUE(ch->carries_frames());
  EXPECT_FALSE(ch->upgraded());
  EXPECT_EQ(ch->held_bytes(), 0u);
  EXPECT_EQ(ch->output_size(), 0u);
  EXPECT_GT(ch->frames_per_write(), 64u);
  EXPECT_EQ(concat(ch->frame_buffers({a, b})), a + b);
  EXPECT_EQ(ch->closing_bytes(), "");
}

struct WebPort {
  std::unique_ptr<FrameChannel> ch;
  std::string frames;  // what reached the protocol
  wire::WsClientConnection client{"127.0.0.1", "/ws"};

  explicit WebPort(std::size_t cap = 1024) {
    wire::WsServerConnection::Handlers h;
    h.http = [](const std::string&, const std::string& target) {
      return wire::HttpReply{200, {{"Content-Type", "text/plain"}}, "page " + target};
    };
    ch = FrameChannel::websocket(std::move(h), cap);
  }
  void feed(const std::string& bytes) {
    ch->receive(bytes.data(), bytes.size(),
                [this](const char* d, std::size_t n) { frames.append(d, n); });
  }
  // The client's bytes to the channel and the channel's to the client.
  void exchange() {
    if (client.has_output()) feed(client.take_output());
    if (ch->output_size() > 0) {
      const std::string out = ch->take_output();
      client.receive(out.data(), out.size());
    }
  }
  void upgrade() {
    exchange();
    ASSERT_TRUE(ch->upgraded());
    ASSERT_TRUE(client.is_open());
  }
};

TEST(FrameChannel, TheWebPortAnswersAPlainRequestAndFinishes) {
  WebPort w;
  w.feed("GET /index.html HTTP/1.1\r\nHost: x\r\n\r\n");
  EXPECT_EQ(w.ch->state(), State::HttpAnswered);
  EXPECT_TRUE(w.ch->finished());
  EXPECT_FALSE(w.ch->carries_frames());
  const std::string reply = w.ch->take_output();
  EXPECT_NE(reply.find("200"), std::string::npos);
  EXPECT_NE(reply.find("page /index.html"), std::string::npos);
  EXPECT_EQ(w.frames, "");
  EXPECT_EQ(w.ch->closing_bytes(), "");  // no WebSocket: nothing to close
}

TEST(FrameChannel, TheWebPortRefusesBytesThatAreNotHttp) {
  WebPort w;
  w.feed(std::string("\x16\x03\x01\x02\x00garbage\r\n\r\n", 16));
  EXPECT_EQ(w.ch->state(), State::Refused);
  EXPECT_TRUE(w.ch->finished());
  EXPECT_FALSE(w.ch->state_message().empty());
}

TEST(FrameChannel, MessagesBecomeFramesAndFramesMessagesBothWays) {
  WebPort w;
  EXPECT_FALSE(w.ch->carries_frames());  // still HTTP
  w.upgrade();
  EXPECT_TRUE(w.ch->carries_frames());
  EXPECT_EQ(w.ch->frames_per_write(), 1u);

  // A message is a frame without its length: the protocol gets the frame whole.
  const std::string f = wire::encode_frame(ping(42));
  w.client.send(std::string_view(f).substr(wire::kFrameHeaderBytes));
  w.exchange();
  EXPECT_EQ(w.frames, f);

  // A frame out is one binary message of its payload.
  const std::string g = wire::encode_frame(ping(43));
  const std::string bytes = concat(w.ch->frame_buffers({g}));
  w.client.receive(bytes.data(), bytes.size());
  const auto messages = w.client.take_messages();
  ASSERT_EQ(messages.size(), 1u);
  EXPECT_TRUE(messages[0].first);
  EXPECT_EQ(messages[0].second, g.substr(wire::kFrameHeaderBytes));
}

TEST(FrameChannel, AnIncompleteMessageIsHeldAndCounted) {
  WebPort w;
  w.upgrade();
  const std::string payload(300, 'x');
  w.client.send(payload);
  const std::string wire_bytes = w.client.take_output();
  w.feed(wire_bytes.substr(0, wire_bytes.size() - 100));
  EXPECT_EQ(w.ch->held_bytes(), 200u);
  EXPECT_EQ(w.frames, "");
}

TEST(FrameChannel, AMessageAboveTheCapOrATextMessageIsRefusedAndTheErrorStillGoesOut) {
  for (const bool text : {false, true}) {
    WebPort w(text ? 1024 : 64);
    w.upgrade();
    w.client.send(std::string(text ? 10 : 200, 'x'), /*binary=*/!text);
    w.exchange();
    EXPECT_EQ(w.ch->state(), text ? State::BadMessage : State::TooLarge);
    EXPECT_FALSE(w.ch->finished());
    EXPECT_TRUE(w.ch->carries_frames());  // the protocol's Error goes out, then the close frame
    EXPECT_EQ(w.frames, "");
    const std::string close = w.ch->closing_bytes();
    ASSERT_FALSE(close.empty());
    EXPECT_EQ(w.ch->closing_bytes(), "");  // once
    w.client.receive(close.data(), close.size());
    EXPECT_EQ(w.client.remote_close_code(),
              static_cast<std::uint16_t>(text ? wire::WsCloseCode::ProtocolError
                                              : wire::WsCloseCode::TooBig));
  }
}

TEST(FrameChannel, AMessageRefusedInTheSameBytesAsTheUpgradeStillGetsTheErrorAndCloseFrame) {
  WebPort w(64);
  // The upgrade request and, in the same read, a binary frame of 200 bytes (masked with a zero
  // key, as a client must mask).
  std::string bytes = w.client.take_output();
  bytes += std::string("\x82\xfe\x00\xc8\x00\x00\x00\x00", 8) + std::string(200, 'x');
  w.feed(bytes);
  EXPECT_TRUE(w.ch->upgraded());
  EXPECT_EQ(w.ch->state(), State::TooLarge);
  EXPECT_TRUE(w.ch->carries_frames());
  EXPECT_GT(w.ch->output_size(), 0u);  // the 101 reply
  const std::string reply = w.ch->take_output();
  w.client.receive(reply.data(), reply.size());
  ASSERT_TRUE(w.client.is_open());
  const std::string close = w.ch->closing_bytes();
  ASSERT_FALSE(close.empty());
  w.client.receive(close.data(), close.size());
  EXPECT_EQ(w.client.remote_close_code(), static_cast<std::uint16_t>(wire::WsCloseCode::TooBig));
}

TEST(FrameChannel, TheCapRisesAfterWelcome) {
  WebPort w(64);
  w.upgrade();
  w.ch->set_max_frame(4096);
  w.client.send(std::string(1000, 'y'));
  w.exchange();
  EXPECT_EQ(w.ch->state(), State::Open);
  EXPECT_EQ(w.frames.size(), 1000u + wire::kFrameHeaderBytes);
}

TEST(FrameChannel, AfterItsCloseFrameTheChannelIgnoresThePeer) {
  WebPort w;
  w.upgrade();
  ASSERT_FALSE(w.ch->closing_bytes().empty());
  w.client.send("late");
  w.exchange();
  EXPECT_EQ(w.frames, "");
  EXPECT_EQ(w.ch->output_size(), 0u);  // no second close frame, no pong
}

TEST(FrameChannel, ThePeersCloseFinishesTheChannel) {
  WebPort w;
  w.upgrade();
  w.client.close(wire::WsCloseCode::Normal, "bye");
  w.exchange();
  EXPECT_EQ(w.ch->state(), State::PeerClosed);
  EXPECT_TRUE(w.ch->finished());
  EXPECT_FALSE(w.ch->carries_frames());
  EXPECT_EQ(w.ch->closing_bytes(), "");
}

}  // namespace
}  // namespace irradcast::test_frame_channel

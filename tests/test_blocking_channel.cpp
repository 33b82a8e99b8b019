// wire::BlockingChannel against a scripted peer on loopback: frames split across writes arrive
// whole, a read past its deadline returns false and keeps the bytes it got, the end of the
// connection and a refused connect are ChannelLost, a bad frame is an Error.
#include <gtest/gtest.h>

#include <asio.hpp>

#include <chrono>
#include <functional>
#include <string>
#include <thread>

#include "irradcast/wire/blocking_channel.h"
#include "irradcast/wire/frame.h"

namespace irradcast::test_blocking_channel {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

// One connection accepted on 127.0.0.1 and handed to `script` on its own thread.
class Peer {
 public:
  explicit Peer(std::function<void(asio::ip::tcp::socket&)> script)
      : acceptor_(io_, {asio::ip::make_address("127.0.0.1"), 0}) {
    thread_ = std::thread([this, script = std::move(script)] {
      asio::ip::tcp::socket s(io_);
      acceptor_.accept(s);
      script(s);
    });
  }
  ~Peer() { thread_.join(); }
  std::uint16_t port() const { return acceptor_.local_endpoint().port(); }

 private:
  asio::io_context io_;
  asio::ip::tcp::acceptor acceptor_;
  std::thread thread_;
};

wire::Envelope ping(std::uint64_t nonce) {
  wire::Envelope e;
  e.mutable_ping()->set_nonce(nonce);
  return e;
}

TEST(BlockingChannel, FramesSplitAcrossWritesArriveWholeAndADeadlineKeepsTheBytesBegun) {
  const std::string a = wire::encode_frame(ping(7)), b = wire::encode_frame(ping(8));
  Peer peer([&](asio::ip::tcp::socket& s) {
    asio::write(s, asio::buffer(a.data(), 2));  // a frame begun ...
    std::this_thread::sleep_for(300ms);
    asio::write(s, asio::buffer(a.data() + 2, a.size() - 2));  // ... and finished
    asio::write(s, asio::buffer(b));
    char c;
    std::error_code ec;
    s.read_some(asio::buffer(&c, 1), ec);  // until the channel closes
  });
  wire::BlockingChannel ch("127.0.0.1", peer.port(), nullptr, 2000ms);
  wire::Envelope e;
  EXPECT_FALSE(ch.read(e, Clock::now() + 100ms));  // only 2 bytes by then
  ASSERT_TRUE(ch.read(e, Clock::now() + 5s));
  EXPECT_EQ(e.ping().nonce(), 7u);
  ASSERT_TRUE(ch.read(e, Clock::now() + 5s));
  EXPECT_EQ(e.ping().nonce(), 8u);
  EXPECT_EQ(ch.bytes_received(), a.size() + b.size());
  ch.close();
}

TEST(BlockingChannel, TheEndOfTheConnectionIsChannelLostAndABadFrameAnError) {
  {
    Peer peer([](asio::ip::tcp::socket& s) { s.close(); });
    wire::BlockingChannel ch("127.0.0.1", peer.port(), nullptr, 2000ms);
    wire::Envelope e;
    EXPECT_THROW(ch.read(e, Clock::now() + 5s), wire::ChannelLost);
  }
  {
    Peer peer([](asio::ip::tcp::socket& s) {
      const std::string junk = "\xff\xff\xff\x7f not a frame";  // a length past the cap
      asio::write(s, asio::buffer(junk));
      char c;
      std::error_code ec;
      s.read_some(asio::buffer(&c, 1), ec);
    });
    wire::BlockingChannel ch("127.0.0.1", peer.port(), nullptr, 2000ms);
    wire::Envelope e;
    try {
      ch.read(e, Clock::now() + 5s);
      ADD_FAILURE() << "a bad frame was read";
    } catch (const wire::ChannelLost& lost) {
      ADD_FAILURE() << "a bad frame is not a lost connection: " << lost.what();
    } catch (const Error& err) {
      EXPECT_NE(std::string(err.what()).find("bad frame"), std::string::npos) << err.what();
    }
  }
}

TEST(BlockingChannel, ARefusedConnectIsChannelLost) {
  std::uint16_t port = 0;
  {
    asio::io_context io;
    asio::ip::tcp::acceptor a(io, {asio::ip::make_address("127.0.0.1"), 0});
    port = a.local_endpoint().port();
  }  // closed: nothing listens there now
  EXPECT_THROW(wire::BlockingChannel("127.0.0.1", port, nullptr, 2000ms), wire::ChannelLost);
}

}  // namespace
}  // namespace irradcast::test_blocking_channel

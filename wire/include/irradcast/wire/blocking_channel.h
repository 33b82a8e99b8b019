// A client's blocking frame channel: one connection to a server (plain TCP, or TLS with the
// server's certificate checked), whole frames out and in, each read bounded by a deadline.
// irradcast-view's ViewClient and irradcast-edit talk to the server through it; the server's
// sessions (server/service/src/session.cpp) and irradcast-load's users read the same frames
// asynchronously.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <system_error>

#include "irradcast/common/error.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/transport.h"

namespace irradcast::wire {

// The connection could not be made, or it ended (EOF, reset, a write that failed): trying again,
// or another server, may do.
struct ChannelLost : irradcast::Error {
  using irradcast::Error::Error;
};

// Resolves host, connects `stream` (made on io) and, with TLS, completes the handshake, all
// within `timeout` (a server that accepts but never answers the handshake cannot hang the
// client). On failure: ec, and `what` says it in one line ("connect: Connection refused",
// "TLS: certificate verify failed", ...).
void connect_stream(asio::io_context& io, Stream& stream, const std::string& host,
                    std::uint16_t port, std::chrono::milliseconds timeout, std::error_code& ec,
                    std::string& what);

class BlockingChannel {
 public:
  using Clock = std::chrono::steady_clock;

  // Connects within `timeout`; `tls` null: plain TCP. Throws ChannelLost when no connection is
  // made, irradcast::Error when TLS refuses it (a certificate not trusted, a server without
  // TLS: trying again will not change that).
  BlockingChannel(const std::string& host, std::uint16_t port,
                  std::shared_ptr<asio::ssl::context> tls, std::chrono::milliseconds timeout);
  ~BlockingChannel();
  BlockingChannel(const BlockingChannel&) = delete;
  BlockingChannel& operator=(const BlockingChannel&) = delete;

  // Writes one frame; throws ChannelLost.
  void send(const Envelope& e);
  // The next frame before `deadline`: true with `out`, false at the deadline (bytes of a frame
  // begun stay for the next call). Throws ChannelLost when the connection ends, irradcast::Error
  // for a frame that is not one.
  bool read(Envelope& out, Clock::time_point deadline);
  // Closes the connection (no Bye: the caller sends one first if it wants to).
  void close();
  bool open() { return stream_.socket().is_open(); }
  std::uint64_t bytes_received() const { return bytes_received_; }
  Clock::time_point last_send() const { return last_send_; }

 private:
  asio::io_context io_;
  std::shared_ptr<asio::ssl::context> tls_;
  Stream stream_;
  FrameDecoder decoder_;
  std::array<char, 64 * 1024> buffer_{};
  std::uint64_t bytes_received_ = 0;
  Clock::time_point last_send_ = Clock::now();
};

}  // namespace irradcast::wire

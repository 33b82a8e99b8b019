// A server connection's bytes to the protocol's frames and back, without I/O. On the protocol
// port the frames are the connection's bytes as they are (TCP or TLS: transport.h); on the web
// port an HTTP request comes first (the page's files, or the upgrade to a WebSocket at /ws) and
// then every frame is one binary WebSocket message, without its 4-byte length (websocket.h).
// The server's Session reads into receive() and writes what the channel hands out the same way
// for both, so it has one read path and one write path; the channel is chosen once, when the
// connection is accepted. A client's blocking counterpart is blocking_channel.h.
#pragma once

// A standard header before asio (see transport.h).
#include <cstddef>

#include <asio/buffer.hpp>

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "irradcast/wire/websocket.h"

namespace irradcast::wire {

class FrameChannel {
 public:
  // Where the connection stands, after the bytes received so far.
  enum class State {
    Open,          // going on (the web port: the HTTP request may still be incomplete)
    HttpAnswered,  // a plain HTTP request was answered: write the output, then close
    Refused,       // not valid HTTP, or an upgrade refused: write the output (a 4xx), then close
    PeerClosed,    // the peer closed its WebSocket
    TooLarge,      // a message above the largest frame: the protocol's FRAME_TOO_LARGE
    BadMessage,    // a malformed WebSocket frame or a text message: the protocol's BAD_FRAME
  };
  // Bytes of the protocol's frames, each with its 4-byte length, as they arrive (in pieces).
  using FrameBytes = std::function<void(const char* data, std::size_t n)>;

  // The protocol port: frames as they are.
  static std::unique_ptr<FrameChannel> plain();
  // The web port: `handlers` answer HTTP and screen requests (their `binary` is the channel's
  // own); `max_message` caps a message until set_max_frame (the protocol's Hello cap).
  static std::unique_ptr<FrameChannel> websocket(WsServerConnection::Handlers handlers,
                                                 std::size_t max_message);

  virtual ~FrameChannel() = default;

  // Bytes read from the peer. The protocol's bytes go to `to_protocol`; nothing goes anywhere
  // once the channel is closing (closing_bytes() taken) or its state is not Open.
  virtual void receive(const char* data, std::size_t n, const FrameBytes& to_protocol) = 0;
  virtual State state() const = 0;
  // One line on why the state is not Open ("" while Open).
  virtual const std::string& state_message() const = 0;
  // The state ends the connection once the output is written (HttpAnswered, Refused, PeerClosed).
  bool finished() const {
    const State s = state();
    return s == State::HttpAnswered || s == State::Refused || s == State::PeerClosed;
  }
  // Frames may go out now (plain: always; the web port: from the upgrade until the peer closes,
  // so that the protocol's Error reaches the peer after a message the channel refused).
  virtual bool carries_frames() const = 0;
  // The peer upgraded to a WebSocket at some point (counted once by the server).
  virtual bool upgraded() const = 0;

  // The channel's own bytes, written before any frame: an HTTP reply or the handshake, pongs,
  // the answer to the peer's close. Taken.
  virtual std::size_t output_size() const = 0;
  virtual std::string take_output() = 0;
  // Payload of an incomplete message the channel holds (counted in the server's budget for
  // incomplete frames; plain: 0, the protocol holds those bytes itself).
  virtual std::size_t held_bytes() const = 0;
  // After Welcome: the largest frame from now on (the web port's message cap).
  virtual void set_max_frame(std::size_t bytes) = 0;
  // The protocol closes the connection: the bytes that end the channel first (a WebSocket close
  // frame with the code for the state), once; "" when there are none (plain, or already taken).
  virtual std::string closing_bytes() = 0;

  // How many frames one write may carry (plain: any, concatenated; the web port: one, as one
  // message behind its header).
  virtual std::size_t frames_per_write() const = 0;
  // The buffers that write `frames` (each a whole frame with its 4-byte length, at most
  // frames_per_write()); they refer to the frames and to the channel, which must stay alive and
  // unchanged until the write is done.
  virtual std::vector<asio::const_buffer> frame_buffers(
      const std::vector<std::string_view>& frames) = 0;
};

}  // namespace irradcast::wire

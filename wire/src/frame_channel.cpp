// The protocol port's and the web port's frame channels (frame_channel.h).
#include "irradcast/wire/frame_channel.h"

#include <cstdint>
#include <stdexcept>
#include <utility>

#include "irradcast/wire/frame.h"

namespace irradcast::wire {

namespace {

// TCP or TLS: the bytes are the frames.
class PlainChannel final : public FrameChannel {
 public:
  void receive(const char* data, std::size_t n, const FrameBytes& to_protocol) override {
    to_protocol(data, n);
  }
  State state() const override { return State::Open; }
  const std::string& state_message() const override { return none_; }
  bool carries_frames() const override { return true; }
  bool upgraded() const override { return false; }
  std::size_t output_size() const override { return 0; }
  std::string take_output() override { return {}; }
  std::size_t held_bytes() const override { return 0; }
  void set_max_frame(std::size_t) override {}
  std::string closing_bytes() override { return {}; }
  std::size_t frames_per_write() const override { return static_cast<std::size_t>(-1); }
  std::vector<asio::const_buffer> frame_buffers(
      const std::vector<std::string_view>& frames) override {
    std::vector<asio::const_buffer> buffers;
    buffers.reserve(frames.size());
    for (const std::string_view f : frames) buffers.push_back(asio::buffer(f.data(), f.size()));
    return buffers;
  }

 private:
  std::string none_;
};

// HTTP, then one binary WebSocket message per frame.
class WebSocketChannel final : public FrameChannel {
 public:
  WebSocketChannel(WsServerConnection::Handlers handlers, std::size_t max_message)
      : ws_(with_binary(std::move(handlers)), max_message) {}

  void receive(const char* data, std::size_t n, const FrameBytes& to_protocol) override {
    // After our close frame the closing handshake is over for us: what the peer sends (its
    // close reply) is not handed to the WebSocket layer, which would answer a second, empty
    // close frame (the peer would read status 1005 instead of ours).
    if (close_sent_) return;
    to_protocol_ = &to_protocol;
    ws_.receive(data, n);  // complete messages reach the protocol through on_binary
    to_protocol_ = nullptr;
  }
  State state() const override {
    using End = WsServerConnection::End;
    switch (ws_.end()) {
      case End::None:
        return State::Open;
      case End::HttpDone:
        return State::HttpAnswered;
      case End::Handshake:
        return State::Refused;
      case End::Closed:
        return State::PeerClosed;
      case End::TooLarge:
        return State::TooLarge;
      case End::BadMessage:
        return State::BadMessage;
    }
    return State::BadMessage;
  }
  const std::string& state_message() const override { return ws_.end_message(); }
  // Once upgraded, frames go out until the peer closes: after a message refused (TooLarge,
  // BadMessage) the protocol's Error still goes out, then the close frame.
  bool carries_frames() const override { return ws_.upgraded() && !finished(); }
  bool upgraded() const override { return ws_.upgraded(); }
  std::size_t output_size() const override { return ws_.output_size(); }
  std::string take_output() override { return ws_.take_output(); }
  std::size_t held_bytes() const override { return ws_.partial_message_bytes(); }
  void set_max_frame(std::size_t bytes) override { ws_.set_max_message(bytes); }
  std::string closing_bytes() override {
    if (close_sent_ || !carries_frames()) return {};
    close_sent_ = true;
    return WsServerConnection::close_frame(ws_.close_code(), "irradcast: see the Error message");
  }
  std::size_t frames_per_write() const override { return 1; }
  std::vector<asio::const_buffer> frame_buffers(
      const std::vector<std::string_view>& frames) override {
    if (frames.size() != 1)
      throw std::logic_error("a WebSocket write carries one frame (frames_per_write)");
    // The payload after the 4-byte length, behind the message's header: no copy of the frame.
    const std::string_view payload = frames.front().substr(kFrameHeaderBytes);
    header_ = WsServerConnection::binary_frame_header(payload.size());
    return {asio::buffer(header_), asio::buffer(payload.data(), payload.size())};
  }

 private:
  WsServerConnection::Handlers with_binary(WsServerConnection::Handlers h) {
    h.binary = [this](std::string payload) { on_binary(payload); };
    return h;
  }
  // A message is a frame without its length: the protocol gets the length, then the payload.
  void on_binary(const std::string& payload) {
    const auto n = static_cast<std::uint32_t>(payload.size());
    const char length[kFrameHeaderBytes] = {
        static_cast<char>(n & 0xff), static_cast<char>((n >> 8) & 0xff),
        static_cast<char>((n >> 16) & 0xff), static_cast<char>((n >> 24) & 0xff)};
    (*to_protocol_)(length, sizeof length);
    (*to_protocol_)(payload.data(), payload.size());
  }

  WsServerConnection ws_;
  const FrameBytes* to_protocol_ = nullptr;  // during receive()
  std::string header_;                       // the message header of the write in flight
  bool close_sent_ = false;
};

}  // namespace

std::unique_ptr<FrameChannel> FrameChannel::plain() {
  return std::make_unique<PlainChannel>();
}

std::unique_ptr<FrameChannel> FrameChannel::websocket(WsServerConnection::Handlers handlers,
                                                      std::size_t max_message) {
  return std::make_unique<WebSocketChannel>(std::move(handlers), max_message);
}

}  // namespace irradcast::wire

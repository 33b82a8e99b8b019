// HTTP and WebSocket (RFC 6455) on one connection, without I/O: the caller feeds the bytes it
// read and writes the bytes handed back, so the same TCP or TLS stream (transport.h), timers and
// limits serve a WebSocket as a plain protocol connection. The WebSocket protocol itself is
// websocketpp's (its I/O-agnostic iostream transport); this wraps it behind plain std types.
// websocketpp 0.8.2 does not compile as C++20 (template-ids on constructors), so its one
// translation unit (src/websocket/websocket.cpp) is built as C++17 in its own target,
// irradcast_websocket; nothing of websocketpp leaks through this header.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace irradcast::wire {

// The answer to a plain HTTP request (one that is not a WebSocket upgrade).
struct HttpReply {
  int status = 404;
  std::vector<std::pair<std::string, std::string>> headers;  // Content-Length is added
  std::string body;
};

// WebSocket close codes (RFC 6455 7.4.1).
enum class WsCloseCode : std::uint16_t {
  Normal = 1000,
  GoingAway = 1001,
  ProtocolError = 1002,
  UnsupportedData = 1003,  // a text message where binary ones are expected
  PolicyViolation = 1008,
  TooBig = 1009,
};

// The server side of one connection: an HTTP request, then either its reply or the upgrade to a
// WebSocket at `ws_path` and binary messages both ways. Not thread-safe (one strand).
class WsServerConnection {
 public:
  // Why the connection is over from the WebSocket side (end()).
  enum class End {
    None,        // going on
    HttpDone,    // a plain HTTP request was answered (the reply is in the output)
    Handshake,   // the request was not valid HTTP or not a valid upgrade (a 4xx reply is out)
    Closed,      // the peer closed the WebSocket (close frame or EOF)
    TooLarge,    // a message above the cap
    BadMessage,  // a malformed WebSocket frame, or a text message
  };
  struct Handlers {
    std::string ws_path = "/ws";  // the only target that upgrades (others: 404)
    // Plain HTTP requests; GET requests to ws_path that do not upgrade get 426 without asking.
    std::function<HttpReply(const std::string& method, const std::string& target)> http;
    // One complete binary message.
    std::function<void(std::string payload)> binary;
    // Whether an upgrade that carries an Origin header (browsers send one) may open, given the
    // request's Host header; unset: any. A refused upgrade gets 403 and ends as Handshake.
    std::function<bool(const std::string& origin, const std::string& host)> allow_origin;
    // Every request first, with a look-up of its headers (by name, any case; repeated headers
    // joined by ", "): a reply refuses it (a plain request and an upgrade alike; the upgrade
    // ends as Handshake). Unset: none is refused here.
    std::function<std::optional<HttpReply>(
        const std::function<std::string(const std::string& name)>& header)>
        request;
  };

  WsServerConnection(Handlers handlers, std::size_t max_message);
  ~WsServerConnection();
  WsServerConnection(const WsServerConnection&) = delete;
  WsServerConnection& operator=(const WsServerConnection&) = delete;

  // Bytes read from the peer; runs the handlers and appends what must be written to the output.
  // Ignored once end() is not None.
  void receive(const char* data, std::size_t n);
  // The largest message accepted from now on (a larger one ends the connection: TooLarge).
  void set_max_message(std::size_t bytes);

  bool is_open() const;  // the WebSocket is established and has not ended
  // The upgrade succeeded at some point (true from then on, also after the end): a message
  // refused in the same bytes as the upgrade ends it before is_open() was ever seen true.
  bool upgraded() const;
  // Payload bytes of the message being received that the library holds (frames without FIN so
  // far, and the received part of the current frame): what the peer makes the server hold for an
  // incomplete message, counted in the server's budget of incomplete frames.
  std::size_t partial_message_bytes() const;
  End end() const;
  const std::string& end_message() const;  // one line on why, for End != None
  // The code a close frame should carry for the end so far (Normal when None).
  WsCloseCode close_code() const;

  // Bytes the library wants written (handshake or HTTP reply, pongs, its close frames); taken.
  bool has_output() const;
  std::size_t output_size() const;
  std::string take_output();

  // One unmasked binary frame carrying `payload` (the server's messages are never fragmented).
  static std::string binary_frame(std::string_view payload);
  // The header of such a frame alone (the payload follows it unchanged: no copy).
  static std::string binary_frame_header(std::size_t payload_size);
  // A close frame (the reason is cut to the 123 bytes a control frame allows).
  static std::string close_frame(WsCloseCode code, std::string_view reason);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The client side, for tests and tools: the upgrade request for `host` and `target`, then
// binary messages both ways (masked, as RFC 6455 requires of clients).
class WsClientConnection {
 public:
  // `headers` go into the upgrade request besides the WebSocket's own.
  WsClientConnection(const std::string& host, const std::string& target,
                     std::size_t max_message = 64u << 20,
                     const std::vector<std::pair<std::string, std::string>>& headers = {});
  ~WsClientConnection();
  WsClientConnection(const WsClientConnection&) = delete;
  WsClientConnection& operator=(const WsClientConnection&) = delete;

  void receive(const char* data, std::size_t n);
  bool is_open() const;
  bool closed() const;                      // the connection ended (close frame, error, failed)
  std::uint16_t remote_close_code() const;  // 0: none received
  const std::string& error() const;         // why it failed or closed abnormally
  // Complete messages received, in order (binary: true for binary, false for text); taken.
  std::vector<std::pair<bool, std::string>> take_messages();
  // Queues a message (after is_open()); its bytes go to the output.
  void send(std::string_view payload, bool binary = true);
  void close(WsCloseCode code, const std::string& reason);
  bool has_output() const;
  std::string take_output();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace irradcast::wire

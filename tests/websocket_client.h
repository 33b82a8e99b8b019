// What the WebSocket tests share: a WebSocket client of the server's web port (websocketpp's
// client role, wire/websocket.h, over the tests' raw TCP or TLS connection) that sends and reads
// protocol Envelopes, one binary message each, or any bytes for tests that misbehave on purpose;
// and a raw HTTP exchange.
#pragma once

#include <deque>
#include <optional>
#include <string>

#include "irradcast/wire/websocket.h"
#include "service_fixture.h"

namespace irradcast::test {

struct WsConnection {
  using Clock = std::chrono::steady_clock;

  // Connects to 127.0.0.1:port and asks for a WebSocket at `target`; opened() says if it came.
  // headers: more headers in the upgrade request (X-Forwarded-For); preamble and from: as for
  // RawConnection.
  explicit WsConnection(std::uint16_t port, asio::ssl::context* tls = nullptr,
                        const std::string& target = "/ws",
                        const std::vector<std::pair<std::string, std::string>>& headers = {},
                        const std::string& preamble = {}, const std::string& from = {})
      : raw(port, tls, preamble, from),
        ws("127.0.0.1:" + std::to_string(port), target, 64u << 20, headers) {
    flush();
    const auto deadline = Clock::now() + std::chrono::seconds(5);
    while (!got_open_ && !ws.closed() && !raw.eof && Clock::now() < deadline) pump(deadline);
  }
  // The upgrade succeeded (the connection may have closed since).
  bool opened() const { return got_open_; }

  void flush() {
    if (ws.has_output()) raw.write(ws.take_output());
  }
  void send(const wire::Envelope& e) { send_message(e.SerializeAsString()); }
  void send_message(const std::string& payload, bool binary = true) {
    ws.send(payload, binary);
    flush();
  }
  // Bytes straight onto the connection (hand-made WebSocket frames).
  void write_raw(const std::string& bytes) { raw.write(bytes); }

  // One read (at most until `deadline`) into the WebSocket layer.
  void pump(Clock::time_point deadline) {
    const auto [result, n] =
        read_some_before(raw.io, raw.stream, asio::buffer(raw.buf), deadline, [&] {
          std::error_code ignored;
          raw.stream.socket().cancel(ignored);
        });
    if (result && result != asio::error::operation_aborted) raw.eof = true;
    ws.receive(raw.buf.data(), n);
    if (ws.is_open()) got_open_ = true;
    for (auto& m : ws.take_messages()) messages.push_back(std::move(m));
    flush();
  }

  // The next binary message as an Envelope; nullopt at EOF, after `limit` or for a message that
  // does not parse (text_messages counts text messages, skipped).
  std::optional<wire::Envelope> read(
      std::chrono::milliseconds limit = std::chrono::milliseconds(5000)) {
    const auto deadline = Clock::now() + limit;
    for (;;) {
      while (!messages.empty()) {
        auto [binary, payload] = std::move(messages.front());
        messages.pop_front();
        if (!binary) {
          ++text_messages;
          continue;
        }
        wire::Envelope e;
        if (!e.ParseFromString(payload)) return std::nullopt;
        return e;
      }
      if (Clock::now() > deadline || raw.eof) return std::nullopt;
      pump(deadline);
    }
  }

  // Reads until the server closes the connection (or the limit); the first Error message.
  std::optional<wire::Error> error_then_close(
      std::chrono::milliseconds limit = std::chrono::milliseconds(5000)) {
    return first_error_before_close(*this, raw.eof, limit);
  }
  // Hello, then waits for the Welcome; false without one.
  bool join(const std::string& name = "ws") { return join_session(*this, name, welcome); }

  RawConnection raw;
  wire::WsClientConnection ws;
  std::deque<std::pair<bool, std::string>> messages;
  int text_messages = 0;
  wire::Welcome welcome;
  bool got_open_ = false;
};

// Writes `request` to 127.0.0.1:port and reads until the server closes (at most 5 s).
// With `head_only`, until the end of the reply's header (an upgrade's connection stays open).
inline std::string http_exchange(std::uint16_t port, const std::string& request,
                                 asio::ssl::context* tls = nullptr, bool head_only = false) {
  RawConnection c(port, tls);
  c.write(request);
  std::string out;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!c.eof && std::chrono::steady_clock::now() < deadline &&
         !(head_only && out.find("\r\n\r\n") != std::string::npos)) {
    const auto [result, n] = read_some_before(c.io, c.stream, asio::buffer(c.buf), deadline, [&] {
      std::error_code ignored;
      c.stream.socket().cancel(ignored);
    });
    out.append(c.buf.data(), n);
    if (result) c.eof = true;
  }
  return out;
}

}  // namespace irradcast::test

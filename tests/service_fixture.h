// What the service tests share: an in-process engine host and server on loopback (their
// options), a viewer's options for that server, and a raw protocol connection (plain or TLS)
// that sends frames and reads them with a deadline, for tests that misbehave on purpose.
#pragma once

// A standard header before asio: asio's config decides between aligned_alloc and operator new
// from libstdc++'s _GLIBCXX_HAVE_ALIGNED_ALLOC, so every file must see it defined alike (else
// one file allocates handler memory with aligned_alloc and another frees it with delete).
#include <cstddef>

#include <asio.hpp>

#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include "irradcast/client/load_generator.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/transport.h"

namespace irradcast::test {

// A small engine host for the cornell box: 16-texel tiles, final after `max_updates` (0: never
// final). Quiets progress bars and logs below warnings.
inline EngineHostOptions host_options(float texels_per_scene, std::uint32_t max_updates) {
  Progress::set_enabled(false);
  log::set_level(log::Level::Warn);
  EngineHostOptions o;
  o.atlas.texels_per_scene = texels_per_scene;
  o.tiles.tile_size = 16;
  o.max_updates = max_updates;
  return o;
}
// 48 texels per scene: enough for images to compare.
inline EngineHostOptions small_host(std::uint32_t max_updates = 0) {
  return host_options(48.0f, max_updates);
}
// 32 texels per scene: the quickest host.
inline EngineHostOptions quick_host(std::uint32_t max_updates = 1) {
  return host_options(32.0f, max_updates);
}

// A port nobody listens on (bound and released by the kernel's choice).
inline std::uint16_t free_port() {
  asio::io_context io;
  asio::ip::tcp::acceptor a(io, asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  return a.local_endpoint().port();
}

// A server on 127.0.0.1, on any free port (Server::port()).
inline ServerOptions loopback(std::chrono::milliseconds idle = ServerOptions{}.idle_timeout) {
  ServerOptions o;
  o.bind = "127.0.0.1";
  o.port = 0;
  o.idle_timeout = idle;
  return o;
}

inline ViewClientOptions client_of(const Server& server, const std::string& name) {
  ViewClientOptions o;
  o.port = server.port();
  o.name = name;
  o.connect_timeout = std::chrono::milliseconds(5000);
  return o;
}

// Polls `condition` every 10 ms until it holds or `limit` passed; its last value.
template <class F>
bool eventually(F condition, std::chrono::milliseconds limit = std::chrono::milliseconds(10000)) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return condition();
}

// A SceneEdit frame of `json` (docs/EDITS.md) with `token`; `stream`: a streamed pose.
inline wire::Envelope edit_frame(const std::string& json, const std::string& token,
                                 std::uint64_t request_id = 0, bool stream = false) {
  wire::Envelope e;
  wire::to_proto(parse_edit_json(json), e.mutable_scene_edit());
  e.mutable_scene_edit()->set_token(token);
  e.mutable_scene_edit()->set_request_id(request_id);
  if (stream) e.mutable_scene_edit()->set_stream(true);
  return e;
}

// A SceneEdit frame that nudges the Cornell box's tall block, with `token`.
inline wire::Envelope nudge_edit_frame(const std::string& token, std::uint64_t request_id) {
  return edit_frame(R"({"op": "move", "node": "tall_block", "by": [0.0001, 0, 0]})", token,
                    request_id);
}

// irradcast-load's options: `users` users of the server at 127.0.0.1:`port` for `seconds`.
inline LoadOptions load_of(std::uint16_t port, int users, double seconds) {
  LoadOptions o;
  o.port = port;
  o.users = users;
  o.duration_s = seconds;
  return o;
}

inline wire::Envelope hello_frame(const std::string& name = "raw",
                                  std::uint32_t version = wire::kProtocolVersion) {
  wire::Envelope e;
  e.mutable_hello()->set_protocol_version(version);
  e.mutable_hello()->set_client_name(name);
  return e;
}

// One read into `buf` that gives up at `deadline` (then `cancel` cancels it): the read's error
// and size; operation_aborted when it timed out.
template <class AsyncReadStream, class Cancel>
std::pair<std::error_code, std::size_t> read_some_before(
    asio::io_context& io, AsyncReadStream& s, asio::mutable_buffer buf,
    std::chrono::steady_clock::time_point deadline, Cancel cancel) {
  std::error_code result = asio::error::would_block;
  std::size_t n = 0;
  s.async_read_some(buf, [&](std::error_code ec, std::size_t got) {
    result = ec;
    n = got;
  });
  io.restart();
  io.run_until(deadline);
  if (result == asio::error::would_block) {
    cancel();
    io.restart();
    io.run();
  }
  return {result, n};
}

// What the raw connections (here and websocket_client.h) share; Connection has send(Envelope)
// and read(limit). Reads until `eof` (the server closed) or the limit: the first Error frame.
template <class Connection>
std::optional<wire::Error> first_error_before_close(Connection& c, const bool& eof,
                                                    std::chrono::milliseconds limit) {
  using Clock = std::chrono::steady_clock;
  std::optional<wire::Error> error;
  const auto deadline = Clock::now() + limit;
  while (!eof && Clock::now() < deadline) {
    auto e = c.read(std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()));
    if (e && e->has_error() && !error) error = e->error();
  }
  return error;
}
// Hello, then waits for the Welcome (skipping other frames); false without one.
template <class Connection>
bool join_session(Connection& c, const std::string& name, wire::Welcome& welcome) {
  c.send(hello_frame(name));
  while (auto e = c.read()) {
    if (e->has_welcome()) {
      welcome = e->welcome();
      return true;
    }
  }
  return false;
}

// A raw protocol connection to 127.0.0.1:port, plain or TLS (the server's name is 127.0.0.1).
// Writes ignore errors (a test may write to a server that closed); reads wait at most a limit.
struct RawConnection {
  using Clock = std::chrono::steady_clock;

  // preamble: bytes written before anything else, the TLS handshake included (a proxy's PROXY
  // protocol header); from: the local address to connect from (another 127.x.y.z is another
  // peer).
  explicit RawConnection(std::uint16_t port, asio::ssl::context* tls = nullptr,
                         const std::string& preamble = {}, const std::string& from = {})
      : stream(io.get_executor(), tls) {
    if (!from.empty()) {
      stream.socket().open(asio::ip::tcp::v4());
      stream.socket().bind(asio::ip::tcp::endpoint(asio::ip::make_address(from), 0));
    }
    stream.socket().connect(asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), port),
                            connect_error);
    if (!connect_error && !preamble.empty())
      asio::write(stream.socket(), asio::buffer(preamble), connect_error);
    if (!connect_error && tls) {
      stream.expect_server_name("127.0.0.1");
      stream.handshake(asio::ssl::stream_base::client, connect_error);
    }
  }
  void write(const std::string& bytes) {
    std::error_code ec;
    asio::write(stream, asio::buffer(bytes), ec);
  }
  void send(const wire::Envelope& e) { write(wire::encode_frame(e)); }

  // The next frame, or nullopt at EOF or after `limit`.
  std::optional<wire::Envelope> read(
      std::chrono::milliseconds limit = std::chrono::milliseconds(5000)) {
    wire::Envelope e;
    const auto deadline = Clock::now() + limit;
    for (;;) {
      if (decoder.next(e) == wire::DecodeStatus::Frame) return e;
      if (Clock::now() > deadline || eof) return std::nullopt;
      const auto [result, n] = read_some_before(io, stream, asio::buffer(buf), deadline, [&] {
        std::error_code ignored;
        stream.socket().cancel(ignored);
      });
      if (result && result != asio::error::operation_aborted) eof = true;
      decoder.feed(buf.data(), n);
    }
  }

  // Sends an edit; its answer (the SceneEdit acknowledgement or an Error), other frames
  // skipped; nullopt at EOF or when none comes within `limit` of a frame.
  std::optional<wire::Envelope> edit(
      const wire::Envelope& e, std::chrono::milliseconds limit = std::chrono::milliseconds(5000)) {
    send(e);
    std::optional<wire::Envelope> a;
    while ((a = read(limit)) && !a->has_scene_edit() && !a->has_error()) {
    }
    return a;
  }

  // Reads until the server closes the connection (or the limit); the first Error frame.
  std::optional<wire::Error> error_then_close(
      std::chrono::milliseconds limit = std::chrono::milliseconds(5000)) {
    return first_error_before_close(*this, eof, limit);
  }
  // Hello, then waits for the Welcome (skipping other frames); false without one.
  bool join(const std::string& name = "raw") { return join_session(*this, name, welcome); }

  asio::io_context io;
  wire::Stream stream;
  std::error_code connect_error;
  wire::FrameDecoder decoder;
  std::array<char, 16384> buf{};
  bool eof = false;
  wire::Welcome welcome;  // set by join()
};

}  // namespace irradcast::test

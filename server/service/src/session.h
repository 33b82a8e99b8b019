// One client connection: the Asio side of a session. It runs the TLS handshake, reads bytes through
// the connection's frame channel (wire/frame_channel.h: the protocol port's frames as they are, or
// the web port's HTTP and WebSocket) into the session's protocol (session_protocol.h), writes the
// frames the protocol hands out (those ready at once in one write, up to 64 KiB, where the channel
// takes several), and runs the timers it asks for (hello, idle, the tile rate cap, a wrong token's
// delay, the grace period before closing) and the write-stall watch. Both ports have the same
// limits and one read path and one write path. Every handler runs on the session's strand, so the
// session needs no locks; the engine thread reaches it only through asio::post.
#pragma once

// A standard header before asio: asio's config decides between aligned_alloc and operator new
// from libstdc++'s _GLIBCXX_HAVE_ALIGNED_ALLOC, so every file must see it defined alike (else
// one file allocates handler memory with aligned_alloc and another frees it with delete).
#include <cstddef>

#include <asio.hpp>

#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "client_address.h"
#include "irradcast/wire/frame_channel.h"
#include "irradcast/wire/transport.h"
#include "irradcast/wire/websocket.h"
#include "session_protocol.h"

namespace irradcast {

class Session;

// What the server lends its sessions; outlives them.
struct SessionServer {
  SessionContext context;
  const wire::ServerTls* tls = nullptr;     // null: plain TCP; a session takes its current context
  const TrustedProxies* proxies = nullptr;  // --trusted-proxy (null: none)
  // A closed session leaves the server's set.
  std::function<void(const std::shared_ptr<Session>&)> remove;
};

class Session : public std::enable_shared_from_this<Session> {
 public:
  // The socket was accepted on a strand of the server's io_context, which becomes the session's
  // strand. peer_key: the address the server counts this session under (PeerTable::admit).
  // web: the connection came to the web port (HTTP, then a WebSocket at /ws).
  // proxied: the peer is a trusted proxy (--trusted-proxy), whose PROXY protocol header (either
  // port) and X-Forwarded-For (the web port) name the client the session is counted under.
  Session(SessionServer& server, asio::ip::tcp::socket socket, std::string peer_key,
          std::uint64_t id, bool web = false, bool proxied = false);

  void start();
  // Engine thread: tiles that got new versions.
  void tiles_changed(std::shared_ptr<const std::vector<std::uint32_t>> tiles);
  // Engine thread: an edit the engine applied, as an encoded SceneEdit frame. Posted like the
  // tile notifications, so it reaches the client before the tiles that show it (control frames
  // go first).
  void edit_applied(std::shared_ptr<const std::string> frame);
  void poses_changed();
  // The presence tick: the avatars now (SessionProtocol::presence_changed).
  void presence_changed(std::shared_ptr<const AvatarSnapshot> avatars);
  // Server shutdown: an Error SERVER_SHUTDOWN, then close.
  void shutdown();
  std::size_t queue_depth() const { return protocol_.queue_depth(); }

 private:
  // A trusted proxy's PROXY protocol header, then the TLS handshake and the protocol.
  void read_proxy_header();
  void handshake();
  // The client behind the trusted proxy: the session is counted under it (else refusal_ says
  // why not, and the session is refused once it can be told).
  void learn_client(const asio::ip::address& client);
  std::optional<wire::HttpReply> screen_request(
      const std::function<std::string(const std::string&)>& header);
  void arm_hello_timer();
  void arm_idle_timer();
  void arm_stall_timer();
  bool handshaking() const { return !reading_started_; }
  void read();
  void on_read(std::error_code ec, std::size_t n);
  void drain();
  // Runs what the protocol asked for, then writes on.
  void act();
  void on_penalty_over(bool banned);
  void pump();
  // The web port's channel: HTTP from the page's files, the upgrade screened (origin, proxies).
  std::unique_ptr<wire::FrameChannel> make_web_channel();
  // After bytes went into the channel: counts an upgrade or an HTTP request, and turns a message
  // the channel refused into the protocol's Error.
  void on_channel_input();
  // The channel's own bytes, or its end: true when the caller writes nothing else now.
  bool pump_channel();
  // Reading waits while the protocol says so, and while the channel's own bytes (pongs) pile up
  // behind a write in flight: a client that pings and does not read is pushed back by TCP.
  static constexpr std::size_t kMaxChannelOutput = 64 << 10;
  bool read_paused() const;
  // A write of protocol frames, or (raw) of the channel's own bytes.
  void write(SessionWrite w, bool raw = false);
  static constexpr std::size_t kMaxBatchBytes = 64 << 10, kMaxBatchFrames = 64;
  void gather(std::vector<SessionWrite>& batch);
  void close(CloseReason reason);

  SessionServer& server_;
  asio::any_io_executor strand_;  // the strand the socket was accepted on
  wire::Stream stream_;
  asio::steady_timer idle_timer_, rate_timer_, close_timer_, hello_timer_, penalty_timer_,
      stall_timer_;
  std::array<char, 64 * 1024> buffer_{};
  SessionProtocol protocol_;
  // The nearest peer whose word counts (the TCP peer, or the PROXY header's source) is a
  // trusted proxy.
  bool proxied_ = false;
  std::unique_ptr<ProxyHeaderReader> proxy_reader_;  // until the PROXY header is read
  std::string refusal_;                              // the client behind the proxy is refused: why
  std::unique_ptr<wire::FrameChannel> channel_;
  bool channel_counted_ = false;  // the upgrade or the HTTP request is counted
  bool writing_ = false;
  bool reading_started_ = false, read_pending_ = false;
  bool stall_armed_ = false, rate_waiting_ = false;
  std::size_t write_progress_ = 0;  // bytes of the write in flight written so far
  std::chrono::steady_clock::time_point write_progress_at_{};
};

}  // namespace irradcast

// The network server: the protocol port and the web port (their accept loops: listener.h;
// admission by PeerTable, a refusal frame or HTTP reply for the rest), the I/O threads, the
// engine's listeners that fan out to the sessions (session.h), shutdown and the stats. Each
// session's protocol is in session_protocol.h.
#include "irradcast/service/net_server.h"

#include <asio.hpp>

#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <mutex>
#include <optional>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include "client_address.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/service/thread_priority.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/transport.h"
#include "listener.h"
#include "peer_table.h"
#include "run_io.h"
#include "session.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

// The server's state. Sessions and handlers refer to it by plain pointer: they only run on the
// I/O threads, which stop() joins before the Impl can go (and a handler that owned a reference
// would make a cycle through the io_context that owns the handler). The engine listener holds a
// weak_ptr.
struct Server::Impl {
  Impl(TileSource& h, ServerOptions o)
      : host(h),
        options(std::move(o)),
        peers(options),
        proxies(options.trusted_proxies),
        port_listener(io, listener_options()),
        web_listener(io, listener_options()),
        session_server{
            SessionContext{host, options, counters, peers, [this] { return stats(); },
                           std::min(options.max_frame,
                                    options.max_hello_frame + 32 * host.tiles().tile_count()),
                           &tile_frames, options.presence ? presence : nullptr},
            nullptr, &proxies, [this](const std::shared_ptr<Session>& s) { remove(s); }} {}

  TileSource& host;
  ServerOptions options;
  ServerCounters counters;
  // Peers by address key; sessions count themselves in and out (admit, release).
  PeerTable peers;
  TrustedProxies proxies;                // --trusted-proxy
  std::unique_ptr<wire::ServerTls> tls;  // null: plain TCP
  asio::io_context io;
  Listener port_listener;
  Listener web_listener;  // the web port (ServerOptions::http_port); not open without one
  std::vector<std::thread> threads;
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  std::atomic<bool> stopping{false};
  std::atomic<std::uint64_t> next_session{1};
  TileFrames tile_frames;      // the tile frames the sessions share
  PresenceBoard own_presence;  // ServerOptions::presence, when the source shares none
  PresenceBoard* presence = host.presence() ? host.presence() : &own_presence;
  asio::steady_timer presence_timer{io};
  SessionServer session_server;  // what the sessions use of the server

  mutable std::mutex sessions_mutex;
  std::set<std::shared_ptr<Session>> sessions;

  // Tiles published since the last fan-out (each once): a source that publishes tile by tile (a
  // gateway, one NATS message per tile) reaches the sessions in batches, one post per session
  // per batch rather than per tile.
  std::mutex publish_mutex;
  std::vector<std::uint8_t> publish_pending;
  std::vector<std::uint32_t> publish_list;
  bool publish_posted = false;
  std::atomic<bool> poses_posted{false};  // a fan_out_poses is posted and has not run
  // Poses go out at most once per kPoseInterval: every node posed meanwhile in one frame per
  // session (at 64 nodes streaming 60 poses a second, 125 frames a second, not 3840).
  static constexpr std::chrono::milliseconds kPoseInterval{8};
  asio::steady_timer pose_timer{io};
  int pose_listener = 0;                                             // on host.poses()
  std::atomic<std::chrono::steady_clock::rep> last_pose_fan_out{0};  // time_since_epoch

  Listener::Options listener_options() {
    return {"server", "--bind", asio::socket_base::max_listen_connections, true,
            [this] { return std::to_string(client_count()) + " sessions"; }};
  }
  void accept(Listener& listener, bool web);
  void admit(tcp::socket socket, bool web);
  void refuse(tcp::socket& socket, const std::string& message, bool web);
  void on_publish(const std::vector<std::uint32_t>& tiles);
  void fan_out();
  void on_edit(const AppliedEdit& applied);
  void on_poses();
  void fan_out_poses();
  void presence_tick();
  void remove(const std::shared_ptr<Session>& s) {
    std::lock_guard lock(sessions_mutex);
    sessions.erase(s);
  }
  std::uint32_t client_count() const {
    std::lock_guard lock(sessions_mutex);
    return static_cast<std::uint32_t>(sessions.size());
  }
  ServerStats stats() const;
};

void check_trusted_proxies(const std::vector<std::string>& cidrs) {
  TrustedProxies{cidrs};
}

// Closes a connection that is not admitted: one Error REFUSED frame, best effort (never blocks: the
// socket is non-blocking and the frame is small), then close.
// On the web port the refusal is an HTTP 503.
void Server::Impl::refuse(tcp::socket& socket, const std::string& message, bool web) {
  std::error_code ignored;
  if (!tls) {
    socket.non_blocking(true, ignored);
    const std::string frame =
        web ? "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\n"
              "Content-Length: " +
                  std::to_string(message.size() + 1) + "\r\nConnection: close\r\n\r\n" + message +
                  "\n"
            : wire::encode_frame(wire::make_error(wire::REFUSED, message));
    socket.write_some(asio::buffer(frame), ignored);
  }
  socket.close(ignored);
}

// Connections to a port: counted, then admitted or refused; failed accepts counted (the listener
// pauses on a lack of descriptors).
void Server::Impl::accept(Listener& listener, bool web) {
  listener.start(
      [this, web](tcp::socket socket) {
        if (stopping) return;
        ++counters.connections;
        admit(std::move(socket), web);
      },
      [this] { ++counters.accept_errors; });
}

// A new connection: a session if the peer table admits it, a refusal otherwise.
// A trusted proxy's connection is admitted without the per-address limit; the session learns its
// client's address (PROXY header, X-Forwarded-For) and is counted under it then.
void Server::Impl::admit(tcp::socket socket, bool web) {
  std::error_code ec;
  const tcp::endpoint peer = socket.remote_endpoint(ec);
  const std::string key = ec ? std::string("?") : peer_key_of(peer.address());
  const bool trusted = !ec && proxies.contains(peer.address());
  const PeerTable::Admission admission = peers.admit(
      key,
      [this]() -> std::size_t {
        std::lock_guard sl(sessions_mutex);
        return sessions.size();
      },
      trusted);
  switch (admission) {
    case PeerTable::Admission::Ok: {
      std::error_code ignored;
      if (options.socket_send_buffer > 0)
        socket.set_option(asio::socket_base::send_buffer_size(options.socket_send_buffer), ignored);
      auto s = std::make_shared<Session>(session_server, std::move(socket), key, next_session++,
                                         web, trusted);
      {
        std::lock_guard lock(sessions_mutex);
        sessions.insert(s);
      }
      s->start();
      return;
    }
    case PeerTable::Admission::Full:
      ++counters.clients_refused;
      break;
    case PeerTable::Admission::PeerLimit:
      ++counters.peer_refused;
      break;
    case PeerTable::Admission::Banned:
      ++counters.banned_refused;
      break;
  }
  refuse(socket, peers.refusal(admission), web);
}

void Server::Impl::on_publish(const std::vector<std::uint32_t>& tiles) {
  std::lock_guard lock(publish_mutex);
  for (std::uint32_t t : tiles) {
    if (t >= publish_pending.size()) publish_pending.resize(std::size_t(t) + 1, 0);
    if (publish_pending[t]) continue;
    publish_pending[t] = 1;
    publish_list.push_back(t);
  }
  // An empty list: the probe volume changed alone; the sessions look at it in the fan-out.
  if (publish_posted) return;
  publish_posted = true;
  asio::post(io, [this] { fan_out(); });
}

// An I/O thread: the tiles published since the last fan-out, to every session at once.
void Server::Impl::fan_out() {
  std::vector<std::uint32_t> tiles;
  {
    std::lock_guard lock(publish_mutex);
    tiles.swap(publish_list);
    for (std::uint32_t t : tiles) publish_pending[t] = 0;
    publish_posted = false;
  }
  auto shared = std::make_shared<const std::vector<std::uint32_t>>(std::move(tiles));
  std::lock_guard lock(sessions_mutex);
  for (const auto& s : sessions) s->tiles_changed(shared);
}

void Server::Impl::on_edit(const AppliedEdit& applied) {
  wire::Envelope e;
  wire::SceneEdit* m = e.mutable_scene_edit();
  wire::to_proto(applied.edit, m);
  m->set_revision(applied.revision);
  // Edits applied together share one package, made after the last of them: only that one
  // names it (the listener runs before the engine can apply anything else).
  if (applied.package && applied.revision == host.revision())
    m->set_scene_hash(applied.package->hash);
  m->set_applied(true);
  m->set_applied_us(applied.applied_us);
  auto frame = std::make_shared<const std::string>(wire::encode_frame(e));
  std::lock_guard lock(sessions_mutex);
  for (const auto& s : sessions) s->edit_applied(frame);
}

// A poster's thread: the sessions hear of new poses once per fan-out, however many were posted
// meanwhile (each sends the newest).
void Server::Impl::on_poses() {
  if (poses_posted.exchange(true)) return;
  asio::post(io, [this] {
    // One handler at a time touches the timer: the next is posted only after fan_out_poses.
    const auto due = std::chrono::steady_clock::time_point(
                         std::chrono::steady_clock::duration(last_pose_fan_out.load())) +
                     kPoseInterval;
    if (std::chrono::steady_clock::now() >= due) {
      fan_out_poses();
      return;
    }
    pose_timer.expires_at(due);
    pose_timer.async_wait([this](std::error_code ec) {
      if (!ec) fan_out_poses();
    });
  });
}

void Server::Impl::fan_out_poses() {
  last_pose_fan_out = std::chrono::steady_clock::now().time_since_epoch().count();
  poses_posted = false;
  std::lock_guard lock(sessions_mutex);
  for (const auto& s : sessions) s->poses_changed();
}

// Every 1 / presence_hz seconds: when any avatar moved, every session gets the new set (each
// sends its client the nearest others'; presence_board.h).
void Server::Impl::presence_tick() {
  if (stopping) return;
  if (auto avatars = presence->take_changed()) {
    std::lock_guard lock(sessions_mutex);
    for (const auto& s : sessions) s->presence_changed(avatars);
  }
  presence_timer.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(1.0 / options.presence_hz)));
  presence_timer.async_wait([this](std::error_code ec) {
    if (!ec) presence_tick();
  });
}

Server::Server(TileSource& host, ServerOptions options)
    : impl_(std::make_shared<Impl>(host, std::move(options))) {
  Impl& im = *impl_;
  const ServerOptions& o = im.options;
  if (o.io_threads < 1) throw Error("the server needs at least one I/O thread");
  if (!o.control_token.empty() && o.control_token.size() < kMinTokenLength)
    throw Error("the control token has " + std::to_string(o.control_token.size()) +
                " characters; it needs at least " + std::to_string(kMinTokenLength) +
                " (e.g. head -c 18 /dev/urandom | base64)");
  if (o.tls_cert.empty() != o.tls_key.empty())
    throw Error("TLS needs both --tls-cert and --tls-key");
  if (!o.tls_cert.empty())
    im.tls = std::make_unique<wire::ServerTls>(o.tls_cert, o.tls_key, "server");
  if (o.presence &&
      (!(o.presence_hz > 0.0 && o.presence_hz <= 60.0) || o.presence_nearest < 1 ||
       o.presence_nearest > 256 || !(o.presence_height > 0.0f && o.presence_height <= 100.0f)))
    throw Error(
        "presence needs 0 < --presence-hz <= 60, 1 <= --presence-nearest <= 256 and "
        "0 < --presence-height <= 100 (metres)");
  im.session_server.tls = im.tls.get();
}

bool Server::reload_tls() {
  if (!impl_->tls) {
    log::info("server", "no TLS certificate to reload (no --tls-cert)");
    return false;
  }
  return impl_->tls->reload();
}

Server::~Server() {
  stop();
}

void Server::start() {
  Impl& im = *impl_;
  im.port_listener.listen(im.options.bind, im.options.port);
  if (im.options.http_port) im.web_listener.listen(im.options.bind, *im.options.http_port);
  std::weak_ptr<Impl> weak = impl_;
  im.host.set_listener([weak](const std::vector<std::uint32_t>& tiles) {
    if (auto s = weak.lock()) s->on_publish(tiles);
  });
  im.host.set_edit_listener([weak](const AppliedEdit& applied) {
    if (auto s = weak.lock()) s->on_edit(applied);
  });
  if (PoseBoard* poses = im.host.poses())
    im.pose_listener = poses->add_listener([weak] {
      if (auto s = weak.lock()) s->on_poses();
    });
  im.work.emplace(asio::make_work_guard(im.io));
  im.accept(im.port_listener, false);
  if (im.options.http_port) im.accept(im.web_listener, true);
  if (im.options.presence) {
    im.presence->set_height(im.options.presence_height);
    asio::post(im.io, [&im] { im.presence_tick(); });
  }
  for (int i = 0; i < im.options.io_threads; ++i)
    im.threads.emplace_back([&im] {
      set_thread_name("irradcast-io");
      run_io(im.io, "server", "I/O handler");  // a handler that throws: the others go on
    });
  log::info("server", "listening on " + im.options.bind + ":" + std::to_string(port()));
  if (im.options.http_port)
    log::info("server", std::string("web viewer on ") + (im.tls ? "https" : "http") + "://" +
                            im.options.bind + ":" + std::to_string(http_port()) + "/");
}

void Server::stop() {
  Impl& im = *impl_;
  if (im.stopping.exchange(true)) return;
  im.host.set_listener(nullptr);
  im.host.set_edit_listener(nullptr);
  if (PoseBoard* poses = im.host.poses(); poses && im.pose_listener)
    poses->remove_listener(std::exchange(im.pose_listener, 0));
  if (im.threads.empty()) return;
  asio::post(im.io, [&im] {
    im.port_listener.close();
    im.web_listener.close();
    im.presence_timer.cancel();
  });
  {
    std::lock_guard lock(im.sessions_mutex);
    for (const auto& s : im.sessions) s->shutdown();
  }
  // Give the sessions a moment to send their Error frames and close.
  const auto deadline = Clock::now() + std::chrono::seconds(2);
  while (im.client_count() > 0 && Clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  im.work.reset();
  im.io.stop();
  for (auto& t : im.threads) t.join();
  im.threads.clear();
  std::lock_guard lock(im.sessions_mutex);
  im.sessions.clear();
}

std::uint16_t Server::port() const {
  return impl_->port_listener.port();
}

std::uint16_t Server::http_port() const {
  return impl_->web_listener.port();  // 0 without a web port
}

ServerStats Server::stats() const {
  return impl_->stats();
}

ServerStats Server::Impl::stats() const {
  const ServerCounters& c = counters;
  ServerStats s;
  s.clients = client_count();
#define IRRADCAST_SERVER_COUNTER(name, wire, metric, help) s.name = c.name.load();
#include "irradcast/service/server_counters.inc"
#undef IRRADCAST_SERVER_COUNTER
  s.partial_bytes = static_cast<std::uint64_t>(std::max<std::int64_t>(0, c.partial_bytes.load()));
  for (std::size_t r = 0; r < kCloseReasons; ++r)
    s.sessions_closed[r] = c.sessions_closed[r].load();
  s.uptime_seconds = std::chrono::duration<double>(Clock::now() - c.started).count();
  std::lock_guard lock(sessions_mutex);
  for (const auto& session : sessions) {
    const std::uint64_t depth = session->queue_depth();
    s.queue_depth += depth;
    s.queue_depth_max = std::max(s.queue_depth_max, depth);
  }
  return s;
}

std::uint64_t raise_open_file_limit() {
  rlimit r{};
  if (getrlimit(RLIMIT_NOFILE, &r) != 0) return 0;
  if (r.rlim_cur < r.rlim_max) {
    const rlim_t before = r.rlim_cur;
    r.rlim_cur = r.rlim_max;
    if (setrlimit(RLIMIT_NOFILE, &r) != 0) return before;
  }
  return r.rlim_cur;
}

const char* close_reason_name(CloseReason reason) {
  // In the order of CloseReason.
  static constexpr const char* kNames[] = {"bye",
                                           "disconnect",
                                           "idle_timeout",
                                           "bad_frame",
                                           "frame_too_large",
                                           "unsupported_version",
                                           "unexpected_message",
                                           "slow_client",
                                           "shutdown",
                                           "internal",
                                           "hello_timeout",
                                           "token_failures",
                                           "tls"};
  static_assert(std::size(kNames) == kCloseReasons);
  const auto i = static_cast<std::size_t>(reason);
  return i < kCloseReasons ? kNames[i] : "unknown";
}

}  // namespace irradcast

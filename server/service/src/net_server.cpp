#include "irradcast/service/net_server.h"

#include <asio.hpp>

#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <deque>
#include <mutex>
#include <optional>
#include <set>
#include <thread>
#include <unordered_map>
#include <vector>

#include "irradcast/wire/edit_message.h"
#include "irradcast/common/error.h"
#include "irradcast/wire/frame.h"
#include "irradcast/common/log.h"
#include "irradcast/service/send_queue.h"
#include "irradcast/service/thread_priority.h"
#include "irradcast/wire/transport.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

class Session;

}  // namespace

// The server's state. Sessions and handlers refer to it by plain pointer: they only run on the
// I/O threads, which stop() joins before the Impl can go (and a handler that owned a reference
// would make a cycle through the io_context that owns the handler). The engine listener holds a
// weak_ptr.
struct Server::Impl {
  Impl(EngineHost& h, ServerOptions o)
      : host(h), options(std::move(o)), acceptor(io), accept_timer(io) {}

  // What the server remembers of one peer address (an IPv4 address, or an IPv6 peer's /64).
  struct Peer {
    std::uint32_t sessions = 0;
    std::uint32_t token_failures = 0;
    Clock::time_point banned_until{};
    Clock::time_point last_seen{};
  };
  enum class Admission { Ok, Full, PeerLimit, Banned };

  EngineHost& host;
  ServerOptions options;
  std::shared_ptr<asio::ssl::context> tls;  // null: plain TCP
  asio::io_context io;
  tcp::acceptor acceptor;
  asio::steady_timer accept_timer;  // the pause after accept() ran out of descriptors
  std::chrono::milliseconds accept_backoff{0};
  std::size_t hello_frame_cap = 0;  // the decoder's cap before Hello
  std::vector<std::thread> threads;
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  std::atomic<bool> stopping{false};
  Clock::time_point started = Clock::now();
  std::atomic<std::uint64_t> next_session{1};

  mutable std::mutex sessions_mutex;
  std::set<std::shared_ptr<Session>> sessions;

  // Peers by address key; sessions count themselves in and out (admit, release).
  std::mutex peers_mutex;
  std::unordered_map<std::string, Peer> peers;

  // Counters (sessions add to them).
  std::atomic<std::uint64_t> connections{0}, clients_refused{0}, bytes_sent{0}, bytes_received{0},
      frames_received{0}, tiles_sent{0}, tile_bytes_sent{0}, tiles_coalesced{0},
      scene_bytes_sent{0}, errors_sent{0}, peer_refused{0}, banned_refused{0}, accept_errors{0},
      token_failures{0}, edits_dropped{0}, log_lines_suppressed{0};
  std::atomic<std::int64_t> partial_bytes{0};  // incomplete frames in every session's decoder
  std::array<std::atomic<std::uint64_t>, kCloseReasons> sessions_closed{};

  void accept();
  void refuse(tcp::socket& socket, const std::string& message);
  Admission admit(const std::string& peer_key);
  void release(const std::string& peer_key);
  // A wrong token from this peer: the delay before the answer, and whether the peer is now
  // refused (banned).
  std::pair<std::chrono::milliseconds, bool> token_failed(const std::string& peer_key);
  void token_passed(const std::string& peer_key);
  void on_publish(const std::vector<std::uint32_t>& tiles);
  void on_edit(const AppliedEdit& applied);
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

namespace {

// The reason a session ends after sending an Error frame with this code.
CloseReason reason_of(wire::ErrorCode code) {
  switch (code) {
    case wire::BAD_FRAME:
      return CloseReason::BadFrame;
    case wire::FRAME_TOO_LARGE:
      return CloseReason::FrameTooLarge;
    case wire::UNSUPPORTED_VERSION:
      return CloseReason::UnsupportedVersion;
    case wire::UNEXPECTED_MESSAGE:
      return CloseReason::UnexpectedMessage;
    case wire::IDLE_TIMEOUT:
      return CloseReason::IdleTimeout;
    case wire::SERVER_SHUTDOWN:
      return CloseReason::Shutdown;
    default:
      return CloseReason::Internal;
  }
}

// One client connection. Every handler runs on the session's strand, so a session's state
// needs no locks; the engine thread reaches it only through asio::post.
class Session : public std::enable_shared_from_this<Session> {
 public:
  // The socket was accepted on a strand of the server's io_context, which becomes the
  // session's strand. peer_key: the address the server counts this session under (admit()).
  Session(Server::Impl* server, tcp::socket socket, std::string peer_key)
      : server_(server),
        strand_(socket.get_executor()),
        stream_(std::move(socket), server_->tls.get()),
        idle_timer_(strand_),
        rate_timer_(strand_),
        close_timer_(strand_),
        hello_timer_(strand_),
        penalty_timer_(strand_),
        stall_timer_(strand_),
        decoder_(server_->hello_frame_cap),
        id_(server_->next_session++),
        peer_key_(std::move(peer_key)) {
    const TileStore& tiles = server_->host.tiles();
    known_.assign(tiles.tile_count(), 0);
    queue_.resize(tiles.tile_count());
    subscribed_.assign(tiles.lightmap_count(), 0);
    std::error_code ec;
    auto ep = stream_.socket().remote_endpoint(ec);
    peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
  }

  void start() {
    asio::post(strand_, [self = shared_from_this()] {
      self->arm_idle_timer();
      self->arm_hello_timer();
      self->stream_.async_handshake(
          asio::ssl::stream_base::server,
          asio::bind_executor(self->strand_, [self](std::error_code ec) {
            if (self->closed_) return;
            if (ec) {
              self->note(log::Level::Info, "TLS handshake failed: " + wire::describe_tls_error(ec));
              self->close(CloseReason::Tls);
              return;
            }
            self->read();
          }));
    });
  }

  // Engine thread: tiles that got new versions.
  void tiles_changed(std::shared_ptr<const std::vector<std::uint32_t>> tiles) {
    asio::post(strand_, [self = shared_from_this(), tiles] {
      if (self->closed_ || !self->streaming_) return;
      const TileStore& store = self->server_->host.tiles();
      for (std::uint32_t t : *tiles)
        if (self->subscribed_[store.tile(t).lightmap]) self->queue_.push(t);
      self->queue_changed();
      self->pump();
    });
  }

  // Engine thread: an edit the engine applied, as an encoded SceneEdit frame. Posted like the
  // tile notifications, so it reaches the client before the tiles that show it (control frames
  // go first in pump()).
  // Broadcasts wait in their own bounded queue (not with the replies, whose bound drops the
  // client): past max_pending_edits the oldest are dropped, and the client, seeing the revision
  // gap, loads the current scene package. Somebody else's burst of edits never drops a viewer.
  void edit_applied(std::shared_ptr<const std::string> frame) {
    asio::post(strand_, [self = shared_from_this(), frame = std::move(frame)]() mutable {
      if (self->closed_ || self->closing_ || self->state_ != State::Ready) return;
      self->edits_.push_back(std::move(frame));
      while (self->edits_.size() > self->server_->options.max_pending_edits) {
        self->edits_.pop_front();
        ++self->server_->edits_dropped;
      }
      self->pump();
    });
  }

  // Server shutdown: an Error SERVER_SHUTDOWN, then close.
  void shutdown() {
    asio::post(strand_, [self = shared_from_this()] {
      self->fail(wire::SERVER_SHUTDOWN, "the server is shutting down");
    });
  }

  std::size_t queue_depth() const { return queue_depth_.load(); }

 private:
  enum class State { AwaitHello, Ready };

  // After tiles were queued: publishes the queue depth, and adds the versions coalesced since
  // the last call to the server's counter (so that it is live, not counted at the end).
  void queue_changed() {
    queue_depth_ = queue_.size() + (held_ ? 1 : 0);
    const std::uint64_t c = queue_.coalesced();
    server_->tiles_coalesced += c - coalesced_counted_;
    coalesced_counted_ = c;
  }

  // A log line this session causes, within its budget (ServerOptions::session_log_burst and
  // session_log_per_s); lines over it are counted, and the next line says how many.
  void note(log::Level level, const std::string& message) {
    if (static_cast<int>(level) < static_cast<int>(log::level())) return;
    const auto now = Clock::now();
    const ServerOptions& o = server_->options;
    log_tokens_ =
        std::min(o.session_log_burst,
                 log_tokens_ + o.session_log_per_s *
                                   std::chrono::duration<double>(now - log_refill_).count());
    log_refill_ = now;
    if (log_tokens_ < 1.0) {
      ++log_suppressed_;
      ++server_->log_lines_suppressed;
      return;
    }
    log_tokens_ -= 1.0;
    std::string line = "session " + std::to_string(id_) + " (" + peer_ + "): " + message;
    if (log_suppressed_ > 0) {
      line += " [" + std::to_string(log_suppressed_) + " earlier lines of this session suppressed]";
      log_suppressed_ = 0;
    }
    log::write(level, "server", line);
  }

  // No Hello (after the TLS handshake) within the hello timeout: close.
  void arm_hello_timer() {
    hello_timer_.expires_after(server_->options.hello_timeout);
    hello_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (ec || self->closed_ || self->state_ != State::AwaitHello) return;
      const std::string text =
          "no hello within " + std::to_string(self->server_->options.hello_timeout.count()) + " ms";
      if (self->handshaking()) {
        // Still in the TLS handshake: no frame can be sent.
        self->note(log::Level::Info, "closed: " + text + " (TLS handshake not completed)");
        self->close(CloseReason::HelloTimeout);
        return;
      }
      self->fail(wire::IDLE_TIMEOUT, text, CloseReason::HelloTimeout);
    });
  }
  bool handshaking() const { return !reading_started_; }

  // Watches a write in flight: one that made no progress for the write stall timeout means a
  // client that does not read, and it is closed as slow. Armed while writes are in flight.
  void arm_stall_timer() {
    if (stall_armed_ || server_->options.write_stall_timeout.count() <= 0) return;
    stall_armed_ = true;
    stall_timer_.expires_after(server_->options.write_stall_timeout / 4);
    stall_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      self->stall_armed_ = false;
      if (ec || self->closed_ || !self->writing_) return;
      if (Clock::now() - self->write_progress_at_ >= self->server_->options.write_stall_timeout) {
        self->note(log::Level::Info,
                   "closed: slow client (no write progress for " +
                       std::to_string(self->server_->options.write_stall_timeout.count()) + " ms)");
        self->close(CloseReason::SlowClient);
        return;
      }
      self->arm_stall_timer();
    });
  }

  void arm_idle_timer() {
    idle_timer_.expires_after(server_->options.idle_timeout);
    idle_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (ec || self->closed_) return;
      self->fail(
          wire::IDLE_TIMEOUT,
          "no frame for " + std::to_string(self->server_->options.idle_timeout.count()) + " ms");
    });
  }

  void read() {
    reading_started_ = true;
    if (closed_ || closing_ || read_pending_) return;
    read_pending_ = true;
    stream_.async_read_some(asio::buffer(buffer_),
                            asio::bind_executor(strand_, [self = shared_from_this()](
                                                             std::error_code ec, std::size_t n) {
                              self->read_pending_ = false;
                              self->on_read(ec, n);
                            }));
  }

  void on_read(std::error_code ec, std::size_t n) {
    if (closed_) return;
    if (ec) {
      if (ec != asio::error::eof && ec != asio::error::operation_aborted)
        log::debug("server", "session " + std::to_string(id_) + ": read: " + ec.message());
      close(CloseReason::Disconnect);
      return;
    }
    server_->bytes_received += n;
    decoder_.feed(buffer_.data(), n);
    drain();
  }

  // Handles the frames the decoder holds, then reads on; stops while a wrong token's answer is
  // delayed or while the client's replies pile up (it reads on once they are written).
  void drain() {
    wire::Envelope env;
    while (!closed_ && !closing_ && !paused()) {
      const wire::DecodeStatus st = decoder_.next(env);
      if (st == wire::DecodeStatus::NeedMore) break;
      if (st == wire::DecodeStatus::TooLarge) {
        fail(wire::FRAME_TOO_LARGE, decoder_.error());
        return;
      }
      if (st == wire::DecodeStatus::Malformed) {
        fail(wire::BAD_FRAME, decoder_.error());
        return;
      }
      ++server_->frames_received;
      arm_idle_timer();
      handle(env);
    }
    if (closed_ || closing_) return;
    if (!account_partial()) return;
    if (!paused()) read();
  }
  bool paused() const {
    return penalty_ || control_.size() >= server_->options.max_control_frames / 2;
  }

  // Adds this session's incomplete frame to the server's total. A session holding more than
  // 64 KiB of one while the total is over the cap is closed; below 64 KiB (any frame that spans
  // two reads) is always allowed, so well-behaved clients never meet the cap. False: closed.
  bool account_partial() {
    const auto held = static_cast<std::int64_t>(decoder_.buffered());
    const std::int64_t total = server_->partial_bytes += held - partial_counted_;
    partial_counted_ = held;
    if (held > (64 << 10) &&
        total > static_cast<std::int64_t>(server_->options.max_partial_bytes)) {
      fail(wire::FRAME_TOO_LARGE,
           "the server holds too many incomplete frames; send smaller frames (" +
               std::to_string(held) + " bytes of one held)");
      return false;
    }
    return true;
  }

  void handle(const wire::Envelope& env) {
    using E = wire::Envelope;
    if (state_ == State::AwaitHello && env.msg_case() != E::kHello) {
      fail(wire::UNEXPECTED_MESSAGE,
           std::string("expected hello as the first frame, got ") + wire::message_name(env));
      return;
    }
    switch (env.msg_case()) {
      case E::kHello:
        on_hello(env.hello());
        break;
      case E::kSceneRequest:
        on_scene_request(env.scene_request());
        break;
      case E::kSubscribe:
        on_subscribe(env.subscribe());
        break;
      case E::kCameraUpdate:
        on_camera(env.camera_update());
        break;
      case E::kSceneEdit:
        on_scene_edit(env.scene_edit());
        break;
      case E::kStatsRequest:
        send_stats();
        break;
      case E::kPing: {
        wire::Envelope pong;
        pong.mutable_pong()->set_nonce(env.ping().nonce());
        pong.mutable_pong()->set_time_us(env.ping().time_us());
        send(pong);
        break;
      }
      case E::kBye:
        note(log::Level::Debug, "bye: " + log::quote(env.bye().reason()));
        close(CloseReason::Bye);
        break;
      case E::kPong:
        break;
      case E::kError:
        note(log::Level::Info, "reports an error: " + log::quote(env.error().message()));
        break;
      default:
        error(wire::UNEXPECTED_MESSAGE,
              std::string("a client does not send ") + wire::message_name(env));
        break;
    }
    pump();
  }

  void on_hello(const wire::Hello& h) {
    if (state_ != State::AwaitHello) {
      error(wire::UNEXPECTED_MESSAGE, "hello was already received");
      return;
    }
    if (h.protocol_version() != wire::kProtocolVersion) {
      fail(wire::UNSUPPORTED_VERSION, "protocol version " + std::to_string(h.protocol_version()) +
                                          " is not supported; this server speaks " +
                                          std::to_string(wire::kProtocolVersion));
      return;
    }
    const EngineHost& host = server_->host;
    const TileStore& tiles = host.tiles();
    // Resume: tiles the client already holds are only sent again when their version changes.
    // Versions only mean something for the same scene package.
    // The package this session serves: the one named in the Welcome (an edit after it is sent
    // to the client as a SceneEdit, which it applies to this package's scene).
    package_ = host.package();
    if (h.cached_scene_hash() == package_->hash && h.known_epoch() == host.tile_epoch())
      for (const wire::TileVersion& k : h.known()) {
        std::int64_t i = tiles.index(k.lightmap(), k.tile_x(), k.tile_y());
        if (i >= 0) known_[static_cast<std::size_t>(i)] = k.version();
      }
    client_name_ = log::quote(h.client_name(), 64);
    hello_timer_.cancel();
    decoder_.set_max_frame(server_->options.max_frame);
    wire::Envelope w;
    wire::Welcome* wm = w.mutable_welcome();
    wm->set_protocol_version(wire::kProtocolVersion);
    wm->set_session(id_);
    wm->set_scene_id(host.scene_id());
    wm->set_scene_hash(package_->hash);
    wm->set_scene_bytes(package_->bytes.size());
    wm->set_tile_size(static_cast<std::uint32_t>(tiles.options().tile_size));
    wm->add_capabilities("tiles.rgb9e5");
    wm->add_capabilities("tiles.half");
    for (std::uint32_t m = 0; m < tiles.lightmap_count(); ++m) {
      wire::LightmapInfo* li = wm->add_lightmaps();
      li->set_width(static_cast<std::uint32_t>(tiles.lightmap_size(m).first));
      li->set_height(static_cast<std::uint32_t>(tiles.lightmap_size(m).second));
      li->set_tiles_x(static_cast<std::uint32_t>(tiles.tiles_x(m)));
      li->set_tiles_y(static_cast<std::uint32_t>(tiles.tiles_y(m)));
    }
    wm->set_max_frame_bytes(static_cast<std::uint32_t>(server_->options.max_frame));
    wm->set_idle_timeout_ms(static_cast<std::uint32_t>(server_->options.idle_timeout.count()));
    wm->set_tile_epoch(host.tile_epoch());
    send(w);
    state_ = State::Ready;
    note(log::Level::Info,
         client_name_ + " joined; " + std::to_string(h.known_size()) + " tiles known");
  }

  void on_scene_request(const wire::SceneRequest& r) {
    const std::string& bytes = package_->bytes;
    if (r.offset() > bytes.size()) {
      error(wire::BAD_REQUEST, "scene offset " + std::to_string(r.offset()) +
                                   " is past the end of the " + std::to_string(bytes.size()) +
                                   "-byte package");
      return;
    }
    scene_offset_ = r.offset();
    scene_active_ = true;
  }

  void on_subscribe(const wire::Subscribe& s) {
    const TileStore& tiles = server_->host.tiles();
    if (s.encoding() != wire::TILE_RGB9E5_ZSTD && s.encoding() != wire::TILE_HALF_ZSTD &&
        s.encoding() != wire::TILE_RGB9E5_DELTA_ZSTD) {
      error(wire::BAD_REQUEST, "unknown tile encoding " + std::to_string(s.encoding()));
      return;
    }
    std::vector<std::uint8_t> wanted(tiles.lightmap_count(), s.all() ? 1 : 0);
    if (!s.all())
      for (std::uint32_t m : s.lightmaps()) {
        if (m >= wanted.size()) {
          error(wire::BAD_REQUEST, "there is no lightmap " + std::to_string(m) +
                                       " (the scene has " + std::to_string(wanted.size()) + ")");
          return;
        }
        wanted[m] = 1;
      }
    // Deltas need a per-client copy of every tile; this server sends full RGB9E5 instead, which
    // a delta-capable client also accepts.
    encoding_ =
        s.encoding() == wire::TILE_HALF_ZSTD ? wire::TILE_HALF_ZSTD : wire::TILE_RGB9E5_ZSTD;
    rate_ = static_cast<double>(s.max_bytes_per_s());
    tokens_ = rate_ > 0.0 ? std::max(rate_ * 0.25, 65536.0) : 0.0;
    last_refill_ = Clock::now();
    subscribed_ = wanted;
    streaming_ = true;
    for (std::uint32_t m = 0; m < tiles.lightmap_count(); ++m) {
      if (!subscribed_[m]) continue;
      auto [first, last] = tiles.tiles_of(m);
      for (std::uint32_t t = first; t < last; ++t)
        if (tiles.version(t) > known_[t]) queue_.push(t);
    }
    queue_changed();
  }

  // The viewer's camera: the engine refines what the viewers see first after an edit.
  void on_camera(const wire::CameraUpdate& c) {
    auto vec = [](const wire::Vec3& v) { return glm::vec3(v.x(), v.y(), v.z()); };
    CameraPose pose;
    pose.eye = vec(c.eye());
    pose.forward = vec(c.forward());
    pose.up = vec(c.up());
    pose.yfov = c.yfov();
    const auto finite = [](glm::vec3 v) {
      return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
    };
    if (!finite(pose.eye) || !finite(pose.forward) || !finite(pose.up) ||
        !std::isfinite(pose.yfov)) {
      error(wire::BAD_REQUEST, "camera update: a number is not finite (NaN or infinity)");
      return;
    }
    if (!(glm::length(pose.forward) > 0.0f)) {
      error(wire::BAD_REQUEST, "camera update: the forward direction is zero");
      return;
    }
    server_->host.set_camera(id_, pose);
  }

  // A scene edit: needs the control token; validated by the host (the scene does not change
  // on a bad edit); acknowledged to the sender with the revision it will make.
  void on_scene_edit(const wire::SceneEdit& m) {
    const std::string& token = server_->options.control_token;
    if (token.empty()) {
      error(wire::PERMISSION_DENIED,
            "this server takes no edits (start it with --control-token or "
            "--control-token-file)");
      return;
    }
    if (!same_secret(m.token(), token)) {
      // Answered after a delay that doubles with each failure of the address; nothing else of
      // this session is handled meanwhile. Too many: the address is refused for a while.
      ++server_->token_failures;
      const auto [delay, banned] = server_->token_failed(peer_key_);
      penalty_ = true;
      penalty_timer_.expires_after(delay);
      penalty_timer_.async_wait([self = shared_from_this(), banned = banned](std::error_code ec) {
        self->penalty_ = false;
        if (ec || self->closed_) return;
        if (banned) {
          self->fail(wire::PERMISSION_DENIED,
                     "scene edits need the control token; too many wrong tokens: this address is "
                     "refused for " +
                         std::to_string(self->server_->options.ban_duration.count() / 1000) + " s",
                     CloseReason::TokenFailures);
          return;
        }
        self->error(wire::PERMISSION_DENIED, "scene edits need the control token");
        self->pump();
        self->drain();
      });
      return;
    }
    server_->token_passed(peer_key_);
    std::uint64_t revision = 0;
    try {
      revision = server_->host.submit_edit(wire::from_proto(m));
    } catch (const Error& e) {
      error(wire::BAD_REQUEST, e.what());
      return;
    }
    note(log::Level::Info, client_name_ + " submitted edit " + std::to_string(revision) + " (" +
                               std::to_string(m.ops_size()) + " operations)");
    wire::Envelope ack;
    wire::SceneEdit* a = ack.mutable_scene_edit();
    a->set_request_id(m.request_id());
    a->set_revision(revision);
    a->set_applied(false);
    send(ack);
  }

  // Compares a client's token with the server's in time independent of where they differ.
  static bool same_secret(const std::string& given, const std::string& secret) {
    unsigned char diff = given.size() == secret.size() ? 0 : 1;
    for (std::size_t i = 0; i < secret.size(); ++i)
      diff |= static_cast<unsigned char>((i < given.size() ? given[i] : '\0') ^ secret[i]);
    return diff == 0;
  }

  void send_stats() {
    const EngineHostStats es = server_->host.stats();
    const ServerStats ss = server_->stats();
    wire::Envelope e;
    wire::Stats* s = e.mutable_stats();
    s->set_clients(ss.clients);
    s->set_bytes_sent(ss.bytes_sent);
    s->set_tiles_sent(ss.tiles_sent);
    s->set_tiles_coalesced(ss.tiles_coalesced);
    s->set_updates(es.updates);
    s->set_rays_per_s(es.rays_per_s);
    s->set_convergence(es.convergence);
    s->set_engine_update_ms(es.last_update_ms);
    s->set_queue_depth(queue_.size() + (held_ ? 1 : 0));
    s->set_uptime_ms(static_cast<std::uint64_t>(
        std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - server_->started)
            .count()));
    s->set_bytes_received(ss.bytes_received);
    s->set_frames_received(ss.frames_received);
    s->set_errors_sent(ss.errors_sent);
    s->set_engine_idle(es.idle);
    s->set_bytes_per_texel(server_->host.tiles().bytes_per_texel());
    for (const EnginePassStats& p : es.passes) {
      wire::PassTime* pt = s->add_pass_times();
      pt->set_pass(p.pass);
      pt->set_bounce(p.bounce);
      pt->set_ms(1e3 * p.seconds);
      pt->set_rays(p.rays);
      pt->set_seconds_total(p.seconds_total);
      pt->set_rays_total(p.rays_total);
    }
    s->set_update_rate(es.update_rate);
    s->set_queue_depth_total(ss.queue_depth);
    s->set_queue_depth_max(ss.queue_depth_max);
    s->set_connections(ss.connections);
    s->set_clients_refused(ss.clients_refused);
    s->set_scene_bytes_sent(ss.scene_bytes_sent);
    s->set_tile_bytes_sent(ss.tile_bytes_sent);
    s->set_tiles_published(es.tiles_published);
    s->set_engine_seconds_total(es.seconds_total);
    s->set_rays_total(es.rays_total);
    for (std::size_t r = 0; r < kCloseReasons; ++r) {
      wire::SessionsClosed* c = s->add_sessions_closed();
      c->set_reason(close_reason_name(static_cast<CloseReason>(r)));
      c->set_sessions(ss.sessions_closed[r]);
    }
    s->set_tiles(es.tiles);
    s->set_texels(es.texels);
    s->set_backend(server_->host.backend_name());
    s->set_scene_revision(es.revision);
    s->set_last_edit_ms(es.last_edit_ms);
    s->set_stale_texels(es.stale_texels);
    send(e);
  }

  // A reply or notice; the connection stays open.
  void error(wire::ErrorCode code, const std::string& message) {
    note(log::Level::Info, "error sent: " + log::quote(message, 200));
    ++server_->errors_sent;
    send(wire::make_error(code, message));
  }

  // An Error frame, then close once it is written (or after a grace period if the client does
  // not read).
  void fail(wire::ErrorCode code, const std::string& message) {
    fail(code, message, reason_of(code));
  }
  void fail(wire::ErrorCode code, const std::string& message, CloseReason reason) {
    if (closed_ || closing_) return;
    note(log::Level::Info, "closed: " + log::quote(message, 200));
    ++server_->errors_sent;
    control_.push_back(wire::encode_frame(wire::make_error(code, message)));
    closing_ = true;
    close_reason_ = reason;
    close_timer_.expires_after(std::chrono::seconds(2));
    close_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (!ec) self->close(CloseReason::Disconnect);
    });
    pump();
  }

  void send(const wire::Envelope& e) { send_frame(wire::encode_frame(e)); }

  void send_frame(std::string frame) {
    if (closed_ || closing_) return;
    if (control_.size() >= server_->options.max_control_frames) {
      fail(wire::BAD_REQUEST,
           "the client does not read its replies (" + std::to_string(control_.size()) + " queued)",
           CloseReason::SlowClient);
      return;
    }
    control_.push_back(std::move(frame));
  }

  // Starts the next write if none is in flight: control frames first, then the scene package,
  // then tiles (within the byte-rate cap).
  void pump() {
    if (closed_ || writing_) return;
    std::string frame;
    std::shared_ptr<const std::string> shared;  // an edit broadcast, shared by every session
    bool is_tile = false, is_scene = false;
    if (!control_.empty()) {
      frame = std::move(control_.front());
      control_.pop_front();
    } else if (!edits_.empty() && !closing_) {
      shared = std::move(edits_.front());
      edits_.pop_front();
    } else if (closing_) {
      close(CloseReason::Disconnect);  // the reason fail() gave stands
      return;
    } else if (scene_active_) {
      frame = next_scene_chunk();
      is_scene = true;
    } else if (streaming_) {
      if (!next_tile(frame)) return;
      is_tile = true;
    } else {
      return;
    }
    writing_ = true;
    write_progress_at_ = Clock::now();
    write_progress_ = 0;
    arm_stall_timer();
    auto data = shared ? std::move(shared) : std::make_shared<const std::string>(std::move(frame));
    // The completion condition runs before each partial write: it notes progress for the
    // stall timer.
    auto progress = [self = this](const std::error_code& ec, std::size_t n) -> std::size_t {
      if (n > self->write_progress_) {
        self->write_progress_ = n;
        self->write_progress_at_ = Clock::now();
      }
      return asio::transfer_all()(ec, n);
    };
    asio::async_write(stream_, asio::buffer(*data), progress,
                      asio::bind_executor(strand_, [self = shared_from_this(), data, is_tile,
                                                    is_scene](std::error_code ec, std::size_t n) {
                        self->writing_ = false;
                        if (ec) {
                          self->close(CloseReason::Disconnect);
                          return;
                        }
                        self->server_->bytes_sent += n;
                        if (is_tile) {
                          ++self->server_->tiles_sent;
                          self->server_->tile_bytes_sent += n;
                        }
                        if (is_scene) self->server_->scene_bytes_sent += n;
                        const bool was_paused = self->paused();
                        self->pump();
                        if (was_paused && !self->paused())
                          self->drain();  // replies written: read on
                      }));
  }

  std::string next_scene_chunk() {
    const wire::ScenePackage& pkg = *package_;
    const std::size_t n =
        std::min<std::size_t>(server_->options.scene_chunk_bytes, pkg.bytes.size() - scene_offset_);
    wire::Envelope e;
    wire::SceneChunk* c = e.mutable_scene_chunk();
    c->set_scene_hash(pkg.hash);
    c->set_offset(scene_offset_);
    c->set_total(pkg.bytes.size());
    c->set_data(pkg.bytes.substr(scene_offset_, n));
    scene_offset_ += n;
    if (scene_offset_ >= pkg.bytes.size()) scene_active_ = false;
    return wire::encode_frame(e);
  }

  // The next tile frame to send, or false when there is none or the rate cap says wait.
  bool next_tile(std::string& frame) {
    const TileStore& store = server_->host.tiles();
    if (!held_) {
      std::uint32_t t = 0;
      for (;;) {
        if (!queue_.pop(t)) {
          queue_depth_ = 0;
          return false;
        }
        TileStore::Snapshot snap = store.snapshot(t, encoding_);
        if (snap.version == 0 || snap.version <= known_[t]) continue;  // nothing new
        const TileStore::Tile& tile = store.tile(t);
        wire::Envelope e;
        wire::TileUpdate* u = e.mutable_tile_update();
        u->set_lightmap(tile.lightmap);
        u->set_tile_x(tile.tx);
        u->set_tile_y(tile.ty);
        u->set_version(snap.version);
        u->set_encoding(encoding_);
        u->set_width(static_cast<std::uint32_t>(tile.rect.w));
        u->set_height(static_cast<std::uint32_t>(tile.rect.h));
        u->set_payload(*snap.payload);
        u->set_server_time_us(snap.time_us);
        held_frame_ = wire::encode_frame(e);
        held_ = true;
        known_[t] = snap.version;
        break;
      }
    }
    queue_depth_ = queue_.size() + 1;
    if (rate_ > 0.0) {
      const auto now = Clock::now();
      tokens_ =
          std::min(tokens_ + rate_ * std::chrono::duration<double>(now - last_refill_).count(),
                   std::max(rate_ * 0.25, 65536.0));
      last_refill_ = now;
      const double need = static_cast<double>(held_frame_.size());
      if (tokens_ < need) {
        if (!rate_waiting_) {
          rate_waiting_ = true;
          const double wait_s = (need - tokens_) / rate_;
          rate_timer_.expires_after(
              std::chrono::microseconds(static_cast<std::int64_t>(std::ceil(wait_s * 1e6))));
          rate_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
            self->rate_waiting_ = false;
            if (!ec) self->pump();
          });
        }
        return false;
      }
      tokens_ -= need;
    }
    frame = std::move(held_frame_);
    held_ = false;
    return true;
  }

  // Closes the connection. `reason` counts unless fail() gave one before.
  void close(CloseReason reason) {
    if (closed_) return;
    closed_ = true;
    if (!close_reason_) close_reason_ = reason;
    idle_timer_.cancel();
    rate_timer_.cancel();
    close_timer_.cancel();
    hello_timer_.cancel();
    penalty_timer_.cancel();
    stall_timer_.cancel();
    stream_.close();
    server_->partial_bytes -= partial_counted_;
    partial_counted_ = 0;
    server_->release(peer_key_);
    server_->host.set_camera(id_, std::nullopt);
    queue_changed();
    ++server_->sessions_closed[static_cast<std::size_t>(*close_reason_)];
    queue_depth_ = 0;
    log::debug("server", "session " + std::to_string(id_) + " ended (" +
                             close_reason_name(*close_reason_) + ")");
    server_->remove(shared_from_this());
  }

  Server::Impl* server_;
  asio::any_io_executor strand_;  // the strand the socket was accepted on
  wire::Stream stream_;
  asio::steady_timer idle_timer_, rate_timer_, close_timer_, hello_timer_, penalty_timer_,
      stall_timer_;
  wire::FrameDecoder decoder_;
  std::array<char, 64 * 1024> buffer_{};
  std::uint64_t id_;
  std::string peer_key_;  // what admit() counted this session under
  std::string peer_, client_name_;
  State state_ = State::AwaitHello;
  bool closed_ = false, closing_ = false, writing_ = false;
  bool reading_started_ = false, read_pending_ = false;
  bool penalty_ = false;  // a wrong token's answer is being delayed
  bool stall_armed_ = false;
  std::size_t write_progress_ = 0;  // bytes of the write in flight written so far
  Clock::time_point write_progress_at_{};
  std::int64_t partial_counted_ = 0;  // of the server's partial_bytes
  double log_tokens_ = 1e9;           // clamped to the burst at the first line
  Clock::time_point log_refill_ = Clock::now();
  std::uint64_t log_suppressed_ = 0;
  std::deque<std::string> control_;
  std::deque<std::shared_ptr<const std::string>> edits_;  // broadcasts not yet written
  std::shared_ptr<const wire::ScenePackage> package_;     // set by Hello
  bool scene_active_ = false;
  std::uint64_t scene_offset_ = 0;
  bool streaming_ = false;
  std::vector<std::uint8_t> subscribed_;
  std::vector<std::uint64_t> known_;  // newest version the client has (or has been sent)
  SendQueue queue_;
  std::uint64_t coalesced_counted_ = 0;  // of queue_.coalesced(), added to the server's counter
  std::optional<CloseReason> close_reason_;
  std::atomic<std::size_t> queue_depth_{0};
  wire::TileEncoding encoding_ = wire::TILE_RGB9E5_ZSTD;
  bool held_ = false;  // a tile frame waiting for the rate cap
  std::string held_frame_;
  double rate_ = 0.0, tokens_ = 0.0;
  bool rate_waiting_ = false;
  Clock::time_point last_refill_ = Clock::now();
};

}  // namespace

namespace {

// The address a peer is counted under: an IPv4 address (IPv4-mapped IPv6 included), or the /64
// of an IPv6 address (one subscriber's network gets one).
std::string peer_key_of(const tcp::socket& socket) {
  std::error_code ec;
  const tcp::endpoint ep = socket.remote_endpoint(ec);
  if (ec) return "?";
  asio::ip::address a = ep.address();
  if (a.is_v6() && a.to_v6().is_v4_mapped())
    a = asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6());
  if (a.is_v4()) return a.to_string();
  asio::ip::address_v6::bytes_type b = a.to_v6().to_bytes();
  std::fill(b.begin() + 8, b.end(), 0);
  return asio::ip::address_v6(b).to_string() + "/64";
}

bool out_of_descriptors(const std::error_code& ec) {
  return ec == asio::error::no_descriptors || ec.value() == ENFILE ||
         ec == asio::error::no_buffer_space || ec == asio::error::no_memory;
}

}  // namespace

Server::Impl::Admission Server::Impl::admit(const std::string& key) {
  const auto now = Clock::now();
  std::lock_guard lock(peers_mutex);
  // Forget peers with no session, no recent failure and no ban (bounded by the sessions and
  // the addresses that failed within the ban duration).
  if (peers.size() > 4 * static_cast<std::size_t>(options.max_clients) + 1024)
    std::erase_if(peers, [&](const auto& kv) {
      return kv.second.sessions == 0 && kv.second.banned_until <= now &&
             now - kv.second.last_seen > options.ban_duration;
    });
  Peer& p = peers[key];
  p.last_seen = now;
  if (p.banned_until > now) return Admission::Banned;
  if (options.max_clients_per_peer > 0 && p.sessions >= options.max_clients_per_peer)
    return Admission::PeerLimit;
  {
    std::lock_guard sl(sessions_mutex);
    if (sessions.size() >= options.max_clients) return Admission::Full;
  }
  ++p.sessions;
  return Admission::Ok;
}

void Server::Impl::release(const std::string& key) {
  std::lock_guard lock(peers_mutex);
  auto it = peers.find(key);
  if (it == peers.end() || it->second.sessions == 0) return;
  --it->second.sessions;
  it->second.last_seen = Clock::now();
}

std::pair<std::chrono::milliseconds, bool> Server::Impl::token_failed(const std::string& key) {
  const auto now = Clock::now();
  std::lock_guard lock(peers_mutex);
  Peer& p = peers[key];
  // Failures older than the ban duration are forgiven.
  if (now - p.last_seen > options.ban_duration) p.token_failures = 0;
  p.last_seen = now;
  ++p.token_failures;
  const std::uint32_t doublings = std::min<std::uint32_t>(p.token_failures - 1, 5);
  const auto delay = options.token_failure_delay * (1 << doublings);
  if (p.token_failures >= options.max_token_failures) {
    p.banned_until = now + options.ban_duration;
    p.token_failures = 0;
    log::warn("server", "peer " + key + ": " + std::to_string(options.max_token_failures) +
                            " wrong control tokens; refused for " +
                            std::to_string(options.ban_duration.count() / 1000) + " s");
    return {delay, true};
  }
  return {delay, false};
}

void Server::Impl::token_passed(const std::string& key) {
  std::lock_guard lock(peers_mutex);
  auto it = peers.find(key);
  if (it != peers.end()) it->second.token_failures = 0;
}

// Closes a connection that is not admitted: one Error frame, best effort (never blocks: the
// socket is non-blocking and the frame is small), then close.
void Server::Impl::refuse(tcp::socket& socket, const std::string& message) {
  std::error_code ignored;
  if (!tls) {
    socket.non_blocking(true, ignored);
    const std::string frame = wire::encode_frame(wire::make_error(wire::INTERNAL, message));
    socket.write_some(asio::buffer(frame), ignored);
  }
  socket.close(ignored);
}

void Server::Impl::accept() {
  acceptor.async_accept(asio::make_strand(io), [self = this](std::error_code ec,
                                                             tcp::socket socket) {
    if (self->stopping) return;
    if (!ec) {
      if (self->accept_backoff.count() > 0) {
        log::warn("server", "accepting connections again");
        self->accept_backoff = std::chrono::milliseconds(0);
      }
      ++self->connections;
      const std::string key = peer_key_of(socket);
      switch (self->admit(key)) {
        case Admission::Ok: {
          std::error_code ignored;
          if (self->options.socket_send_buffer > 0)
            socket.set_option(asio::socket_base::send_buffer_size(self->options.socket_send_buffer),
                              ignored);
          auto s = std::make_shared<Session>(self, std::move(socket), key);
          {
            std::lock_guard lock(self->sessions_mutex);
            self->sessions.insert(s);
          }
          s->start();
          break;
        }
        case Admission::Full:
          ++self->clients_refused;
          self->refuse(socket, "the server is full");
          break;
        case Admission::PeerLimit:
          ++self->peer_refused;
          self->refuse(socket, "too many connections from this address (" +
                                   std::to_string(self->options.max_clients_per_peer) + ")");
          break;
        case Admission::Banned:
          ++self->banned_refused;
          self->refuse(socket, "this address is refused for a while (wrong control tokens)");
          break;
      }
    } else if (ec == asio::error::operation_aborted) {
      return;
    } else {
      ++self->accept_errors;
      if (out_of_descriptors(ec)) {
        // Out of file descriptors (or kernel memory): the pending connection stays in the
        // backlog. Pause accepting, doubling the pause up to 1 s, and say so once.
        if (self->accept_backoff.count() == 0)
          log::warn("server", "accept: " + ec.message() + " (" +
                                  std::to_string(self->client_count()) +
                                  " sessions); pausing accepts until descriptors are free");
        self->accept_backoff = std::clamp(self->accept_backoff * 2, std::chrono::milliseconds(10),
                                          std::chrono::milliseconds(1000));
        self->accept_timer.expires_after(self->accept_backoff);
        self->accept_timer.async_wait([self](std::error_code tec) {
          if (!tec && !self->stopping) self->accept();
        });
        return;
      }
      log::warn("server", "accept: " + ec.message());
    }
    self->accept();
  });
}

void Server::Impl::on_publish(const std::vector<std::uint32_t>& tiles) {
  auto shared = std::make_shared<const std::vector<std::uint32_t>>(tiles);
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

Server::Server(EngineHost& host, ServerOptions options)
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
  if (!o.tls_cert.empty()) im.tls = wire::make_server_tls(o.tls_cert, o.tls_key);
  im.hello_frame_cap = std::min(o.max_frame, o.max_hello_frame + 32 * host.tiles().tile_count());
}

Server::~Server() {
  stop();
}

void Server::start() {
  Impl& im = *impl_;
  std::error_code ec;
  asio::ip::address address = asio::ip::make_address(im.options.bind, ec);
  if (ec) throw Error("--bind: '" + im.options.bind + "' is not an IP address");
  tcp::endpoint endpoint(address, im.options.port);
  im.acceptor.open(endpoint.protocol(), ec);
  if (!ec) im.acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) im.acceptor.bind(endpoint, ec);
  if (!ec) im.acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    throw Error("cannot listen on " + im.options.bind + ":" + std::to_string(im.options.port) +
                ": " + ec.message());
  std::weak_ptr<Impl> weak = impl_;
  im.host.set_listener([weak](const std::vector<std::uint32_t>& tiles) {
    if (auto s = weak.lock()) s->on_publish(tiles);
  });
  im.host.set_edit_listener([weak](const AppliedEdit& applied) {
    if (auto s = weak.lock()) s->on_edit(applied);
  });
  im.work.emplace(asio::make_work_guard(im.io));
  im.accept();
  for (int i = 0; i < im.options.io_threads; ++i)
    im.threads.emplace_back([&im] {
      set_thread_name("irradcast-io");
      for (;;) {
        try {
          im.io.run();
          break;
        } catch (const std::exception& e) {
          // A handler threw: log it and keep serving the other clients.
          log::error("server", std::string("I/O handler failed: ") + e.what());
        }
      }
    });
  log::info("server", "listening on " + im.options.bind + ":" + std::to_string(port()));
}

void Server::stop() {
  Impl& im = *impl_;
  if (im.stopping.exchange(true)) return;
  im.host.set_listener(nullptr);
  im.host.set_edit_listener(nullptr);
  if (im.threads.empty()) return;
  asio::post(im.io, [&im] {
    std::error_code ec;
    im.acceptor.close(ec);
    im.accept_timer.cancel();
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
  std::error_code ec;
  auto ep = impl_->acceptor.local_endpoint(ec);
  return ec ? impl_->options.port : ep.port();
}

ServerStats Server::stats() const {
  return impl_->stats();
}

ServerStats Server::Impl::stats() const {
  const Impl& im = *this;
  ServerStats s;
  s.clients = im.client_count();
  s.connections = im.connections.load();
  s.clients_refused = im.clients_refused.load();
  s.bytes_sent = im.bytes_sent.load();
  s.bytes_received = im.bytes_received.load();
  s.frames_received = im.frames_received.load();
  s.tiles_sent = im.tiles_sent.load();
  s.tile_bytes_sent = im.tile_bytes_sent.load();
  s.tiles_coalesced = im.tiles_coalesced.load();
  s.scene_bytes_sent = im.scene_bytes_sent.load();
  s.errors_sent = im.errors_sent.load();
  s.peer_refused = im.peer_refused.load();
  s.banned_refused = im.banned_refused.load();
  s.accept_errors = im.accept_errors.load();
  s.token_failures = im.token_failures.load();
  s.edits_dropped = im.edits_dropped.load();
  s.log_lines_suppressed = im.log_lines_suppressed.load();
  s.partial_bytes = static_cast<std::uint64_t>(std::max<std::int64_t>(0, im.partial_bytes.load()));
  for (std::size_t r = 0; r < kCloseReasons; ++r)
    s.sessions_closed[r] = im.sessions_closed[r].load();
  s.uptime_seconds = std::chrono::duration<double>(Clock::now() - im.started).count();
  std::lock_guard lock(im.sessions_mutex);
  for (const auto& session : im.sessions) {
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
  switch (reason) {
    case CloseReason::Bye:
      return "bye";
    case CloseReason::Disconnect:
      return "disconnect";
    case CloseReason::IdleTimeout:
      return "idle_timeout";
    case CloseReason::BadFrame:
      return "bad_frame";
    case CloseReason::FrameTooLarge:
      return "frame_too_large";
    case CloseReason::UnsupportedVersion:
      return "unsupported_version";
    case CloseReason::UnexpectedMessage:
      return "unexpected_message";
    case CloseReason::SlowClient:
      return "slow_client";
    case CloseReason::Shutdown:
      return "shutdown";
    case CloseReason::Internal:
      return "internal";
    case CloseReason::HelloTimeout:
      return "hello_timeout";
    case CloseReason::TokenFailures:
      return "token_failures";
    case CloseReason::Tls:
      return "tls";
  }
  return "unknown";
}

}  // namespace irradcast

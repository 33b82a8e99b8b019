#include "irradcast/client/load_generator.h"

#include <asio.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>

#include "irradcast/client/camera_message.h"
#include "irradcast/client/client_session.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/scene_package.h"
#include "latency_histogram.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;
namespace {

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// The scene as the users need it. Every user downloads the package and checks its hash; the
// unpacking (and in render mode the BVH) is done once per process and shared, since it is the
// same for everyone and would only make the load generator, not the server, slower. (The users
// do not follow edits, so nobody changes a shared scene.)
class SceneCache {
 public:
  std::shared_ptr<ClientScene> get(const std::string& bytes, const std::string& hash,
                                   bool need_rays) {
    if (wire::sha256(bytes) != hash) throw Error("the scene package does not match its hash");
    std::lock_guard lock(mutex_);
    auto it = scenes_.find(hash);
    if (it != scenes_.end()) return it->second;
    auto s = std::make_shared<ClientScene>();
    s->unpacked = wire::open_scene_package(bytes, hash);
    s->world = World::build(s->unpacked.scene);
    if (need_rays) s->build_ray_scenes();
    scenes_.emplace(hash, s);
    return s;
  }

 private:
  std::mutex mutex_;
  std::map<std::string, std::shared_ptr<ClientScene>> scenes_;
};

// What all users share: options, the io_context, the resolved servers, and live counters.
struct Run {
  explicit Run(const LoadOptions& o) : options(o), servers(servers_or(o.servers, o.host, o.port)) {}
  const LoadOptions& options;
  const std::vector<HostPort> servers;  // the failover list
  asio::io_context io;
  std::vector<tcp::resolver::results_type> endpoints;  // one per server
  std::shared_ptr<asio::ssl::context> tls;             // null: plain TCP
  Clock::time_point start = Clock::now();
  Clock::time_point end = Clock::time_point::max();  // users retry connections until then
  SceneCache scenes;
  std::vector<CameraKeyframe> keyframes;
  std::atomic<int> connected{0}, scene_loaded{0}, full_image{0}, failed{0};
  std::atomic<std::uint64_t> tiles{0}, bytes{0}, frames{0}, errors{0}, reconnects{0};
  LatencyHistogram latency;
  std::shared_ptr<TileDecodeCache> decodes = std::make_shared<TileDecodeCache>();
  std::mutex errors_mutex;
  std::map<std::string, std::uint64_t> error_kinds;

  void count_error(const std::string& kind) {
    ++errors;
    std::lock_guard lock(errors_mutex);
    ++error_kinds[kind];
  }
  double elapsed_s() const { return std::chrono::duration<double>(Clock::now() - start).count(); }
};

// One connection of a user: the socket and everything tied to its byte stream. Every handler
// holds the connection it was started for, so a handler of a dropped connection finds its
// buffers alive and sees that it is no longer the user's connection.
struct Connection {
  Connection(const asio::strand<asio::io_context::executor_type>& strand, asio::ssl::context* tls)
      : socket(strand, tls), decoder(64u << 20) {}
  wire::Stream socket;  // TCP, or TLS over it
  wire::FrameDecoder decoder;
  std::array<char, 64 * 1024> buffer{};
  std::deque<std::string> out;  // frames to write, the front one in flight while `writing`
  bool writing = false;
  std::string server_error;  // the last Error frame the server sent on this connection
};

// One simulated user. Every handler runs on the user's strand.
class User : public std::enable_shared_from_this<User> {
 public:
  User(Run& run, int index)
      : run_(run),
        index_(index),
        strand_(asio::make_strand(run.io)),
        retry_timer_(strand_),
        reply_timer_(strand_),
        camera_timer_(strand_),
        ping_timer_(strand_),
        frame_timer_(strand_),
        close_timer_(strand_),
        server_(static_cast<std::size_t>(index) % run.servers.size()),
        backoff_(run.options.backoff,
                 mix64(run.options.seed ^ mix64(static_cast<std::uint64_t>(index) + 1))),
        core_(session_options(run, index),
              [&run](const std::string& bytes, const std::string& hash) {
                return run.scenes.get(bytes, hash, run.options.render);
              }) {}

  void start(Clock::duration delay) {
    retry_timer_.expires_after(delay);
    retry_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (ec || self->finishing_) return;
      self->started_ = Clock::now();
      self->open_connection();
    });
  }

  // End of the run: Bye, then close once it is written (or after a second).
  void finish() {
    asio::post(strand_, [self = shared_from_this()] { self->do_finish(); });
  }

  // After the I/O threads are joined (also for a user the run had to stop before it closed).
  LoadUserResult result() const {
    LoadUserResult r = result_;
    if (r.frames > 0) r.frame_ms_mean = frame_ms_total_ / static_cast<double>(r.frames);
    if (r.full_image) {
      r.bytes_after_full_image = r.bytes_received - r.bytes_to_full_image;
      const Clock::time_point end = closed_ ? closed_at_ : Clock::now();
      r.seconds_after_full_image = std::chrono::duration<double>(end - full_image_at_).count();
    }
    r.tiles_held = core_.tiles().tiles_received();
    r.versions_digest = versions_digest(core_.tiles().versions());
    return r;
  }
  std::vector<double> take_latencies() { return std::move(latencies_ms_); }
  std::vector<double> take_steady_latencies() { return std::move(steady_ms_); }

 private:
  // Waiting: no connection, the next attempt after a back-off delay (or none before the end).
  // Session: Hello sent; the protocol's phase is the core's.
  enum class State { Idle, Connecting, Session, Waiting, Done };
  using Phase = ClientSession::Phase;

  static ClientSessionOptions session_options(const Run& run, int index) {
    const LoadOptions& o = run.options;
    ClientSessionOptions s;
    if (!o.decode_per_user) {
      s.shared_decodes = run.decodes;
      // Thin users never compose: they keep references to the shared decodes.
      if (!o.render && !o.copy_shared_texels) s.shared_texels = SharedTexels::Reference;
    }
    s.name = o.name + "-" + std::to_string(index);
    s.encoding = o.encoding;
    s.ping_interval = std::chrono::milliseconds(5000);
    s.min_ping_interval = std::chrono::milliseconds(100);
    s.follow_edits = false;
    s.log_tag = "load";
    s.presence = o.presence;
    return s;
  }

  using ConnPtr = std::shared_ptr<Connection>;

  // A connection attempt (the socket: here, read(), write_next() and drop_connection()).
  void open_connection() {
    state_ = State::Connecting;
    conn_ = std::make_shared<Connection>(strand_, run_.tls.get());
    conn_->socket.expect_server_name(run_.servers[server_].host);
    asio::async_connect(
        conn_->socket.socket(), run_.endpoints[server_],
        [self = shared_from_this(), c = conn_](std::error_code ec, const tcp::endpoint&) {
          if (c == self->conn_) self->on_connect(ec);
        });
  }

  void on_connect(std::error_code ec) {
    if (finishing_ || closed_) return;
    if (ec) {
      // Refused or unreachable: not an error yet, only if it lasts to the end of the run.
      last_error_ = ec.message();
      drop_connection();
      retry_later();
      return;
    }
    std::error_code ignored;
    conn_->socket.socket().set_option(tcp::no_delay(true), ignored);
    conn_->socket.async_handshake(
        asio::ssl::stream_base::client,
        asio::bind_executor(strand_, [self = shared_from_this(), c = conn_](std::error_code hec) {
          if (c == self->conn_) self->on_secured(hec);
        }));
  }

  // After the TLS handshake (at once without TLS): Hello.
  void on_secured(std::error_code ec) {
    if (finishing_ || closed_) return;
    if (ec) {
      // An untrusted certificate or a server without TLS stays so: fail. A cut: retry.
      if (ec.category() == asio::error::get_ssl_category()) {
        fail("tls", wire::describe_tls_error(ec));
        return;
      }
      last_error_ = wire::describe_tls_error(ec);
      drop_connection();
      retry_later();
      return;
    }
    if (!result_.connected) {
      result_.connected = true;
      ++run_.connected;
    }
    send(core_.hello());  // resuming with the scene and tile versions held
    state_ = State::Session;
    arm_reply_timer("no Welcome within the reply timeout");
    read();
  }

  // The next attempt, on the next server, after a back-off (none if the run ends first).
  void retry_later() {
    state_ = State::Waiting;
    server_ = (server_ + 1) % run_.servers.size();
    const auto delay = backoff_.next_before(Clock::now(), run_.end);
    if (!delay) return;
    retry_timer_.expires_after(*delay);
    retry_timer_.async_wait([self = shared_from_this()](std::error_code e) {
      if (!e && !self->finishing_ && !self->closed_) self->open_connection();
    });
  }

  // The connection is gone (reset, EOF, a write error, a server Error that ends it, a timed-out
  // handshake or download): count it under `kind` ("" = already counted) and reconnect.
  void lost(const std::string& kind, const std::string& detail) {
    if (closed_) return;
    if (finishing_) {
      close();
      return;
    }
    if (!kind.empty()) run_.count_error(kind);
    last_error_ = (kind.empty() ? std::string("server error") : kind) + ": " + detail;
    ++result_.connections_lost;
    lost_ = true;
    drop_connection();
    retry_later();
  }

  void arm_reply_timer(const char* what) {
    reply_timer_.expires_after(run_.options.reply_timeout);
    reply_timer_.async_wait([self = shared_from_this(), c = conn_, what](std::error_code ec) {
      if (ec || c != self->conn_ || self->finishing_ || self->closed_) return;
      const Phase phase = self->core_.phase();
      if (self->state_ == State::Session && phase != Phase::Streaming) self->lost("timeout", what);
    });
  }

  void read() {
    ConnPtr c = conn_;
    c->socket.async_read_some(asio::buffer(c->buffer),
                              [self = shared_from_this(), c](std::error_code ec, std::size_t n) {
                                self->on_read(c, ec, n);
                              });
  }

  void on_read(const ConnPtr& c, std::error_code ec, std::size_t n) {
    if (closed_ || c != conn_) return;
    if (ec) {
      if (finishing_)
        close();
      else if (!c->server_error.empty())
        fail("", c->server_error);  // the server refused us (counted as its Error): no retry
      else
        lost("disconnected", ec == asio::error::eof ? "the server closed the connection"
                                                    : wire::describe_tls_error(ec));
      return;
    }
    result_.bytes_received += n;
    run_.bytes += n;
    c->decoder.feed(c->buffer.data(), n);
    wire::Envelope env;
    for (;;) {
      const wire::DecodeStatus st = c->decoder.next(env);
      if (st == wire::DecodeStatus::NeedMore) break;
      if (st != wire::DecodeStatus::Frame) {
        fail("bad frame", c->decoder.error());
        return;
      }
      handle(env);
      if (closed_ || c != conn_) return;
    }
    read();
  }

  void handle(const wire::Envelope& env) {
    using Event = ClientStep::Event;
    if (finishing_ && env.msg_case() != wire::Envelope::kError) return;  // Bye is on its way
    if (env.has_avatars()) {
      ++result_.avatar_messages;
      result_.avatars_listed += static_cast<std::uint64_t>(env.avatars().avatars_size());
      result_.avatar_bytes += env.ByteSizeLong() + wire::kFrameHeaderBytes;
    }
    try {
      const ClientStep step = core_.on_frame(env);
      switch (step.event) {
        case Event::NeedScene:
          send(core_.download());
          arm_reply_timer("the scene download stalled");
          break;
        case Event::Downloading:
          arm_reply_timer("the scene download stalled");
          break;
        case Event::SessionReady:
          on_ready(step);
          break;
        case Event::TileApplied:
          on_tile(env.tile_update());
          break;
        case Event::ServerError: {
          const std::string code = wire::ErrorCode_Name(env.error().code());
          conn_->server_error = code + ": " + env.error().message();
          run_.count_error("server " + code);
          // The server closes after these: reconnect now, not at the EOF (refused by the only
          // server: the user fails at the EOF, as a retry would be refused again).
          if (server_error_is_transient(env.error().code()) && !finishing_ &&
              (env.error().code() != wire::REFUSED || run_.servers.size() > 1))
            lost("", conn_->server_error);
          break;
        }
        default:
          break;  // Pong, Stats, Bye, edits (the users do not follow them), anything newer
      }
    } catch (const ClientSessionFailure& f) {
      fail(f.kind(), f.what());
    }
  }

  // Set up (after a download: a new scene): subscribe; start camera updates, pings, frames.
  void on_ready(const ClientStep& step) {
    if (step.scene_loaded) {
      if (!result_.scene_loaded) {
        result_.scene_loaded = true;
        result_.scene_ms = ms_between(started_, Clock::now());
        ++run_.scene_loaded;
      }
      make_path();
    }
    reply_timer_.cancel();
    backoff_.reset();
    if (lost_) {
      lost_ = false;
      ++result_.reconnects;
      ++run_.reconnects;
    }
    subscribed_us_ = wall_time_us();
    for (const wire::Envelope& e : step.send) send(e);  // the Subscribe
    if (run_.options.camera_hz > 0.0) send_camera();
    arm_ping();
    if (run_.options.render) arm_frame(Clock::now());
  }

  void make_path() {
    const double phase =
        run_.options.users > 0 ? static_cast<double>(index_) / run_.options.users : 0.0;
    const std::string& p = run_.options.camera_path;
    if (p == "orbit")
      path_ = CameraPath::orbit(core_.scene().world.bounds, 20.0, phase);
    else if (p == "random-walk")
      path_ = CameraPath::random_walk(core_.scene().world.bounds,
                                      run_.options.seed * 7919u + static_cast<unsigned>(index_));
    else
      path_ = CameraPath::keyframes(run_.keyframes, phase);
  }

  // A tile newer than the one held was applied: its latency.
  void on_tile(const wire::TileUpdate& t) {
    ++result_.tiles_applied;
    ++run_.tiles;
    if (t.server_time_us() >= subscribed_us_) {
      const std::uint64_t now = wall_time_us();
      const double us =
          now > t.server_time_us() ? static_cast<double>(now - t.server_time_us()) : 0.0;
      latencies_ms_.push_back(us / 1000.0);
      if (run_.full_image.load() == run_.options.users) {
        steady_ms_.push_back(us / 1000.0);
        ++result_.tiles_steady;
      }
      run_.latency.add(us);
      ++result_.tiles_live;
    }
    if (!run_.options.render && !result_.full_image && core_.tiles().all_received())
      mark_full_image();
  }

  void mark_full_image() {
    result_.full_image = true;
    result_.full_image_ms = ms_between(started_, Clock::now());
    result_.bytes_to_full_image = result_.bytes_received;
    full_image_at_ = Clock::now();
    ++run_.full_image;
  }

  // The timers of a session stop with its connection (drop_connection cancels them; a handler
  // that was already queued sees another connection, or none, and does nothing).
  bool streaming_on(const ConnPtr& c) const {
    return c == conn_ && state_ == State::Session && core_.phase() == Phase::Streaming &&
           !finishing_ && !closed_;
  }

  void send_camera() {
    send(camera_update(path_.at(run_.elapsed_s())));
    ++result_.camera_updates;
    camera_timer_.expires_after(std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / run_.options.camera_hz)));
    camera_timer_.async_wait([self = shared_from_this(), c = conn_](std::error_code ec) {
      if (!ec && self->streaming_on(c)) self->send_camera();
    });
  }

  void arm_ping() {
    ping_timer_.expires_after(core_.ping_interval());
    ping_timer_.async_wait([self = shared_from_this(), c = conn_](std::error_code ec) {
      if (ec || !self->streaming_on(c)) return;
      if (Clock::now() - self->last_sent_ >= self->core_.ping_interval())
        self->send(ClientSession::ping(self->result_.tiles_applied, wall_time_us()));
      self->arm_ping();
    });
  }

  void arm_frame(Clock::time_point at) {
    frame_timer_.expires_at(at);
    frame_timer_.async_wait([self = shared_from_this(), c = conn_](std::error_code ec) {
      if (!ec && self->streaming_on(c)) self->render_frame();
    });
  }

  void render_frame() {
    const auto t0 = Clock::now();
    const ClientScene& s = core_.scene();
    const DynamicView dynamic{s.dynamic_rays.get(), core_.probe_volume().lit(), s.lights.get()};
    const ImageRGB img = compose(s.world, *s.rays, s.unpacked.atlas, core_.tiles().lightmaps(),
                                 path_.at(run_.elapsed_s()), run_.options.width,
                                 run_.options.height, nullptr, &dynamic);
    (void)img;
    const auto t1 = Clock::now();
    frame_ms_total_ += ms_between(t0, t1);
    ++result_.frames;
    ++run_.frames;
    if (!result_.full_image && core_.tiles().all_received()) mark_full_image();
    const auto period = run_.options.fps > 0.0
                            ? std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(1.0 / run_.options.fps))
                            : Clock::duration::zero();
    arm_frame(std::max(t1, t0 + period));
  }

  void send(const wire::Envelope& e) {
    if (closed_ || !conn_) return;
    conn_->out.push_back(wire::encode_frame(e));
    last_sent_ = Clock::now();
    write_next();
  }

  void write_next() {
    ConnPtr c = conn_;
    if (closed_ || !c || c->writing || c->out.empty()) return;
    c->writing = true;
    asio::async_write(c->socket, asio::buffer(c->out.front()),
                      [self = shared_from_this(), c](std::error_code ec, std::size_t) {
                        c->writing = false;
                        if (self->closed_ || c != self->conn_) return;
                        c->out.pop_front();
                        if (ec) {
                          if (self->finishing_)
                            self->close();
                          else if (!c->server_error.empty())
                            self->fail("", c->server_error);  // counted as the Error
                          else
                            self->lost("disconnected", "write: " + ec.message());
                          return;
                        }
                        if (c->out.empty() && self->finishing_)
                          self->close();
                        else
                          self->write_next();
                      });
  }

  void do_finish() {
    if (finishing_ || closed_) return;
    finishing_ = true;
    const bool live = conn_ && state_ == State::Session;
    if (!live) {
      if (result_.failure.empty()) {
        const std::string last = last_error_.empty() ? "" : " (last: " + last_error_ + ")";
        if (!result_.connected) {
          result_.failure = "connect: not connected by the end of the run" + last;
          run_.count_error("connect");
        } else {
          result_.failure = "reconnect: not connected again by the end of the run" + last;
          run_.count_error("reconnect");
        }
        ++run_.failed;
      }
      close();
      return;
    }
    conn_->out.push_back(wire::encode_frame(wire::make_bye("load test done")));
    write_next();
    close_timer_.expires_after(std::chrono::seconds(1));
    close_timer_.async_wait([self = shared_from_this()](std::error_code ec) {
      if (!ec) self->close();
    });
  }

  // Records a failure of this user (kind "" = already counted) and closes: for what reconnecting
  // would not cure (a protocol error, a bad frame, tile or scene, a session the server refused).
  void fail(const std::string& kind, const std::string& detail) {
    if (closed_) return;
    if (!kind.empty()) run_.count_error(kind);
    if (result_.failure.empty()) {
      result_.failure = (kind.empty() ? std::string("server error") : kind) + ": " + detail;
      ++run_.failed;
    }
    close();
  }

  // Closes the connection (if any) and stops its session's timers; the user lives on.
  void drop_connection() {
    for (asio::steady_timer* t : {&reply_timer_, &camera_timer_, &ping_timer_, &frame_timer_})
      t->cancel();
    if (!conn_) return;
    core_.disconnect();
    conn_->socket.close();
    conn_.reset();
  }

  void close() {
    if (closed_) return;
    closed_ = true;
    state_ = State::Done;
    retry_timer_.cancel();
    close_timer_.cancel();
    drop_connection();
    closed_at_ = Clock::now();
  }

  Run& run_;
  int index_;
  asio::strand<asio::io_context::executor_type> strand_;
  ConnPtr conn_;  // null between connections
  asio::steady_timer retry_timer_, reply_timer_, camera_timer_, ping_timer_, frame_timer_,
      close_timer_;
  std::size_t server_;  // index into run_.servers: users spread their first attempt over them
  Backoff backoff_;
  bool finishing_ = false, closed_ = false;
  bool lost_ = false;  // a connection dropped since the last session was set up
  State state_ = State::Idle;
  Clock::time_point started_ = Clock::now(), last_sent_ = Clock::now(), full_image_at_{},
                    closed_at_{};
  std::string last_error_;  // why the last connection attempt failed or the last one dropped
  ClientSession core_;      // the protocol: the viewer's code
  CameraPath path_;
  std::uint64_t subscribed_us_ = 0;
  double frame_ms_total_ = 0.0;
  std::vector<double> latencies_ms_, steady_ms_;
  LoadUserResult result_;
};

// Camera keyframes, the server's address and the TLS context: everything that can fail before
// a user starts.
void prepare(Run& run) {
  const LoadOptions& options = run.options;
  if (options.camera_path != "orbit" && options.camera_path != "random-walk")
    run.keyframes = load_camera_keyframes(options.camera_path);
  tcp::resolver resolver(run.io);
  for (const HostPort& server : run.servers) {
    std::error_code ec;
    run.endpoints.push_back(resolver.resolve(server.host, std::to_string(server.port), ec));
    if (ec) throw Error("cannot resolve '" + server.host + "': " + ec.message());
  }
  run.tls = make_tls_context(options.tls);
}

std::vector<std::thread> start_io_threads(Run& run) {
  const int threads = run.options.threads > 0
                          ? run.options.threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i)
    pool.emplace_back([&run] {
      for (;;) {
        try {
          run.io.run();
          return;
        } catch (const std::exception& e) {
          // A handler threw (a bug): count it and keep the other users going.
          run.count_error(std::string("internal: ") + e.what());
        }
      }
    });
  return pool;
}

// The main thread reports progress until the end of the run.
void report_progress(Run& run, const std::function<void(const LoadProgress&)>& on_progress) {
  auto next_report = run.start + std::chrono::seconds(1);
  while (Clock::now() < run.end) {
    std::this_thread::sleep_until(std::min(run.end, next_report));
    if (Clock::now() < next_report) continue;
    next_report += std::chrono::seconds(1);
    if (!on_progress) continue;
    LoadProgress p;
    p.elapsed_s = run.elapsed_s();
    p.users = run.options.users;
    p.connected = run.connected;
    p.scene_loaded = run.scene_loaded;
    p.full_image = run.full_image;
    p.failed = run.failed;
    p.tiles_applied = run.tiles;
    p.bytes_received = run.bytes;
    p.frames = run.frames;
    p.errors = run.errors;
    p.reconnects = run.reconnects;
    p.latency_p99_ms = run.latency.take_p99_ms();
    on_progress(p);
  }
}

// Users close within a second of finish(); a server that never reads makes us stop anyway.
void join_io_threads(Run& run, std::vector<std::thread>& pool) {
  std::mutex done_mutex;
  std::condition_variable done_cv;
  bool done = false;
  std::thread stopper([&] {
    std::unique_lock lock(done_mutex);
    if (!done_cv.wait_for(lock, std::chrono::seconds(3), [&] { return done; })) run.io.stop();
  });
  for (auto& t : pool) t.join();
  {
    std::lock_guard lock(done_mutex);
    done = true;
  }
  done_cv.notify_all();
  stopper.join();
}

}  // namespace

LoadReport run_load(const LoadOptions& options,
                    const std::function<void(const LoadProgress&)>& on_progress) {
  options.validate();
  Run run(options);
  prepare(run);

  std::vector<std::shared_ptr<User>> users;
  users.reserve(static_cast<std::size_t>(options.users));
  run.start = Clock::now();
  run.end = run.start + std::chrono::duration_cast<Clock::duration>(
                            std::chrono::duration<double>(options.duration_s));
  for (int i = 0; i < options.users; ++i) {
    users.push_back(std::make_shared<User>(run, i));
    const double at = options.users > 1 ? options.ramp_s * i / (options.users - 1) : 0.0;
    users.back()->start(
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(at)));
  }
  auto work = asio::make_work_guard(run.io);
  std::vector<std::thread> pool = start_io_threads(run);
  report_progress(run, on_progress);
  const double elapsed = run.elapsed_s();
  for (auto& u : users) u->finish();
  work.reset();
  join_io_threads(run, pool);

  std::vector<LoadUserResult> results;
  std::vector<double> latency, steady_latency;
  for (auto& u : users) {
    results.push_back(u->result());
    std::vector<double> l = u->take_latencies();
    latency.insert(latency.end(), l.begin(), l.end());
    l = u->take_steady_latencies();
    steady_latency.insert(steady_latency.end(), l.begin(), l.end());
  }
  return LoadReport::of(options, elapsed, std::move(results), std::move(latency),
                        std::move(steady_latency), run.error_kinds);
}

}  // namespace irradcast

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
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/wire/frame.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast/client/tile_cache.h"

namespace irradcast {

using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

std::uint64_t now_us() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// The scene as the users need it. Every user downloads the package and checks its hash; the
// unpacking (and in render mode the BVH) is done once per process and shared, since it is the
// same for everyone and would only make the load generator, not the server, slower.
struct SharedScene {
  wire::UnpackedScene unpacked;
  World world;
  std::unique_ptr<RayScene> rays;
};

class SceneCache {
 public:
  std::shared_ptr<const SharedScene> get(const std::string& bytes, const std::string& hash,
                                         bool need_rays) {
    std::lock_guard lock(mutex_);
    auto it = scenes_.find(hash);
    if (it != scenes_.end()) return it->second;
    auto s = std::make_shared<SharedScene>();
    s->unpacked = wire::open_scene_package(bytes, hash);
    s->world = World::build(s->unpacked.scene);
    if (need_rays) s->rays = std::make_unique<RayScene>(s->world);
    scenes_.emplace(hash, s);
    return s;
  }

 private:
  std::mutex mutex_;
  std::map<std::string, std::shared_ptr<const SharedScene>> scenes_;
};

// Tile latencies for the progress line: 8 buckets per octave of microseconds.
class LatencyHistogram {
 public:
  static constexpr int kBuckets = 8 * 32;
  void add(double us) {
    const int b = std::clamp(static_cast<int>(std::log2(us + 1.0) * 8.0), 0, kBuckets - 1);
    counts_[static_cast<std::size_t>(b)].fetch_add(1, std::memory_order_relaxed);
  }
  // p99 in ms of what was added since the last call.
  double take_p99_ms() {
    std::array<std::uint64_t, kBuckets> now{};
    std::uint64_t total = 0;
    for (int b = 0; b < kBuckets; ++b) {
      const auto i = static_cast<std::size_t>(b);
      now[i] = counts_[i].load(std::memory_order_relaxed) - seen_[i];
      seen_[i] += now[i];
      total += now[i];
    }
    if (total == 0) return 0.0;
    const auto rank = static_cast<std::uint64_t>(std::ceil(0.99 * static_cast<double>(total)));
    std::uint64_t acc = 0;
    for (int b = 0; b < kBuckets; ++b) {
      acc += now[static_cast<std::size_t>(b)];
      if (acc >= rank) return (std::exp2((b + 1) / 8.0) - 1.0) / 1000.0;  // bucket's upper edge
    }
    return 0.0;
  }

 private:
  std::array<std::atomic<std::uint64_t>, kBuckets> counts_{};
  std::array<std::uint64_t, kBuckets> seen_{};
};

// What all users share: options, the io_context, the resolved server, and live counters.
struct Run {
  explicit Run(const LoadOptions& o) : options(o) {}
  const LoadOptions& options;
  asio::io_context io;
  tcp::resolver::results_type endpoints;
  std::shared_ptr<asio::ssl::context> tls;  // null: plain TCP
  Clock::time_point start = Clock::now();
  Clock::time_point end = Clock::time_point::max();  // users retry connections until then
  SceneCache scenes;
  std::vector<CameraKeyframe> keyframes;
  std::atomic<int> connected{0}, scene_loaded{0}, full_image{0}, failed{0};
  std::atomic<std::uint64_t> tiles{0}, bytes{0}, frames{0}, errors{0}, reconnects{0};
  LatencyHistogram latency;
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
        backoff_(run.options.backoff,
                 mix64(run.options.seed ^ mix64(static_cast<std::uint64_t>(index) + 1))) {}

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
    r.tiles_held = tiles_.tiles_received();
    r.versions_digest = versions_digest(tiles_.versions());
    return r;
  }
  std::vector<double> take_latencies() { return std::move(latencies_ms_); }
  std::vector<double> take_steady_latencies() { return std::move(steady_ms_); }

 private:
  // Waiting: no connection, the next attempt after a back-off delay (or none before the end).
  enum class State { Idle, Connecting, AwaitWelcome, Downloading, Streaming, Waiting, Done };

  using ConnPtr = std::shared_ptr<Connection>;

  // A connection attempt. Socket handling lives here and in read(), write_next() and
  // drop_connection().
  void open_connection() {
    state_ = State::Connecting;
    conn_ = std::make_shared<Connection>(strand_, run_.tls.get());
    conn_->socket.expect_server_name(run_.options.host);
    asio::async_connect(
        conn_->socket.socket(), run_.endpoints,
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
    wire::Envelope hello;
    wire::Hello* h = hello.mutable_hello();
    h->set_protocol_version(wire::kProtocolVersion);
    h->set_client_name(run_.options.name + "-" + std::to_string(index_));
    if (scene_) {
      // Resume: the scene we hold and the tile versions we have.
      h->set_cached_scene_hash(welcome_.scene_hash());
      h->set_known_epoch(welcome_.tile_epoch());
      tiles_.add_known(*h);
    }
    send(hello);
    state_ = State::AwaitWelcome;
    arm_reply_timer("no Welcome within the reply timeout");
    read();
  }

  // The next connection attempt after a back-off delay; none when the run ends first (then
  // do_finish records the user as failed).
  void retry_later() {
    state_ = State::Waiting;
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
      if (self->state_ == State::AwaitWelcome || self->state_ == State::Downloading)
        self->lost("timeout", what);
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
    using E = wire::Envelope;
    if (finishing_ && env.msg_case() != E::kError) return;  // Bye is on its way
    switch (env.msg_case()) {
      case E::kWelcome:
        on_welcome(env.welcome());
        break;
      case E::kSceneChunk:
        on_chunk(env.scene_chunk());
        break;
      case E::kTileUpdate:
        on_tile(env.tile_update());
        break;
      case E::kError: {
        const std::string code = wire::ErrorCode_Name(env.error().code());
        conn_->server_error = code + ": " + env.error().message();
        run_.count_error("server " + code);
        // The server closes after these: reconnect now rather than at the EOF.
        if (server_error_is_transient(env.error().code()) && !finishing_)
          lost("", conn_->server_error);
        break;
      }
      default:
        break;  // Pong, Stats, Bye, anything newer
    }
  }

  void on_welcome(const wire::Welcome& w) {
    if (state_ != State::AwaitWelcome) {
      fail("protocol", "an unexpected Welcome");
      return;
    }
    if (w.protocol_version() != wire::kProtocolVersion) {
      fail("protocol", "the server speaks protocol " + std::to_string(w.protocol_version()));
      return;
    }
    if (w.idle_timeout_ms() > 0)
      ping_interval_ = std::clamp(std::chrono::milliseconds(w.idle_timeout_ms() / 3),
                                  std::chrono::milliseconds(100), ping_interval_);
    const bool same_scene = scene_ && w.scene_hash() == welcome_.scene_hash();
    // Another lineage of versions: any version the server sends is news.
    if (same_scene && w.tile_epoch() != welcome_.tile_epoch()) tiles_.forget_versions();
    welcome_ = w;
    if (same_scene) {  // resumed: the scene is the one we hold
      subscribe();
      return;
    }
    assembler_ = std::make_unique<wire::SceneAssembler>(w.scene_hash(), w.scene_bytes());
    wire::Envelope req;
    req.mutable_scene_request()->set_offset(0);
    send(req);
    state_ = State::Downloading;
    arm_reply_timer("the scene download stalled");
  }

  void on_chunk(const wire::SceneChunk& c) {
    if (state_ != State::Downloading) {
      fail("protocol", "a SceneChunk outside a download");
      return;
    }
    try {
      arm_reply_timer("the scene download stalled");
      if (!assembler_->add(c)) return;
      const std::string& bytes = assembler_->bytes();
      if (wire::sha256(bytes) != welcome_.scene_hash())
        throw Error("the scene package does not match its hash");
      scene_ = run_.scenes.get(bytes, welcome_.scene_hash(), run_.options.render);
      tiles_.configure(welcome_, scene_->unpacked.atlas);
    } catch (const std::exception& e) {
      fail("bad scene", e.what());
      return;
    }
    assembler_.reset();
    if (!result_.scene_loaded) {
      result_.scene_loaded = true;
      result_.scene_ms = ms_between(started_, Clock::now());
      ++run_.scene_loaded;
    }
    make_path();
    subscribe();
  }

  // The session is set up: subscribe, and start the camera updates, pings and frames.
  void subscribe() {
    reply_timer_.cancel();
    backoff_.reset();
    if (lost_) {
      lost_ = false;
      ++result_.reconnects;
      ++run_.reconnects;
    }
    wire::Envelope s;
    s.mutable_subscribe()->set_all(true);
    s.mutable_subscribe()->set_encoding(run_.options.encoding);
    subscribed_us_ = now_us();
    send(s);
    state_ = State::Streaming;
    if (run_.options.camera_hz > 0.0) send_camera();
    arm_ping();
    if (run_.options.render) arm_frame(Clock::now());
  }

  void make_path() {
    const double phase =
        run_.options.users > 0 ? static_cast<double>(index_) / run_.options.users : 0.0;
    const std::string& p = run_.options.camera_path;
    if (p == "orbit")
      path_ = CameraPath::orbit(scene_->world.bounds, 20.0, phase);
    else if (p == "random-walk")
      path_ = CameraPath::random_walk(scene_->world.bounds,
                                      run_.options.seed * 7919u + static_cast<unsigned>(index_));
    else
      path_ = CameraPath::keyframes(run_.keyframes, phase);
  }

  void on_tile(const wire::TileUpdate& t) {
    if (state_ != State::Streaming) {
      fail("protocol", "a TileUpdate before the subscription");
      return;
    }
    bool applied = false;
    try {
      applied = tiles_.apply(t);
    } catch (const std::exception& e) {
      fail("bad tile", e.what());
      return;
    }
    if (!applied) return;
    ++result_.tiles_applied;
    ++run_.tiles;
    if (t.server_time_us() >= subscribed_us_) {
      const std::uint64_t now = now_us();
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
    if (!run_.options.render && !result_.full_image && tiles_.all_received()) mark_full_image();
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
    return c == conn_ && state_ == State::Streaming && !finishing_ && !closed_;
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
    ping_timer_.expires_after(ping_interval_);
    ping_timer_.async_wait([self = shared_from_this(), c = conn_](std::error_code ec) {
      if (ec || !self->streaming_on(c)) return;
      if (Clock::now() - self->last_sent_ >= self->ping_interval_) {
        wire::Envelope p;
        p.mutable_ping()->set_nonce(self->result_.tiles_applied);
        p.mutable_ping()->set_time_us(now_us());
        self->send(p);
      }
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
    const ImageRGB img =
        compose(scene_->world, *scene_->rays, scene_->unpacked.atlas, tiles_.lightmaps(),
                path_.at(run_.elapsed_s()), run_.options.width, run_.options.height);
    (void)img;
    const auto t1 = Clock::now();
    frame_ms_total_ += ms_between(t0, t1);
    ++result_.frames;
    ++run_.frames;
    if (!result_.full_image && tiles_.all_received()) mark_full_image();
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
    const bool live = conn_ && (state_ == State::AwaitWelcome || state_ == State::Downloading ||
                                state_ == State::Streaming);
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
  Backoff backoff_;
  bool finishing_ = false, closed_ = false;
  bool lost_ = false;  // a connection dropped since the last session was set up
  State state_ = State::Idle;
  Clock::time_point started_ = Clock::now(), last_sent_ = Clock::now(), full_image_at_{},
                    closed_at_{};
  std::chrono::milliseconds ping_interval_{5000};
  std::string last_error_;  // why the last connection attempt failed or the last one dropped
  wire::Welcome welcome_;
  std::unique_ptr<wire::SceneAssembler> assembler_;
  std::shared_ptr<const SharedScene> scene_;
  TileCache tiles_;
  CameraPath path_;
  std::uint64_t subscribed_us_ = 0;
  double frame_ms_total_ = 0.0;
  std::vector<double> latencies_ms_, steady_ms_;
  LoadUserResult result_;
};

void check(const LoadOptions& o) {
  if (o.users < 1) throw Error("--users must be at least 1");
  if (!(o.duration_s > 0.0)) throw Error("--duration must be positive");
  if (o.render && (o.width < 1 || o.height < 1 || o.width > 8192 || o.height > 8192))
    throw Error("--width and --height must be in 1..8192");
  if (o.fps < 0.0 || o.camera_hz < 0.0 || o.ramp_s < 0.0)
    throw Error("--fps, --camera-hz and --ramp must not be negative");
  if (o.threads < 0) throw Error("--threads must not be negative");
  if (o.ramp_s >= o.duration_s) throw Error("--ramp must be shorter than --duration");
  o.backoff.validate();
}

}  // namespace

Percentiles Percentiles::of(std::vector<double> v) {
  Percentiles p;
  p.count = v.size();
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  auto rank = [&](double q) {
    const auto i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
    return v[std::clamp<std::size_t>(i, 1, v.size()) - 1];
  };
  p.p50 = rank(0.50);
  p.p95 = rank(0.95);
  p.p99 = rank(0.99);
  p.max = v.back();
  double sum = 0.0;
  for (double x : v) sum += x;
  p.mean = sum / static_cast<double>(v.size());
  return p;
}

std::uint64_t versions_digest(const std::vector<std::uint64_t>& versions) {
  std::uint64_t h = 1469598103934665603ull;
  for (std::uint64_t v : versions)
    for (int b = 0; b < 8; ++b) {
      h ^= (v >> (8 * b)) & 0xffu;
      h *= 1099511628211ull;
    }
  return h;
}

LoadReport run_load(const LoadOptions& options,
                    const std::function<void(const LoadProgress&)>& on_progress) {
  check(options);
  Run run(options);
  if (options.camera_path != "orbit" && options.camera_path != "random-walk")
    run.keyframes = load_camera_keyframes(options.camera_path);
  {
    tcp::resolver resolver(run.io);
    std::error_code ec;
    run.endpoints = resolver.resolve(options.host, std::to_string(options.port), ec);
    if (ec) throw Error("cannot resolve '" + options.host + "': " + ec.message());
  }
  run.tls = make_tls_context(options.tls);

  std::vector<std::shared_ptr<User>> users;
  users.reserve(static_cast<std::size_t>(options.users));
  run.start = Clock::now();
  const auto end = run.start + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(options.duration_s));
  run.end = end;
  for (int i = 0; i < options.users; ++i) {
    users.push_back(std::make_shared<User>(run, i));
    const double at = options.users > 1 ? options.ramp_s * i / (options.users - 1) : 0.0;
    users.back()->start(
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(at)));
  }
  auto work = asio::make_work_guard(run.io);
  const int threads = options.threads > 0
                          ? options.threads
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

  // The main thread reports progress until the end of the run.
  auto next_report = run.start + std::chrono::seconds(1);
  while (Clock::now() < end) {
    std::this_thread::sleep_until(std::min(end, next_report));
    if (Clock::now() >= next_report) {
      next_report += std::chrono::seconds(1);
      if (on_progress) {
        LoadProgress p;
        p.elapsed_s = run.elapsed_s();
        p.users = options.users;
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
  }
  const double elapsed = run.elapsed_s();
  for (auto& u : users) u->finish();
  work.reset();
  // Users close within a second of finish(); a server that never reads makes us stop anyway.
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

  LoadReport r;
  r.options = options;
  r.elapsed_s = elapsed;
  r.users = options.users;
  std::vector<double> scene, full, latency, steady_latency, rate, steady, to_full, fps, frame_ms;
  for (auto& u : users) {
    LoadUserResult res = u->result();
    std::vector<double> l = u->take_latencies();
    latency.insert(latency.end(), l.begin(), l.end());
    l = u->take_steady_latencies();
    steady_latency.insert(steady_latency.end(), l.begin(), l.end());
    r.connected += res.connected;
    r.failed += !res.failure.empty();
    r.scene_loaded += res.scene_loaded;
    r.full_image += res.full_image;
    if (res.scene_loaded) scene.push_back(res.scene_ms);
    if (res.full_image) {
      full.push_back(res.full_image_ms);
      to_full.push_back(static_cast<double>(res.bytes_to_full_image));
      if (res.seconds_after_full_image > 0.5)
        steady.push_back(static_cast<double>(res.bytes_after_full_image) /
                         res.seconds_after_full_image);
    }
    if (res.connected) rate.push_back(static_cast<double>(res.bytes_received) / elapsed);
    if (options.render && res.connected) {
      fps.push_back(static_cast<double>(res.frames) / elapsed);
      if (res.frames > 0) frame_ms.push_back(res.frame_ms_mean);
    }
    r.tiles_applied += res.tiles_applied;
    r.tiles_live += res.tiles_live;
    r.bytes_received += res.bytes_received;
    r.frames += res.frames;
    r.camera_updates += res.camera_updates;
    r.connections_lost += res.connections_lost;
    r.reconnects += res.reconnects;
    r.per_user.push_back(std::move(res));
  }
  r.scene_ms = Percentiles::of(std::move(scene));
  r.full_image_ms = Percentiles::of(std::move(full));
  r.tile_latency_ms = Percentiles::of(std::move(latency));
  r.steady_tile_latency_ms = Percentiles::of(std::move(steady_latency));
  r.bytes_per_s = Percentiles::of(std::move(rate));
  r.steady_bytes_per_s = Percentiles::of(std::move(steady));
  r.bytes_to_full_image = Percentiles::of(std::move(to_full));
  r.frames_per_s = Percentiles::of(std::move(fps));
  r.frame_ms = Percentiles::of(std::move(frame_ms));
  r.errors = run.error_kinds;
  return r;
}

}  // namespace irradcast

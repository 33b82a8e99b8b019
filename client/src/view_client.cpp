#include "irradcast/client/view_client.h"

#include <asio.hpp>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include "irradcast/client/camera_message.h"
#include "irradcast/client/client_tls.h"
#include "irradcast/common/compositor.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/common/error.h"
#include "irradcast/wire/frame.h"
#include "irradcast/common/log.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast {

namespace fs = std::filesystem;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

// The connection dropped (EOF, reset, or the server closed it after an Error).
struct ConnectionLost : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::uint64_t now_us() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

}  // namespace

struct ViewClient::Net {
  explicit Net(asio::ssl::context* tls) : socket(io.get_executor(), tls) {}
  asio::io_context io;
  wire::Stream socket;  // TCP, or TLS over it (--tls)
  wire::FrameDecoder decoder;
  std::array<char, 64 * 1024> buffer{};
};

// The scene and what is derived from it; World and RayScene hold pointers into the Scene, so
// they live together at a stable address.
struct ViewClient::Loaded {
  wire::UnpackedScene unpacked;
  World world;
  std::unique_ptr<RayScene> rays;
};

ViewClient::ViewClient(ViewClientOptions options)
    : options_(std::move(options)),
      tls_(make_tls_context(options_.tls)),
      backoff_(options_.backoff,
               options_.backoff_seed != 0 ? options_.backoff_seed : std::random_device{}()) {}

ViewClient::~ViewClient() {
  try {
    close();
  } catch (...) {
  }
}

void ViewClient::connect() {
  establish(false);
}

void ViewClient::establish(bool after_loss) {
  const auto start = Clock::now();
  const auto deadline = options_.deadline != Clock::time_point{} ? options_.deadline
                                                                 : start + options_.connect_timeout;
  const std::string where = options_.host + ":" + std::to_string(options_.port);
  backoff_.reset();
  std::string last_error;
  for (int attempt = 0;; ++attempt) {
    if (attempt > 0 || after_loss) {
      const auto delay = backoff_.next_before(Clock::now(), deadline);
      if (!delay) {
        const double waited = std::chrono::duration<double>(Clock::now() - start).count();
        char secs[32];
        std::snprintf(secs, sizeof secs, "%.1f", waited);
        throw Error(std::string(loaded_ ? "cannot reconnect to " : "cannot connect to ") + where +
                    " (" + std::to_string(attempt) + " attempts in " + secs +
                    " s): " + (last_error.empty() ? "no attempt before the deadline" : last_error));
      }
      std::this_thread::sleep_for(*delay);
    }
    pending_edits_.clear();
    try {
      open_connection(deadline);
      handshake();
      if (attempt > 0 || after_loss)
        log::info("view", "connected to " + where + " after " + std::to_string(attempt + 1) +
                              " attempt(s)");
      return;
    } catch (const ConnectionLost& lost) {
      last_error = lost.what();
      drop_connection();
      log::debug("view", "connection attempt " + std::to_string(attempt + 1) + " to " + where +
                             " failed: " + last_error);
    }
  }
}

// One attempt: resolve and connect, bounded by the deadline (a SYN into a black hole would
// otherwise block for minutes) and by the reply timeout.
void ViewClient::open_connection(Clock::time_point deadline) {
  ++counters_.connect_attempts;
  net_ = std::make_unique<Net>(tls_.get());
  const auto limit = std::chrono::duration_cast<std::chrono::milliseconds>(
      std::max(std::min<Clock::duration>(deadline - Clock::now(), options_.reply_timeout),
               Clock::duration(std::chrono::milliseconds(100))));
  std::error_code ec;
  std::string what;
  connect_stream(net_->io, net_->socket, options_.host, options_.port, limit, ec, what);
  if (!ec) return;
  // A certificate the client does not trust, or a server that does not speak TLS, will not
  // change by trying again: a clear error. A connection cut during the handshake is retried.
  if (ec.category() == asio::error::get_ssl_category())
    throw Error("cannot connect to " + options_.host + ":" + std::to_string(options_.port) + ": " +
                what);
  throw ConnectionLost(what);
}

void ViewClient::drop_connection() {
  if (!net_) return;
  net_->socket.close();
  net_.reset();
}

void ViewClient::send(const wire::Envelope& e) {
  std::string frame = wire::encode_frame(e);
  std::error_code ec;
  asio::write(net_->socket, asio::buffer(frame), ec);
  if (ec) throw ConnectionLost("write: " + wire::describe_tls_error(ec));
}

bool ViewClient::read_frame(wire::Envelope& out, Clock::time_point deadline) {
  for (;;) {
    switch (net_->decoder.next(out)) {
      case wire::DecodeStatus::Frame:
        ++counters_.frames_received;
        return true;
      case wire::DecodeStatus::TooLarge:
      case wire::DecodeStatus::Malformed:
        throw Error("the server sent a bad frame: " + net_->decoder.error());
      case wire::DecodeStatus::NeedMore:
        break;
    }
    const auto now = Clock::now();
    if (now >= deadline) return false;
    std::error_code result = asio::error::would_block;
    std::size_t got = 0;
    net_->socket.async_read_some(asio::buffer(net_->buffer),
                                 [&](std::error_code ec, std::size_t n) {
                                   result = ec;
                                   got = n;
                                 });
    net_->io.restart();
    net_->io.run_for(deadline - now);
    if (result == asio::error::would_block) {
      // Timed out: cancel the read and let its handler run before the buffer goes out of use.
      std::error_code ignored;
      net_->socket.socket().cancel(ignored);
      net_->io.restart();
      net_->io.run();
      if (result == asio::error::would_block || result == asio::error::operation_aborted) {
        if (got > 0) {
          counters_.bytes_received += got;
          net_->decoder.feed(net_->buffer.data(), got);
        }
        return false;
      }
    }
    if (result && result != asio::error::operation_aborted)
      throw ConnectionLost(result == asio::error::eof ? "the server closed the connection"
                                                      : wire::describe_tls_error(result));
    counters_.bytes_received += got;
    net_->decoder.feed(net_->buffer.data(), got);
  }
}

void ViewClient::handshake() {
  wire::Envelope hello;
  wire::Hello* h = hello.mutable_hello();
  h->set_protocol_version(wire::kProtocolVersion);
  h->set_client_name(options_.name);
  if (loaded_) {
    // Resume: the scene we hold and the tile versions we have.
    h->set_cached_scene_hash(scene_hash_);
    h->set_known_epoch(tile_epoch_);
    tiles_.add_known(*h);
  }
  send(hello);
  wire::Envelope e;
  const auto deadline = Clock::now() + options_.reply_timeout;
  for (;;) {
    if (!read_frame(e, deadline))
      throw ConnectionLost("no Welcome within " + std::to_string(options_.reply_timeout.count()) +
                           " ms");
    if (e.has_error()) {
      if (server_error_is_transient(e.error().code()))
        throw ConnectionLost("the server says: " + e.error().message());
      throw Error("the server refused the session: " + e.error().message());
    }
    if (e.has_welcome()) break;
  }
  const wire::Welcome& w = e.welcome();
  if (w.protocol_version() != wire::kProtocolVersion)
    throw Error("the server speaks protocol " + std::to_string(w.protocol_version()) +
                ", this client " + std::to_string(wire::kProtocolVersion));
  session_ = w.session();
  if (loaded_ && w.tile_epoch() != tile_epoch_) {
    // Another lineage of versions: what we hold stays on screen until replaced, but any version
    // the server sends is news.
    tiles_.forget_versions();
  }
  tile_epoch_ = w.tile_epoch();
  // Ping often enough for the server's idle timer.
  ping_interval_ = options_.ping_interval;
  if (w.idle_timeout_ms() > 0)
    ping_interval_ = std::min(ping_interval_, std::chrono::milliseconds(w.idle_timeout_ms() / 3));
  if (!loaded_ || w.scene_hash() != scene_hash_) load_scene(w);
  subscribe();
  last_ping_ = Clock::now();
  ++counters_.connections;
}

void ViewClient::load_scene(const wire::Welcome& w) {
  std::string bytes;
  fs::path cached;
  if (!options_.cache_dir.empty()) {
    cached = fs::path(options_.cache_dir) / (wire::hex(w.scene_hash()) + ".scene");
    std::ifstream f(cached, std::ios::binary);
    if (f) {
      std::ostringstream ss;
      ss << f.rdbuf();
      bytes = ss.str();
    }
  }
  std::unique_ptr<Loaded> loaded = std::make_unique<Loaded>();
  bool from_cache = false;
  if (!bytes.empty()) {
    try {
      loaded->unpacked = wire::open_scene_package(bytes, w.scene_hash());
      from_cache = true;
    } catch (const Error& e) {
      log::warn("view", cached.string() + " is damaged (" + e.what() + "); downloading again");
      bytes.clear();
    }
  }
  // Edits that arrive meanwhile wait for the scene (on_scene_edit).
  loading_ = true;
  struct Done {
    bool& flag;
    ~Done() { flag = false; }
  } done{loading_};
  if (!from_cache) {
    wire::Envelope req;
    req.mutable_scene_request()->set_offset(0);
    send(req);
    wire::SceneAssembler assembler(w.scene_hash(), w.scene_bytes());
    wire::Envelope e;
    while (!assembler.complete()) {
      if (!read_frame(e, Clock::now() + options_.reply_timeout))
        throw ConnectionLost("the scene download stalled");
      if (e.has_error()) {
        if (server_error_is_transient(e.error().code()))
          throw ConnectionLost("scene download: the server says: " + e.error().message());
        throw Error("scene download: the server says: " + e.error().message());
      }
      if (e.has_scene_chunk()) {
        counters_.scene_bytes_downloaded += e.scene_chunk().data().size();
        assembler.add(e.scene_chunk());
      } else {
        apply(e);
      }
    }
    bytes = assembler.bytes();
    loaded->unpacked = wire::open_scene_package(bytes, w.scene_hash());
    if (!cached.empty()) {
      std::error_code ec;
      fs::create_directories(cached.parent_path(), ec);
      const fs::path tmp = cached.string() + ".tmp" + std::to_string(session_);
      std::ofstream f(tmp, std::ios::binary);
      f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
      f.close();
      if (f) fs::rename(tmp, cached, ec);
      if (!f || ec) log::warn("view", "cannot cache the scene in " + cached.string());
    }
  }
  counters_.scene_from_cache = from_cache;
  loaded->world = World::build(loaded->unpacked.scene);
  loaded->rays = std::make_unique<RayScene>(loaded->world);
  tiles_.configure(w, loaded->unpacked.atlas);
  scene_hash_ = w.scene_hash();
  revision_ = loaded->unpacked.revision;
  loaded_ = std::move(loaded);
  loading_ = false;
  log::info("view", "scene '" + w.scene_id() + "' revision " + std::to_string(revision_) + " " +
                        (from_cache ? "from the cache" : "downloaded") + ": " +
                        std::to_string(tiles_.lightmaps().size()) + " lightmaps, " +
                        std::to_string(tiles_.tile_count()) + " tiles");
  // Edits that arrived during the download, in order (those the package has are skipped).
  std::vector<wire::SceneEdit> pending;
  pending.swap(pending_edits_);
  for (const wire::SceneEdit& m : pending) on_scene_edit(m);
}

void ViewClient::subscribe() {
  wire::Envelope s;
  s.mutable_subscribe()->set_all(true);
  s.mutable_subscribe()->set_encoding(options_.encoding);
  s.mutable_subscribe()->set_max_bytes_per_s(options_.max_bytes_per_s);
  send(s);
}

void ViewClient::apply(const wire::Envelope& e) {
  switch (e.msg_case()) {
    case wire::Envelope::kTileUpdate:
      apply_tile(e.tile_update());
      break;
    case wire::Envelope::kStats:
      last_stats_ = e.stats();
      break;
    case wire::Envelope::kSceneEdit:
      on_scene_edit(e.scene_edit());
      break;
    case wire::Envelope::kError:
      ++counters_.errors_received;
      // The server closes after these: reconnect now rather than at the EOF.
      if (server_error_is_transient(e.error().code()))
        throw ConnectionLost("the server says: " + e.error().message());
      log::warn("view", "server error: " + e.error().message());
      break;
    case wire::Envelope::kBye:
      log::info("view", "server says bye: " + e.bye().reason());
      break;
    default:
      break;  // Pong and anything newer: nothing to do
  }
}

void ViewClient::on_scene_edit(const wire::SceneEdit& m) {
  if (!m.applied()) return;  // an acknowledgement: for the client that sent the edit
  if (loading_ || !loaded_) {
    pending_edits_.push_back(m);
    return;
  }
  if (m.revision() <= revision_) return;  // the scene has it already
  if (m.revision() > revision_ + 1) {
    // Missed one: the simplest correct thing is the current scene package, which a new
    // connection's Welcome names.
    log::warn("view", "scene edit " + std::to_string(m.revision()) + " after revision " +
                          std::to_string(revision_) + ": edits missed; loading the scene again");
    reload_ = true;
    return;
  }
  apply_scene_edit(m);
}

void ViewClient::apply_scene_edit(const wire::SceneEdit& m) {
  Loaded& l = *loaded_;
  try {
    const SceneEdit edit = wire::from_proto(m);
    apply_edit(l.unpacked.scene, edit);  // validates first: unchanged on a bad edit
    const std::vector<int> changed = l.world.update(l.unpacked.scene);
    l.rays->update(changed);
    revision_ = m.revision();
    ++counters_.edits_applied;
    log::info("view", "applied scene edit " + std::to_string(revision_) + ": " +
                          edit_to_json(edit) + " (" + std::to_string(changed.size()) +
                          " objects changed)");
  } catch (const Error& e) {
    log::warn("view", "scene edit " + std::to_string(m.revision()) +
                          " does not apply to this scene (" + e.what() +
                          "); loading the scene again");
    reload_ = true;
  }
}

void ViewClient::apply_tile(const wire::TileUpdate& t) {
  if (tiles_.apply(t)) ++counters_.tiles_applied;
}

std::size_t ViewClient::poll(std::chrono::milliseconds budget) {
  if (!net_) throw Error("not connected");
  const auto deadline = Clock::now() + budget;
  const std::uint64_t before = counters_.tiles_applied;
  while (Clock::now() < deadline) {
    try {
      if (Clock::now() - last_ping_ >= ping_interval_) {
        wire::Envelope p;
        p.mutable_ping()->set_nonce(counters_.frames_received);
        p.mutable_ping()->set_time_us(now_us());
        send(p);
        last_ping_ = Clock::now();
      }
      wire::Envelope e;
      const auto until = std::min(deadline, last_ping_ + ping_interval_);
      if (read_frame(e, until)) apply(e);
      if (reload_) {
        reload_ = false;
        close();  // Bye, then a new session with the current scene
        establish(false);
      }
    } catch (const ConnectionLost& lost) {
      connection_lost(lost);
    }
  }
  return counters_.tiles_applied - before;
}

void ViewClient::connection_lost(const std::exception& lost) {
  drop_connection();
  ++counters_.connections_lost;
  if (!options_.reconnect) throw Error(std::string("connection lost: ") + lost.what());
  log::info("view", std::string("connection lost (") + lost.what() + "); reconnecting");
  establish(true);
}

std::optional<wire::Stats> ViewClient::request_stats(std::chrono::milliseconds timeout) {
  last_stats_.reset();
  wire::Envelope r;
  r.mutable_stats_request();
  try {
    send(r);
  } catch (const ConnectionLost& lost) {
    connection_lost(lost);
    return std::nullopt;
  }
  const auto deadline = Clock::now() + timeout;
  while (!last_stats_ && Clock::now() < deadline)
    poll(std::min(std::chrono::milliseconds(50),
                  std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()) +
                      std::chrono::milliseconds(1)));
  return last_stats_;
}

void ViewClient::send_camera(const CameraPose& c) {
  try {
    send(camera_update(c));
  } catch (const ConnectionLost&) {
  }
}

void ViewClient::close() {
  if (!net_) return;
  if (net_->socket.socket().is_open()) {
    try {
      send(wire::make_bye("viewer done"));
    } catch (const ConnectionLost&) {
    }
    net_->socket.close();
  }
  net_.reset();
}

ImageRGB ViewClient::compose(const CameraPose& camera, int width, int height) const {
  if (!loaded_) throw Error("no scene yet");
  return irradcast::compose(loaded_->world, *loaded_->rays, loaded_->unpacked.atlas,
                            tiles_.lightmaps(), camera, width, height);
}

ImageRGB ViewClient::compose(const CameraPose& camera, int width, int height, ClientPasses& passes,
                             ClientFrameStats* stats) const {
  if (!loaded_) throw Error("no scene yet");
  return passes.compose(loaded_->world, *loaded_->rays, loaded_->unpacked.atlas, tiles_.lightmaps(),
                        camera, width, height, stats);
}

const Scene& ViewClient::scene() const {
  if (!loaded_) throw Error("no scene yet");
  return loaded_->unpacked.scene;
}

const World& ViewClient::world() const {
  if (!loaded_) throw Error("no scene yet");
  return loaded_->world;
}

const Atlas& ViewClient::atlas() const {
  if (!loaded_) throw Error("no scene yet");
  return loaded_->unpacked.atlas;
}

}  // namespace irradcast

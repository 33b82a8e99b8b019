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
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/wire/blocking_channel.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast {

namespace fs = std::filesystem;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

// The connection dropped (EOF, reset, or the server closed it after an Error).
using ConnectionLost = wire::ChannelLost;

ClientSessionOptions session_options(const ViewClientOptions& o) {
  ClientSessionOptions so;
  so.name = o.name;
  so.encoding = o.encoding;
  so.max_bytes_per_s = o.max_bytes_per_s;
  so.ping_interval = o.ping_interval;
  so.log_tag = "view";
  so.presence = o.presence;
  so.avatar_nodes = o.presence ? o.avatars : 0;
  return so;
}

}  // namespace

ViewClient::ViewClient(ViewClientOptions options)
    : options_(std::move(options)),
      servers_(servers_or(options_.servers, options_.host, options_.port)),
      tls_(make_tls_context(options_.tls)),
      backoff_(options_.backoff,
               options_.backoff_seed != 0 ? options_.backoff_seed : std::random_device{}()),
      core_(session_options(options_)) {}

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
  std::string where = servers_[0].text();
  for (std::size_t i = 1; i < servers_.size(); ++i) where += "," + servers_[i].text();
  backoff_.reset();
  std::string last_error;
  const std::size_t n = servers_.size();
  for (std::size_t attempt = 0;; ++attempt) {
    // After a loss the next address first; one back-off delay per round over the list.
    if (n > 1 && (attempt > 0 || after_loss)) {
      current_ = (current_ + 1) % n;
      ++failovers_;
    }
    if ((attempt > 0 && attempt % n == 0) || (attempt == 0 && after_loss)) {
      const auto delay = backoff_.next_before(Clock::now(), deadline);
      if (!delay) {
        const double waited = std::chrono::duration<double>(Clock::now() - start).count();
        char secs[32];
        std::snprintf(secs, sizeof secs, "%.1f", waited);
        throw Error(std::string(core_.has_scene() ? "cannot reconnect to " : "cannot connect to ") +
                    where + " (" + std::to_string(attempt) + " attempts in " + secs +
                    " s): " + (last_error.empty() ? "no attempt before the deadline" : last_error));
      }
      std::this_thread::sleep_for(*delay);
    }
    try {
      open_connection(deadline);
      handshake();
      if (attempt > 0 || after_loss)
        log::info("view", "connected to " + server().text() + " after " +
                              std::to_string(attempt + 1) + " attempt(s)");
      return;
    } catch (const ConnectionLost& lost) {
      last_error = server().text() + ": " + lost.what();
      drop_connection();
      log::debug("view", "connection attempt " + std::to_string(attempt + 1) + " to " +
                             server().text() + " failed: " + lost.what());
    }
  }
}

// One attempt: resolve and connect, bounded by the deadline (a SYN into a black hole would
// otherwise block for minutes) and by the reply timeout.
void ViewClient::open_connection(Clock::time_point deadline) {
  ++connect_attempts_;
  const auto limit = std::chrono::duration_cast<std::chrono::milliseconds>(
      std::max(std::min<Clock::duration>(deadline - Clock::now(), options_.reply_timeout),
               Clock::duration(std::chrono::milliseconds(100))));
  // A certificate the client does not trust, or a server that does not speak TLS, will not
  // change by trying again: irradcast::Error. A connection cut during the handshake is retried.
  net_ = std::make_unique<wire::BlockingChannel>(server().host, server().port, tls_, limit);
}

void ViewClient::drop_connection() {
  if (!net_) return;
  core_.disconnect();
  bytes_received_ += net_->bytes_received();
  net_.reset();
}

void ViewClient::send(const wire::Envelope& e) {
  net_->send(e);
}

bool ViewClient::read_frame(wire::Envelope& out, Clock::time_point deadline) {
  return net_->read(out, deadline);
}

void ViewClient::send_all(const ClientStep& step) {
  for (const wire::Envelope& e : step.send) send(e);
}

void ViewClient::handshake() {
  send(core_.hello());
  const auto deadline = Clock::now() + options_.reply_timeout;
  ClientStep step;
  while (core_.phase() == ClientSession::Phase::AwaitWelcome) {
    wire::Envelope e;
    if (!read_frame(e, deadline))
      throw ConnectionLost("no Welcome within " + std::to_string(options_.reply_timeout.count()) +
                           " ms");
    step = feed(e);
  }
  if (step.event == ClientStep::Event::NeedScene) step = load_scene();
  send_all(step);  // the Subscribe
  last_ping_ = Clock::now();
  ++connections_;
}

ClientStep ViewClient::load_scene() {
  const wire::Welcome& w = core_.welcome();
  ClientStep step;
  fs::path cached;
  if (!options_.cache_dir.empty()) {
    cached = fs::path(options_.cache_dir) / (wire::hex(w.scene_hash()) + ".scene");
    std::ifstream f(cached, std::ios::binary);
    std::ostringstream ss;
    if (f) ss << f.rdbuf();
    std::string why;
    if (!ss.str().empty()) {
      if (core_.use_cached_package(ss.str(), step, &why)) {
        log_scene(w, true);
        return step;
      }
      log::warn("view", cached.string() + " is damaged (" + why + "); downloading again");
    }
  }
  send(core_.download());
  while (core_.phase() == ClientSession::Phase::Downloading) {
    wire::Envelope e;
    if (!read_frame(e, Clock::now() + options_.reply_timeout))
      throw ConnectionLost("the scene download stalled");
    step = feed(e);
  }
  if (!cached.empty()) {
    const std::string& bytes = core_.downloaded_package();
    std::error_code ec;
    fs::create_directories(cached.parent_path(), ec);
    const fs::path tmp = cached.string() + ".tmp" + std::to_string(core_.session());
    std::ofstream f(tmp, std::ios::binary);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    f.close();
    if (f) fs::rename(tmp, cached, ec);
    if (!f || ec) log::warn("view", "cannot cache the scene in " + cached.string());
  }
  log_scene(w, false);
  return step;
}

void ViewClient::log_scene(const wire::Welcome& w, bool from_cache) const {
  log::info("view", "scene '" + w.scene_id() + "' revision " +
                        std::to_string(core_.scene().unpacked.revision) + " " +
                        (from_cache ? "from the cache" : "downloaded") + ": " +
                        std::to_string(core_.tiles().lightmaps().size()) + " lightmaps, " +
                        std::to_string(core_.tiles().tile_count()) + " tiles");
}

ClientStep ViewClient::feed(const wire::Envelope& e) {
  const ClientSession::Phase phase = core_.phase();
  ClientStep step = core_.on_frame(e);
  if (step.event == ClientStep::Event::Bye)
    log::info("view", "server says bye: " + e.bye().reason());
  if (step.event != ClientStep::Event::ServerError) return step;
  const std::string& message = e.error().message();
  // The server closes after transient errors: reconnect now rather than at the EOF.
  const bool transient = server_error_is_transient(e.error().code());
  if (phase == ClientSession::Phase::AwaitWelcome) {
    if (transient) throw ConnectionLost("the server says: " + message);
    throw Error("the server refused the session: " + message);
  }
  if (phase == ClientSession::Phase::Downloading) {
    if (transient) throw ConnectionLost("scene download: the server says: " + message);
    throw Error("scene download: the server says: " + message);
  }
  if (transient) throw ConnectionLost("the server says: " + message);
  log::warn("view", "server error: " + message);
  return step;
}

std::size_t ViewClient::poll(std::chrono::milliseconds budget) {
  if (!net_) throw Error("not connected");
  const auto deadline = Clock::now() + budget;
  const std::uint64_t before = core_.counters().tiles_applied;
  while (Clock::now() < deadline) {
    try {
      if (Clock::now() - last_ping_ >= core_.ping_interval()) {
        send(ClientSession::ping(core_.counters().frames_received, wall_time_us()));
        last_ping_ = Clock::now();
      }
      wire::Envelope e;
      const auto until = std::min(deadline, last_ping_ + core_.ping_interval());
      if (read_frame(e, until)) feed(e);
      if (core_.take_reload()) {
        close();  // Bye, then a new session with the current scene
        establish(false);
      }
    } catch (const ConnectionLost& lost) {
      connection_lost(lost);
    }
  }
  return core_.counters().tiles_applied - before;
}

void ViewClient::connection_lost(const std::exception& lost) {
  drop_connection();
  ++connections_lost_;
  if (!options_.reconnect) throw Error(std::string("connection lost: ") + lost.what());
  log::info("view", std::string("connection lost (") + lost.what() + "); reconnecting");
  establish(true);
}

std::optional<wire::Stats> ViewClient::request_stats(std::chrono::milliseconds timeout) {
  core_.clear_stats();
  wire::Envelope r;
  r.mutable_stats_request();
  try {
    send(r);
  } catch (const ConnectionLost& lost) {
    connection_lost(lost);
    return std::nullopt;
  }
  const auto deadline = Clock::now() + timeout;
  while (!core_.last_stats() && Clock::now() < deadline)
    poll(std::min(std::chrono::milliseconds(50),
                  std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()) +
                      std::chrono::milliseconds(1)));
  return core_.last_stats();
}

void ViewClient::send_camera(const CameraPose& c) {
  try {
    send(camera_update(c));
  } catch (const ConnectionLost&) {
  }
}

void ViewClient::close() {
  if (!net_) return;
  if (net_->open()) {
    try {
      send(wire::make_bye("viewer done"));
    } catch (const ConnectionLost&) {
    }
  }
  bytes_received_ += net_->bytes_received();
  net_.reset();
}

DynamicView ViewClient::dynamic_view() const {
  const ClientScene& s = core_.scene();
  return {s.dynamic_rays.get(), core_.probe_volume().lit(),
          options_.trace_emitters ? s.lights.get() : nullptr};
}

ImageRGB ViewClient::compose(const CameraPose& camera, int width, int height) const {
  const ClientScene& s = core_.scene();
  const DynamicView dynamic = dynamic_view();
  return irradcast::compose(s.world, *s.rays, s.unpacked.atlas, lightmaps(), camera, width, height,
                            nullptr, &dynamic);
}

ImageRGB ViewClient::compose(const CameraPose& camera, int width, int height, ClientPasses& passes,
                             ClientFrameStats* stats) const {
  const ClientScene& s = core_.scene();
  const DynamicView dynamic = dynamic_view();
  return passes.compose(s.world, *s.rays, s.unpacked.atlas, lightmaps(), camera, width, height,
                        stats, &dynamic);
}

const Scene& ViewClient::scene() const {
  return core_.scene().unpacked.scene;
}
const World& ViewClient::world() const {
  return core_.scene().world;
}
const Atlas& ViewClient::atlas() const {
  return core_.scene().unpacked.atlas;
}

ViewClientCounters ViewClient::counters() const {
  const ClientSessionCounters& p = core_.counters();
  ViewClientCounters c;
  c.bytes_received = bytes_received_ + (net_ ? net_->bytes_received() : 0);
  c.frames_received = p.frames_received;
  c.tiles_applied = p.tiles_applied;
  c.scene_bytes_downloaded = p.scene_bytes_downloaded;
  c.connections = connections_;
  c.connections_lost = connections_lost_;
  c.connect_attempts = connect_attempts_;
  c.failovers = failovers_;
  c.scene_from_cache = p.scene_from_cache;
  c.errors_received = p.errors_received;
  c.edits_applied = p.edits_applied;
  c.avatar_messages = p.avatar_messages;
  c.avatars_shown = static_cast<std::uint32_t>(core_.avatars_shown());
  return c;
}

}  // namespace irradcast

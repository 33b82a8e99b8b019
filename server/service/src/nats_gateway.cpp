// NatsGateway: the stream's messages into a tile store, package and stats; the requests to the
// origin. See nats_gateway.h.
#include "irradcast/service/nats_gateway.h"

#include <cmath>
#include <condition_variable>
#include <map>
#include <mutex>
#include <random>
#include <thread>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast/service/thread_priority.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/probe_volume_message.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast_nats.pb.h"
#include "nats_gateway_impl.h"
#include "nats_link.h"
#include "presence_board.h"
#include "session_messages.h"

namespace irradcast {

using namespace nats_gateway;

namespace {

// A state message's problem, or "" when it can be used.
std::string check_state(const wire::NatsSceneState& s) {
  if (s.scene_hash().size() != 32) return "the scene hash is not 32 bytes";
  if (s.package_chunks() == 0 || s.package_chunks() > kMaxChunks)
    return "package chunk count " + std::to_string(s.package_chunks()) + " is out of range";
  if (s.tile_size() < 1 || s.tile_size() > 4096) return "tile size is out of range";
  if (s.lightmaps_size() == 0 || static_cast<std::uint32_t>(s.lightmaps_size()) > kMaxLightmaps)
    return "lightmap count is out of range";
  // A dynamic object's lightmap is 0 x 0 (docs/DYNAMIC.md): it has no tiles.
  for (const wire::LightmapInfo& l : s.lightmaps())
    if ((l.width() == 0) != (l.height() == 0) || l.width() > 65536 || l.height() > 65536)
      return "a lightmap size is out of range";
  return "";
}

std::vector<std::pair<int, int>> sizes_of(const wire::NatsSceneState& s) {
  std::vector<std::pair<int, int>> sizes;
  for (const wire::LightmapInfo& l : s.lightmaps())
    sizes.emplace_back(static_cast<int>(l.width()), static_cast<int>(l.height()));
  return sizes;
}

}  // namespace

void NatsGateway::Impl::on_message(natsMsg* msg) {
  Impl& im = *this;
  const std::string subject = natsMsg_GetSubject(msg) ? natsMsg_GetSubject(msg) : "";
  const std::string data = nats_link::data_of(msg);
  natsMsg_Destroy(msg);
  const std::string prefix = im.subjects.filter.substr(0, im.subjects.filter.size() - 1);
  if (subject.rfind(prefix, 0) != 0) return;
  std::lock_guard lock(im.handle_mutex);
  {
    std::lock_guard l(im.mutex);
    ++im.st.messages;
  }
  try {
    im.handle(subject.substr(prefix.size()), data);
  } catch (const std::exception& e) {
    im.bad(subject + ": " + e.what());
  }
}

void NatsGateway::Impl::handle(const std::string& kind, const std::string& data) {
  if (kind == "state") return on_state(data);
  if (kind == "edit") return on_edit(data);
  if (kind == "stats") return on_stats(data);
  if (kind == "volume") return on_volume(data);
  if (kind == "poses") return on_poses(data);
  if (kind == "presence") return on_presence(data);
  if (kind.rfind("volchunk.", 0) == 0) return on_volume_chunk(data);
  if (kind.rfind("package.", 0) == 0) return on_chunk(data);
  if (kind.rfind("tile.", 0) == 0) {
    wire::NatsTile t;
    if (!t.ParseFromString(data)) return bad("a tile does not parse");
    return on_tile(std::move(t));
  }
  bad("unknown subject ." + kind);
}

void NatsGateway::Impl::on_state(const std::string& data) {
  wire::NatsSceneState s;
  if (!s.ParseFromString(data)) return bad("the scene state does not parse");
  if (const std::string problem = check_state(s); !problem.empty())
    return bad("scene state: " + problem);
  pending_state = std::move(s);
  try_complete();
}

void NatsGateway::Impl::on_chunk(const std::string& data) {
  wire::NatsPackageChunk c;
  if (!c.ParseFromString(data) || c.index() >= kMaxChunks) return bad("a package chunk");
  chunks[c.index()] = std::move(c);
  try_complete();
}

// The pending state once every chunk of its package is there, with the right hash.
void NatsGateway::Impl::try_complete() {
  if (!pending_state) return;
  const wire::NatsSceneState& s = *pending_state;
  std::string bytes;
  for (std::uint32_t i = 0; i < s.package_chunks(); ++i) {
    auto it = chunks.find(i);
    if (it == chunks.end() || it->second.scene_hash() != s.scene_hash()) return;  // not yet
    bytes += it->second.data();
    if (bytes.size() > s.package_bytes()) break;
  }
  wire::NatsSceneState state = std::move(*pending_state);
  pending_state.reset();
  if (bytes.size() != state.package_bytes() || wire::sha256(bytes) != state.scene_hash())
    return bad("the scene package's chunks do not make the announced package");
  auto p = std::make_shared<wire::ScenePackage>();
  p->bytes = std::move(bytes);
  p->hash = state.scene_hash();
  apply_state(state, std::move(p));
}

void NatsGateway::Impl::apply_state(const wire::NatsSceneState& s,
                                    std::shared_ptr<const wire::ScenePackage> p) {
  if (s.scene_id() != options.scene_id)
    log::warn("gateway", "the stream's scene is '" + log::quote(s.scene_id(), 64) + "', not '" +
                             options.scene_id + "'");
  std::vector<std::uint32_t> installed;
  {
    std::unique_lock lock(mutex);
    if (store &&
        (sizes_of(s) != sizes || static_cast<int>(s.tile_size()) != store->options().tile_size)) {
      lock.unlock();
      return bad("the origin's lightmap layout changed; restart the gateway to serve it");
    }
    if (origin != 0 && s.origin() != origin && s.tile_epoch() != epoch) {
      reset_origin = s.origin();  // another lineage: its versions replace ours
      last_edit = s.revision();
      log::warn("gateway", "a new origin with another tile epoch: its tiles replace ours");
    }
    origin = s.origin();
    package = std::move(p);
    revision = s.revision();
    epoch = s.tile_epoch();
    backend = s.backend();
    ++st.packages_received;
    st.revision = revision;
    if (!store) {
      TileStoreOptions to;
      to.tile_size = static_cast<int>(s.tile_size());
      sizes = sizes_of(s);
      store = std::make_unique<TileStore>(sizes, to);
      tile_origin.assign(store->tile_count(), 0);
      st.ready = true;
      log::info("gateway", "scene '" + options.scene_id + "' revision " + std::to_string(revision) +
                               ": " + std::to_string(store->tile_count()) + " tiles");
    }
  }
  cv.notify_all();
  for (auto& [index, t] : early_tiles)
    if (install(t)) installed.push_back(index);
  early_tiles.clear();
  early_bytes = 0;
  listeners.tiles(installed);
}

void NatsGateway::Impl::on_tile(wire::NatsTile t) {
  {
    std::unique_lock lock(mutex);
    ++st.tiles_received;
    // A tile's version grows by at most one per engine update, and the origin's stats say how
    // many updates it ran: a version far beyond that was not made by it (a forged tile would
    // otherwise stay ahead of every real version for good).
    if (updates_seen > 0 && t.version() > updates_seen &&
        t.version() - updates_seen > kMaxVersionLead) {
      const std::uint64_t seen = updates_seen;
      lock.unlock();
      return bad("tile " + std::to_string(t.index()) + " at version " +
                 std::to_string(t.version()) + ", beyond what the origin's " +
                 std::to_string(seen) + " updates can have made");
    }
    st.lag_seconds =
        static_cast<double>(wall_clock_us() - std::min(wall_clock_us(), t.time_us())) * 1e-6;
    if (!store) {
      // Kept until the layout is known, bounded in count and bytes (the rest come again with the
      // next catch-up or version).
      auto it = early_tiles.find(t.index());
      const std::size_t held = it == early_tiles.end() ? 0 : it->second.payload().size();
      if (early_bytes - held + t.payload().size() > kMaxEarlyBytes ||
          (it == early_tiles.end() && early_tiles.size() >= kMaxEarlyTiles))
        return;
      early_bytes = early_bytes - held + t.payload().size();
      early_tiles[t.index()] = std::move(t);
      return;
    }
  }
  if (install(t)) listeners.tiles({t.index()});
}

bool NatsGateway::Impl::install(const wire::NatsTile& t) {
  if (t.index() >= tile_origin.size())
    throw Error("tile " + std::to_string(t.index()) + " is not in the layout");
  const bool force = t.origin() == reset_origin && tile_origin[t.index()] != t.origin();
  if (!store->install(t.index(), t.version(), t.time_us(),
                      std::make_shared<const std::string>(t.payload()), force))
    return false;
  tile_origin[t.index()] = t.origin();
  std::lock_guard lock(mutex);
  ++st.tiles_installed;
  return true;
}

void NatsGateway::Impl::on_edit(const std::string& data) {
  wire::NatsEdit e;
  if (!e.ParseFromString(data) || !e.edit().applied()) return bad("an edit does not parse");
  {
    std::lock_guard lock(mutex);
    ++st.edits_received;
  }
  if (e.edit().revision() <= last_edit) return;  // forwarded before (a catch-up's replay)
  last_edit = e.edit().revision();
  AppliedEdit a;
  a.edit = wire::from_proto(e.edit());
  a.revision = e.edit().revision();
  a.tile_epoch = e.tile_epoch();
  a.applied_us = e.edit().applied_us();
  {
    std::lock_guard lock(mutex);
    if (e.edit().scene_hash() == (package ? package->hash : "")) a.package = package;
  }
  listeners.edit(a);
}

void NatsGateway::Impl::on_stats(const std::string& data) {
  wire::Stats s;
  if (!s.ParseFromString(data)) return bad("the stats do not parse");
  std::lock_guard lock(mutex);
  engine = engine_stats_from(s);
  updates_seen = engine.updates;
}

void NatsGateway::Impl::run() {
  set_thread_name("irradcast-nats");
  std::uint64_t subscribed = 0;  // the connection generation the subscription belongs to
  Clock::time_point retry{}, cameras_sent{};
  std::unique_lock lock(mutex);
  while (!stopping) {
    cv.wait_for(lock, std::chrono::milliseconds(50));
    if (stopping || !conn->connected()) continue;
    const Clock::time_point now = Clock::now();
    const bool avatars_moved = options.presence && presence.local_version() != avatars_sent;
    const bool send = (cameras_changed && now - cameras_sent >= options.camera_every) ||
                      (avatars_moved && now - cameras_sent >= options.presence_every) ||
                      (!cameras.empty() && now - cameras_sent >= kCameraKeepalive);
    expire_presence(now);
    lock.unlock();
    // Catch up after every (re)connection: read the stream again from its start.
    if (subscribed != conn->generation() && now >= retry) {
      const std::uint64_t generation = conn->generation();
      subscribe();
      if (sub.active()) subscribed = generation;
      retry = now + std::chrono::milliseconds(500);
    }
    if (send) {
      send_cameras();
      cameras_sent = now;
    }
    lock.lock();
  }
}

void NatsGateway::Impl::subscribe() {
  {
    std::lock_guard lock(mutex);
    updates_seen = 0;  // the replay brings its stats after the tiles published before them
  }
  jsSubOptions so;
  jsSubOptions_Init(&so);
  so.Stream = subjects.stream.c_str();
  so.Ordered = true;
  so.Config.DeliverPolicy = js_DeliverAll;
  jsErrCode jerr = static_cast<jsErrCode>(0);
  const natsStatus s = sub.subscribe(conn->js(), subjects.filter, &so, &jerr,
                                     [this](natsConnection*, natsMsg* msg) { on_message(msg); });
  if (s != NATS_OK) {
    log::debug("gateway", "no stream " + subjects.stream + " yet: " + nats_link::describe(s));
    return;
  }
  std::lock_guard lock(mutex);
  ++st.subscriptions;
  log::info("gateway", "reading stream " + subjects.stream + " from its start");
}

// All of this gateway's viewers' cameras, in one request (the origin replaces the set it had).
void NatsGateway::Impl::send_cameras() {
  wire::NatsCameras m;
  m.set_gateway(gateway);
  {
    std::lock_guard lock(mutex);
    for (const auto& [viewer, pose] : cameras) {
      if (static_cast<std::size_t>(m.cameras_size()) >= kMaxCameras) break;
      wire::CameraUpdate* c = m.add_cameras();
      auto vec = [](wire::Vec3* v, glm::vec3 x) {
        v->set_x(x.x);
        v->set_y(x.y);
        v->set_z(x.z);
      };
      vec(c->mutable_eye(), pose.eye);
      vec(c->mutable_forward(), pose.forward);
      vec(c->mutable_up(), pose.up);
      c->set_yfov(pose.yfov);
    }
    cameras_changed = false;
    ++st.camera_requests;
  }
  if (options.presence) {
    std::uint64_t version = 0;
    for (const AvatarState& a : presence.local(&version)) avatar_to_wire(a, m.add_avatars());
    std::lock_guard lock(mutex);
    avatars_sent = version;
  }
  const std::string bytes = m.SerializeAsString();
  natsMsg* reply = nullptr;
  natsConnection_Request(&reply, conn->nc(), subjects.cameras.c_str(), bytes.data(),
                         static_cast<int>(bytes.size()), 1000);
  natsMsg_Destroy(reply);  // the origin's answer says nothing we need
}

NatsGateway::NatsGateway(NatsGatewayOptions options)
    : impl_(std::make_unique<Impl>(std::move(options))) {
  Impl& im = *impl_;
  im.conn = std::make_unique<nats_link::Connection>(im.options.url, im.options.credentials,
                                                    "irradcast-gateway " + im.options.scene_id,
                                                    [&im] { im.cv.notify_all(); });
  im.worker = std::thread([&im] { im.run(); });
  log::info("gateway", "reading scene '" + im.options.scene_id + "' from " + im.conn->url() + " (" +
                           im.options.credentials.describe(im.options.url) + ")" + " (stream " +
                           im.subjects.stream + ")");
}

NatsGateway::~NatsGateway() {
  Impl& im = *impl_;
  {
    std::lock_guard lock(im.mutex);
    im.stopping = true;
  }
  im.cv.notify_all();
  im.worker.join();
  if (im.conn->connected()) {
    // The origin forgets this gateway's cameras and avatars now rather than when they expire.
    {
      std::lock_guard lock(im.mutex);
      im.cameras.clear();
    }
    im.send_cameras();  // (the Server went first: its sessions took their avatars away)
  }
  im.sub.close();  // no handler runs after this: the state it uses can go
  im.conn.reset();
}

std::shared_ptr<const ProbeVolumeFrames> NatsGateway::probe_volume() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->volume;
}

PoseBoard* NatsGateway::poses() {
  return &impl_->poses;
}

PresenceBoard* NatsGateway::presence() {
  return impl_->options.presence ? &impl_->presence : nullptr;
}

bool NatsGateway::wait_ready(std::chrono::milliseconds limit) const {
  std::unique_lock lock(impl_->mutex);
  return impl_->cv.wait_for(lock, limit, [&] { return impl_->store != nullptr; });
}

void NatsGateway::set_listener(PublishListener listener) {
  impl_->listeners.set(std::move(listener));
}

void NatsGateway::set_edit_listener(EditListener listener) {
  impl_->listeners.set(std::move(listener));
}

const std::string& NatsGateway::scene_id() const {
  return impl_->options.scene_id;
}

std::string NatsGateway::backend_name() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->backend;
}

std::shared_ptr<const wire::ScenePackage> NatsGateway::package() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->package;
}

std::uint64_t NatsGateway::tile_epoch() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->epoch;
}

std::uint64_t NatsGateway::revision() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->revision;
}

const TileStore& NatsGateway::tiles() const {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->store) throw Error("the gateway has no scene from the origin yet");
  return *impl_->store;
}

// Forwards an edit (which the session accepted with the control token) to the origin and waits
// for its answer: the revision, or why it refused.
EditReceipt NatsGateway::submit(const SceneEdit& edit, bool stream) {
  Impl& im = *impl_;
  if (!im.conn->connected())
    throw Error("the gateway has lost NATS; the edit was not sent to the origin");
  wire::SceneEdit m;
  wire::to_proto(edit, &m);
  m.set_stream(stream);
  // No token: the session checked it, and it never crosses NATS (NATS's permissions decide who
  // may publish req.edit).
  const std::string bytes = m.SerializeAsString();
  natsMsg* reply = nullptr;
  {
    std::lock_guard lock(im.mutex);
    ++im.st.edit_requests;
  }
  const natsStatus s =
      natsConnection_Request(&reply, im.conn->nc(), im.subjects.submit.c_str(), bytes.data(),
                             static_cast<int>(bytes.size()),
                             static_cast<std::int64_t>(im.options.request_timeout.count()));
  if (s == NATS_NO_RESPONDERS || s == NATS_TIMEOUT)
    throw Error("no origin answered for scene '" + im.options.scene_id +
                "'; the edit was not applied");
  if (s != NATS_OK)
    throw Error("the edit could not be sent to the origin: " + nats_link::describe(s));
  wire::NatsReply r;
  const bool parsed = r.ParseFromString(nats_link::data_of(reply));
  natsMsg_Destroy(reply);
  if (!parsed) throw Error("the origin's answer to the edit does not parse");
  if (!r.error().empty() && r.code() == wire::RATE_LIMITED) throw PoseRateLimited(r.error());
  if (!r.error().empty()) throw Error(r.error());
  EditReceipt receipt;
  receipt.revision = r.revision();
  receipt.pose_sequence = r.pose_sequence();
  return receipt;
}

void NatsGateway::set_camera(std::uint64_t viewer, std::optional<CameraPose> pose) {
  std::lock_guard lock(impl_->mutex);
  if (pose)
    impl_->cameras[viewer] = *pose;
  else
    impl_->cameras.erase(viewer);
  impl_->cameras_changed = true;
}

EngineHostStats NatsGateway::stats() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->engine;
}

NatsGatewayStats NatsGateway::nats_stats() const {
  std::lock_guard lock(impl_->mutex);
  NatsGatewayStats s = impl_->st;
  s.connected = impl_->conn->connected();
  return s;
}

std::string format_nats_gateway_metrics(const NatsGatewayStats& s) {
  std::string out;
#define IRRADCAST_NATS_GATEWAY_STAT(type, name, kind, metric, help) \
  append_metric(out, metric, #kind, help, static_cast<double>(s.name));
#include "irradcast/service/nats_gateway_stats.inc"
#undef IRRADCAST_NATS_GATEWAY_STAT
  return out;
}

}  // namespace irradcast

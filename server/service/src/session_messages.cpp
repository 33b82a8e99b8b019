// The messages a session builds from the server's state, and the control token's comparison.
#include "session_messages.h"

#include <chrono>
#include <cmath>
#include <set>
#include <utility>

#include <glm/geometric.hpp>

namespace irradcast {

std::uint64_t wall_clock_us() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

bool same_secret(const std::string& given, const std::string& secret) {
  unsigned char diff = given.size() == secret.size() ? 0 : 1;
  for (std::size_t i = 0; i < secret.size(); ++i)
    diff |= static_cast<unsigned char>((i < given.size() ? given[i] : '\0') ^ secret[i]);
  return diff == 0;
}

std::optional<CameraPose> camera_pose_of(const wire::CameraUpdate& c, std::string& problem) {
  auto vec = [](const wire::Vec3& v) { return glm::vec3(v.x(), v.y(), v.z()); };
  CameraPose pose;
  pose.eye = vec(c.eye());
  pose.forward = vec(c.forward());
  pose.up = vec(c.up());
  pose.yfov = c.yfov();
  const auto finite = [](glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  if (!finite(pose.eye) || !finite(pose.forward) || !finite(pose.up) || !std::isfinite(pose.yfov)) {
    problem = "camera update: a number is not finite (NaN or infinity)";
    return std::nullopt;
  }
  if (!(glm::length(pose.forward) > 0.0f)) {
    problem = "camera update: the forward direction is zero";
    return std::nullopt;
  }
  return pose;
}

void avatar_to_wire(const AvatarState& a, wire::Avatar* w) {
  w->set_id(a.id);
  w->mutable_eye()->set_x(a.eye.x);
  w->mutable_eye()->set_y(a.eye.y);
  w->mutable_eye()->set_z(a.eye.z);
  w->set_heading(a.heading);
}

std::vector<AvatarState> avatars_from_wire(
    const google::protobuf::RepeatedPtrField<wire::Avatar>& in, std::size_t* refused) {
  std::vector<AvatarState> out;
  std::set<std::uint64_t> seen;
  std::size_t bad = 0;
  for (const wire::Avatar& w : in) {
    const AvatarState a{w.id(), {w.eye().x(), w.eye().y(), w.eye().z()}, w.heading()};
    if (out.size() >= PresenceBoard::kMaxGroupAvatars || !valid_avatar(a) ||
        !seen.insert(a.id).second) {
      ++bad;
      continue;
    }
    out.push_back(a);
  }
  if (refused) *refused = bad;
  return out;
}

CloseReason reason_of(wire::ErrorCode code) {
  static constexpr std::pair<wire::ErrorCode, CloseReason> kReasons[] = {
      {wire::BAD_FRAME, CloseReason::BadFrame},
      {wire::FRAME_TOO_LARGE, CloseReason::FrameTooLarge},
      {wire::UNSUPPORTED_VERSION, CloseReason::UnsupportedVersion},
      {wire::UNEXPECTED_MESSAGE, CloseReason::UnexpectedMessage},
      {wire::IDLE_TIMEOUT, CloseReason::IdleTimeout},
      {wire::SERVER_SHUTDOWN, CloseReason::Shutdown}};
  for (const auto& [c, reason] : kReasons)
    if (c == code) return reason;
  return CloseReason::Internal;
}

// The Welcome that answers a Hello: the session, the scene package, the lightmaps and tiles,
// the server's limits.
wire::Envelope welcome_message(const TileSource& host, const ServerOptions& options,
                               std::uint64_t session, const wire::ScenePackage& package) {
  const TileStore& tiles = host.tiles();
  wire::Envelope w;
  wire::Welcome* wm = w.mutable_welcome();
  wm->set_protocol_version(wire::kProtocolVersion);
  wm->set_session(session);
  wm->set_scene_id(host.scene_id());
  wm->set_scene_hash(package.hash);
  wm->set_scene_bytes(package.bytes.size());
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
  wm->set_max_frame_bytes(static_cast<std::uint32_t>(options.max_frame));
  wm->set_idle_timeout_ms(static_cast<std::uint32_t>(options.idle_timeout.count()));
  wm->set_tile_epoch(host.tile_epoch());
  return w;
}

// The engine's part of a Stats reply.
void add_engine_stats(const EngineHostStats& es, wire::Stats* s) {
  s->set_updates(es.updates);
  s->set_rays_per_s(es.rays_per_s);
  s->set_convergence(es.convergence);
  s->set_engine_update_ms(es.last_update_ms);
  s->set_engine_idle(es.idle);
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
  s->set_tiles_published(es.tiles_published);
  s->set_engine_seconds_total(es.seconds_total);
  s->set_rays_total(es.rays_total);
  s->set_tiles(es.tiles);
  s->set_texels(es.texels);
  s->set_scene_revision(es.revision);
  s->set_last_edit_ms(es.last_edit_ms);
  s->set_stale_texels(es.stale_texels);
  s->set_bytes_per_texel(es.bytes_per_texel);
}

EngineHostStats engine_stats_from(const wire::Stats& s) {
  EngineHostStats es;
  es.updates = s.updates();
  es.rays_per_s = s.rays_per_s();
  es.convergence = s.convergence();
  es.last_update_ms = s.engine_update_ms();
  es.idle = s.engine_idle();
  for (const wire::PassTime& pt : s.pass_times())
    es.passes.push_back(
        {pt.pass(), pt.bounce(), pt.ms() * 1e-3, pt.rays(), pt.seconds_total(), pt.rays_total()});
  es.update_rate = s.update_rate();
  es.tiles_published = s.tiles_published();
  es.seconds_total = s.engine_seconds_total();
  es.rays_total = s.rays_total();
  es.tiles = s.tiles();
  es.texels = s.texels();
  es.revision = s.scene_revision();
  es.last_edit_ms = s.last_edit_ms();
  es.stale_texels = s.stale_texels();
  es.bytes_per_texel = s.bytes_per_texel();
  return es;
}

// The server's part of a Stats reply.
void add_server_stats(const ServerStats& ss, wire::Stats* s) {
  s->set_clients(ss.clients);
  // The counters whose `wire` is Wire (server_counters.inc), each into its field of that name.
#define IRRADCAST_SERVER_COUNTER_Wire(name) s->set_##name(ss.name);
#define IRRADCAST_SERVER_COUNTER_Local(name)
#define IRRADCAST_SERVER_COUNTER(name, wire, metric, help) IRRADCAST_SERVER_COUNTER_##wire(name)
#include "irradcast/service/server_counters.inc"
#undef IRRADCAST_SERVER_COUNTER
#undef IRRADCAST_SERVER_COUNTER_Local
#undef IRRADCAST_SERVER_COUNTER_Wire
  s->set_queue_depth_total(ss.queue_depth);
  s->set_queue_depth_max(ss.queue_depth_max);
  for (std::size_t r = 0; r < kCloseReasons; ++r) {
    wire::SessionsClosed* c = s->add_sessions_closed();
    c->set_reason(close_reason_name(static_cast<CloseReason>(r)));
    c->set_sessions(ss.sessions_closed[r]);
  }
}

// The TileUpdate that carries a snapshot of `tile`.
wire::Envelope tile_update_message(const TileStore::Tile& tile, const TileStore::Snapshot& snap,
                                   wire::TileEncoding encoding) {
  wire::Envelope e;
  wire::TileUpdate* u = e.mutable_tile_update();
  u->set_lightmap(tile.lightmap);
  u->set_tile_x(tile.tx);
  u->set_tile_y(tile.ty);
  u->set_version(snap.version);
  u->set_encoding(encoding);
  u->set_width(static_cast<std::uint32_t>(tile.rect.w));
  u->set_height(static_cast<std::uint32_t>(tile.rect.h));
  u->set_payload(*snap.payload);
  u->set_server_time_us(snap.time_us);
  return e;
}

std::shared_ptr<const std::string> TileFrames::frame(const TileStore& store, std::uint32_t tile,
                                                     const TileStore::Snapshot& snap,
                                                     wire::TileEncoding encoding) {
  std::vector<Entry>& entries = entries_[encoding == wire::TILE_HALF_ZSTD ? 1 : 0];
  {
    std::lock_guard lock(mutex_);
    if (entries.size() != store.tile_count()) entries.assign(store.tile_count(), {});
    if (tile < entries.size() && entries[tile].payload == snap.payload) return entries[tile].frame;
  }
  auto built = std::make_shared<const std::string>(
      wire::encode_frame(tile_update_message(store.tile(tile), snap, encoding)));
  std::lock_guard lock(mutex_);
  if (tile < entries.size()) entries[tile] = {snap.payload, built};
  return built;
}

}  // namespace irradcast

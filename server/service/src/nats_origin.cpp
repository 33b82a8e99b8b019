// NatsOrigin: the origin's publisher thread (stream, package, tiles, edits, the probe volume,
// poses and avatars) and its public API; the gateways' requests are in nats_origin_requests.cpp.
#include "irradcast/service/nats_origin.h"

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <thread>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast/service/thread_priority.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast_nats.pb.h"
#include "nats_link.h"
#include "nats_origin_impl.h"
#include "presence_board.h"
#include "session_messages.h"

namespace irradcast {

using namespace nats_origin;

void NatsOrigin::Impl::on_tiles(const std::vector<std::uint32_t>& tiles) {
  {
    std::lock_guard lock(mutex);
    for (std::uint32_t t : tiles) {
      if (dirty[t]) {
        ++st.tiles_coalesced;
        continue;
      }
      dirty[t] = 1;
      dirty_list.push_back(t);
    }
    idle = false;
  }
  cv.notify_all();
  listeners.tiles(tiles);
}

void NatsOrigin::Impl::on_edit(const AppliedEdit& applied) {
  {
    std::lock_guard lock(mutex);
    if (edits.size() >= options.max_queued_edits) {
      edits.pop_front();
      ++st.edits_dropped;
    }
    edits.push_back(applied);
    idle = false;
  }
  cv.notify_all();
  listeners.edit(applied);
}

void NatsOrigin::Impl::run() {
  set_thread_name("irradcast-nats");
  std::unique_lock lock(mutex);
  while (!stopping) {
    auto wait = std::chrono::milliseconds(100);
    // Poses waiting are published kPoseEvery after the last set, but only while there is a
    // NATS to publish them to (else this loop would spin on them).
    if (poses_dirty && conn->connected() && refusal.empty()) {
      const auto due = poses_published_at + kPoseEvery, now = Clock::now();
      wait = due > now ? std::chrono::ceil<std::chrono::milliseconds>(due - now)
                       : std::chrono::milliseconds(0);
    }
    if (options.presence) wait = std::min(wait, options.presence_every);
    if (wait.count() > 0) cv.wait_for(lock, wait);
    if (stopping) break;
    if (!conn->connected() || !refusal.empty()) continue;
    const std::uint64_t generation = conn->generation();
    const bool full = generation != published_generation;
    std::vector<std::uint32_t> tiles;
    tiles.swap(dirty_list);
    for (std::uint32_t t : tiles) dirty[t] = 0;
    std::deque<AppliedEdit> eds;
    eds.swap(edits);
    const bool poses = poses_dirty && Clock::now() >= poses_published_at + kPoseEvery;
    if (poses) poses_dirty = false;
    lock.unlock();
    const bool ok = round(full, tiles, eds, poses);
    lock.lock();
    if (ok && full) published_generation = generation;
    if (!ok) {
      ++st.publish_errors;
      published_generation = 0;  // publish everything again next round
    }
    idle = ok && dirty_list.empty() && edits.empty() && !poses_dirty;
    cv.notify_all();
  }
}

// One round of the worker: everything after a (re)connection, then the queued edits (with the
// package they made) and tiles, the stats when due; waits for JetStream's acknowledgements.
bool NatsOrigin::Impl::round(bool full, const std::vector<std::uint32_t>& tiles,
                             std::deque<AppliedEdit>& eds, bool poses) {
  bool ok = true;
  if (!full && Clock::now() >= next_check) {
    next_check = Clock::now() + options.stats_every;
    if (!stream_intact()) {
      // Put back what this round would have published: everything goes out again next round.
      count(&NatsOriginStats::stream_losses);
      std::lock_guard lock(mutex);
      for (std::uint32_t t : tiles)
        if (!dirty[t]) {
          dirty[t] = 1;
          dirty_list.push_back(t);
        }
      for (auto it = eds.rbegin(); it != eds.rend(); ++it) edits.push_front(std::move(*it));
      eds.clear();
      return false;
    }
  }
  if (full) ok = publish_everything(eds);
  if (ok) ok = publish_edits(eds);
  for (std::size_t i = 0; ok && i < tiles.size(); ++i) ok = publish_tile(tiles[i]);
  if (ok) ok = publish_volume(full);
  if (ok && (poses || full)) ok = publish_poses(full);
  if (ok) ok = publish_presence(full);
  if (ok && Clock::now() >= next_stats) {
    ok = publish_stats();
    next_stats = Clock::now() + options.stats_every;
  }
  expire_cameras();
  jsPubOptions po;
  jsPubOptions_Init(&po);
  po.MaxWait = 5000;
  const natsStatus s = js_PublishAsyncComplete(conn->js(), &po);
  if (s != NATS_OK) {
    log::warn("nats", "publish to JetStream: " + nats_link::describe(s));
    return false;
  }
  return ok;
}

// After a (re)connection: the stream, the current package, the newest edit (a gateway that
// missed edits forwards it, and its viewers see the revision gap and load the package), every
// tile. Queued edits the package already holds are dropped.
bool NatsOrigin::Impl::publish_everything(std::deque<AppliedEdit>& eds) {
  if (!ensure_stream()) return false;
  const auto package = host.package();
  const std::uint64_t revision = host.revision();
  if (!stream_allows(revision)) return false;
  if (!publish_package(*package, revision, host.tile_epoch())) return false;
  last_package = package.get();
  while (!eds.empty() && eds.front().revision <= revision) {
    last_edit = std::move(eds.front());
    eds.pop_front();
  }
  if (last_edit && !publish_edit(*last_edit, last_edit->revision == revision)) return false;
  for (std::uint32_t t = 0; t < host.tiles().tile_count(); ++t)
    if (!publish_tile(t)) return false;
  count(&NatsOriginStats::republished);
  next_stats = {};
  return true;
}

bool NatsOrigin::Impl::ensure_stream() {
  jsStreamConfig cfg;
  jsStreamConfig_Init(&cfg);
  cfg.Name = subjects.stream.c_str();
  const char* subject_list[] = {subjects.filter.c_str()};
  cfg.Subjects = subject_list;
  cfg.SubjectsLen = 1;
  cfg.MaxMsgsPerSubject = 1;
  cfg.Storage = js_FileStorage;
  jsStreamInfo* si = nullptr;
  jsErrCode jerr = static_cast<jsErrCode>(0);
  natsStatus s = js_AddStream(&si, conn->js(), &cfg, nullptr, &jerr);
  if (s != NATS_OK && jerr == JSStreamNameExistErr)
    s = js_UpdateStream(&si, conn->js(), &cfg, nullptr, &jerr);
  jsStreamInfo_Destroy(si);
  if (s != NATS_OK) {
    log::warn("nats", "stream " + subjects.stream + ": " + nats_link::describe(s));
    return false;
  }
  return true;
}

// Whether the stream still holds this origin's scene state (checked once a second, between
// rounds whose publishes JetStream acknowledged): not after an operator deleted or purged the
// stream, or another origin published over it. Then everything is published again (the stream
// created anew; another origin's newer revision is respected: stream_allows).
bool NatsOrigin::Impl::stream_intact() {
  natsMsg* msg = nullptr;
  jsErrCode jerr = static_cast<jsErrCode>(0);
  jsOptions quick;
  jsOptions_Init(&quick);
  quick.Wait = 2000;
  const natsStatus s = js_GetLastMsg(&msg, conn->js(), subjects.stream.c_str(),
                                     subjects.state.c_str(), &quick, &jerr);
  std::string why;
  if (s == NATS_OK) {
    wire::NatsSceneState held;
    const bool parsed = held.ParseFromArray(natsMsg_GetData(msg), natsMsg_GetDataLength(msg));
    natsMsg_Destroy(msg);
    if (!parsed || held.origin() != origin) why = "holds another origin's scene state";
  } else if (s == NATS_NOT_FOUND || jerr == JSStreamNotFoundErr || jerr == JSNoMessageFoundErr) {
    why = "lost its scene state (deleted or purged)";
  } else {
    return true;  // no answer now: nothing to conclude
  }
  if (why.empty()) return true;  // our own state: intact
  log::warn("nats", "the stream " + subjects.stream + " " + why + "; publishing everything again");
  return false;
}

// Whether this origin may publish `revision` over what the stream holds. Not when the stream's
// newest scene state comes from another origin process and is of a newer revision: that origin
// applied edits this one does not have (started without its --state-dir, or on another machine),
// and publishing would roll every gateway back (unless options.replace_newer).
bool NatsOrigin::Impl::stream_allows(std::uint64_t revision) {
  natsMsg* msg = nullptr;
  jsErrCode jerr = static_cast<jsErrCode>(0);
  const natsStatus s = js_GetLastMsg(&msg, conn->js(), subjects.stream.c_str(),
                                     subjects.state.c_str(), nullptr, &jerr);
  std::string why;
  if (s == NATS_OK) {
    wire::NatsSceneState held;
    const bool parsed = held.ParseFromArray(natsMsg_GetData(msg), natsMsg_GetDataLength(msg));
    natsMsg_Destroy(msg);
    if (parsed && held.origin() != origin && held.revision() > revision) {
      const std::string what = "the stream " + subjects.stream + " holds revision " +
                               std::to_string(held.revision()) + " of scene '" + host.scene_id() +
                               "' from another origin, and this origin is at revision " +
                               std::to_string(revision);
      if (!options.replace_newer)
        why = what +
              ": not publishing over it (start the origin with the --state-dir that holds its "
              "edits, or with --nats-replace-newer to roll the gateways back to revision " +
              std::to_string(revision) + ")";
      else
        log::warn("nats", what + ": replacing it (--nats-replace-newer)");
    }
  } else if (s != NATS_NOT_FOUND && jerr != JSNoMessageFoundErr) {
    log::warn("nats", "the stream's scene state: " + nats_link::describe(s));
    return false;  // checked again next round
  }
  {
    std::lock_guard lock(mutex);
    stream_checked = true;
    refusal = why;
    st.refused_newer_stream = !why.empty();
  }
  cv.notify_all();
  if (!why.empty()) log::error("nats", why);
  return why.empty();
}

bool NatsOrigin::Impl::publish(const std::string& subject, const google::protobuf::MessageLite& m) {
  const std::string bytes = m.SerializeAsString();
  const natsStatus s = js_PublishAsync(conn->js(), subject.c_str(), bytes.data(),
                                       static_cast<int>(bytes.size()), nullptr);
  if (s != NATS_OK) {
    log::warn("nats", "publish " + subject + ": " + nats_link::describe(s));
    return false;
  }
  return true;
}

bool NatsOrigin::Impl::publish_package(const wire::ScenePackage& package, std::uint64_t revision,
                                       std::uint64_t epoch) {
  const std::int64_t max_payload = natsConnection_GetMaxPayload(conn->nc());
  const std::size_t chunk_bytes =
      static_cast<std::size_t>(std::clamp<std::int64_t>(max_payload - 4096, 4096, 512 << 10));
  const std::vector<std::string> chunks = wire::chunk(package.bytes, chunk_bytes);
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    wire::NatsPackageChunk c;
    c.set_scene_hash(package.hash);
    c.set_index(static_cast<std::uint32_t>(i));
    c.set_data(chunks[i]);
    if (!publish(subjects.package_chunk(static_cast<std::uint32_t>(i)), c)) return false;
  }
  const TileStore& tiles = host.tiles();
  wire::NatsSceneState state;
  state.set_scene_id(host.scene_id());
  state.set_origin(origin);
  state.set_revision(revision);
  state.set_tile_epoch(epoch);
  state.set_scene_hash(package.hash);
  state.set_package_bytes(package.bytes.size());
  state.set_package_chunks(static_cast<std::uint32_t>(chunks.size()));
  state.set_tile_size(static_cast<std::uint32_t>(tiles.options().tile_size));
  for (std::uint32_t m = 0; m < tiles.lightmap_count(); ++m) {
    wire::LightmapInfo* li = state.add_lightmaps();
    li->set_width(static_cast<std::uint32_t>(tiles.lightmap_size(m).first));
    li->set_height(static_cast<std::uint32_t>(tiles.lightmap_size(m).second));
  }
  state.set_backend(host.backend_name());
  if (!publish(subjects.state, state)) return false;
  count(&NatsOriginStats::packages_published);
  return true;
}

bool NatsOrigin::Impl::publish_tile(std::uint32_t index) {
  const TileStore::Snapshot snap = host.tiles().snapshot(index, wire::TILE_RGB9E5_ZSTD);
  if (snap.version == 0) return true;
  wire::NatsTile t;
  t.set_origin(origin);
  t.set_index(index);
  t.set_version(snap.version);
  t.set_time_us(snap.time_us);
  t.set_payload(*snap.payload);
  if (!publish(subjects.tile(index), t)) return false;
  count(&NatsOriginStats::tiles_published);
  return true;
}

// The edits in order, each after the package it made (edits applied together share the package
// made after the last of them, which names it, as Server's broadcast does).
bool NatsOrigin::Impl::publish_edits(std::deque<AppliedEdit>& eds) {
  for (std::size_t i = 0; i < eds.size(); ++i) {
    const AppliedEdit& a = eds[i];
    std::size_t last = i;
    while (last + 1 < eds.size() && eds[last + 1].package == a.package) ++last;
    if (a.package && a.package.get() != last_package) {
      if (!publish_package(*a.package, eds[last].revision, eds[last].tile_epoch)) return false;
      last_package = a.package.get();
    }
    if (!publish_edit(a, a.package && i == last)) return false;
    last_edit = a;
  }
  return true;
}

bool NatsOrigin::Impl::publish_edit(const AppliedEdit& a, bool names_package) {
  wire::NatsEdit e;
  e.set_origin(origin);
  e.set_tile_epoch(a.tile_epoch);
  wire::SceneEdit* m = e.mutable_edit();
  wire::to_proto(a.edit, m);
  m->set_revision(a.revision);
  if (names_package && a.package) m->set_scene_hash(a.package->hash);
  m->set_applied(true);
  m->set_applied_us(a.applied_us);
  if (!publish(subjects.edit, e)) return false;
  count(&NatsOriginStats::edits_published);
  return true;
}

// The probe volume's newest version when it is not published yet (or after a reconnection): its
// frame with the layout in chunks, then the announcement (a gateway has the chunks when it comes).
// Without a volume (none yet, or a scene without dynamic nodes), a whole publish announces that
// there is none, so that a gateway does not serve one an earlier origin left in the stream.
bool NatsOrigin::Impl::publish_volume(bool full) {
  const std::shared_ptr<const ProbeVolumeFrames> v = host.probe_volume();
  if (!v) {
    if (!full) return true;
    wire::NatsVolume none;
    none.set_origin(origin);
    if (!publish(subjects.volume, none)) return false;
    published_volume = nullptr;
    return true;
  }
  if (!full && v == published_volume) return true;
  const std::string& frame = *v->with_layout;
  const std::string hash = wire::sha256(frame);
  const std::int64_t max_payload = natsConnection_GetMaxPayload(conn->nc());
  const std::size_t chunk_bytes =
      static_cast<std::size_t>(std::clamp<std::int64_t>(max_payload - 4096, 4096, 512 << 10));
  const std::vector<std::string> chunks = wire::chunk(frame, chunk_bytes);
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    wire::NatsVolumeChunk c;
    c.set_hash(hash);
    c.set_index(static_cast<std::uint32_t>(i));
    c.set_data(chunks[i]);
    if (!publish(subjects.volume_chunk(static_cast<std::uint32_t>(i)), c)) return false;
  }
  wire::NatsVolume m;
  m.set_origin(origin);
  m.set_epoch(v->epoch);
  m.set_version(v->version);
  m.set_hash(hash);
  m.set_bytes(frame.size());
  m.set_chunks(static_cast<std::uint32_t>(chunks.size()));
  if (!publish(subjects.volume, m)) return false;
  published_volume = v;
  count(&NatsOriginStats::volumes_published);
  return true;
}

// Every posed node's newest pose, when the sequence moved (or after a reconnection). A scene
// without dynamic nodes publishes an empty set on a whole publish: poses an earlier origin left
// in the stream would name nodes this scene does not pose, which its viewers refuse.
bool NatsOrigin::Impl::publish_poses(bool full) {
  PoseBoard* board = host.poses();
  if (!board && !full) return true;
  std::uint64_t sequence = 0;
  const std::map<int, NodePoseState> poses =
      board ? board->snapshot(&sequence) : std::map<int, NodePoseState>{};
  if (!full && sequence == published_poses) return true;
  wire::NatsPoses m;
  m.set_origin(origin);
  wire::Poses* p = m.mutable_poses();
  p->set_sequence(sequence);
  p->set_complete(true);
  p->set_posed_us(
      static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count()));
  for (const auto& [node, pose] : poses)
    *p->add_poses() =
        wire::node_pose_to_proto(static_cast<std::uint32_t>(node), pose.local, pose.visible);
  if (static_cast<std::int64_t>(m.ByteSizeLong()) >
      natsConnection_GetMaxPayload(conn->nc()) - 1024) {
    log::warn("nats", std::to_string(poses.size()) +
                          " posed nodes are more than one NATS message holds: the gateways' "
                          "viewers do not get them");
    published_poses = sequence;
    return true;
  }
  if (!publish(subjects.poses, m)) return false;
  published_poses = sequence;
  poses_published_at = Clock::now();
  count(&NatsOriginStats::poses_published);
  return true;
}

// Every avatar (this origin's viewers' as group 0, then each gateway's), when they changed and
// presence_every passed since the last set, or a second passed. An origin without presence
// publishes an empty set on a whole publish: avatars an earlier origin left are not shown.
bool NatsOrigin::Impl::publish_presence(bool full) {
  if (!options.presence && !full) return true;
  const Clock::time_point now = Clock::now();
  const std::uint64_t version = presence.version();
  if (!full &&
      (now < presence_published_at + options.presence_every ||
       (version == published_presence && now < presence_published_at + kPresenceKeepalive)))
    return true;
  wire::NatsPresence m;
  m.set_origin(origin);
  m.set_time_us(wall_clock_us());
  if (options.presence) {
    m.set_height(presence.height());
    std::size_t n = 0;
    auto add = [&](std::uint64_t source, const std::vector<AvatarState>& avatars) {
      wire::NatsAvatarGroup* g = m.add_groups();
      g->set_source(source);
      for (const AvatarState& a : avatars)
        if (n++ < kMaxPublishedAvatars) avatar_to_wire(a, g->add_avatars());
    };
    add(0, presence.local());
    for (const auto& [source, avatars] : presence.groups()) add(source, avatars);
    if (n > kMaxPublishedAvatars)
      log::warn("nats", std::to_string(n) + " avatars: the gateways are sent the first " +
                            std::to_string(kMaxPublishedAvatars));
  }
  if (!publish(subjects.presence, m)) return false;
  published_presence = version;
  presence_published_at = now;
  count(&NatsOriginStats::presence_published);
  return true;
}

bool NatsOrigin::Impl::publish_stats() {
  wire::Stats s;
  add_engine_stats(host.stats(), &s);
  s.set_backend(host.backend_name());
  return publish(subjects.stats, s);
}

NatsOrigin::NatsOrigin(EngineHost& host, NatsOriginOptions options)
    : host_(host), impl_(std::make_unique<Impl>(host, std::move(options))) {
  Impl& im = *impl_;
  im.dirty.assign(host.tiles().tile_count(), 0);  // the first round publishes every tile
  im.conn = std::make_unique<nats_link::Connection>(im.options.url, im.options.credentials,
                                                    "irradcast-origin " + host.scene_id(),
                                                    [&im] { im.cv.notify_all(); });
  natsStatus s =
      im.camera_sub.subscribe(im.conn->nc(), im.subjects.cameras,
                              [&im](natsConnection* nc, natsMsg* msg) { im.on_cameras(nc, msg); });
  if (s == NATS_OK)
    s = im.edit_sub.subscribe(im.conn->nc(), im.subjects.submit,
                              [&im](natsConnection* nc, natsMsg* msg) { im.on_submit(nc, msg); });
  if (s != NATS_OK) {
    im.camera_sub.close();
    throw Error("NATS at " + im.conn->url() + ": the origin cannot subscribe (" +
                nats_link::describe(s) +
                "; TLS required and not offered, or refused credentials?)");
  }
  host.set_listener([&im](const std::vector<std::uint32_t>& tiles) { im.on_tiles(tiles); });
  host.set_edit_listener([&im](const AppliedEdit& applied) { im.on_edit(applied); });
  if (PoseBoard* board = host.poses())
    im.pose_listener = board->add_listener([&im] {
      {
        std::lock_guard lock(im.mutex);
        if (im.poses_dirty) return;  // the worker knows already
        im.poses_dirty = true;
        im.idle = false;
      }
      im.cv.notify_all();
    });
  im.worker = std::thread([&im] { im.run(); });
  log::info("nats", "publishing scene '" + host.scene_id() + "' to " + im.conn->url() + " (" +
                        im.options.credentials.describe(im.options.url) + ")" + " (stream " +
                        im.subjects.stream + ")");
}

std::string NatsOrigin::check_stream(std::chrono::milliseconds limit) {
  Impl& im = *impl_;
  std::unique_lock lock(im.mutex);
  im.cv.wait_for(lock, limit, [&im] { return im.stream_checked || im.stopping; });
  return im.refusal;
}

NatsOrigin::~NatsOrigin() {
  Impl& im = *impl_;
  host_.set_listener(nullptr);
  host_.set_edit_listener(nullptr);
  if (PoseBoard* board = host_.poses(); board && im.pose_listener)
    board->remove_listener(im.pose_listener);
  {
    std::lock_guard lock(im.mutex);
    im.stopping = true;
  }
  im.cv.notify_all();
  im.worker.join();
  im.camera_sub.close();  // no handler runs after these: the state they use can go
  im.edit_sub.close();
  im.conn.reset();
}

PresenceBoard* NatsOrigin::presence() {
  return impl_->options.presence ? &impl_->presence : nullptr;
}

void NatsOrigin::set_listener(PublishListener listener) {
  impl_->listeners.set(std::move(listener));
}

void NatsOrigin::set_edit_listener(EditListener listener) {
  impl_->listeners.set(std::move(listener));
}

NatsOriginStats NatsOrigin::nats_stats() const {
  std::lock_guard lock(impl_->mutex);
  NatsOriginStats s = impl_->st;
  s.connected = impl_->conn->connected();
  return s;
}

bool NatsOrigin::flush(std::chrono::milliseconds limit) {
  std::unique_lock lock(impl_->mutex);
  impl_->idle = false;
  impl_->cv.notify_all();
  return impl_->cv.wait_for(lock, limit, [&] { return impl_->idle; });
}

}  // namespace irradcast

// The client side of the protocol without I/O (client_session.h).
#include "irradcast/client/client_session.h"

#include <algorithm>
#include <set>

#include "irradcast/common/log.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/probe_volume_message.h"

namespace irradcast {

std::shared_ptr<ClientScene> make_client_scene(const std::string& bytes, const std::string& hash,
                                               int avatar_nodes) {
  auto s = std::make_shared<ClientScene>();
  s->unpacked = wire::open_scene_package(bytes, hash);
  if (avatar_nodes > 0) {
    s->avatar_first = add_avatar_nodes(s->unpacked, avatar_nodes);
    s->avatar_count = avatar_nodes;
  }
  s->world = World::build(s->unpacked.scene);
  s->build_ray_scenes();
  return s;
}

void ClientScene::build_ray_scenes() {
  rays = std::make_unique<RayScene>(world);
  const bool any_dynamic = std::any_of(world.objects.begin(), world.objects.end(),
                                       [](const WorldObject& o) { return o.dynamic; });
  dynamic_rays =
      any_dynamic ? std::make_unique<RayScene>(world, true, RaySceneContent::Dynamic) : nullptr;
  lights = any_dynamic ? std::make_unique<LightSampler>(world) : nullptr;
}

ClientSession::ClientSession(ClientSessionOptions options, ClientSceneFactory factory)
    : options_(std::move(options)),
      factory_(factory ? std::move(factory)
                       : ClientSceneFactory([n = options_.follow_edits ? options_.avatar_nodes : 0](
                                                const std::string& bytes, const std::string& hash) {
                           return make_client_scene(bytes, hash, n);
                         })),
      ping_interval_(options_.ping_interval) {
  tiles_.share_decodes(options_.shared_decodes, options_.shared_texels);
}

wire::Envelope ClientSession::hello() {
  phase_ = Phase::AwaitWelcome;
  assembler_.reset();
  pending_edits_.clear();
  wire::Envelope hello;
  wire::Hello* h = hello.mutable_hello();
  h->set_protocol_version(wire::kProtocolVersion);
  h->set_client_name(options_.name);
  if (scene_) {
    // Resume: the scene we hold and the tile versions we have.
    h->set_cached_scene_hash(scene_hash_);
    h->set_known_epoch(tile_epoch_);
    tiles_.add_known(*h);
  }
  return hello;
}

void ClientSession::disconnect() {
  phase_ = Phase::Idle;
  assembler_.reset();
}

ClientStep ClientSession::on_frame(const wire::Envelope& e) {
  ++counters_.frames_received;
  ClientStep step;
  switch (e.msg_case()) {
    case wire::Envelope::kWelcome:
      return on_welcome(e.welcome());
    case wire::Envelope::kSceneChunk:
      return on_chunk(e.scene_chunk());
    case wire::Envelope::kTileUpdate:
      return on_tile(e.tile_update());
    case wire::Envelope::kSceneEdit:
      on_scene_edit(e.scene_edit());
      break;
    case wire::Envelope::kStats:
      last_stats_ = e.stats();
      step.event = ClientStep::Event::Stats;
      break;
    case wire::Envelope::kError:
      ++counters_.errors_received;
      step.event = ClientStep::Event::ServerError;
      break;
    case wire::Envelope::kBye:
      step.event = ClientStep::Event::Bye;
      break;
    case wire::Envelope::kPoses:
      on_poses(e.poses());
      break;
    case wire::Envelope::kAvatars:
      on_avatars(e.avatars());
      break;
    case wire::Envelope::kProbeVolume:
      try {
        wire::apply_probe_volume(e.probe_volume(), volume_);
      } catch (const Error& ex) {
        throw ClientSessionFailure("protocol", ex.what());
      }
      break;
    default:
      break;  // Pong and anything newer: nothing to do
  }
  return step;
}

ClientStep ClientSession::on_welcome(const wire::Welcome& w) {
  if (phase_ != Phase::AwaitWelcome)
    throw ClientSessionFailure("protocol", "an unexpected Welcome");
  if (w.protocol_version() != wire::kProtocolVersion)
    throw ClientSessionFailure(
        "protocol", "the server speaks protocol " + std::to_string(w.protocol_version()) +
                        ", this client " + std::to_string(wire::kProtocolVersion));
  session_ = w.session();
  // Another lineage of versions: what we hold stays on screen until replaced, but any version
  // the server sends is news.
  if (scene_ && w.tile_epoch() != tile_epoch_) tiles_.forget_versions();
  tile_epoch_ = w.tile_epoch();
  welcome_ = w;
  // Ping often enough for the server's idle timer.
  ping_interval_ = options_.ping_interval;
  if (w.idle_timeout_ms() > 0)
    ping_interval_ = std::min(
        ping_interval_,
        std::max(options_.min_ping_interval, std::chrono::milliseconds(w.idle_timeout_ms() / 3)));
  ClientStep step;
  if (scene_ && w.scene_hash() == scene_hash_) {  // resumed: the scene is the one we hold
    phase_ = Phase::Streaming;
    step.event = ClientStep::Event::SessionReady;
    step.send.push_back(subscribe());
    return step;
  }
  phase_ = Phase::NeedScene;
  step.event = ClientStep::Event::NeedScene;
  return step;
}

bool ClientSession::use_cached_package(const std::string& bytes, ClientStep& step,
                                       std::string* why) {
  if (phase_ != Phase::NeedScene) throw Error("use_cached_package() without NeedScene");
  std::shared_ptr<ClientScene> scene;
  try {
    scene = factory_(bytes, welcome_.scene_hash());
  } catch (const Error& e) {
    if (why) *why = e.what();
    return false;
  }
  step = install(std::move(scene), true);
  return true;
}

wire::Envelope ClientSession::download() {
  if (phase_ != Phase::NeedScene) throw Error("download() without NeedScene");
  try {
    assembler_ =
        std::make_unique<wire::SceneAssembler>(welcome_.scene_hash(), welcome_.scene_bytes());
  } catch (const Error& e) {
    throw ClientSessionFailure("bad scene", e.what());
  }
  phase_ = Phase::Downloading;
  wire::Envelope req;
  req.mutable_scene_request()->set_offset(0);
  return req;
}

ClientStep ClientSession::on_chunk(const wire::SceneChunk& c) {
  if (phase_ != Phase::Downloading)
    throw ClientSessionFailure("protocol", "a SceneChunk outside a download");
  counters_.scene_bytes_downloaded += c.data().size();
  std::shared_ptr<ClientScene> scene;
  try {
    if (!assembler_->add(c)) {
      ClientStep step;
      step.event = ClientStep::Event::Downloading;
      return step;
    }
    scene = factory_(assembler_->bytes(), welcome_.scene_hash());
  } catch (const Error& e) {
    throw ClientSessionFailure("bad scene", e.what());
  }
  downloaded_ = assembler_->bytes();
  assembler_.reset();
  return install(std::move(scene), false);
}

ClientStep ClientSession::install(std::shared_ptr<ClientScene> scene, bool from_cache) {
  try {
    tiles_.configure(welcome_, scene->unpacked.atlas,
                     static_cast<std::size_t>(scene->avatar_count));
  } catch (const Error& e) {
    throw ClientSessionFailure("bad scene", e.what());
  }
  if (from_cache) downloaded_.clear();
  counters_.scene_from_cache = from_cache;
  scene_ = std::move(scene);
  scene_hash_ = welcome_.scene_hash();
  revision_ = scene_->unpacked.revision;
  ++static_revision_;
  volume_ = wire::ReceivedVolume{};  // the old scene's; the server sends this one's on subscribe
  package_poses_.clear();            // the new scene's nodes stand as its package places them
  posable_.clear();
  pose_sequence_ = 0;
  avatars_ = AvatarNodes(scene_->avatar_first, scene_->avatar_count);
  phase_ = Phase::Streaming;
  // Edits that arrived during the download, in order (those the package has are skipped).
  std::vector<wire::SceneEdit> pending;
  pending.swap(pending_edits_);
  for (const wire::SceneEdit& m : pending) on_scene_edit(m);
  ClientStep step;
  step.event = ClientStep::Event::SessionReady;
  step.scene_loaded = true;
  step.send.push_back(subscribe());
  return step;
}

wire::Envelope ClientSession::subscribe() {
  wire::Envelope s;
  s.mutable_subscribe()->set_all(true);
  s.mutable_subscribe()->set_encoding(options_.encoding);
  s.mutable_subscribe()->set_max_bytes_per_s(options_.max_bytes_per_s);
  s.mutable_subscribe()->set_presence(options_.presence);
  return s;
}

ClientStep ClientSession::on_tile(const wire::TileUpdate& t) {
  if (phase_ != Phase::Streaming)
    throw ClientSessionFailure("protocol", "a TileUpdate before the subscription");
  bool applied = false;
  try {
    applied = tiles_.apply(t);
  } catch (const std::exception& e) {
    throw ClientSessionFailure("bad tile", e.what());
  }
  ClientStep step;
  if (applied) {
    ++counters_.tiles_applied;
    step.event = ClientStep::Event::TileApplied;
  }
  return step;
}

void ClientSession::on_scene_edit(const wire::SceneEdit& m) {
  if (!options_.follow_edits || !m.applied()) return;  // an acknowledgement: for its sender
  if (phase_ == Phase::NeedScene || phase_ == Phase::Downloading) {
    pending_edits_.push_back(m);
    return;
  }
  if (phase_ != Phase::Streaming || !scene_) return;  // before the Welcome
  if (m.revision() <= revision_) return;              // the scene has it already
  if (m.revision() > revision_ + 1) {
    // Missed one: the simplest correct thing is the current scene package, which a new
    // connection's Welcome names.
    log::warn(options_.log_tag, "scene edit " + std::to_string(m.revision()) + " after revision " +
                                    std::to_string(revision_) +
                                    ": edits missed; loading the scene again");
    reload_ = true;
    return;
  }
  apply_scene_edit(m);
}

void ClientSession::apply_scene_edit(const wire::SceneEdit& m) {
  ClientScene& s = *scene_;
  try {
    const SceneEdit edit = wire::from_proto(m);
    const bool static_change = edit_changes_static_scene(s.unpacked.scene, edit);
    apply_edit(s.unpacked.scene, edit);  // validates first: unchanged on a bad edit
    const std::vector<int> changed = s.world.update(s.unpacked.scene);
    if (s.rays) s.rays->update(changed);
    if (s.dynamic_rays) s.dynamic_rays->update(changed);
    revision_ = m.revision();
    if (static_change) ++static_revision_;
    ++counters_.edits_applied;
    log::info(options_.log_tag, "applied scene edit " + std::to_string(revision_) + ": " +
                                    edit_to_json(edit) + " (" + std::to_string(changed.size()) +
                                    " objects changed)");
  } catch (const Error& e) {
    log::warn(options_.log_tag, "scene edit " + std::to_string(m.revision()) +
                                    " does not apply to this scene (" + e.what() +
                                    "); loading the scene again");
    reload_ = true;
  }
}

void ClientSession::on_poses(const wire::Poses& m) {
  if (!options_.follow_edits || phase_ != Phase::Streaming || !scene_) return;
  ClientScene& s = *scene_;
  Scene& scene = s.unpacked.scene;
  if (posable_.size() != scene.nodes.size()) posable_ = pose_nodes(scene);
  SceneEdit edit;
  std::map<int, NodePoseState> before;  // the package's pose of nodes posed for the first time
  try {
    edit = wire::pose_edit(m, scene, posable_);  // nodes and shapes: a bad one is hostile
  } catch (const Error& ex) {
    throw ClientSessionFailure("protocol", ex.what());
  }
  for (const wire::NodePose& p : m.poses()) {
    const int n = static_cast<int>(p.node());
    if (!package_poses_.count(n))
      before.emplace(n, NodePoseState{scene.nodes[n].local, scene.nodes[n].visible});
  }
  if (m.complete()) {  // nodes posed before and not now: back where the package places them
    std::set<int> listed;
    for (const wire::NodePose& p : m.poses()) listed.insert(static_cast<int>(p.node()));
    for (const auto& [n, pose] : package_poses_) {
      if (listed.count(n)) continue;
      EditOp op;
      op.kind = EditOp::Kind::SetTransform;
      op.target = "#" + std::to_string(n);
      op.matrix = pose.local;
      edit.ops.push_back(op);
      op.kind = pose.visible ? EditOp::Kind::Show : EditOp::Kind::Hide;
      edit.ops.push_back(op);
    }
  }
  if (!edit.ops.empty()) {
    try {
      apply_edit(scene, edit);  // validates first: unchanged on bad numbers
    } catch (const Error& ex) {
      // The server's scene may have moved on (a revision not applied here yet): a pose it took
      // need not fit this copy. Loaded again, as for an edit that does not apply.
      log::warn(options_.log_tag, std::string("poses do not apply to this scene (") + ex.what() +
                                      "); loading the scene again");
      reload_ = true;
      return;
    }
    const std::vector<int> changed = s.world.update(scene);
    if (s.rays) s.rays->update(changed);
    if (s.dynamic_rays) s.dynamic_rays->update(changed);
  }
  package_poses_.merge(before);
  pose_sequence_ = m.sequence();
  ++counters_.poses_applied;
}

void ClientSession::on_avatars(const wire::Avatars& m) {
  if (phase_ != Phase::Streaming || !scene_) return;
  ++counters_.avatar_messages;
  counters_.avatars_listed += static_cast<std::uint64_t>(m.avatars_size());
  if (avatars_.count() == 0) return;
  ClientScene& s = *scene_;
  SceneEdit edit;
  try {
    edit = avatars_.place(m, s.world.bounds);
    if (edit.ops.empty()) return;
    apply_edit(s.unpacked.scene, edit);
  } catch (const Error& ex) {
    throw ClientSessionFailure("protocol", ex.what());
  }
  const std::vector<int> changed = s.world.update(s.unpacked.scene);
  if (s.rays) s.rays->update(changed);
  if (s.dynamic_rays) s.dynamic_rays->update(changed);
}

bool ClientSession::take_reload() {
  const bool r = reload_;
  reload_ = false;
  return r;
}

std::uint64_t wall_time_us() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

wire::Envelope ClientSession::ping(std::uint64_t nonce, std::uint64_t time_us) {
  wire::Envelope p;
  p.mutable_ping()->set_nonce(nonce);
  p.mutable_ping()->set_time_us(time_us);
  return p;
}

const ClientScene& ClientSession::scene() const {
  if (!scene_) throw Error("no scene yet");
  return *scene_;
}

}  // namespace irradcast

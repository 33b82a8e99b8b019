#include "irradcast/service/engine_host.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/lap_timer.h"
#include "irradcast/common/log.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/engine.h"
#include "irradcast/service/thread_priority.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/probe_volume_message.h"
#include "session_messages.h"

namespace irradcast {

struct EngineHost::Impl {
  std::unique_ptr<Engine> engine;
  // The irradiance volume (a scene with dynamic nodes only; docs/DYNAMIC.md), its epoch (a new
  // one per placement) and version, and the band-0 irradiance it last published.
  std::unique_ptr<IrradianceVolumeBuilder> volume;
  std::uint64_t volume_epoch = 0, volume_version = 0;
  std::vector<float> volume_published;
  bool volume_placed = false;              // placed again since the last publish: a new epoch
  std::uint64_t volume_since_publish = 0;  // refines since the last version
  std::string volume_layout;               // ProbeVolume.layout of the current epoch
};

namespace {
std::uint64_t digest64(const std::string& key) {
  const std::string digest = wire::sha256(key);
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i)
    v = (v << 8) | static_cast<unsigned char>(digest[static_cast<std::size_t>(i)]);
  return v;
}

// The scene as the engine needs it, with an editable ray scene. Validates the parameters first.
PreparedScene prepare(Scene scene, const std::string& scene_id, const EngineHostOptions& options) {
  options.engine.validate();
  // Zero-area and non-finite triangles break the BVH builders and rays (the tools drop them at
  // load already; a scene built in code may still have them).
  drop_degenerate_triangles(scene, scene_id);
  PreparedSceneOptions po;
  po.atlas = options.atlas;
  po.editable = true;  // the two-level BVH that an edit updates incrementally
  po.name = scene_id;
  PreparedScene prepared = PreparedScene::build(std::move(scene), po);
  if (prepared.lights().empty())
    log::warn("engine", scene_id + " has no lights: every tile will be black");
  return prepared;
}

// `edit` with the map of every sky op that names a file read from `sky_dir` (the name confined
// to it like a glTF URI, the map checked by validate_sky); any map the sender put in is dropped.
SceneEdit read_sky_files(SceneEdit edit, const std::string& sky_dir) {
  for (std::size_t i = 0; i < edit.ops.size(); ++i) {
    EditOp& op = edit.ops[i];
    if (op.kind != EditOp::Kind::Sky) continue;
    op.sky_map.reset();
    if (!(op.sky_parts & EditOp::kSkyFile)) continue;
    const std::string where = "edit op " + std::to_string(i + 1) + " (sky)";
    if (sky_dir.empty())
      throw Error(where + ": this server reads no sky files (start it with --sky-dir DIR)");
    const std::string path = confined_file(sky_dir, op.target, where + ": the sky file");
    Sky sky;
    try {
      sky.map = read_exr(path, kMaxSkyWidth, kMaxSkyHeight);
    } catch (const Error& e) {
      std::string why = e.what();  // "<path>: cannot read EXR: ...": the client sees no path
      if (why.rfind(path, 0) == 0) why = why.substr(std::min(why.size(), path.size() + 2));
      throw Error(where + ": the sky file '" + op.target + "': " + why);
    }
    validate_sky(sky, where + ": the sky file '" + op.target + "'");
    op.sky_map = std::make_shared<const ImageRGB>(std::move(sky.map));
  }
  return edit;
}

}  // namespace

EngineHost::EngineHost(Scene scene, std::string scene_id, EngineHostOptions options)
    : scene_id_(std::move(scene_id)),
      options_(options),
      prepared_(prepare(std::move(scene), scene_id_, options_)),
      impl_(std::make_unique<Impl>()) {
  const std::uint64_t replayed = options_.state_dir.empty() ? 0 : replay_journal();
  const PreparedScene& p = prepared_;
  BackendChoice backend = make_backend(options_.backend, p.world(), p.rays(), p.lights());
  backend_ = backend.reason;
  impl_->engine =
      std::make_unique<Engine>(p.world(), p.atlas(), p.gbuffers(), p.rays(),
                               std::move(backend.backend), options_.engine, &p.lights());
  std::vector<std::pair<int, int>> sizes;
  for (const ObjectLightmap& o : p.atlas().objects) sizes.emplace_back(o.width, o.height);
  tiles_ = std::make_unique<TileStore>(sizes, options_.tiles);
  package_ = std::make_shared<const wire::ScenePackage>(
      wire::make_scene_package(p.scene(), p.atlas(), replayed));
  validation_scene_ = p.scene();
  {
    const std::vector<bool> dynamic = prepared_.scene().dynamic_nodes();
    has_dynamic_ = std::find(dynamic.begin(), dynamic.end(), true) != dynamic.end();
    posable_ = pose_nodes(validation_scene_);
  }
  if (has_dynamic_ && journal_) restore_poses();
  {
    const EngineParams& e = options_.engine;
    // Every engine parameter (engine_params.inc) changes the published lightmaps.
    std::string key = package_->hash + "|" + engine_params_key(e);
    auto add = [&](double v) {
      key += '|';  // not "|" + ...: GCC 12 -O3 -Werror=restrict (GCC bug 105329)
      key += std::to_string(v);
    };
    for (double v : {static_cast<double>(options_.atlas.texels_per_scene),
                     static_cast<double>(options_.atlas.max_lightmap_size),
                     static_cast<double>(options_.tiles.tile_size),
                     static_cast<double>(options_.tiles.change_threshold),
                     static_cast<double>(options_.tiles.floor_fraction),
                     static_cast<double>(options_.tiles.refresh_ratio),
                     static_cast<double>(options_.tiles.significance)})
      add(v);
    backend_name_ = impl_->engine->backend().describe();
    key += "|" + backend_name_;  // backends agree only within noise
    tile_epoch_ = digest64(key);
    // Replayed edits: the tiles are not those of a host that applied them while it ran.
    if (replayed > 0) tile_epoch_ = digest64(std::to_string(tile_epoch_) + "|journal");
  }
  if (has_dynamic_ || options_.avatars) {
    impl_->volume = std::make_unique<IrradianceVolumeBuilder>(
        prepared_.world(), prepared_.rays(), prepared_.atlas(), options_.probe_volume);
    impl_->volume_placed = true;
    const VolumeGrid& g = impl_->volume->volume().grid;
    log::info("engine", "probe volume: " + std::to_string(g.counts.x) + " x " +
                            std::to_string(g.counts.y) + " x " + std::to_string(g.counts.z) +
                            " probes every " + std::to_string(g.spacing) + " (" +
                            std::to_string(impl_->volume->switched_off()) + " off, " +
                            std::to_string(impl_->volume->moved()) + " moved out of geometry)");
  }
  revision_ = submitted_revision_ = stats_.revision = replayed;
  stats_.texels = impl_->engine->texel_count();
  stats_.tiles = tiles_->tile_count();
  if (pose_file_)  // last: nothing after it throws, so no joinable thread meets a throw
    pose_saver_ = std::thread([this] {
      set_thread_name("irradcast-pose");
      save_poses();
    });
  log::info("engine", scene_id_ + ": method " + method_name(options_.engine.method) + ", " +
                          std::to_string(p.atlas().objects.size()) + " lightmaps, " +
                          std::to_string(impl_->engine->texel_count()) + " texels, " +
                          std::to_string(tiles_->tile_count()) + " tiles, scene package " +
                          std::to_string(package_->bytes.size()) + " bytes");
}

std::string EngineHost::method_summary() const {
  return impl_->engine->method_summary();
}

std::shared_ptr<const wire::ScenePackage> EngineHost::package() const {
  std::lock_guard lock(mutex_);
  return package_;
}

std::uint64_t EngineHost::tile_epoch() const {
  std::lock_guard lock(mutex_);
  return tile_epoch_;
}

std::uint64_t EngineHost::revision() const {
  std::lock_guard lock(mutex_);
  return revision_;
}

void EngineHost::set_edit_listener(EditListener listener) {
  std::lock_guard lock(mutex_);
  edit_listener_ = std::move(listener);
}

void EngineHost::set_camera(std::uint64_t viewer, std::optional<CameraPose> pose) {
  std::lock_guard lock(mutex_);
  if (pose)
    cameras_[viewer] = *pose;
  else
    cameras_.erase(viewer);
}

EditReceipt EngineHost::submit(const SceneEdit& edit, bool stream) {
  // The validation scene is the scene as every accepted edit will leave it: an edit is checked
  // against the transforms the edits before it lead to (13 edits of scale 1000 each are refused
  // like one edit of 13). Under its own lock, so validation order is revision order and the
  // engine thread is not held up.
  // Sky files are read before the lock: another edit's validation need not wait for them.
  const SceneEdit loaded = read_sky_files(edit, options_.sky_dir);
  std::lock_guard validation(validation_mutex_);
  if (journal_) journal_->check_usable();  // a failed journal refuses poses too
  // Poses (docs/DYNAMIC.md#moving-them-poses): with dynamic nodes, the ops that move, show or
  // hide them are not revisions. The two parts are independent, so the poses go first.
  auto [poses, rest] = has_dynamic_ ? split_poses(validation_scene_, posable_, loaded)
                                    : std::make_pair(SceneEdit{}, loaded);
  if (stream) {
    if (!has_dynamic_) throw Error("a streamed pose moves dynamic nodes, and this scene has none");
    for (std::size_t i = 0; i < loaded.ops.size(); ++i)
      if (pose_node(validation_scene_, posable_, loaded.ops[i]) < 0)
        throw Error("edit op " + std::to_string(i + 1) + " (" + edit_kind_name(loaded.ops[i].kind) +
                    "): a streamed pose moves, shows or hides dynamic nodes only, and '" +
                    loaded.ops[i].target +
                    "' is not one (an edit of the static scene is sent without --stream)");
  }
  if (!rest.ops.empty()) {
    std::lock_guard lock(mutex_);
    if (pending_edits_.size() >= kMaxPendingEdits)
      throw Error("the engine has " + std::to_string(pending_edits_.size()) +
                  " edits waiting; send this one again later");
  }
  validate_edit(validation_scene_, loaded);  // the whole edit, in its order
  EditReceipt receipt;
  if (!poses.ops.empty()) receipt.pose_sequence = post_poses(poses, stream);
  if (!rest.ops.empty()) receipt.revision = submit_revision(rest);
  return receipt;
}

// submit(): the pose ops of a validated edit, applied to the validation scene, then (each node
// within its rate, the posed nodes within what a Poses message holds, an edit's poses on disk)
// posted; on any refusal the validation scene is put back.
std::uint64_t EngineHost::post_poses(const SceneEdit& poses, bool stream) {
  std::vector<int> nodes;
  for (const EditOp& op : poses.ops) nodes.push_back(pose_node(validation_scene_, posable_, op));
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  std::vector<std::pair<int, NodePoseState>> before, after;
  for (int n : nodes)
    before.emplace_back(
        n, NodePoseState{validation_scene_.nodes[n].local, validation_scene_.nodes[n].visible});
  apply_edit(validation_scene_, poses);
  for (int n : nodes)
    after.emplace_back(
        n, NodePoseState{validation_scene_.nodes[n].local, validation_scene_.nodes[n].visible});
  const auto put_back = [&] {
    for (const auto& [n, p] : before) {
      validation_scene_.nodes[n].local = p.local;
      validation_scene_.nodes[n].visible = p.visible;
    }
  };
  std::uint64_t sequence = 0;
  std::map<int, NodePoseState> held = poses_.snapshot(&sequence);
  std::size_t posed = held.size();
  for (int n : nodes) posed += held.count(n) ? 0 : 1;
  if (posed > static_cast<std::size_t>(wire::kMaxWirePoses)) {
    put_back();
    throw Error("poses: " + std::to_string(posed) + " posed nodes would be more than a Poses " +
                "message holds (" + std::to_string(wire::kMaxWirePoses) + ")");
  }
  // Every pose counts against its node's rate, streamed or not (an edit's is also an fsync).
  if (const std::optional<int> over =
          poses_.admit_stream(nodes, std::chrono::steady_clock::now())) {
    put_back();
    throw PoseRateLimited("node '" + validation_scene_.nodes[*over].name + "' is posed more than " +
                          std::to_string(static_cast<int>(PoseBoard::kStreamRate)) +
                          " times a second; this pose was dropped");
  }
  if (pose_file_ && !stream) {
    // On disk before the edit is acknowledged, like a revision.
    SavedPoses saved;
    saved.poses = std::move(held);
    saved.sequence = sequence + 1;
    for (const auto& [n, p] : after) saved.poses[n] = p;
    try {
      pose_file_->write(saved);
    } catch (const Error&) {
      put_back();
      throw;
    }
  }
  const std::uint64_t posted = poses_.post(after, wall_clock_us());
  if (pose_file_ && stream) {
    std::lock_guard lock(saver_mutex_);
    poses_dirty_ = true;
    saver_cv_.notify_all();
  }
  return posted;
}

std::uint64_t EngineHost::submit_revision(const SceneEdit& loaded) {
  std::uint64_t revision = 0;
  {
    std::lock_guard lock(mutex_);
    revision = submitted_revision_ + 1;
  }
  if (journal_) {
    // On disk before it is accepted: validated first, so the journal holds only edits that
    // apply; appended and fsynced; only then applied to the validation scene and queued.
    validate_edit(validation_scene_, loaded);
    journal_->append(revision, loaded);
  }
  apply_edit(validation_scene_, loaded);  // validates first: unchanged when it throws
  const bool static_change = edit_changes_static_scene(validation_scene_, loaded);
  if (journal_ && journal_->wants_compaction()) {
    try {
      // The snapshot must replay: its absolute ops are checked like any edit's (a transform
      // that edits made singular cannot be set in one op; then the journal grows on).
      // Poses are saved apart (DIR/poses): the package places dynamic nodes as loaded.
      const SceneEdit snapshot =
          split_poses(loaded_state_, posable_, state_edit(loaded_state_, validation_scene_)).second;
      if (!snapshot.ops.empty()) validate_edit_ops(loaded_state_, snapshot);
      journal_->compact(revision, snapshot);
    } catch (const Error& e) {
      log::error("journal", std::string("not compacted (the journal grows on): ") + e.what());
    }
  }
  std::lock_guard lock(mutex_);
  submitted_revision_ = revision;
  pending_edits_.emplace_back(revision, loaded);
  // Refining again from now on (nobody waits for an idle that is stale), unless the edit moves
  // dynamic nodes only: the engine applies it and stays idle.
  if (static_change) stats_.idle = false;
  cv_.notify_all();
  return revision;
}

EngineHost::QueuedEdits EngineHost::take_queued_edits() {
  std::deque<std::pair<std::uint64_t, SceneEdit>> pending;
  QueuedEdits q;
  {
    std::lock_guard lock(mutex_);
    pending.swap(pending_edits_);
    for (const auto& [id, pose] : cameras_) q.cameras.push_back(pose);
  }
  for (auto& [revision, edit] : pending) {
    q.revisions.push_back(revision);
    q.edits.push_back(std::move(edit));
  }
  return q;
}

void EngineHost::apply_edits() {
  QueuedEdits queued = take_queued_edits();
  if (queued.edits.empty()) return;
  const auto began = std::chrono::steady_clock::now();
  // Validated when submitted against the scene as loaded; against the edited scene an edit can
  // still fail (a transform pushed out of range by many edits): not applied, not sent.
  EditReport report;
  const SceneChange change = prepared_.apply(queued.edits, &report);
  for (std::size_t i = 0; i < report.edits.size(); ++i)
    if (!report.edits[i].applied)
      log::error("engine", std::string("edit ") + std::to_string(queued.revisions[i]) +
                               " could not be applied: " + report.edits[i].error);
  if (report.applied == 0) return;
  LapTimer lap(report.timings);
  // Dynamic nodes only: the lightmaps and their tiles stay as they are (docs/DYNAMIC.md).
  const bool lightmaps_change = !change.empty();
  if (lightmaps_change) {
    impl_->engine->scene_changed(change, queued.cameras);
    lap.lap("engine (" + impl_->engine->change_timings() + ")");
    if (impl_->volume) {  // the probes see the static scene: placed again, or their light anew
      if (change.geometry) {
        impl_->volume->place();
        impl_->volume_placed = true;
      } else {
        impl_->volume->restart();
      }
      lap.lap("probe volume");
    }
  }
  publish_edits(queued, report, lap, began, lightmaps_change);
}

void EngineHost::publish_edits(QueuedEdits& queued, const EditReport& report, LapTimer& lap,
                               std::chrono::steady_clock::time_point began, bool lightmaps_change) {
  std::vector<AppliedEdit> applied;
  for (std::size_t i = 0; i < queued.edits.size(); ++i) {
    if (!report.edits[i].applied) continue;
    AppliedEdit a;
    a.edit = std::move(queued.edits[i]);
    a.revision = queued.revisions[i];
    applied.push_back(std::move(a));
  }
  const std::uint64_t revision = applied.back().revision;
  auto package = std::make_shared<const wire::ScenePackage>(
      wire::make_scene_package(prepared_.scene(), prepared_.atlas(), revision));
  lap.lap("package");
  std::uint64_t epoch = 0;
  {
    std::lock_guard lock(mutex_);
    // The tiles' versions go on under the same epoch when no lightmap changed.
    epoch = lightmaps_change ? digest64(std::to_string(tile_epoch_) + "|" + package->hash)
                             : tile_epoch_;
  }
  const double ms =
      1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  EditListener listener;
  {
    std::lock_guard lock(mutex_);
    revision_ = revision;
    package_ = package;
    tile_epoch_ = epoch;
    stats_.revision = revision;
    stats_.last_edit_ms = ms;
    if (lightmaps_change) {
      stats_.idle = false;
      stats_.stale_texels = impl_->engine->stale_texels();
      stats_.texels = impl_->engine->texel_count();
      updates_since_edit_ = 0;
    }
    listener = edit_listener_;
  }
  log::info("engine",
            "applied edit " + std::to_string(revision) + " (" + std::to_string(report.moved) +
                " objects moved or shown/hidden, " + std::to_string(report.lights) + " lights, " +
                std::to_string(report.materials) + " materials" + (report.sky ? ", the sky" : "") +
                ") in " + std::to_string(static_cast<int>(ms)) + " ms; " +
                std::to_string(impl_->engine->stale_texels()) + " texels to refresh");
  log::info("engine", "edit " + std::to_string(revision) + " took: " + lap.text());
  const std::uint64_t at = wall_clock_us();
  for (AppliedEdit& a : applied) {
    a.package = package;
    a.tile_epoch = epoch;
    a.applied_us = at;
    a.apply_ms = ms;
    if (listener) listener(a);
  }
  cv_.notify_all();
}

EngineHost::~EngineHost() {
  stop();
  if (pose_saver_.joinable()) {
    {
      std::lock_guard lock(saver_mutex_);
      saver_stop_ = true;
    }
    saver_cv_.notify_all();
    pose_saver_.join();  // after writing the newest poses
  }
}

void EngineHost::set_listener(PublishListener listener) {
  std::lock_guard lock(mutex_);
  listener_ = std::move(listener);
}

void EngineHost::start() {
  if (thread_.joinable()) return;
  stopping_ = false;
  thread_ = std::thread([this] {
    set_thread_name("irradcast-eng");
    if (options_.engine_nice <= 0) {
      run();
      return;
    }
    // The updates run in an arena whose threads (this one and the TBB workers that help)
    // are niced: the network threads come first.
    NiceArena arena(options_.engine_nice);
    arena.execute([this] { run(); });
  });
}

void EngineHost::stop() {
  {
    std::lock_guard lock(mutex_);  // the engine thread checks it under the lock before waiting
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void EngineHost::step() {
  if (thread_.joinable()) throw Error("engine host: step() while the engine thread runs");
  apply_edits();
  do_update();
}

void EngineHost::run() {
  while (!stopping_) {
    {
      std::unique_lock lock(mutex_);
      if (stats_.idle) {
        cv_.wait(lock, [&] { return stopping_.load() || !pending_edits_.empty(); });
        if (stopping_) break;
      }
    }
    try {
      apply_edits();
      {
        // Still idle after the edits: they moved dynamic nodes only (no texel to refine).
        std::lock_guard lock(mutex_);
        if (stats_.idle) continue;
      }
      do_update();
    } catch (const std::exception& e) {
      // The engine's input was validated at construction; a failure here is a bug or a lost
      // device (VK_ERROR_DEVICE_LOST). Keep the last published tiles and stop refining rather
      // than take the service down.
      log::error("engine", std::string("update failed, refinement stopped: ") + e.what());
      std::lock_guard lock(mutex_);
      stats_.idle = true;
      cv_.notify_all();
    }
  }
}

void EngineHost::do_update() {
  const auto began = std::chrono::steady_clock::now();
  // A full update (not a catch-up batch after an edit) counts towards max_updates.
  const bool full = impl_->engine->stale_texels() == 0;
  UpdateStats u = impl_->engine->update();
  // Denoised with --denoise (a copy: the engine's means stay unfiltered). The tile store's
  // noise test below uses the means' standard error, which bounds the denoised values' noise.
  std::vector<Lightmap> maps = impl_->engine->published_lightmaps();
  // With the engine's own noise estimate, tiles that only changed by Monte Carlo noise wait
  // until their refresh is worth the bytes (TileStoreOptions::refresh_ratio). The last update
  // (max_updates) publishes every change beyond the threshold: final tiles are the final means.
  // Updates count from the start, or from the last edit once every texel has a new estimate.
  if (full) ++updates_since_edit_;
  const bool last = options_.max_updates > 0 && updates_since_edit_ >= options_.max_updates;
  // The first update has no error estimate yet, but its sample count is recorded with its
  // versions all the same: else the second update would refresh every tile at once (a burst of
  // the whole image to every client of a fresh server).
  const bool noise_aware = !last && options_.tiles.refresh_ratio > 1.0f;
  std::vector<Lightmap> standard_error;
  if (noise_aware) standard_error = impl_->engine->standard_error();
  const TileStore::Noise noise{impl_->engine->min_samples(),
                               standard_error.empty() ? nullptr : &standard_error};
  std::vector<std::uint32_t> changed =
      tiles_->publish(maps, wall_clock_us(), noise_aware ? &noise : nullptr);
  const bool volume_changed = refine_probe_volume(maps);
  const double bytes_per_texel = tiles_->bytes_per_texel();
  const auto ended = std::chrono::steady_clock::now();
  PublishListener listener;
  {
    std::lock_guard lock(mutex_);
    stats_.updates = impl_->engine->updates();
    stats_.last_update_ms = 1e3 * u.total_seconds;
    stats_.rays_per_s = u.total_seconds > 0.0 ? u.total_rays() / u.total_seconds : 0.0;
    stats_.convergence = impl_->engine->mean_relative_error();
    stats_.tiles_published += changed.size();
    stats_.seconds_total += u.total_seconds;
    stats_.rays_total += u.total_rays();
    stats_.bytes_per_texel = bytes_per_texel;
    record_passes(u);
    if (stats_.updates == 1) first_update_ = began;
    update_ends_.push_back(ended);
    while (!update_ends_.empty() && (ended - update_ends_.front() > kUpdateRateWindow ||
                                     update_ends_.size() > kMaxUpdateEnds))
      update_ends_.pop_front();
    stats_.stale_texels = impl_->engine->stale_texels();
    listener = listener_;
  }
  log::debug("engine", "update " + std::to_string(impl_->engine->updates()) + ": " +
                           std::to_string(changed.size()) + " tiles changed");
  if (listener && (!changed.empty() || volume_changed)) listener(changed);
  if (last) {
    // Idle only once the listener has queued the final tiles: whoever sees "idle" and an
    // empty queue then really has every final tile.
    std::lock_guard lock(mutex_);
    stats_.idle = true;
    const std::string method = impl_->engine->method_summary();
    log::info("engine", "reached " + std::to_string(options_.max_updates) +
                            " updates; the lightmaps are final" +
                            (method.empty() ? "" : " (" + method + ")"));
  }
  cv_.notify_all();
}

// Refines the irradiance volume from the published lightmaps. A new version after a new
// placement (a new epoch, with its layout), else when its band-0 irradiance moved by more than
// 1 % (summed over the probes) since the last one and enough refines have passed: their number
// doubles from a restart up to 32, so that Monte Carlo noise alone cannot send a version per
// update. True when there is a new version. A failure stops the volume, not the engine.
bool EngineHost::refine_probe_volume(const std::vector<Lightmap>& maps) {
  if (!impl_->volume) return false;
  try {
    IrradianceVolumeBuilder& b = *impl_->volume;
    b.refine(maps);
    ++impl_->volume_since_publish;
    const IrradianceVolume& v = b.volume();
    std::vector<float> level(v.probe_count());
    double moved = 0.0, total = 0.0;
    for (std::size_t i = 0; i < level.size(); ++i) {
      level[i] = luminance(v.sh[i][0] + v.emitted[i][0]);
      if (i < impl_->volume_published.size())
        moved += std::fabs(level[i] - impl_->volume_published[i]);
      total += std::fabs(level[i]);
    }
    const std::uint64_t wait = std::clamp<std::uint64_t>(b.rounds() / 2, 1, 32);
    if (!impl_->volume_placed && (impl_->volume_since_publish < wait || moved <= 0.01 * total))
      return false;
    if (impl_->volume_placed) {
      ++impl_->volume_epoch;
      impl_->volume_layout = wire::encode_probe_layout(v);  // once per epoch
    }
    ++impl_->volume_version;
    auto frames = std::make_shared<ProbeVolumeFrames>();
    frames->epoch = impl_->volume_epoch;
    frames->version = impl_->volume_version;
    wire::Envelope e;
    *e.mutable_probe_volume() =
        wire::probe_volume_to_proto(v, frames->epoch, frames->version, impl_->volume_layout);
    frames->with_layout = std::make_shared<const std::string>(wire::encode_frame(e));
    e.mutable_probe_volume()->clear_layout();  // the same SH, encoded once
    frames->sh_only = std::make_shared<const std::string>(wire::encode_frame(e));
    impl_->volume_published = std::move(level);
    impl_->volume_placed = false;
    impl_->volume_since_publish = 0;
    std::lock_guard lock(mutex_);
    probe_volume_ = std::move(frames);
    return true;
  } catch (const std::exception& e) {
    log::error("engine", std::string("probe volume stopped: ") + e.what());
    impl_->volume.reset();
    return false;
  }
}

std::shared_ptr<const ProbeVolumeFrames> EngineHost::probe_volume() const {
  std::lock_guard lock(mutex_);
  return probe_volume_;
}

void EngineHost::record_passes(const UpdateStats& u) {
  // The list of passes is fixed by the parameters; it is built on the first update.
  const EngineParams& e = options_.engine;
  const bool probes = e.uses_probes();
  const bool cells = e.method == Method::Cells;
  const char* bounce_pass = e.method == Method::Vpl ? "vpl-gather"
                            : cells                 ? "scatter"
                                                    : "cache-records";
  if (stats_.passes.empty()) {
    stats_.passes.push_back({"direct", 0});
    if (!cells)
      stats_.passes.push_back({e.method == Method::Vpl ? "vpl-shoot" : "cache-placement", 0});
    const auto bounces = static_cast<std::size_t>(e.indirect_bounces);
    for (std::size_t b = 1; b <= bounces; ++b) {
      if (probes) stats_.passes.push_back({"probes", static_cast<std::uint32_t>(b)});
      stats_.passes.push_back({bounce_pass, static_cast<std::uint32_t>(b)});
    }
  }
  auto add = [](EnginePassStats& p, const PassTiming& t) {
    p.seconds = t.seconds;
    p.rays = t.rays;
    p.seconds_total += t.seconds;
    p.rays_total += t.rays;
  };
  std::size_t i = 0;
  add(stats_.passes[i++], u.direct);
  if (!cells && i < stats_.passes.size()) add(stats_.passes[i++], u.prepare);
  for (std::size_t b = 0; b < u.scatter.size() && i < stats_.passes.size(); ++b) {
    if (probes && b < u.probes.size()) add(stats_.passes[i++], u.probes[b]);
    if (i < stats_.passes.size()) add(stats_.passes[i++], u.scatter[b]);
  }
}

EngineHostStats EngineHost::stats() const {
  std::lock_guard lock(mutex_);
  EngineHostStats s = stats_;
  // Updates that finished within the window, over the window (or the time since the first
  // update began, when shorter).
  const auto now = std::chrono::steady_clock::now();
  std::size_t recent = 0;
  for (auto it = update_ends_.rbegin(); it != update_ends_.rend() && now - *it <= kUpdateRateWindow;
       ++it)
    ++recent;
  const double span = std::min(std::chrono::duration<double>(kUpdateRateWindow).count(),
                               std::chrono::duration<double>(now - first_update_).count());
  s.update_rate = recent > 0 && span > 0.0 ? static_cast<double>(recent) / span : 0.0;
  return s;
}

void EngineHost::wait_for_updates(std::uint64_t updates) const {
  std::unique_lock lock(mutex_);
  cv_.wait(lock, [&] { return stats_.updates >= updates || stats_.idle || stopping_.load(); });
}

}  // namespace irradcast

// The engine as a service: owns a prepared scene (the scene, world, ray scene, atlas, G-buffers:
// PreparedScene) and the engine on it, applies scene edits to both, runs progressive updates on
// its own thread, and publishes each update's lightmaps to a TileStore. The network server reads
// the tile store and the stats; it never touches the engine.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/backend_select.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/engine/irradiance_volume_builder.h"
#include "irradcast/engine/prepared_scene.h"
#include "irradcast/service/edit_journal.h"
#include "irradcast/service/pose_board.h"
#include "irradcast/service/pose_file.h"
#include "irradcast/service/tile_source.h"
#include "irradcast/service/tile_store.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

class LapTimer;
struct UpdateStats;

struct EngineHostOptions {
  EngineParams engine;
  BackendOptions backend;  // which TraceBackend runs the passes
  AtlasOptions atlas;
  TileStoreOptions tiles;
  std::uint32_t max_updates = 0;  // stop refining after this many updates (0 = never)
  // Nice value of the engine thread and its TBB workers while the host runs (0 = as the
  // process): the network threads come first (see thread_priority.h).
  int engine_nice = 10;
  // The folder sky edits may name map files in (irradcast-server --sky-dir); empty: edits that
  // name a sky file are refused. A name is confined to it like a glTF URI (confined_file).
  std::string sky_dir;
  // The folder of the durable edit journal (irradcast-server --state-dir; empty: edits live in
  // memory only). Every accepted edit is on disk there before submit_edit returns, and a host
  // built on the same scene and folder starts at the journal's revision
  // (docs/EDITS.md#durable-edits).
  std::string state_dir;
  // The journal is rewritten as one snapshot once it holds this many edits (0: never).
  std::uint32_t journal_compact_after = 1000;
  // The irradiance volume that lights dynamic objects (computed when the scene has dynamic
  // nodes, or with `avatars`; docs/DYNAMIC.md).
  IrradianceVolumeOptions probe_volume;
  // The volume is computed for viewers' avatars (irradcast-server --presence) even without
  // dynamic nodes.
  bool avatars = false;
};

class EngineHost final : public TileSource {
 public:
  // Builds everything (the slow part of start-up). Throws irradcast::Error on a bad scene or
  // bad parameters.
  EngineHost(Scene scene, std::string scene_id, EngineHostOptions options);
  ~EngineHost() override;
  EngineHost(const EngineHost&) = delete;
  EngineHost& operator=(const EngineHost&) = delete;

  // Called on the engine thread after each publish with the tiles that got a new version.
  void set_listener(PublishListener listener) override;

  // Scene edits (docs/EDITS.md). Validates `edit` against the scene and accepts it. Its pose
  // ops (moving, showing or hiding dynamic nodes) are posted to poses() at once, as the nodes'
  // new poses: no revision, no engine work (docs/DYNAMIC.md#poses). Its other ops are queued as
  // a revision: the engine thread applies queued edits before its next update (waking up if it
  // was idle) and then refines the affected texels first. Returns the revision the scene will
  // have once it is applied (0: poses only) and the pose sequence. Throws irradcast::Error with
  // a clear message on an invalid edit (nothing queued or posted); PoseRateLimited on a streamed
  // pose past its node's rate.
  // With a state folder the revision is appended to the journal and fsynced before this
  // returns (an I/O failure throws, and refuses every later edit), and so are the poses of an
  // edit that is not streamed (DIR/poses); streamed poses are saved at most kPoseSaveInterval
  // later.
  // A sky op that names a file gets its map here, read from options.sky_dir (validate_sky), and
  // carries it to the engine and, with the broadcast, to the viewers; a map in `edit` itself is
  // never used. Any thread.
  EditReceipt submit(const SceneEdit& edit, bool stream) override;
  PoseBoard* poses() override { return has_dynamic_ ? &poses_ : nullptr; }
  static constexpr std::chrono::milliseconds kPoseSaveInterval{100};
  // Called on the engine thread once per applied edit, before the tiles that show it are
  // published: the server sends the edit to every viewer from here.
  void set_edit_listener(EditListener listener) override;
  // The revision of the scene as applied (0: as loaded).
  std::uint64_t revision() const override;

  // The cameras of connected viewers (from their CameraUpdates): the engine refines what they
  // see first after an edit. `pose` empty removes the viewer. Any thread.
  void set_camera(std::uint64_t viewer, std::optional<CameraPose> pose) override;

  void start();  // starts the engine thread
  void stop();   // stops it after the update in flight; idempotent
  // Runs one update and publishes it on the calling thread (tests; not while started).
  void step();

  const std::string& scene_id() const override { return scene_id_; }
  // Which backend runs the passes and why (make_backend's reason line).
  const std::string& backend() const { return backend_; }
  // The backend and its device ("embree", "vulkan on NVIDIA ... (discrete GPU, ...)").
  std::string backend_name() const override { return backend_name_; }
  // The scene, world and atlas: the engine thread changes the scene and world when it applies
  // an edit, so other threads must not read them while the engine runs (tests read them
  // between step() calls).
  const Scene& scene() const { return prepared_.scene(); }
  const World& world() const { return prepared_.world(); }
  const Atlas& atlas() const { return prepared_.atlas(); }
  // The indirect method's state in one line ("" for radiance cells); engine thread or stopped.
  std::string method_summary() const;
  // The scene package at the current revision (a new one after every edit). Any thread.
  std::shared_ptr<const wire::ScenePackage> package() const override;
  // Identifies the lineage of tile versions (Welcome.tile_epoch): a hash of everything that
  // determines them (scene package, engine, atlas and tile options, and every edit since). The
  // engine is deterministic, so a host built from the same inputs publishes the same versions.
  // Any thread.
  std::uint64_t tile_epoch() const override;
  TileStore& tiles() { return *tiles_; }
  const TileStore& tiles() const override { return *tiles_; }
  // A copy of the stats; update_rate is computed at the time of the call.
  EngineHostStats stats() const override;
  std::shared_ptr<const ProbeVolumeFrames> probe_volume() const override;
  static constexpr std::chrono::seconds kUpdateRateWindow{10};
  // Blocks until at least `updates` updates are published or the engine is idle (tests).
  void wait_for_updates(std::uint64_t updates) const;

 private:
  struct Impl;
  // Edits taken from the queue, and the viewers' cameras at that time.
  struct QueuedEdits {
    std::vector<std::uint64_t> revisions;
    std::vector<SceneEdit> edits;
    std::vector<CameraPose> cameras;
  };
  // Constructor, with a state folder: opens the journal and applies its edits to the prepared
  // scene (before the engine exists); returns the journal's revision.
  std::uint64_t replay_journal();
  // Constructor, with a state folder and dynamic nodes: the poses saved in it.
  void restore_poses();
  // The saver thread: streamed poses, at most every kPoseSaveInterval.
  void save_poses();
  // submit(): queues the edit's ops that are not poses as the next revision (validation_mutex_).
  std::uint64_t submit_revision(const SceneEdit& edit);
  // submit(): posts an edit's pose ops; returns the pose sequence (validation_mutex_).
  std::uint64_t post_poses(const SceneEdit& poses, bool stream);
  void run();
  void do_update();
  void apply_edits();  // engine thread: applies the queued edits
  QueuedEdits take_queued_edits();
  // After the prepared scene and the engine took the applied edits: the new scene package and
  // tile epoch (the same epoch when no lightmap changes: dynamic nodes only), the stats, the log
  // and the edit listener.
  void publish_edits(QueuedEdits& queued, const EditReport& report, LapTimer& lap,
                     std::chrono::steady_clock::time_point began, bool lightmaps_change);
  void record_passes(const UpdateStats& u);                     // with mutex_ held
  bool refine_probe_volume(const std::vector<Lightmap>& maps);  // engine thread
  static constexpr std::size_t kMaxUpdateEnds = 1u << 16;

  std::string scene_id_;
  std::string backend_;
  std::string backend_name_;
  EngineHostOptions options_;
  PreparedScene prepared_;  // the scene, world, ray scene, lights, atlas, G-buffers
  std::shared_ptr<const wire::ScenePackage> package_;  // guarded by mutex_
  std::uint64_t tile_epoch_ = 0;                       // guarded by mutex_
  // submit_edit: the scene as the accepted edits will leave it (validation_mutex_).
  std::mutex validation_mutex_;
  Scene validation_scene_;
  // With a state folder: the journal, and the editable state of the scene as loaded (no meshes
  // or textures) that a compaction's snapshot starts from (validation_mutex_).
  std::unique_ptr<EditJournal> journal_;
  Scene loaded_state_;
  std::string scene_hash_;  // wire::scene_content_hash of the scene as loaded (with a folder)
  // The dynamic nodes' poses; with a state folder, saved in DIR/poses (synchronously for an
  // edit, by pose_saver_ for streamed poses).
  bool has_dynamic_ = false;
  std::vector<bool> posable_;  // pose_nodes() of the scene (edits never change it)
  PoseBoard poses_;
  std::unique_ptr<PoseFile> pose_file_;
  std::thread pose_saver_;
  std::mutex saver_mutex_;
  std::condition_variable saver_cv_;
  bool poses_dirty_ = false, saver_stop_ = false;                  // saver_mutex_
  static constexpr std::size_t kMaxPendingEdits = 4096;            // accepted, not yet applied
  std::deque<std::pair<std::uint64_t, SceneEdit>> pending_edits_;  // guarded by mutex_
  std::uint64_t revision_ = 0;                                     // applied; guarded by mutex_
  std::uint64_t submitted_revision_ = 0;                           // guarded by mutex_
  std::uint32_t updates_since_edit_ = 0;                           // engine thread
  EditListener edit_listener_;                                     // guarded by mutex_
  std::map<std::uint64_t, CameraPose> cameras_;                    // guarded by mutex_
  std::unique_ptr<Impl> impl_;
  std::unique_ptr<TileStore> tiles_;
  PublishListener listener_;
  std::thread thread_;
  std::atomic<bool> stopping_{false};
  mutable std::mutex mutex_;
  mutable std::condition_variable cv_;
  EngineHostStats stats_;
  std::shared_ptr<const ProbeVolumeFrames> probe_volume_;  // guarded by mutex_
  // For update_rate: when the first update began, and when each update of the last
  // kUpdateRateWindow finished (oldest first).
  std::chrono::steady_clock::time_point first_update_{};
  std::deque<std::chrono::steady_clock::time_point> update_ends_;
};

}  // namespace irradcast

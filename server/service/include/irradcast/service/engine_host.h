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
#include "irradcast/engine/prepared_scene.h"
#include "irradcast/service/tile_store.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

class LapTimer;
struct UpdateStats;

// An edit the engine thread has applied (EngineHost::set_edit_listener).
struct AppliedEdit {
  SceneEdit edit;
  std::uint64_t revision = 0;  // the scene's revision after it (the first edit makes 1)
  std::shared_ptr<const wire::ScenePackage> package;  // the scene package at that revision
  std::uint64_t tile_epoch = 0;                       // EngineHost::tile_epoch() after it
  std::uint64_t applied_us = 0;                       // system clock when the engine had applied it
  double apply_ms = 0.0;  // time to apply (scene, ray scene, G-buffers, engine)
};

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
};

// One engine pass (direct, or a bounce's probe gather or scatter): the last update's time and
// rays, and the totals over every update.
struct EnginePassStats {
  std::string pass;          // "direct", "probes" or "scatter"
  std::uint32_t bounce = 0;  // 0 for direct, k for the k-th indirect bounce
  double seconds = 0.0;      // last update
  std::uint64_t rays = 0;    // last update
  double seconds_total = 0.0;
  std::uint64_t rays_total = 0;
};

struct EngineHostStats {
  std::uint64_t updates = 0;
  double last_update_ms = 0.0;
  double rays_per_s = 0.0;   // of the last update
  double convergence = 1.0;  // mean relative standard error of the texels
  bool idle = false;         // max_updates reached: the lightmaps will not change
  std::uint64_t tiles_published = 0;
  // Passes in the order they run: direct, then per bounce probes (not in unbiased mode, which
  // has no probes) and scatter. Empty before the first update.
  std::vector<EnginePassStats> passes;
  double seconds_total = 0.0;  // time in updates (Engine::update), summed
  std::uint64_t rays_total = 0;
  // Updates per second over the last kUpdateRateWindow: the updates that finished in that
  // window divided by the window (or by the time since the first update began, when that is
  // shorter). Sliding, so it falls to 0 within the window once the engine stops refining.
  double update_rate = 0.0;
  double bytes_per_texel = 0.0;  // TileStore::bytes_per_texel() after the last publish
  std::uint64_t texels = 0;      // texels the engine computes
  std::uint64_t tiles = 0;       // tiles in the tile store
  std::uint64_t revision = 0;    // scene revision (edits applied so far)
  double last_edit_ms = 0.0;     // time the last edit took to apply
  // Texels still waiting for their first estimate since the last edit (0: caught up).
  std::uint64_t stale_texels = 0;
};

class EngineHost {
 public:
  // Builds everything (the slow part of start-up). Throws irradcast::Error on a bad scene or
  // bad parameters.
  EngineHost(Scene scene, std::string scene_id, EngineHostOptions options);
  ~EngineHost();
  EngineHost(const EngineHost&) = delete;
  EngineHost& operator=(const EngineHost&) = delete;

  // Called on the engine thread after each publish with the tiles that got a new version.
  using PublishListener = std::function<void(const std::vector<std::uint32_t>&)>;
  void set_listener(PublishListener listener);

  // Scene edits (docs/EDITS.md). Validates `edit` against the scene and queues it; the engine
  // thread applies queued edits before its next update (waking up if it was idle) and then
  // refines the affected texels first. Returns the revision the scene will have once it is
  // applied. Throws irradcast::Error with a clear message on an invalid edit (nothing queued).
  // A sky op that names a file gets its map here, read from options.sky_dir (validate_sky), and
  // carries it to the engine and, with the broadcast, to the viewers; a map in `edit` itself is
  // never used. Any thread.
  std::uint64_t submit_edit(const SceneEdit& edit);
  // Called on the engine thread once per applied edit, before the tiles that show it are
  // published: the server sends the edit to every viewer from here.
  using EditListener = std::function<void(const AppliedEdit&)>;
  void set_edit_listener(EditListener listener);
  // The revision of the scene as applied (0: as loaded).
  std::uint64_t revision() const;

  // The cameras of connected viewers (from their CameraUpdates): the engine refines what they
  // see first after an edit. `pose` empty removes the viewer. Any thread.
  void set_camera(std::uint64_t viewer, std::optional<CameraPose> pose);

  void start();  // starts the engine thread
  void stop();   // stops it after the update in flight; idempotent
  // Runs one update and publishes it on the calling thread (tests; not while started).
  void step();

  const std::string& scene_id() const { return scene_id_; }
  // Which backend runs the passes and why (make_backend's reason line).
  const std::string& backend() const { return backend_; }
  // The backend and its device ("embree", "vulkan on NVIDIA ... (discrete GPU, ...)").
  const std::string& backend_name() const { return backend_name_; }
  // The scene, world and atlas: the engine thread changes the scene and world when it applies
  // an edit, so other threads must not read them while the engine runs (tests read them
  // between step() calls).
  const Scene& scene() const { return prepared_.scene(); }
  const World& world() const { return prepared_.world(); }
  const Atlas& atlas() const { return prepared_.atlas(); }
  // The indirect method's state in one line ("" for radiance cells); engine thread or stopped.
  std::string method_summary() const;
  // The scene package at the current revision (a new one after every edit). Any thread.
  std::shared_ptr<const wire::ScenePackage> package() const;
  // Identifies the lineage of tile versions (Welcome.tile_epoch): a hash of everything that
  // determines them (scene package, engine, atlas and tile options, and every edit since). The
  // engine is deterministic, so a host built from the same inputs publishes the same versions.
  // Any thread.
  std::uint64_t tile_epoch() const;
  TileStore& tiles() { return *tiles_; }
  const TileStore& tiles() const { return *tiles_; }
  // A copy of the stats; update_rate is computed at the time of the call.
  EngineHostStats stats() const;
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
  void run();
  void do_update();
  void apply_edits();  // engine thread: applies the queued edits
  QueuedEdits take_queued_edits();
  // After the prepared scene and the engine took the applied edits: the new scene package and
  // tile epoch, the stats, the log and the edit listener.
  void publish_edits(QueuedEdits& queued, const EditReport& report, LapTimer& lap,
                     std::chrono::steady_clock::time_point began);
  void record_passes(const UpdateStats& u);  // with mutex_ held
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
  // For update_rate: when the first update began, and when each update of the last
  // kUpdateRateWindow finished (oldest first).
  std::chrono::steady_clock::time_point first_update_{};
  std::deque<std::chrono::steady_clock::time_point> update_ends_;
};

}  // namespace irradcast

// The engine as a service: owns a scene and everything the engine needs (world, ray scene,
// atlas, G-buffers, the engine itself), runs progressive updates on its own thread, and
// publishes each update's lightmaps to a TileStore. The network server reads the tile store and
// the stats; it never touches the engine.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/atlas.h"
#include "irradcast/backend_select.h"
#include "irradcast/engine_params.h"
#include "irradcast/scene.h"
#include "irradcast/scene_package.h"
#include "irradcast/tile_store.h"
#include "irradcast/world.h"

namespace irradcast {

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

  void start();  // starts the engine thread
  void stop();   // stops it after the update in flight; idempotent
  // Runs one update and publishes it on the calling thread (tests; not while started).
  void step();

  const std::string& scene_id() const { return scene_id_; }
  // Which backend runs the passes and why (make_backend's reason line).
  const std::string& backend() const { return backend_; }
  // The backend and its device ("embree", "vulkan on NVIDIA ... (discrete GPU, ...)").
  const std::string& backend_name() const { return backend_name_; }
  const Scene& scene() const { return scene_; }
  const World& world() const { return world_; }
  const Atlas& atlas() const { return atlas_; }
  const wire::ScenePackage& package() const { return package_; }
  // Identifies the lineage of tile versions (Welcome.tile_epoch): a hash of everything that
  // determines them (scene package, engine, atlas and tile options). The engine is
  // deterministic, so a host built from the same inputs publishes the same versions.
  std::uint64_t tile_epoch() const { return tile_epoch_; }
  TileStore& tiles() { return *tiles_; }
  const TileStore& tiles() const { return *tiles_; }
  // A copy of the stats; update_rate is computed at the time of the call.
  EngineHostStats stats() const;
  static constexpr std::chrono::seconds kUpdateRateWindow{10};
  // Blocks until at least `updates` updates are published or the engine is idle (tests).
  void wait_for_updates(std::uint64_t updates) const;

 private:
  struct Impl;
  void run();
  void do_update();
  void record_passes(const UpdateStats& u);  // with mutex_ held
  static constexpr std::size_t kMaxUpdateEnds = 1u << 16;

  Scene scene_;
  std::string scene_id_;
  std::string backend_;
  std::string backend_name_;
  EngineHostOptions options_;
  World world_;
  Atlas atlas_;
  wire::ScenePackage package_;
  std::uint64_t tile_epoch_ = 0;
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

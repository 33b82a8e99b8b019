// The engine as a service: owns a scene and everything the engine needs (world, ray scene,
// atlas, G-buffers, the engine itself), runs progressive updates on its own thread, and
// publishes each update's lightmaps to a TileStore. The network server reads the tile store and
// the stats; it never touches the engine.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/atlas.h"
#include "irradcast/engine_params.h"
#include "irradcast/scene.h"
#include "irradcast/scene_package.h"
#include "irradcast/tile_store.h"
#include "irradcast/world.h"

namespace irradcast {

struct EngineHostOptions {
  EngineParams engine;
  AtlasOptions atlas;
  TileStoreOptions tiles;
  std::uint32_t max_updates = 0;  // stop refining after this many updates (0 = never)
};

struct EngineHostStats {
  std::uint64_t updates = 0;
  double last_update_ms = 0.0;
  double rays_per_s = 0.0;   // of the last update
  double convergence = 1.0;  // mean relative standard error of the texels
  bool idle = false;         // max_updates reached: the lightmaps will not change
  std::uint64_t tiles_published = 0;
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
  EngineHostStats stats() const;
  // Blocks until at least `updates` updates are published or the engine is idle (tests).
  void wait_for_updates(std::uint64_t updates) const;

 private:
  struct Impl;
  void run();
  void do_update();

  Scene scene_;
  std::string scene_id_;
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
};

}  // namespace irradcast

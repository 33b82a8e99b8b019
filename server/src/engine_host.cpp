#include "irradcast/engine_host.h"

#include <algorithm>
#include <chrono>

#include "irradcast/embree_backend.h"
#include "irradcast/engine.h"
#include "irradcast/error.h"
#include "irradcast/gbuffer.h"
#include "irradcast/lights.h"
#include "irradcast/log.h"
#include "irradcast/ray_scene.h"
#include "irradcast/texel_validity.h"
#include "irradcast/thread_priority.h"

namespace irradcast {

struct EngineHost::Impl {
  std::unique_ptr<RayScene> rays;
  std::unique_ptr<LightSampler> lights;
  std::vector<TexelGBuffer> gbuffers;
  std::unique_ptr<Engine> engine;
};

namespace {
std::uint64_t now_us() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}
}  // namespace

EngineHost::EngineHost(Scene scene, std::string scene_id, EngineHostOptions options)
    : scene_(std::move(scene)),
      scene_id_(std::move(scene_id)),
      options_(options),
      impl_(std::make_unique<Impl>()) {
  options_.engine.validate();
  world_ = World::build(scene_);
  if (world_.objects.empty()) throw Error(scene_id_ + ": the scene has no triangles to light");
  impl_->rays = std::make_unique<RayScene>(world_);
  impl_->lights = std::make_unique<LightSampler>(world_);
  if (impl_->lights->empty())
    log::warn("engine", scene_id_ + " has no lights: every tile will be black");
  atlas_ = build_atlas(world_, options_.atlas);
  impl_->gbuffers = rasterize_gbuffer(world_, atlas_);
  mark_hidden_texels(*impl_->rays, impl_->gbuffers);
  BackendChoice backend = make_backend(options_.backend, world_, *impl_->rays, *impl_->lights);
  backend_ = backend.reason;
  impl_->engine = std::make_unique<Engine>(world_, atlas_, impl_->gbuffers, *impl_->rays,
                                           std::move(backend.backend), options_.engine);
  std::vector<std::pair<int, int>> sizes;
  for (const ObjectLightmap& o : atlas_.objects) sizes.emplace_back(o.width, o.height);
  tiles_ = std::make_unique<TileStore>(sizes, options_.tiles);
  package_ = wire::make_scene_package(scene_, atlas_);
  {
    const EngineParams& e = options_.engine;
    std::string key = package_.hash;
    auto add = [&](double v) { key += "|" + std::to_string(v); };
    for (double v :
         {static_cast<double>(e.cell_size), static_cast<double>(e.tracing_range),
          static_cast<double>(e.direct_samples), static_cast<double>(e.indirect_samples),
          static_cast<double>(e.indirect_bounces), static_cast<double>(e.probe_resolution),
          static_cast<double>(e.dispatch), static_cast<double>(e.distant_point),
          static_cast<double>(e.relocate_probes), static_cast<double>(e.probe_visibility),
          static_cast<double>(e.seed), static_cast<double>(options_.atlas.texels_per_scene),
          static_cast<double>(options_.atlas.max_lightmap_size),
          static_cast<double>(options_.tiles.tile_size),
          static_cast<double>(options_.tiles.change_threshold),
          static_cast<double>(options_.tiles.floor_fraction),
          static_cast<double>(options_.tiles.refresh_ratio),
          static_cast<double>(options_.tiles.significance)})
      add(v);
    backend_name_ = impl_->engine->backend().describe();
    key += "|" + backend_name_;  // backends agree only within noise
    const std::string digest = wire::sha256(key);
    for (int i = 0; i < 8; ++i)
      tile_epoch_ =
          (tile_epoch_ << 8) | static_cast<unsigned char>(digest[static_cast<std::size_t>(i)]);
  }
  stats_.texels = impl_->engine->texel_count();
  stats_.tiles = tiles_->tile_count();
  log::info("engine", scene_id_ + ": " + std::to_string(atlas_.objects.size()) + " lightmaps, " +
                          std::to_string(impl_->engine->texel_count()) + " texels, " +
                          std::to_string(tiles_->tile_count()) + " tiles, scene package " +
                          std::to_string(package_.bytes.size()) + " bytes");
}

EngineHost::~EngineHost() {
  stop();
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
  stopping_ = true;
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void EngineHost::step() {
  if (thread_.joinable()) throw Error("engine host: step() while the engine thread runs");
  do_update();
}

void EngineHost::run() {
  while (!stopping_) {
    {
      std::unique_lock lock(mutex_);
      if (stats_.idle) {
        cv_.wait(lock, [&] { return stopping_.load(); });
        break;
      }
    }
    try {
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
  UpdateStats u = impl_->engine->update();
  std::vector<Lightmap> maps = impl_->engine->lightmaps();
  // With the engine's own noise estimate, tiles that only changed by Monte Carlo noise wait
  // until their refresh is worth the bytes (TileStoreOptions::refresh_ratio). The last update
  // (max_updates) publishes every change beyond the threshold: final tiles are the final means.
  const bool last = options_.max_updates > 0 && impl_->engine->updates() >= options_.max_updates;
  std::vector<Lightmap> standard_error;
  if (!last && options_.tiles.refresh_ratio > 1.0f)
    standard_error = impl_->engine->standard_error();
  const TileStore::Noise noise{impl_->engine->updates(), &standard_error};
  std::vector<std::uint32_t> changed =
      tiles_->publish(maps, now_us(), standard_error.empty() ? nullptr : &noise);
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
    if (options_.max_updates > 0 && stats_.updates >= options_.max_updates) {
      stats_.idle = true;
      log::info("engine", "reached " + std::to_string(options_.max_updates) +
                              " updates; the lightmaps are final");
    }
    listener = listener_;
  }
  log::debug("engine", "update " + std::to_string(impl_->engine->updates()) + ": " +
                           std::to_string(changed.size()) + " tiles changed");
  if (listener && !changed.empty()) listener(changed);
  cv_.notify_all();
}

void EngineHost::record_passes(const UpdateStats& u) {
  // The list of passes is fixed by the parameters; it is built on the first update.
  const bool probes = !options_.engine.unbiased();
  if (stats_.passes.empty()) {
    stats_.passes.push_back({"direct", 0});
    for (std::size_t b = 1; b <= u.scatter.size(); ++b) {
      if (probes) stats_.passes.push_back({"probes", static_cast<std::uint32_t>(b)});
      stats_.passes.push_back({"scatter", static_cast<std::uint32_t>(b)});
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

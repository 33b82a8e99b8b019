#include "irradcast/service/engine_host.h"

#include <algorithm>
#include <chrono>

#include "irradcast/engine/embree_backend.h"
#include "irradcast/engine/engine.h"
#include "irradcast/common/error.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/texel_validity.h"
#include "irradcast/service/thread_priority.h"

namespace irradcast {

struct EngineHost::Impl {
  std::unique_ptr<RayScene> rays;
  std::unique_ptr<LightSampler> lights;
  std::vector<TexelGBuffer> gbuffers;
  std::unique_ptr<Engine> engine;
};

namespace {
std::uint64_t digest64(const std::string& key) {
  const std::string digest = wire::sha256(key);
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i)
    v = (v << 8) | static_cast<unsigned char>(digest[static_cast<std::size_t>(i)]);
  return v;
}

Bounds object_box(const WorldObject& o) {
  Bounds b;
  for (const glm::vec3& p : o.positions) b.extend(p);
  return b;
}

bool emits(const World& w, const WorldObject& o) {
  for (std::uint32_t t = 0; t < o.triangles().size(); ++t)
    if (w.material(o.object, t).is_emissive()) return true;
  return false;
}

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
  // Zero-area and non-finite triangles break the BVH builders and rays (the tools drop them at
  // load already; a scene built in code may still have them).
  drop_degenerate_triangles(scene_, scene_id_);
  world_ = World::build(scene_);
  if (world_.objects.empty()) throw Error(scene_id_ + ": the scene has no triangles to light");
  // Editable: the two-level BVH that an edit updates incrementally.
  impl_->rays = std::make_unique<RayScene>(world_, /*editable=*/true);
  impl_->lights = std::make_unique<LightSampler>(world_);
  if (impl_->lights->empty())
    log::warn("engine", scene_id_ + " has no lights: every tile will be black");
  atlas_ = build_atlas(world_, options_.atlas);
  impl_->gbuffers = rasterize_gbuffer(world_, atlas_);
  mark_hidden_texels(*impl_->rays, impl_->gbuffers);
  BackendChoice backend = make_backend(options_.backend, world_, *impl_->rays, *impl_->lights);
  backend_ = backend.reason;
  impl_->engine =
      std::make_unique<Engine>(world_, atlas_, impl_->gbuffers, *impl_->rays,
                               std::move(backend.backend), options_.engine, impl_->lights.get());
  std::vector<std::pair<int, int>> sizes;
  for (const ObjectLightmap& o : atlas_.objects) sizes.emplace_back(o.width, o.height);
  tiles_ = std::make_unique<TileStore>(sizes, options_.tiles);
  package_ = std::make_shared<const wire::ScenePackage>(wire::make_scene_package(scene_, atlas_));
  validation_scene_ = scene_;
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
  }
  stats_.texels = impl_->engine->texel_count();
  stats_.tiles = tiles_->tile_count();
  log::info("engine", scene_id_ + ": method " + method_name(options_.engine.method) + ", " +
                          std::to_string(atlas_.objects.size()) + " lightmaps, " +
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

std::uint64_t EngineHost::submit_edit(const SceneEdit& edit) {
  // The validation scene is the scene as every accepted edit will leave it: an edit is checked
  // against the transforms the edits before it lead to (13 edits of scale 1000 each are refused
  // like one edit of 13). Under its own lock, so validation order is revision order and the
  // engine thread is not held up.
  std::lock_guard validation(validation_mutex_);
  {
    std::lock_guard lock(mutex_);
    if (pending_edits_.size() >= kMaxPendingEdits)
      throw Error("the engine has " + std::to_string(pending_edits_.size()) +
                  " edits waiting; send this one again later");
  }
  apply_edit(validation_scene_, edit);  // validates first: unchanged when it throws
  std::lock_guard lock(mutex_);
  const std::uint64_t revision = ++submitted_revision_;
  pending_edits_.emplace_back(revision, edit);
  stats_.idle = false;  // refining again from now on: nobody waits for an idle that is stale
  cv_.notify_all();
  return revision;
}

void EngineHost::apply_edits() {
  std::deque<std::pair<std::uint64_t, SceneEdit>> edits;
  std::vector<CameraPose> cameras;
  {
    std::lock_guard lock(mutex_);
    edits.swap(pending_edits_);
    for (const auto& [id, pose] : cameras_) cameras.push_back(pose);
  }
  if (edits.empty()) return;
  const auto began = std::chrono::steady_clock::now();
  // Boxes and emitters before, to tell the engine where things were.
  std::vector<Bounds> boxes_before;
  std::vector<bool> emitted_before;
  for (const WorldObject& o : world_.objects) {
    boxes_before.push_back(object_box(o));
    emitted_before.push_back(o.visible && emits(world_, o));
  }
  const std::vector<WorldLight> lights_before = world_.lights;

  EditEffect effect;
  std::vector<AppliedEdit> applied;
  for (auto& [revision, edit] : edits) {
    try {
      EditEffect e = apply_edit(scene_, edit);
      effect.nodes.insert(effect.nodes.end(), e.nodes.begin(), e.nodes.end());
      effect.lights.insert(effect.lights.end(), e.lights.begin(), e.lights.end());
      effect.materials.insert(effect.materials.end(), e.materials.begin(), e.materials.end());
    } catch (const std::exception& ex) {
      // Validated when submitted against the scene as loaded; against the edited scene it can
      // still fail (a transform pushed out of range by many edits). Not applied, not sent.
      log::error("engine", std::string("edit ") + std::to_string(revision) +
                               " could not be applied: " + ex.what());
      continue;
    }
    AppliedEdit a;
    a.edit = std::move(edit);
    a.revision = revision;
    applied.push_back(std::move(a));
  }
  if (applied.empty()) return;

  // World, ray scene (refit + top level), lights, G-buffers.
  std::string timings;
  auto lap_start = std::chrono::steady_clock::now();
  auto lap = [&](const std::string& what) {
    const auto now = std::chrono::steady_clock::now();
    timings += (timings.empty() ? "" : ", ") + what + " " +
               std::to_string(
                   static_cast<int>(1e3 * std::chrono::duration<double>(now - lap_start).count())) +
               " ms";
    lap_start = now;
  };
  const std::vector<int> moved = world_.update(scene_);
  lap("world");
  impl_->rays->update(moved);
  lap("ray scene");
  *impl_->lights = LightSampler(world_);
  const bool geometry = !moved.empty();
  const bool surfaces = !effect.materials.empty();
  if (geometry || surfaces) {
    // G-buffers again for what moved, what uses a changed material, and what lies near a moved
    // object (its texels may have been buried in it, or be now): hidden texels are marked
    // again on exactly those.
    std::vector<std::uint8_t> which(world_.objects.size(), 0);
    std::vector<Bounds> near;
    for (int o : moved) {
      which[static_cast<std::size_t>(o)] = 1;
      near.push_back(boxes_before[static_cast<std::size_t>(o)]);
      near.push_back(object_box(world_.objects[static_cast<std::size_t>(o)]));
    }
    std::vector<bool> changed_material(scene_.materials.size(), false);
    for (int m : effect.materials) changed_material[static_cast<std::size_t>(m)] = true;
    const float margin = 0.02f * world_.bounds.max_extent();
    for (std::size_t o = 0; o < world_.objects.size(); ++o) {
      const WorldObject& obj = world_.objects[o];
      for (std::uint32_t m : obj.source->triangle_material)
        if (m < changed_material.size() && changed_material[m]) {
          which[o] = 1;
          break;
        }
      const Bounds box = object_box(obj);
      for (const Bounds& b : near)
        if (glm::all(glm::lessThanEqual(box.lo, b.hi + margin)) &&
            glm::all(glm::lessThanEqual(b.lo - margin, box.hi)))
          which[o] = 1;
    }
    rasterize_gbuffer(world_, atlas_, impl_->gbuffers, which);
    mark_hidden_texels(*impl_->rays, impl_->gbuffers, which);
  }
  lap("lights and G-buffers");

  SceneChange change;
  change.geometry = geometry;
  change.surfaces = surfaces;
  std::vector<bool> is_moved(world_.objects.size(), false);
  for (int o : moved) {
    is_moved[static_cast<std::size_t>(o)] = true;
    change.regions.push_back(boxes_before[static_cast<std::size_t>(o)]);
    if (world_.objects[static_cast<std::size_t>(o)].visible)
      change.regions.push_back(object_box(world_.objects[static_cast<std::size_t>(o)]));
  }
  // Emitters whose light changed: moved or shown/hidden ones, ones whose material changed.
  std::vector<bool> material_changed(scene_.materials.size(), false);
  for (int m : effect.materials) material_changed[static_cast<std::size_t>(m)] = true;
  for (std::size_t o = 0; o < world_.objects.size(); ++o) {
    const WorldObject& obj = world_.objects[o];
    bool uses_changed = false;
    for (std::uint32_t t = 0; t < obj.triangles().size() && !uses_changed; ++t) {
      const std::uint32_t m =
          t < obj.source->triangle_material.size() ? obj.source->triangle_material[t] : ~0u;
      uses_changed = m < material_changed.size() && material_changed[m];
    }
    const bool emits_now = obj.visible && emits(world_, obj);
    if (uses_changed && !is_moved[o]) change.regions.push_back(object_box(obj));
    if ((emitted_before[o] || emits_now) && (is_moved[o] || uses_changed)) {
      if (emitted_before[o]) change.light_points.push_back(boxes_before[o].center());
      if (emits_now) change.light_points.push_back(object_box(obj).center());
    } else if (emits_now) {
      change.other_lights.push_back(object_box(obj).center());
    }
  }
  // Punctual lights, matched by their node: the old and new positions of those that moved,
  // changed or were shown or hidden; the others are unchanged emitters.
  std::vector<bool> light_changed(scene_.lights.size(), false);
  for (int l : effect.lights) light_changed[static_cast<std::size_t>(l)] = true;
  auto before_of = [&](int node) -> const WorldLight* {
    for (const WorldLight& l : lights_before)
      if (l.node == node) return &l;
    return nullptr;
  };
  for (const WorldLight& l : world_.lights) {
    const WorldLight* old = before_of(l.node);
    const bool changed = !old || old->position != l.position || old->direction != l.direction ||
                         light_changed[static_cast<std::size_t>(
                             scene_.nodes[static_cast<std::size_t>(l.node)].light)];
    if (changed) {
      change.light_points.push_back(l.position);
      if (old) change.light_points.push_back(old->position);
    } else {
      change.other_lights.push_back(l.position);
    }
  }
  for (const WorldLight& old : lights_before) {  // lights hidden by the edit
    bool still = false;
    for (const WorldLight& l : world_.lights) still = still || l.node == old.node;
    if (!still) change.light_points.push_back(old.position);
  }
  lap("regions");
  impl_->engine->scene_changed(change, cameras);
  lap("engine (" + impl_->engine->change_timings() + ")");

  const std::uint64_t revision = applied.back().revision;
  auto package = std::make_shared<const wire::ScenePackage>(
      wire::make_scene_package(scene_, atlas_, revision));
  lap("package");
  std::uint64_t epoch = 0;
  {
    std::lock_guard lock(mutex_);
    std::string key = std::to_string(tile_epoch_) + "|" + package->hash;
    epoch = digest64(key);
  }
  const double ms =
      1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  EditListener listener;
  {
    std::lock_guard lock(mutex_);
    revision_ = revision;
    package_ = package;
    tile_epoch_ = epoch;
    stats_.idle = false;
    stats_.revision = revision;
    stats_.last_edit_ms = ms;
    stats_.stale_texels = impl_->engine->stale_texels();
    stats_.texels = impl_->engine->texel_count();
    updates_since_edit_ = 0;
    listener = edit_listener_;
  }
  log::info("engine", "applied edit " + std::to_string(revision) + " (" +
                          std::to_string(moved.size()) + " objects moved or shown/hidden, " +
                          std::to_string(effect.lights.size()) + " lights, " +
                          std::to_string(effect.materials.size()) + " materials) in " +
                          std::to_string(static_cast<int>(ms)) + " ms; " +
                          std::to_string(impl_->engine->stale_texels()) + " texels to refresh");
  log::info("engine", "edit " + std::to_string(revision) + " took: " + timings);
  const std::uint64_t at = now_us();
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
  std::vector<Lightmap> maps = impl_->engine->lightmaps();
  // With the engine's own noise estimate, tiles that only changed by Monte Carlo noise wait
  // until their refresh is worth the bytes (TileStoreOptions::refresh_ratio). The last update
  // (max_updates) publishes every change beyond the threshold: final tiles are the final means.
  // Updates count from the start, or from the last edit once every texel has a new estimate.
  if (full) ++updates_since_edit_;
  const bool last = options_.max_updates > 0 && updates_since_edit_ >= options_.max_updates;
  std::vector<Lightmap> standard_error;
  if (!last && options_.tiles.refresh_ratio > 1.0f)
    standard_error = impl_->engine->standard_error();
  const TileStore::Noise noise{impl_->engine->min_samples(), &standard_error};
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
    stats_.stale_texels = impl_->engine->stale_texels();
    listener = listener_;
  }
  log::debug("engine", "update " + std::to_string(impl_->engine->updates()) + ": " +
                           std::to_string(changed.size()) + " tiles changed");
  if (listener && !changed.empty()) listener(changed);
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

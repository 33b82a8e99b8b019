// PreparedScene: builds the world, ray scene, lights, atlas and G-buffers in one order, and after
// scene edits updates them in place and works out the SceneChange.
#include "irradcast/engine/prepared_scene.h"

#include <chrono>
#include <exception>

#include "irradcast/common/error.h"
#include "irradcast/common/lap_timer.h"
#include "irradcast/engine/texel_validity.h"

namespace irradcast {

struct PreparedScene::Parts {
  Scene scene;
  World world;
  std::unique_ptr<RayScene> rays;
  std::unique_ptr<LightSampler> lights;
  Atlas atlas;
  std::vector<TexelGBuffer> gbuffers;
  std::size_t hidden = 0;
  PreparedSceneTimings timings;
};

namespace {

double seconds_since(std::chrono::steady_clock::time_point& since) {
  const auto now = std::chrono::steady_clock::now();
  const double s = std::chrono::duration<double>(now - since).count();
  since = now;
  return s;
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

// The world before the edits: where each object was, which ones emitted light, and the
// punctual lights, to tell the engine where things were.
struct Before {
  std::vector<Bounds> boxes;
  std::vector<bool> emitted;
  std::vector<WorldLight> lights;
};

Before snapshot(const World& world) {
  Before b;
  for (const WorldObject& o : world.objects) {
    b.boxes.push_back(object_box(o));
    b.emitted.push_back(o.in_static_scene() && emits(world, o));
  }
  b.lights = world.lights;
  return b;
}

std::vector<bool> flags(std::size_t n, const std::vector<int>& set) {
  std::vector<bool> f(n, false);
  for (int i : set) f[static_cast<std::size_t>(i)] = true;
  return f;
}

// The objects whose G-buffers are drawn again: what moved, what uses a changed material, and
// what lies near a moved object (its texels may have been buried in it, or be now).
std::vector<std::uint8_t> objects_to_redraw(const World& world, const Scene& scene,
                                            const std::vector<int>& moved, const Before& before,
                                            const EditEffect& effect) {
  std::vector<std::uint8_t> which(world.objects.size(), 0);
  std::vector<Bounds> near;
  for (int o : moved) {
    which[static_cast<std::size_t>(o)] = 1;
    near.push_back(before.boxes[static_cast<std::size_t>(o)]);
    near.push_back(object_box(world.objects[static_cast<std::size_t>(o)]));
  }
  const std::vector<bool> changed_material = flags(scene.materials.size(), effect.materials);
  const float margin = 0.02f * world.bounds.max_extent();
  for (std::size_t o = 0; o < world.objects.size(); ++o) {
    const WorldObject& obj = world.objects[o];
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
  return which;
}

// The objects' part of the change: the moved objects' boxes before and after, the boxes of
// objects with a changed material, and the emitters whose light changed (moved, shown or
// hidden, or a changed material) apart from those that did not.
void object_changes(const World& world, const Scene& scene, const std::vector<int>& moved,
                    const Before& before, const EditEffect& effect, SceneChange& change) {
  std::vector<bool> is_moved(world.objects.size(), false);
  for (int o : moved) {
    is_moved[static_cast<std::size_t>(o)] = true;
    change.regions.push_back(before.boxes[static_cast<std::size_t>(o)]);
    if (world.objects[static_cast<std::size_t>(o)].visible)
      change.regions.push_back(object_box(world.objects[static_cast<std::size_t>(o)]));
  }
  const std::vector<bool> material_changed = flags(scene.materials.size(), effect.materials);
  for (std::size_t o = 0; o < world.objects.size(); ++o) {
    const WorldObject& obj = world.objects[o];
    bool uses_changed = false;
    for (std::uint32_t t = 0; t < obj.triangles().size() && !uses_changed; ++t) {
      const std::uint32_t m =
          t < obj.source->triangle_material.size() ? obj.source->triangle_material[t] : ~0u;
      uses_changed = m < material_changed.size() && material_changed[m];
    }
    if (obj.dynamic) continue;  // not in the static scene
    const bool emits_now = obj.visible && emits(world, obj);
    if (uses_changed && !is_moved[o]) change.regions.push_back(object_box(obj));
    if ((before.emitted[o] || emits_now) && (is_moved[o] || uses_changed)) {
      if (before.emitted[o]) change.light_points.push_back(before.boxes[o].center());
      if (emits_now) change.light_points.push_back(object_box(obj).center());
    } else if (emits_now) {
      change.other_lights.push_back(object_box(obj).center());
    }
  }
}

// The punctual lights' part, matched by their node: the old and new positions of those that
// moved, changed or were shown or hidden; the others are unchanged emitters.
void light_changes(const World& world, const Scene& scene, const Before& before,
                   const EditEffect& effect, SceneChange& change) {
  const std::vector<bool> light_changed = flags(scene.lights.size(), effect.lights);
  auto before_of = [&](int node) -> const WorldLight* {
    for (const WorldLight& l : before.lights)
      if (l.node == node) return &l;
    return nullptr;
  };
  for (const WorldLight& l : world.lights) {
    const WorldLight* old = before_of(l.node);
    const bool changed = !old || old->position != l.position || old->direction != l.direction ||
                         light_changed[static_cast<std::size_t>(
                             scene.nodes[static_cast<std::size_t>(l.node)].light)];
    if (changed) {
      change.light_points.push_back(l.position);
      if (old) change.light_points.push_back(old->position);
    } else {
      change.other_lights.push_back(l.position);
    }
  }
  for (const WorldLight& old : before.lights) {  // lights hidden by the edit
    bool still = false;
    for (const WorldLight& l : world.lights) still = still || l.node == old.node;
    if (!still) change.light_points.push_back(old.position);
  }
}

void append(std::vector<int>& to, const std::vector<int>& from) {
  to.insert(to.end(), from.begin(), from.end());
}

}  // namespace

PreparedScene::PreparedScene() = default;
PreparedScene::PreparedScene(PreparedScene&&) noexcept = default;
PreparedScene& PreparedScene::operator=(PreparedScene&&) noexcept = default;
PreparedScene::~PreparedScene() = default;

PreparedScene PreparedScene::build(Scene scene, const PreparedSceneOptions& options) {
  PreparedScene prepared;
  prepared.p_ = std::make_unique<Parts>();
  Parts& s = *prepared.p_;
  auto lap = std::chrono::steady_clock::now();
  s.scene = std::move(scene);
  s.world = World::build(s.scene);
  if (s.world.objects.empty()) throw Error(options.name + ": the scene has no triangles to light");
  s.rays = std::make_unique<RayScene>(s.world, options.editable);
  s.lights = std::make_unique<LightSampler>(s.world);
  s.timings.bvh = seconds_since(lap);
  s.atlas = build_atlas(s.world, options.atlas);
  s.timings.atlas = seconds_since(lap);
  s.gbuffers = rasterize_gbuffer(s.world, s.atlas);
  s.hidden = mark_hidden_texels(*s.rays, s.gbuffers);
  s.timings.gbuffers = seconds_since(lap);
  return prepared;
}

SceneChange PreparedScene::apply(std::span<const SceneEdit> edits, EditReport* report) {
  Parts& s = *p_;
  EditReport local;
  EditReport& r = report ? *report : local;
  r = EditReport{};
  const Before before = snapshot(s.world);
  EditEffect effect;
  for (const SceneEdit& edit : edits) {
    EditReport::Outcome& outcome = r.edits.emplace_back();
    try {
      const EditEffect e = apply_edit(s.scene, edit);
      append(effect.nodes, e.nodes);
      append(effect.lights, e.lights);
      append(effect.materials, e.materials);
      effect.sky = effect.sky || e.sky;
    } catch (const std::exception& ex) {
      outcome.error = ex.what();
      continue;
    }
    outcome.applied = true;
    ++r.applied;
  }
  if (r.applied == 0) return {};

  // World, ray scene (refit + top level), lights, G-buffers.
  LapTimer lap;
  // A dynamic object's move is the viewers' business: no ray, texel or region of the static scene
  // changes with it.
  std::vector<int> moved = s.world.update(s.scene);
  std::erase_if(moved, [&](int o) { return s.world.objects[static_cast<std::size_t>(o)].dynamic; });
  lap.lap("world");
  s.rays->update(moved);
  lap.lap("ray scene");
  // Emitters, punctual lights and the sky's sampling tables (Scene::sky) from the edited scene.
  *s.lights = LightSampler(s.world);
  SceneChange change;
  change.geometry = !moved.empty();
  change.surfaces = !effect.materials.empty();
  change.sky = effect.sky;
  if (change.geometry || change.surfaces) {
    // Hidden texels are marked again on exactly the objects drawn again.
    const std::vector<std::uint8_t> which =
        objects_to_redraw(s.world, s.scene, moved, before, effect);
    rasterize_gbuffer(s.world, s.atlas, s.gbuffers, which);
    mark_hidden_texels(*s.rays, s.gbuffers, which);
  }
  lap.lap("lights and G-buffers");
  object_changes(s.world, s.scene, moved, before, effect, change);
  light_changes(s.world, s.scene, before, effect, change);
  lap.lap("regions");
  r.moved = moved.size();
  r.lights = effect.lights.size();
  r.materials = effect.materials.size();
  r.sky = effect.sky;
  r.timings = lap.text();
  return change;
}

const Scene& PreparedScene::scene() const {
  return p_->scene;
}
const World& PreparedScene::world() const {
  return p_->world;
}
const RayScene& PreparedScene::rays() const {
  return *p_->rays;
}
const LightSampler& PreparedScene::lights() const {
  return *p_->lights;
}
const Atlas& PreparedScene::atlas() const {
  return p_->atlas;
}
const std::vector<TexelGBuffer>& PreparedScene::gbuffers() const {
  return p_->gbuffers;
}
std::size_t PreparedScene::hidden_texels() const {
  return p_->hidden;
}
std::uint64_t PreparedScene::valid_texels() const {
  std::uint64_t valid = 0;
  for (const TexelGBuffer& g : p_->gbuffers) valid += g.valid_count();
  return valid;
}
const PreparedSceneTimings& PreparedScene::timings() const {
  return p_->timings;
}

}  // namespace irradcast

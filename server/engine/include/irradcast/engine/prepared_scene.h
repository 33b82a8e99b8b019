// The prepared scene: a scene with everything the engine reads from it, built in one fixed order
// (world, ray scene, light sampler, lightmap atlas, texel G-buffers, hidden texels) and kept in
// step with scene edits. The engine host, irradcast-bake, the benches and the tests all start
// from one; apply() changes it in place after edits and says what changed (SceneChange), which
// the engine then reacts to (Engine::scene_changed).
//
// The ray scene and light sampler refer to the world, and an Engine or TraceBackend built on a
// PreparedScene refers to its world, ray scene, lights, atlas and G-buffers. They all live on
// the heap behind one pointer, so their addresses never change: not when apply() updates them
// (in place), and not when the PreparedScene is moved. They live as long as the PreparedScene.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/pass_data.h"

namespace irradcast {

struct PreparedSceneOptions {
  AtlasOptions atlas;
  // A two-level ray scene that apply() updates incrementally (a service that takes edits); a
  // flat one otherwise (bake, benches, tests: it traces faster).
  bool editable = false;
  // Names the scene in errors ("NAME: the scene has no triangles to light").
  std::string name = "scene";
};

// Seconds build() spent on each step.
struct PreparedSceneTimings {
  double bvh = 0.0;       // world, ray scene and light sampler
  double atlas = 0.0;     // lightmap atlas
  double gbuffers = 0.0;  // texel G-buffers and hidden texels
};

// What PreparedScene::apply did with each edit, for the caller's log.
struct EditReport {
  struct Outcome {
    bool applied = false;
    std::string error;  // why not, when not applied
  };
  std::vector<Outcome> edits;  // one per edit, in order
  std::size_t applied = 0;     // edits applied
  std::size_t moved = 0;       // objects moved, shown or hidden
  std::size_t lights = 0;      // punctual lights whose colour or intensity changed
  std::size_t materials = 0;   // materials whose albedo or emission changed
  bool sky = false;            // the sky changed
  std::string timings;         // "world 0 ms, ray scene 1 ms, ..." (LapTimer::text)
};

class PreparedScene {
 public:
  // Builds everything from `scene` (the slow part of start-up). Throws irradcast::Error when
  // the scene has no triangles. The atlas and hidden texels are deterministic: the same scene
  // and options give the same bits.
  static PreparedScene build(Scene scene, const PreparedSceneOptions& options);

  PreparedScene(PreparedScene&&) noexcept;
  PreparedScene& operator=(PreparedScene&&) noexcept;
  ~PreparedScene();

  // Applies `edits` to the scene in order (an edit that fails against the edited scene, say a
  // transform pushed out of range by the edits before it, is skipped and reported), then, when
  // any was applied, updates the world, refits the ray scene, rebuilds the light sampler and
  // draws the G-buffers again (and marks their hidden texels again) of the objects that moved,
  // use a changed material or lie near a moved object. Returns what changed for
  // Engine::scene_changed (nothing when no edit was applied). Every object keeps its address.
  SceneChange apply(std::span<const SceneEdit> edits, EditReport* report = nullptr);

  const Scene& scene() const;
  const World& world() const;
  const RayScene& rays() const;
  const LightSampler& lights() const;
  const Atlas& atlas() const;
  const std::vector<TexelGBuffer>& gbuffers() const;
  // Texels that build() found inside geometry (mark_hidden_texels).
  std::size_t hidden_texels() const;
  // Texels on visible surfaces (valid in the G-buffers), now.
  std::uint64_t valid_texels() const;
  const PreparedSceneTimings& timings() const;

 private:
  struct Parts;
  PreparedScene();
  std::unique_ptr<Parts> p_;
};

}  // namespace irradcast

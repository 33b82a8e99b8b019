// A scene set up for a bench the way irradcast-bake does it: world, ray scene, light sampler,
// lightmap atlas, texel G-buffers with their hidden texels marked. Header-only, for the benches
// that link irradcast_engine. Not movable: the ray scene and lights refer to the world.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/texel_validity.h"

namespace irradcast::bench {

struct BenchScene {
  explicit BenchScene(Scene s, const AtlasOptions& ao = {})
      : scene(std::move(s)), world(World::build(scene)), rays(world), lights(world) {
    atlas = build_atlas(world, ao);
    gbuffers = rasterize_gbuffer(world, atlas);
    mark_hidden_texels(rays, gbuffers);
  }
  BenchScene(const BenchScene&) = delete;
  BenchScene& operator=(const BenchScene&) = delete;

  // The atlas at `texels_per_scene`, the other atlas options at their defaults.
  static AtlasOptions density(float texels_per_scene) {
    AtlasOptions ao;
    ao.texels_per_scene = texels_per_scene;
    return ao;
  }

  Scene scene;
  World world;
  RayScene rays;
  LightSampler lights;
  Atlas atlas;
  std::vector<TexelGBuffer> gbuffers;
};

}  // namespace irradcast::bench

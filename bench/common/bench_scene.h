// The benches' scene set-up: a PreparedScene (world, flat ray scene, light sampler, lightmap
// atlas, texel G-buffers with their hidden texels marked), built the way irradcast-bake builds
// it. Header-only, for the benches that link irradcast_engine.
#pragma once

#include <utility>

#include "irradcast/common/atlas.h"
#include "irradcast/common/scene.h"
#include "irradcast/engine/prepared_scene.h"

namespace irradcast::bench {

// The atlas at `texels_per_scene`, the other atlas options at their defaults.
inline AtlasOptions density(float texels_per_scene) {
  AtlasOptions ao;
  ao.texels_per_scene = texels_per_scene;
  return ao;
}

inline PreparedScene prepare(Scene scene, const AtlasOptions& atlas = {}) {
  PreparedSceneOptions po;
  po.atlas = atlas;
  return PreparedScene::build(std::move(scene), po);
}

}  // namespace irradcast::bench

// A scene with everything the engine needs (world, Embree rays, lights, atlas, G-buffers), at a
// low lightmap density so tests stay fast; engines on either backend. Shared by the engine and
// Vulkan backend tests.
#pragma once

#include <memory>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/embree_backend.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/texel_validity.h"
#include "irradcast/common/world.h"

namespace irradcast::test {

struct EngineSetup {
  EngineSetup(Scene s, float texels_per_scene)
      : scene(std::move(s)), world(World::build(scene)), rays(world), lights(world) {
    Progress::set_enabled(false);
    AtlasOptions ao;
    ao.texels_per_scene = texels_per_scene;
    atlas = build_atlas(world, ao);
    gbuffers = rasterize_gbuffer(world, atlas);
    hidden = mark_hidden_texels(rays, gbuffers);
  }
  // An engine on `backend`, or on Embree when none is given.
  std::unique_ptr<Engine> engine(EngineParams p,
                                 std::unique_ptr<TraceBackend> backend = nullptr) const {
    if (!backend) backend = std::make_unique<EmbreeBackend>(rays, lights);
    return std::make_unique<Engine>(world, atlas, gbuffers, rays, std::move(backend), p, &lights);
  }
  Scene scene;
  World world;
  RayScene rays;
  LightSampler lights;
  Atlas atlas;
  std::vector<TexelGBuffer> gbuffers;
  std::size_t hidden = 0;
};

// Mean over all valid texels of the luminance of a set of lightmaps.
inline double mean_valid(const EngineSetup& s, const std::vector<Lightmap>& maps) {
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t o = 0; o < maps.size(); ++o)
    for (std::size_t i = 0; i < maps[o].texels.size(); ++i)
      if (s.gbuffers[o].valid(i)) {
        const glm::vec3& e = maps[o].texels[i];
        sum += (e.x + e.y + e.z) / 3.0;
        ++n;
      }
  return sum / static_cast<double>(n);
}

}  // namespace irradcast::test

// A prepared scene (world, Embree rays, lights, atlas, G-buffers: PreparedScene) at a low
// lightmap density so tests stay fast, with references to its parts by name; engines on either
// backend. Shared by the engine and Vulkan backend tests.
#pragma once

#include <memory>
#include <vector>

#include "irradcast/common/progress.h"
#include "irradcast/engine/embree_backend.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/prepared_scene.h"

namespace irradcast::test {

inline PreparedScene prepare_for_test(Scene s, float texels_per_scene) {
  Progress::set_enabled(false);
  PreparedSceneOptions po;
  po.atlas.texels_per_scene = texels_per_scene;
  return PreparedScene::build(std::move(s), po);
}

struct EngineSetup {
  EngineSetup(Scene s, float texels_per_scene)
      : prepared(prepare_for_test(std::move(s), texels_per_scene)),
        scene(prepared.scene()),
        world(prepared.world()),
        rays(prepared.rays()),
        lights(prepared.lights()),
        atlas(prepared.atlas()),
        gbuffers(prepared.gbuffers()),
        hidden(prepared.hidden_texels()) {}
  // An engine on `backend`, or on Embree when none is given.
  std::unique_ptr<Engine> engine(EngineParams p,
                                 std::unique_ptr<TraceBackend> backend = nullptr) const {
    if (!backend) backend = std::make_unique<EmbreeBackend>(rays, lights);
    return std::make_unique<Engine>(world, atlas, gbuffers, rays, std::move(backend), p, &lights);
  }
  PreparedScene prepared;
  // The prepared scene's parts (they live as long as `prepared`).
  const Scene& scene;
  const World& world;
  const RayScene& rays;
  const LightSampler& lights;
  const Atlas& atlas;
  const std::vector<TexelGBuffer>& gbuffers;
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

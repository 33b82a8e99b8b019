// A prepared scene (world, Embree rays, lights, atlas, G-buffers: PreparedScene) at a low
// lightmap density so tests stay fast, with references to its parts by name; engines on either
// backend. Shared by the engine and Vulkan backend tests.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "embree_backend.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/image.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/prepared_scene.h"

namespace irradcast::test {

inline PreparedScene prepare_for_test(Scene s, float texels_per_scene) {
  Progress::set_enabled(false);
  PreparedSceneOptions po;
  po.atlas.texels_per_scene = texels_per_scene;
  return PreparedScene::build(std::move(s), po);
}

// A backend that hands every pass to an EmbreeBackend (`inner`): a test derives from it and
// overrides the pass it watches or checks.
class EmbreeForwarder : public TraceBackend {
 public:
  EmbreeForwarder(const RayScene& rays, const LightSampler& lights) : inner(rays, lights) {}
  std::string name() const override { return "embree (watched)"; }
  void scene_changed() override { inner.scene_changed(); }
  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override {
    return inner.direct(in, out);
  }
  PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                           std::vector<glm::vec3>& out) override {
    return inner.gather_probes(in, prev, out);
  }
  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override {
    return inner.scatter(in, prev, probe_radiance, out);
  }
  EmbreeBackend inner;
};

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

// The default view of a scene (48 x 48 pixels) with its reference: the path tracer at 1024 spp,
// 2 bounces, seed 99. rel_mse(engine) is the relative MSE of the engine's composed view.
struct ReferenceView {
  static constexpr int kW = 48, kH = 48;
  explicit ReferenceView(const EngineSetup& setup)
      : s(setup),
        cam(default_camera(s.scene, s.world)),
        ref(PathTracer(s.world, s.rays, s.lights, PathTracerOptions{2, true, 99})
                .render(cam, kW, kH, 1024)) {}
  double rel_mse(const Engine& engine) const {
    return compare(compose(s.world, s.rays, s.atlas, engine.lightmaps(), cam, kW, kH), ref).rel_mse;
  }
  // Updates the engine 16 times: the relative MSE after the first update and after the last
  // (also recorded as the test's properties rel_mse_1_update and rel_mse_16_updates).
  std::pair<double, double> after_1_and_16_updates(Engine& engine) const {
    engine.update();
    const double first = rel_mse(engine);
    for (int u = 1; u < 16; ++u) engine.update();
    const double last = rel_mse(engine);
    ::testing::Test::RecordProperty("rel_mse_1_update", std::to_string(first));
    ::testing::Test::RecordProperty("rel_mse_16_updates", std::to_string(last));
    return {first, last};
  }
  const EngineSetup& s;
  CameraPose cam;
  ImageRGB ref;
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

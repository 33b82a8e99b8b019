// EmbreeBackend's direct pass traces its shadow rays in packets of 8 or one by one (ShadowRays).
// The default (Auto) takes packets for a texel whose lights in front belong to at most two light
// objects, single rays for one with more or whose lights the hierarchy picks: cornell all in
// packets (the lightmaps of forced packets bit for bit), rooms:6 all single (those of forced
// single rays), rooms:3 some of each. The two ways differ only where Embree's packet and
// single-ray kernels answer a ray apart (about one shadow ray in millions): a texel by a sample.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine_setup.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/scene_edit.h"

namespace irradcast::test_embree_backend {

namespace {

// The Embree backend with its shadow rays taken `mode`'s way, keeping every direct pass's output.
class RecordingDirect final : public test::EmbreeForwarder {
 public:
  RecordingDirect(const RayScene& rays, const LightSampler& lights, ShadowRays mode)
      : EmbreeForwarder(rays, lights) {
    inner.set_shadow_rays(mode);
    // Learned light tables would spread a rare packet / single-ray disagreement to the later
    // picks of a region (rooms:6 learns); test_light_cache.cpp covers learning.
    inner.set_learn_lights(false);
  }
  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override {
    const PassResult r = inner.direct(in, out);
    outputs.push_back(out);
    rays += r.rays;
    area_rays += inner.direct_area_rays();
    packet_rays += inner.direct_packet_rays();
    occluded_rays += inner.direct_occluded_rays();
    return r;
  }
  std::vector<std::vector<glm::vec3>> outputs;
  // Over the direct passes: all rays, those toward area lights, in packets, ended occluded.
  std::uint64_t rays = 0, area_rays = 0, packet_rays = 0, occluded_rays = 0;
};

struct Case {
  const char* scene;
  ShadowRays auto_takes;  // the way Auto takes in it (Auto: some texels each way)
};

class ShadowRaysTest : public ::testing::TestWithParam<Case> {};

TEST_P(ShadowRaysTest, AutoIsTheWayItTakesBitForBitAndTheWaysAgree) {
  const test::EngineSetup s(load_scene(GetParam().scene), 32.0f);
  EngineParams p;
  p.indirect_bounces = 0;  // the direct pass is what is compared
  std::vector<RecordingDirect*> backends;
  std::vector<std::unique_ptr<Engine>> engines;
  for (ShadowRays mode : {ShadowRays::Auto, ShadowRays::Packets, ShadowRays::Single}) {
    auto b = std::make_unique<RecordingDirect>(s.rays, s.lights, mode);
    backends.push_back(b.get());
    engines.push_back(s.engine(p, std::move(b)));
  }
  constexpr int kUpdates = 3;
  for (int u = 0; u < kUpdates; ++u)
    for (auto& e : engines) e->update();
  const ShadowRays takes = GetParam().auto_takes;
  const RecordingDirect& automatic = *backends[0];
  const RecordingDirect& packets = *backends[1];
  const RecordingDirect& single = *backends[2];
  // Which way Auto's rays went.
  EXPECT_EQ(packets.packet_rays, packets.rays);
  EXPECT_EQ(single.packet_rays, 0u);
  EXPECT_EQ(automatic.rays, packets.rays);
  if (takes == ShadowRays::Packets) {
    EXPECT_EQ(automatic.packet_rays, automatic.rays);
  }
  if (takes == ShadowRays::Single) {
    EXPECT_EQ(automatic.packet_rays, 0u);
  }
  if (takes == ShadowRays::Auto) {
    EXPECT_GT(automatic.packet_rays, automatic.rays / 20) << "some texels take packets";
    EXPECT_LT(automatic.packet_rays, automatic.rays - automatic.rays / 20)
        << "some take single rays";
  }
  std::size_t texels = 0, lit = 0, apart = 0;
  for (const RecordingDirect* b : backends) ASSERT_EQ(b->outputs.size(), std::size_t{kUpdates});
  for (int u = 0; u < kUpdates; ++u) {
    const std::vector<glm::vec3>& a = automatic.outputs[u];
    ASSERT_EQ(packets.outputs[u].size(), a.size());
    ASSERT_EQ(single.outputs[u].size(), a.size());
    if (takes != ShadowRays::Auto) {
      const RecordingDirect& taken = takes == ShadowRays::Packets ? packets : single;
      EXPECT_EQ(std::memcmp(taken.outputs[u].data(), a.data(), a.size() * sizeof(glm::vec3)), 0)
          << "update " << u << ": auto differs from " << shadow_rays_name(takes);
    }
    for (std::size_t i = 0; i < a.size(); ++i) {
      lit += a[i] != glm::vec3(0.0f);
      apart += std::memcmp(&packets.outputs[u][i], &single.outputs[u][i], sizeof(glm::vec3)) != 0;
    }
    texels += a.size();
  }
  EXPECT_GT(lit, texels / 4) << "most texels see a light: the shadow rays were traced";
  // The occluded rays as counted: the same in both ways but for the few rays they answer apart,
  // some and not all (these scenes have walls and boxes between texels and lights), and all the
  // rays go to area lights (no sky, no punctual light).
  for (const RecordingDirect* b : backends) {
    EXPECT_EQ(b->area_rays, b->rays);
    EXPECT_GT(b->occluded_rays, b->rays / 100);
    EXPECT_LT(b->occluded_rays, b->rays);
  }
  EXPECT_EQ(automatic.occluded_rays, takes == ShadowRays::Single    ? single.occluded_rays
                                     : takes == ShadowRays::Packets ? packets.occluded_rays
                                                                    : automatic.occluded_rays);
  EXPECT_LE(std::max(packets.occluded_rays, single.occluded_rays) -
                std::min(packets.occluded_rays, single.occluded_rays),
            packets.rays / 10000 + 1);
  // Packets and single rays agree on all but a few rays: at most one texel in 10,000 apart.
  EXPECT_LE(apart * 10000, texels) << apart << " of " << texels << " texels";
}

INSTANTIATE_TEST_SUITE_P(Scenes, ShadowRaysTest,
                         ::testing::Values(Case{"cornell", ShadowRays::Packets},
                                           Case{"rooms:3", ShadowRays::Auto},
                                           Case{"rooms:6", ShadowRays::Single}),
                         [](const ::testing::TestParamInfo<Case>& info) {
                           std::string name = info.param.scene;
                           std::erase(name, ':');
                           return name;
                         });

// An edit that makes a material emissive replaces the light sampler under the backend (more
// emissive triangles, of more objects): the next direct pass takes its lights as they are now.
// Cornell's walls become lights: every texel then has more than two light objects in front, and
// its rays go one by one.
TEST(ShadowRays, FollowTheLightsAfterAnEdit) {
  test::EngineSetup s(load_scene("cornell"), 24.0f);
  auto b = std::make_unique<RecordingDirect>(s.rays, s.lights, ShadowRays::Auto);
  RecordingDirect& backend = *b;
  EngineParams p;
  p.indirect_bounces = 0;
  auto engine = s.engine(p, std::move(b));
  engine->update();
  const std::size_t before = s.lights.emissive_triangles().size();
  EXPECT_EQ(backend.packet_rays, backend.rays) << "one light: all in packets";
  const SceneEdit edit = parse_edit_json(
      R"({"op": "emission", "material": "white", "color": [1, 1, 1], "strength": 0.5})");
  engine->scene_changed(s.prepared.apply(std::span(&edit, 1)), {});
  ASSERT_GT(s.lights.emissive_triangles().size(), before);
  backend.rays = backend.packet_rays = 0;
  engine->update();
  EXPECT_GT(backend.rays, 0u);
  EXPECT_LT(backend.packet_rays, backend.rays / 2) << "the white walls, floor and ceiling glow";
}

TEST(ShadowRays, NamesAndTheDefault) {
  const test::EngineSetup s(load_scene("cornell"), 16.0f);
  EmbreeBackend b(s.rays, s.lights);
  EXPECT_EQ(b.shadow_rays(), ShadowRays::Auto);
  b.set_shadow_rays(ShadowRays::Single);
  EXPECT_EQ(b.shadow_rays(), ShadowRays::Single);
  EXPECT_STREQ(shadow_rays_name(ShadowRays::Auto), "auto");
  EXPECT_STREQ(shadow_rays_name(ShadowRays::Packets), "packets");
  EXPECT_STREQ(shadow_rays_name(ShadowRays::Single), "single");
}

}  // namespace

}  // namespace irradcast::test_embree_backend

// The engine's direct-pass sampling (LightSampler::front_lights, direct_samples): the lights left
// out of a texel's front list never contribute there, the list's pick probabilities are the
// renormalised ones, and the SIMD samples (4 lanes) are the scalar direct_sample's bit for bit;
// RayScene::occluded8 answers as occluded() does, ray by ray.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "irradcast/common/builtin.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/prepared_scene.h"

namespace irradcast::test_lights {

namespace {

PreparedScene prepared(const std::string& spec) {
  Progress::set_enabled(false);
  PreparedSceneOptions o;
  o.atlas.texels_per_scene = 48.0f;
  o.name = spec;
  return PreparedScene::build(load_scene(spec), o);
}

struct Texel {
  glm::vec3 p, n;
};

// Every `step`-th texel that holds an estimate.
std::vector<Texel> texels(const PreparedScene& s, std::size_t step) {
  std::vector<Texel> t;
  std::size_t k = 0;
  for (std::size_t o = 0; o < s.gbuffers().size(); ++o) {
    const TexelGBuffer& g = s.gbuffers()[o];
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i) || k++ % step != 0) continue;
      const TexelPoint p = g.point(s.world().objects[o], i);
      t.push_back({p.position, p.normal});
    }
  }
  return t;
}

bool same_bits(glm::vec3 a, glm::vec3 b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

class DirectSampling : public ::testing::TestWithParam<const char*> {};

TEST_P(DirectSampling, LightsLeftOutNeverContributeAndTheRestAreRenormalised) {
  const PreparedScene s = prepared(GetParam());
  const LightSampler& l = s.lights();
  const std::size_t lights = l.emissive_triangles().size();
  std::size_t left_out = 0, kept = 0;
  Rng rng(7);
  for (const Texel& t : texels(s, 5)) {
    LightSampler::FrontLights f;
    ASSERT_TRUE(l.front_lights(t.p, t.n, f));
    std::vector<bool> in(lights, false);
    float total = 0.0f;
    for (int j = 0; j < f.count; ++j) {
      in[f.index[j]] = true;
      total += l.pick_pdf()[f.index[j]];
      EXPECT_EQ(f.cdf[j], total);
    }
    EXPECT_EQ(f.total, total);
    kept += static_cast<std::size_t>(f.count);
    for (std::size_t k = 0; k < lights; ++k) {
      if (in[k]) continue;
      ++left_out;
      for (int r = 0; r < 16; ++r) {  // no point of a left-out light passes the cosine tests
        LightSampler::ShadowSample sample;
        EXPECT_FALSE(l.triangle_sample(s.rays(), k, t.p, t.n, t.n, rng.next_2d(), sample));
      }
    }
  }
  EXPECT_GT(kept, 0u);
  EXPECT_GT(left_out, 0u);  // every scene here has texels behind its lights (the ceiling)
}

TEST_P(DirectSampling, SimdSamplesAreTheScalarSamplesBitForBit) {
  const PreparedScene s = prepared(GetParam());
  const LightSampler& l = s.lights();
  constexpr int n = 11;  // not a multiple of the 4 lanes
  std::size_t lit_samples = 0;
  std::uint64_t seed = 1;
  for (const Texel& t : texels(s, 3)) {
    LightSampler::FrontLights f;
    ASSERT_TRUE(l.front_lights(t.p, t.n, f));
    Rng a(seed), b(seed);
    ++seed;
    LightSampler::ShadowSample simd[n];
    glm::vec3 weight[n];
    bool lit[n];
    l.direct_samples(s.rays(), &f, t.p, t.n, t.n, a, 0, n, n, simd, weight, lit);
    for (int k = 0; k < n; ++k) {
      const float pick = (static_cast<float>(k) + b.next_float()) / static_cast<float>(n);
      const glm::vec2 pos = b.next_2d();
      LightSampler::ShadowSample one;
      glm::vec3 w;
      const bool ok = l.direct_sample(s.rays(), &f, t.p, t.n, t.n, glm::vec3(pick, pos), one, w);
      ASSERT_EQ(lit[k], ok) << "sample " << k;
      if (!ok) continue;
      ++lit_samples;
      EXPECT_TRUE(same_bits(simd[k].shadow.origin, one.shadow.origin));
      EXPECT_TRUE(same_bits(simd[k].shadow.direction, one.shadow.direction));
      EXPECT_EQ(simd[k].shadow.tmax, one.shadow.tmax);
      EXPECT_TRUE(same_bits(weight[k], w));
    }
    EXPECT_EQ(a.next_u32(), b.next_u32()) << "the same random numbers drawn";
  }
  EXPECT_GT(lit_samples, 1000u);
}

TEST_P(DirectSampling, PacketsOfShadowRaysAnswerAsSingleRays) {
  const PreparedScene s = prepared(GetParam());
  const LightSampler& l = s.lights();
  std::size_t blocked = 0, open = 0;
  std::uint64_t seed = 1;
  for (const Texel& t : texels(s, 7)) {
    LightSampler::FrontLights f;
    ASSERT_TRUE(l.front_lights(t.p, t.n, f));
    Rng rng(seed++);
    constexpr int n = 8;
    LightSampler::ShadowSample sample[n];
    glm::vec3 weight[n];
    bool lit[n];
    l.direct_samples(s.rays(), &f, t.p, t.n, t.n, rng, 0, n, n, sample, weight, lit);
    Ray rays[n];
    int count = 0;
    for (int k = 0; k < n; ++k)
      if (lit[k]) rays[count++] = sample[k].shadow;
    bool packet[n];
    s.rays().occluded8(rays, count, packet);
    for (int k = 0; k < count; ++k) {
      EXPECT_EQ(packet[k], s.rays().occluded(rays[k]));
      (packet[k] ? blocked : open) += 1;
    }
  }
  EXPECT_GT(blocked, 100u);
  EXPECT_GT(open, 100u);
}

INSTANTIATE_TEST_SUITE_P(Light, DirectSampling, ::testing::Values("cornell", "rooms:2"),
                         [](const auto& info) {
                           return std::string(info.param[0] == 'c' ? "cornell" : "rooms2");
                         });

}  // namespace

}  // namespace irradcast::test_lights

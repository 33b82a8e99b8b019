// The CPU scatter pass in batches (ScatterTexel: rays drawn, traced and shaded as arrays, the
// misses' arithmetic four at a time, traced in Embree packets where the CPU has AVX-512) gives,
// bit for bit, what tracing and shading each ray in turn gives (the estimator as written in
// embree_backend.h: texel_rng, cosine_hemisphere_fast, RayScene::intersect, radiance_at,
// scatter_miss); and RayScene::intersect(RayBatch&) the hits of intersect() ray by ray.
#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "engine_setup.h"
#include "irradcast/common/builtin.h"

namespace irradcast::test_scatter_texel {

using namespace irradcast::embree_sampling;

namespace {

bool same_bits(glm::vec3 a, glm::vec3 b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

// Texel i's scatter estimate ray by ray, as the pass computed it before it ran in batches.
glm::vec3 scatter_ray_by_ray(const RayScene& rays, const PassInput& in, const RadianceField& prev,
                             const std::vector<glm::vec3>& probe_radiance, std::uint32_t i) {
  const int n = in.params.indirect_samples;
  const glm::vec3 p = in.texels.position[i], ng = in.texels.geo_normal(in.world, i);
  Rng rng = texel_rng(in.params, i, in.update, kScatter, in.bounce);
  Rng pick = texel_rng(in.params, i, in.update, kProbePick, in.bounce);
  const Frame frame(in.texels.normal[i]);
  glm::vec3 sum(0.0f);
  for (int s = 0; s < n; ++s) {
    Ray ray;
    ray.direction = frame.to_world(cosine_hemisphere_fast(rng.next_2d()));
    ray.origin = rays.offset(p, ng, ray.direction);
    ray.tmax = scatter_range(in, i);
    const Hit h = rays.intersect(ray);
    sum += h.valid() ? radiance_at(prev, h)
                     : scatter_miss(in, probe_radiance, i, p, ray.direction, pick);
  }
  return sum * (kPi / static_cast<float>(n));
}

// The Embree backend, with every scatter pass's output checked against scatter_ray_by_ray on
// every `step`-th texel.
class CheckedScatter final : public test::EmbreeForwarder {
 public:
  CheckedScatter(const RayScene& rays, const LightSampler& lights, std::size_t step)
      : EmbreeForwarder(rays, lights), rays_(&rays), step_(step) {}
  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override {
    const PassResult r = inner.scatter(in, prev, probe_radiance, out);
    for (std::uint32_t i = 0; i < in.texels.size(); i += static_cast<std::uint32_t>(step_)) {
      const glm::vec3 expected = scatter_ray_by_ray(*rays_, in, prev, probe_radiance, i);
      ++checked;
      if (!same_bits(out[i], expected)) {
        ++differ;
        if (differ <= 3)
          ADD_FAILURE() << "texel " << i << " bounce " << in.bounce << ": " << out[i].x << " "
                        << out[i].y << " " << out[i].z << " vs " << expected.x << " " << expected.y
                        << " " << expected.z;
      }
      nonzero += out[i] != glm::vec3(0.0f);
    }
    ++passes;
    return r;
  }
  std::size_t passes = 0, checked = 0, differ = 0, nonzero = 0;

 private:
  const RayScene* rays_;
  std::size_t step_;
};

class ScatterBatch : public ::testing::TestWithParam<const char*> {};

TEST_P(ScatterBatch, EqualsTracingAndShadingEachRayInTurn) {
  const test::EngineSetup s(load_scene(GetParam()), 48.0f);
  auto backend = std::make_unique<CheckedScatter>(s.rays, s.lights, 7);
  CheckedScatter& checked = *backend;
  EngineParams p;
  p.indirect_samples = 37;  // two batches per texel, the second partly filled
  auto engine = s.engine(p, std::move(backend));
  engine->update();
  engine->update();  // the second update's bounces read probes and lightmaps with light in them
  EXPECT_GE(checked.passes, 4u);
  EXPECT_GT(checked.checked, 1000u);
  EXPECT_GT(checked.nonzero, checked.checked / 2);  // most texels receive indirect light
  EXPECT_EQ(checked.differ, 0u) << "of " << checked.checked;
}

TEST_P(ScatterBatch, RayBatchGivesTheHitsOfSingleRays) {
  const test::EngineSetup s(load_scene(GetParam()), 48.0f);
  const Bounds& b = s.world.bounds;
  Rng rng(3);
  std::size_t hits = 0, rays = 0;
  for (int count : {1, 5, 16, 17, 32}) {
    for (int batch = 0; batch < 40; ++batch) {
      RayBatch rb;
      rb.count = count;
      rb.tmax = (batch % 2 ? 0.3f : 3.0f) * b.max_extent();
      for (int k = 0; k < count; ++k) {
        const glm::vec3 o =
            b.lo + glm::vec3(rng.next_float(), rng.next_float(), rng.next_float()) * (b.hi - b.lo);
        const glm::vec3 d = octahedral_decode(rng.next_2d());
        rb.ox[k] = o.x, rb.oy[k] = o.y, rb.oz[k] = o.z;
        rb.dx[k] = d.x, rb.dy[k] = d.y, rb.dz[k] = d.z;
      }
      s.rays.intersect(rb);
      for (int k = 0; k < count; ++k) {
        Ray r;
        r.origin = glm::vec3(rb.ox[k], rb.oy[k], rb.oz[k]);
        r.direction = glm::vec3(rb.dx[k], rb.dy[k], rb.dz[k]);
        r.tmax = rb.tmax;
        const Hit h = s.rays.intersect(r);
        const Hit& g = rb.hit[k];
        ASSERT_EQ(g.object, h.object) << count << " " << batch << " " << k;
        if (!h.valid()) continue;
        EXPECT_EQ(g.triangle, h.triangle);
        EXPECT_EQ(std::memcmp(&g.u, &h.u, sizeof(float) * 3), 0) << "u, v, t differ";
        ++hits;
      }
      rays += static_cast<std::size_t>(count);
    }
  }
  EXPECT_GT(hits, rays / 4);
}

INSTANTIATE_TEST_SUITE_P(Scenes, ScatterBatch, ::testing::Values("cornell", "rooms:2"),
                         [](const ::testing::TestParamInfo<const char*>& info) {
                           return std::string(info.param) == "cornell" ? std::string("cornell")
                                                                       : std::string("rooms2");
                         });

}  // namespace

}  // namespace irradcast::test_scatter_texel

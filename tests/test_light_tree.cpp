// The light hierarchy (light_tree.h): at any point its pick probabilities sum to at most one
// over the lights, a light that can light the point is never left out, the walk picks each light as
// often as its probability says, and LightSampler's estimate with it (more than kMaxFront
// emissive triangles) has the mean of the sum over every light, with 1, 10 and 1,200 lights.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <string>
#include <vector>

#include "irradcast/common/light_tree.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/prepared_scene.h"
#include "scene_builders.h"

namespace irradcast::test_light_tree {

namespace {

// A direction uniform on the sphere.
glm::vec3 uniform_sphere(glm::vec2 u) {
  const float z = 1.0f - 2.0f * u.x, r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  const float phi = 2.0f * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

// A 20 x 20 m floor under `quads` small emissive squares (0.3 m) at 1-4 m, each turned at
// random (some face the floor, some away from it), of random power; a tenth are double sided.
PreparedScene many_lights(int quads, std::uint64_t seed) {
  Progress::set_enabled(false);
  Scene scene;
  const std::uint32_t floor = test::add_material(scene, glm::vec3(0.5f));
  test::add_quad_object(scene, "floor", {-10, 0, -10}, {-10, 0, 10}, {10, 0, 10}, {10, 0, -10},
                        floor);
  Rng rng(seed);
  for (int q = 0; q < quads; ++q) {
    const glm::vec3 c(rng.next_float() * 20.0f - 10.0f, 1.0f + 3.0f * rng.next_float(),
                      rng.next_float() * 20.0f - 10.0f);
    const glm::vec3 n = uniform_sphere(rng.next_2d());
    const Frame f(n);
    const glm::vec3 a = f.to_world({-0.15f, -0.15f, 0.0f}), b = f.to_world({0.15f, -0.15f, 0.0f}),
                    d = f.to_world({0.15f, 0.15f, 0.0f}), e = f.to_world({-0.15f, 0.15f, 0.0f});
    const std::uint32_t m = test::add_material(scene, glm::vec3(0.0f), glm::vec3(1.0f, 0.8f, 0.6f),
                                               1.0f + 20.0f * rng.next_float());
    if (q % 10 == 3) scene.materials[m].double_sided = true;
    test::add_quad_object(scene, ("light" + std::to_string(q)).c_str(), c + a, c + b, c + d, c + e,
                          m);
  }
  PreparedSceneOptions o;
  o.atlas.texels_per_scene = 16.0f;
  o.name = "many lights";
  return PreparedScene::build(std::move(scene), o);
}

// Whether triangle t can light p (normal n): some point of it in front of p's tangent plane
// that p sees from the emitting side. Tested at its corners, centre and edge midpoints.
bool can_light(const EmissiveTriangle& t, glm::vec3 p, glm::vec3 n) {
  const glm::vec3 pts[] = {t.p0,
                           t.p0 + t.e1,
                           t.p0 + t.e2,
                           t.p0 + (t.e1 + t.e2) / 3.0f,
                           t.p0 + 0.5f * t.e1,
                           t.p0 + 0.5f * t.e2,
                           t.p0 + 0.5f * (t.e1 + t.e2)};
  for (const glm::vec3& x : pts) {
    const glm::vec3 to = x - p;
    if (glm::dot(n, to) > 1e-4f && (t.double_sided || glm::dot(t.normal, -to) > 1e-4f)) return true;
  }
  return false;
}

struct Point {
  glm::vec3 p, n;
};

std::vector<Point> points(int count, std::uint64_t seed) {
  std::vector<Point> out;
  Rng rng(seed);
  for (int k = 0; k < count; ++k) {
    const glm::vec3 p(rng.next_float() * 20.0f - 10.0f, 4.5f * rng.next_float(),
                      rng.next_float() * 20.0f - 10.0f);
    out.push_back({p, uniform_sphere(rng.next_2d())});
  }
  return out;
}

class LightTreeSizes : public ::testing::TestWithParam<int> {};

TEST_P(LightTreeSizes, NoLightThatCanLightAPointIsLeftOut) {
  const PreparedScene s = many_lights(GetParam(), 11);
  const LightSampler& l = s.lights();
  const auto& tris = l.emissive_triangles();
  ASSERT_EQ(tris.size(), 2u * static_cast<std::size_t>(GetParam()));
  const LightTree tree(tris, l.pick_pdf());
  ASSERT_FALSE(tree.empty());
  EXPECT_EQ(tree.nodes().size(), 2 * tris.size() - 1);  // one light per leaf
  int lit_points = 0;
  for (const Point& pt : points(60, 5)) {
    double sum = 0.0;
    bool any = false;
    for (std::uint32_t i = 0; i < tris.size(); ++i) {
      const float pmf = tree.pmf(pt.p, pt.n, i);
      ASSERT_GE(pmf, 0.0f);
      sum += pmf;
      if (can_light(tris[i], pt.p, pt.n)) {
        any = true;
        ASSERT_GT(pmf, 0.0f) << "light " << i << " left out";
      }
    }
    // At most one: a walk may end where a node's bounds said yes and both its children say no
    // (no light under it can light p), a sample that adds nothing.
    EXPECT_LE(sum, 1.0 + 1e-4);
    if (any) {
      ++lit_points;
      EXPECT_GT(sum, 0.0);
    }
    // sample() gives the probability pmf() gives.
    for (float u : {0.05f, 0.37f, 0.9f}) {
      std::uint32_t index = 0;
      float pmf = 0.0f;
      if (tree.sample(pt.p, pt.n, u, index, pmf)) {
        EXPECT_NEAR(pmf, tree.pmf(pt.p, pt.n, index), 1e-5f * pmf);
      }
    }
  }
  EXPECT_GT(lit_points, GetParam() == 1 ? 3 : 30);
}

// A point's remembered walks (LightTree::At, a table of 128 nodes: 2,399 nodes for 1,200 lights
// share its slots) give the tree's picks and probabilities bit for bit, in any order of calls.
TEST_P(LightTreeSizes, APointsRememberedWalksAreTheTreesBitForBit) {
  const PreparedScene s = many_lights(GetParam(), 11);
  const auto& tris = s.lights().emissive_triangles();
  const LightTree tree(tris, s.lights().pick_pdf());
  Rng rng(5);
  for (const Point& pt : points(30, 7)) {
    LightTree::At at(tree, pt.p, pt.n);
    for (int k = 0; k < 64; ++k) {
      const float u = rng.next_float();
      std::uint32_t i0 = 0, i1 = 0;
      float p0 = -1.0f, p1 = -2.0f;
      const bool ok0 = tree.sample(pt.p, pt.n, u, i0, p0), ok1 = at.sample(u, i1, p1);
      ASSERT_EQ(ok0, ok1);
      if (ok0) {
        ASSERT_EQ(i0, i1);
        ASSERT_EQ(std::bit_cast<std::uint32_t>(p0), std::bit_cast<std::uint32_t>(p1));
      }
      const auto light = static_cast<std::uint32_t>(rng.next_float() * tris.size());
      ASSERT_EQ(std::bit_cast<std::uint32_t>(tree.pmf(pt.p, pt.n, light)),
                std::bit_cast<std::uint32_t>(at.pmf(light)));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Lights, LightTreeSizes, ::testing::Values(1, 10, 1200));

// The walk picks each of 20 lights as often as pmf() says (within 5 standard deviations), and
// nothing as often as the lights' probabilities leave: a walk can enter a node whose bounds might
// light p (its cone of normals, merged from its lights', spans a direction towards p) while none
// of its lights can, and then picks nothing (as pbrt-v4's does; those lights bring nothing, so
// the estimate stays unbiased). On this scene one inner node does so at this point in the clang
// (sanitizer) build and none in the GCC builds; why their trees differ was not traced.
TEST(LightTree, PicksEachLightAsOftenAsItsProbability) {
  const PreparedScene s = many_lights(10, 3);
  const LightTree tree(s.lights().emissive_triangles(), s.lights().pick_pdf());
  const glm::vec3 p(0.5f, 0.0f, -1.0f), n(0.0f, 1.0f, 0.0f);
  const int draws = 200000;
  std::vector<int> count(s.lights().emissive_triangles().size(), 0);
  int none = 0;
  for (int k = 0; k < draws; ++k) {
    std::uint32_t i;
    float pmf;
    if (tree.sample(p, n, (static_cast<float>(k) + 0.5f) / draws, i, pmf))
      ++count[i];
    else
      ++none;
  }
  double picked = 0.0;
  for (std::uint32_t i = 0; i < count.size(); ++i) {
    const double expect = draws * static_cast<double>(tree.pmf(p, n, i));
    EXPECT_NEAR(count[i], expect, 5.0 * std::sqrt(expect) + 2.0) << "light " << i;
    picked += expect;
  }
  EXPECT_GT(picked, 0.5 * draws);
  EXPECT_NEAR(none, draws - picked, 5.0 * std::sqrt(draws - picked) + 2.0);
}

// With 2,400 emissive triangles (over kMaxFront) LightSampler picks by the hierarchy; its
// one-sample estimate's mean at floor points is the sum over every triangle of its own mean
// (stratified samples of each): unbiased, and with far less noise than picking by power.
TEST(LightTree, ManyLightEstimateHasTheMeanOfEveryLightSummed) {
  const PreparedScene s = many_lights(1200, 17);
  const LightSampler& l = s.lights();
  ASSERT_FALSE(l.tree().empty());
  const RayScene& rays = s.rays();
  const glm::vec3 up(0.0f, 1.0f, 0.0f);
  Rng rng(9);
  for (const glm::vec3 p :
       {glm::vec3(0.0f, 0.0f, 0.0f), glm::vec3(6.5f, 0.0f, -3.0f), glm::vec3(-9.0f, 0.0f, 8.5f)}) {
    glm::dvec3 truth(0.0);
    const int per = 16;  // 4 x 4 strata per triangle
    for (std::size_t i = 0; i < l.emissive_triangles().size(); ++i)
      for (int k = 0; k < per; ++k) {
        const glm::vec2 u((static_cast<float>(k % 4) + rng.next_float()) / 4.0f,
                          (static_cast<float>(k / 4) + rng.next_float()) / 4.0f);
        truth += glm::dvec3(l.triangle_irradiance(rays, i, p, up, up, u)) / double(per);
      }
    glm::dvec3 tree_mean(0.0), tree_sq(0.0);
    const int n = 60000;
    for (int k = 0; k < n; ++k) {
      const glm::vec3 u((static_cast<float>(k) + rng.next_float()) / n, rng.next_float(),
                        rng.next_float());
      const glm::dvec3 e(l.area_irradiance(rays, p, up, up, u));
      tree_mean += e / double(n);
      tree_sq += e * e / double(n);
    }
    const double mean = tree_mean.x, truth_x = truth.x;
    const double stderr_x = std::sqrt(std::max(tree_sq.x - mean * mean, 0.0) / n);
    ASSERT_GT(truth_x, 0.0);
    EXPECT_NEAR(mean / truth_x, 1.0, 0.02 + 4.0 * stderr_x / truth_x)
        << "at " << p.x << "," << p.z << ": hierarchy " << mean << ", every light " << truth_x;
  }
}

}  // namespace

}  // namespace irradcast::test_light_tree

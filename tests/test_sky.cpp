// The sky (common/sky.h): map orientation, the sampling distribution against its own density,
// and LightSampler::sky_irradiance against irradiance integrated numerically.
#include <gtest/gtest.h>

#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/sky.h"
#include "scene_builders.h"

namespace irradcast::test_sky {
namespace {

// A map with a bright blob, a dimmer band at the horizon and a black lower half.
Sky test_map_sky() {
  Sky sky;
  sky.map = ImageRGB(64, 32);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) {
      glm::vec3 c(0.0f);
      if (y < 16) c = glm::vec3(0.2f, 0.3f, 0.5f);
      if (y >= 4 && y < 8 && x >= 40 && x < 46) c = glm::vec3(30.0f, 25.0f, 20.0f);
      sky.map.at(x, y) = c;
    }
  sky.strength = 2.0f;
  return sky;
}

TEST(Sky, OrientationFollowsTheDocumentedConvention) {
  // Centre faces -Z, the right of the image +X, the top row +Y.
  EXPECT_NEAR(glm::distance(sky_direction({0.5f, 0.5f}), glm::vec3(0, 0, -1)), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::distance(sky_direction({0.75f, 0.5f}), glm::vec3(1, 0, 0)), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::distance(sky_direction({0.25f, 0.5f}), glm::vec3(-1, 0, 0)), 0.0f, 1e-5f);
  EXPECT_NEAR(sky_direction({0.3f, 0.0f}).y, 1.0f, 1e-5f);
  EXPECT_NEAR(sky_direction({0.3f, 1.0f}).y, -1.0f, 1e-5f);
  for (glm::vec2 uv : {glm::vec2(0.1f, 0.2f), glm::vec2(0.6f, 0.7f), glm::vec2(0.9f, 0.45f)}) {
    glm::vec2 back = sky_uv(sky_direction(uv));
    EXPECT_NEAR(back.x, uv.x, 1e-5f);
    EXPECT_NEAR(back.y, uv.y, 1e-5f);
  }
}

TEST(Sky, SamplesMatchTheirDensityAndItIntegratesToOne) {
  Sky sky = test_map_sky();
  SkyDistribution dist(sky);
  ASSERT_TRUE(dist.valid());
  Rng rng(7);
  int bright = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    SkyDistribution::Sample s = dist.sample(rng.next_2d());
    ASSERT_GT(s.pdf, 0.0f);
    EXPECT_NEAR(dist.pdf(s.direction), s.pdf, 1e-3f * s.pdf + 1e-4f);
    bright += luminance(sky.radiance(s.direction)) > 10.0f;
  }
  // The share of samples in the blob is its share of luminance x sin(theta).
  double blob = 0.0, all = 0.0;
  for (int y = 0; y < sky.map.height; ++y)
    for (int x = 0; x < sky.map.width; ++x) {
      double w = luminance(sky.map.at(x, y)) * std::sin((y + 0.5) / sky.map.height * kPi);
      all += w;
      if (luminance(sky.map.at(x, y)) > 10.0f) blob += w;
    }
  EXPECT_NEAR(static_cast<double>(bright) / n, blob / all, 0.015);
  // Uniform directions: E[pdf / (1 / 4 pi)] = 1.
  double sum = 0.0;
  const int m = 200000;
  for (int i = 0; i < m; ++i) {
    glm::vec2 u = rng.next_2d();
    float z = 1.0f - 2.0f * u.x, r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    glm::vec3 d(r * std::cos(2.0f * kPi * u.y), z, r * std::sin(2.0f * kPi * u.y));
    sum += dist.pdf(d) * 4.0 * kPi;
  }
  EXPECT_NEAR(sum / m, 1.0, 0.03);
}

TEST(Sky, ConstantAndBlackSkiesNeedNoDistribution) {
  Sky sky;
  sky.color = glm::vec3(1.0f);
  EXPECT_TRUE(sky.enabled());
  EXPECT_FALSE(SkyDistribution(sky).valid());
  sky.strength = 0.0f;
  EXPECT_FALSE(sky.enabled());
  Sky black;
  black.map = ImageRGB(8, 4);
  EXPECT_TRUE(black.enabled());
  EXPECT_FALSE(SkyDistribution(black).valid());
}

TEST(Sky, ValidateRefusesBadSkies) {
  Sky sky;
  sky.strength = -1.0f;
  EXPECT_THROW(validate_sky(sky, "t"), Error);
  sky.strength = 1.0f;
  sky.color = glm::vec3(1.0f, NAN, 0.0f);
  EXPECT_THROW(validate_sky(sky, "t"), Error);
  sky.color = glm::vec3(1.0f);
  EXPECT_NO_THROW(validate_sky(sky, "t"));
  sky.map = ImageRGB(kMaxSkyWidth + 1, 2);
  EXPECT_THROW(validate_sky(sky, "t"), Error);
  sky.map = ImageRGB(4, 2);
  sky.map.at(1, 1) = glm::vec3(-1.0f);
  EXPECT_THROW(validate_sky(sky, "t"), Error);
  sky.map.at(1, 1) = glm::vec3(INFINITY);
  EXPECT_THROW(validate_sky(sky, "t"), Error);
  sky.map.at(1, 1) = glm::vec3(1.0f);
  EXPECT_NO_THROW(validate_sky(sky, "t"));
}

// A single open quad (the plane y = 0, facing up): every direction above it leaves the scene.
Scene open_plane() {
  Scene s;
  std::uint32_t mat = test::add_material(s, glm::vec3(0.5f));
  test::add_quad_object(s, "plane", {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, mat);
  return s;
}

// Irradiance at the plane's centre estimated with `n` samples.
glm::vec3 estimate(const Scene& s, glm::vec3 normal, int n) {
  World world = World::build(s);
  RayScene rays(world);
  LightSampler lights(world);
  EXPECT_TRUE(lights.has_sky());
  Rng rng(3);
  glm::dvec3 sum(0.0);
  for (int i = 0; i < n; ++i) {
    glm::vec2 a = rng.next_2d(), b = rng.next_2d();
    sum +=
        glm::dvec3(lights.sky_irradiance(rays, glm::vec3(0.0f), normal, normal, glm::vec4(a, b)));
  }
  return glm::vec3(sum / static_cast<double>(n));
}

TEST(Sky, ConstantSkyOnAnOpenPlaneGivesPiL) {
  Scene s = open_plane();
  s.sky.color = glm::vec3(0.5f, 1.0f, 2.0f);
  s.sky.strength = 3.0f;
  glm::vec3 e = estimate(s, {0, 1, 0}, 1000);
  const glm::vec3 expected = kPi * s.sky.color * s.sky.strength;
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], expected[c], 1e-4f * expected[c]);
  // The plane's underside sees the sky too (it is a single quad), through nothing.
  glm::vec3 under = estimate(s, {0, -1, 0}, 1000);
  EXPECT_NEAR(under.y, expected.y, 1e-4f * expected.y);
}

TEST(Sky, MapSkyIrradianceMatchesNumericalIntegration) {
  Scene s = open_plane();
  s.sky = test_map_sky();
  // Reference: the map's texels integrated against cos+ on a fine grid of directions.
  const glm::vec3 n = glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f));
  glm::dvec3 ref(0.0);
  const int nu = 1024, nv = 512;
  for (int y = 0; y < nv; ++y)
    for (int x = 0; x < nu; ++x) {
      glm::vec2 uv((x + 0.5f) / nu, (y + 0.5f) / nv);
      glm::vec3 d = sky_direction(uv);
      float c = glm::dot(d, n);
      if (c <= 0.0f || d.y <= 0.0f) continue;  // the plane hides the lower half
      double d_omega = (2.0 * kPi / nu) * (kPi / nv) * std::sin(uv.y * kPi);
      ref += glm::dvec3(s.sky.radiance(d)) * static_cast<double>(c) * d_omega;
    }
  glm::vec3 e = estimate(s, n, 40000);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], ref[c], 0.02 * ref[c]) << "channel " << c;
}

}  // namespace
}  // namespace irradcast::test_sky

// The sky and cut-out (Mask) materials on the Vulkan backend (issue 18), on this machine's Vulkan
// device (lavapipe in CI) with the validation layer on: the direct pass and the reference path
// tracer under a constant sky (pi L on an open plane, nothing inside a closed box), under a map
// sky against LightSampler::sky_irradiance on the CPU and the map integrated numerically, the
// sky as the background of the reference view, and a Mask plane whose holes let exactly their
// share of a sun through.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>

#include "engine_setup.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/sky.h"
#include "scene_builders.h"
#include "vulkan_backend.h"

namespace irradcast::test_vulkan_sky {

using test::EngineSetup;

namespace {

std::unique_ptr<VulkanBackend> vulkan(const EngineSetup& s) {
  VulkanContextOptions o;
  o.validation = true;
  return std::make_unique<VulkanBackend>(s.world, s.rays, s.lights, o, false);
}

void expect_no_validation_messages(const VulkanBackend& v) {
  const auto log = v.validation_log();
  EXPECT_EQ(v.validation_messages(), 0u) << (log.empty() ? std::string() : log.front());
}

// One open quad through the origin facing `normal` (2 x 2): every direction on its normal
// side leaves the scene.
Scene open_plane(glm::vec3 normal, float albedo = 0.5f) {
  Scene s;
  const std::uint32_t mat = test::add_material(s, glm::vec3(albedo));
  const glm::vec3 n = glm::normalize(normal);
  const glm::vec3 t = glm::normalize(glm::cross(n, glm::vec3(0.0f, 0.0f, 1.0f)));
  const glm::vec3 b = glm::cross(n, t);  // (t, b, n) right-handed: the quad faces n
  test::add_quad_object(s, "plane", -t - b, t - b, t + b, -t + b, mat);
  return s;
}

// A map with a bright blob to the right of the centre, high up, a bluish upper half with a
// gradient and a dim lower half: its irradiance depends on the orientation.
Sky map_sky() {
  Sky sky;
  sky.map = ImageRGB(64, 32);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) {
      glm::vec3 c = y < 16 ? glm::vec3(0.2f, 0.3f, 0.5f) * (0.5f + x / 64.0f)
                           : glm::vec3(0.02f, 0.015f, 0.01f);
      if (y >= 5 && y < 9 && x >= 40 && x < 46) c = glm::vec3(40.0f, 32.0f, 25.0f);
      sky.map.at(x, y) = c;
    }
  sky.strength = 1.5f;
  return sky;
}

// The irradiance from the sky on a surface facing n that sees every direction of its side:
// the map's texels integrated against cos+ on a fine grid.
glm::dvec3 integrated_sky(const Sky& sky, glm::vec3 n) {
  glm::dvec3 sum(0.0);
  const int nu = 1024, nv = 512;
  for (int y = 0; y < nv; ++y)
    for (int x = 0; x < nu; ++x) {
      const glm::vec2 uv((x + 0.5f) / nu, (y + 0.5f) / nv);
      const glm::vec3 d = sky_direction(uv);
      const float c = glm::dot(d, n);
      if (c <= 0.0f) continue;
      const double d_omega = (2.0 * kPi / nu) * (kPi / nv) * std::sin(uv.y * kPi);
      sum += glm::dvec3(sky.radiance(d)) * static_cast<double>(c) * d_omega;
    }
  return sum;
}

EngineParams direct_only(int samples) {
  EngineParams p;
  p.indirect_bounces = 0;
  p.tracing_range = INFINITY;
  p.direct_samples = samples;
  return p;
}

// A constant sky of radiance L: an open plane receives pi L in every texel whatever the
// sampling (every cosine ray escapes), in the direct pass and with the unbiased bounces (their
// rays escape too, bringing nothing: the sky is direct light); the reference path tracer's
// lightmaps agree. Single precision: within 1e-5 relative.
TEST(VulkanSky, ConstantSkyOnAnOpenPlaneGivesPiL) {
  Scene scene = open_plane({0.0f, 1.0f, 0.0f});
  scene.sky.color = glm::vec3(0.5f, 1.0f, 2.0f);
  scene.sky.strength = 3.0f;
  EngineSetup s(std::move(scene), 32.0f);
  const glm::vec3 expected = kPi * s.scene.sky.color * s.scene.sky.strength;
  auto check = [&](const std::vector<Lightmap>& maps, const char* what) {
    std::size_t texels = 0;
    for (std::size_t o = 0; o < maps.size(); ++o)
      for (std::size_t i = 0; i < maps[o].texels.size(); ++i) {
        if (!s.gbuffers[o].valid(i)) continue;
        ++texels;
        for (int c = 0; c < 3; ++c)
          ASSERT_NEAR(maps[o].texels[i][c], expected[c], 1e-5f * expected[c]) << what << " " << i;
      }
    EXPECT_GT(texels, 50u) << what;
  };
  for (int bounces : {0, 2}) {
    EngineParams p = direct_only(4);
    p.indirect_bounces = bounces;
    auto backend = vulkan(s);
    VulkanBackend* v = backend.get();
    auto engine = s.engine(p, std::move(backend));
    const UpdateStats st = engine->update();
    // One cosine ray per sample and texel, counted by the shader.
    EXPECT_EQ(st.direct.rays, engine->texel_count() * 4u);
    check(engine->lightmaps(), bounces == 0 ? "direct pass" : "2 bounces");
    check(v->reference_lightmaps(s.gbuffers, 4, 2, 3), "reference");
    expect_no_validation_messages(*v);
  }
}

// A closed box with a bright sky outside and nothing inside: not one texel receives light, in
// the direct pass, with bounces, or from the reference path tracer.
TEST(VulkanSky, ClosedBoxWithASkyOutsideStaysBlack) {
  Scene scene = test::closed_box(glm::vec3(0.8f), glm::vec3(0.0f));
  scene.sky = map_sky();
  EngineSetup s(std::move(scene), 24.0f);
  EngineParams p = direct_only(8);
  p.indirect_bounces = 2;
  auto backend = vulkan(s);
  VulkanBackend* v = backend.get();
  auto engine = s.engine(p, std::move(backend));
  for (int u = 0; u < 2; ++u) engine->update();
  auto brightest = [&](const std::vector<Lightmap>& maps) {
    float m = 0.0f;
    for (std::size_t o = 0; o < maps.size(); ++o)
      for (std::size_t i = 0; i < maps[o].texels.size(); ++i)
        if (s.gbuffers[o].valid(i)) m = std::max(m, luminance(maps[o].texels[i]));
    return m;
  };
  EXPECT_EQ(brightest(engine->lightmaps()), 0.0f);
  EXPECT_EQ(brightest(v->reference_lightmaps(s.gbuffers, 8, 2, 3)), 0.0f);
  EXPECT_GT(engine->texel_count(), 100u);
  expect_no_validation_messages(*v);
}

// The CPU's estimator (LightSampler::sky_irradiance) at every valid texel, the mean of `n`
// estimates from a stream of `seed`.
std::vector<Lightmap> cpu_sky(const EngineSetup& s, int n, std::uint64_t seed) {
  std::vector<Lightmap> maps(s.gbuffers.size());
  Rng rng(seed);
  for (std::size_t o = 0; o < s.gbuffers.size(); ++o) {
    const TexelGBuffer& g = s.gbuffers[o];
    maps[o] = Lightmap(g.width, g.height);
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i)) continue;
      const TexelPoint p = g.point(s.world.objects[o], i);
      glm::dvec3 sum(0.0);
      for (int k = 0; k < n; ++k) {
        const glm::vec2 a = rng.next_2d(), b = rng.next_2d();
        sum += glm::dvec3(
            s.lights.sky_irradiance(s.rays, p.position, p.normal, p.geo_normal, glm::vec4(a, b)));
      }
      maps[o].texels[i] = glm::vec3(sum / static_cast<double>(n));
    }
  }
  return maps;
}

// Per valid texel: the RMS luminance difference of a against b relative to b's mean, and a's
// mean relative to b's.
struct Gap {
  double rms = 0.0, mean = 0.0;
};

Gap gap(const EngineSetup& s, const std::vector<Lightmap>& a, const std::vector<Lightmap>& b) {
  double d2 = 0.0, sa = 0.0, sb = 0.0;
  std::size_t n = 0;
  for (std::size_t o = 0; o < a.size(); ++o)
    for (std::size_t i = 0; i < a[o].texels.size(); ++i) {
      if (!s.gbuffers[o].valid(i)) continue;
      const double ya = luminance(a[o].texels[i]), yb = luminance(b[o].texels[i]);
      d2 += (ya - yb) * (ya - yb);
      sa += ya;
      sb += yb;
      ++n;
    }
  const double nn = static_cast<double>(n);
  return {std::sqrt(d2 / nn) / (sb / nn), sa / sb - 1.0};
}

// A map sky on a tilted open plane: the direct pass's mean over the texels within 1% of the
// map integrated numerically (the mean of ~20 000 estimates: ~0.3% noise), and its spread
// across texels like the CPU estimator's at the same sample count (RMS deviation from the
// integral within 0.8 to 1.25 x the CPU's: the same estimator; cosine rays alone would scatter
// several times more on this map's blob).
TEST(VulkanSky, MapSkyDirectPassIsTheCpuEstimator) {
  const glm::vec3 n = glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f));
  Scene scene = open_plane(n);
  scene.sky = map_sky();
  EngineSetup s(std::move(scene), 32.0f);
  const int samples = 32;
  auto backend = vulkan(s);
  VulkanBackend* v = backend.get();
  auto engine = s.engine(direct_only(samples), std::move(backend));
  engine->update();
  const auto gpu = engine->lightmaps(), cpu = cpu_sky(s, samples, 11);
  // The integral as a lightmap of the same shape, to measure both against.
  std::vector<Lightmap> exact = gpu;
  const glm::vec3 e(integrated_sky(s.scene.sky, n));
  for (Lightmap& m : exact) std::fill(m.texels.begin(), m.texels.end(), e);
  const Gap g = gap(s, gpu, exact), c = gap(s, cpu, exact);
  RecordProperty("gpu_mean", std::to_string(g.mean));
  RecordProperty("gpu_rms", std::to_string(g.rms));
  RecordProperty("cpu_mean", std::to_string(c.mean));
  RecordProperty("cpu_rms", std::to_string(c.rms));
  EXPECT_LT(std::fabs(g.mean), 0.01) << "CPU: " << c.mean;
  EXPECT_LT(g.rms, 1.25 * c.rms) << "CPU: " << c.rms;
  EXPECT_GT(g.rms, 0.8 * c.rms) << "CPU: " << c.rms;
  expect_no_validation_messages(*v);
}

// An open-topped corner (a floor and two walls) under the map sky: the walls hide parts of
// the sky, differently for every texel. The reference path tracer's lightmaps with no bounce
// (the sky's direct light only) against the CPU estimator at the same texels and sample
// count, judged against the CPU with another seed: RMS per-texel difference at most 1.25 x the
// control's, mean within 2% (the control: about 0.3%).
TEST(VulkanSky, MapSkyUnderOcclusionAgreesWithTheCpuEstimator) {
  Scene scene;
  const std::uint32_t mat = test::add_material(scene, glm::vec3(0.5f));
  test::add_quad_object(scene, "floor", {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, mat);
  test::add_quad_object(scene, "wall+x", {1, 0, -1}, {1, 0, 1}, {1, 1, 1}, {1, 1, -1}, mat);
  test::add_quad_object(scene, "wall-z", {-1, 0, -1}, {1, 0, -1}, {1, 1, -1}, {-1, 1, -1}, mat);
  scene.sky = map_sky();
  EngineSetup s(std::move(scene), 32.0f);
  const int spp = 32;
  auto v = vulkan(s);
  const auto gpu = v->reference_lightmaps(s.gbuffers, spp, 0, 5);
  const auto cpu = cpu_sky(s, spp, 5), cpu2 = cpu_sky(s, spp, 6);
  const Gap g = gap(s, gpu, cpu), c = gap(s, cpu2, cpu);
  RecordProperty("rms_vulkan_cpu", std::to_string(g.rms));
  RecordProperty("rms_cpu_cpu", std::to_string(c.rms));
  RecordProperty("mean_vulkan_cpu", std::to_string(g.mean));
  RecordProperty("mean_cpu_cpu", std::to_string(c.mean));
  EXPECT_LT(g.rms, 1.25 * c.rms) << "CPU vs CPU: " << c.rms;
  EXPECT_LT(std::fabs(g.mean), 0.02) << "CPU vs CPU: " << c.mean;
  expect_no_validation_messages(*v);
}

// The reference view of an open plane (albedo rho) from above, the horizon in the picture:
// under a constant sky L a pixel on the plane shows rho L (pi L reaches it, no bounce adds),
// one that misses shows L; under the map sky a pixel that misses shows Sky::radiance of its
// direction (the map's orientation). Which pixels hit is Embree's answer; a pixel on the
// plane's outline may differ (at most 1%).
TEST(VulkanSky, ReferenceViewShowsTheSkyWhereRaysMiss) {
  const float rho = 0.5f;
  Scene scene = open_plane({0.0f, 1.0f, 0.0f}, rho);
  scene.sky.color = glm::vec3(0.25f, 0.5f, 1.0f);
  scene.sky.strength = 2.0f;
  CameraPose cam;
  cam.eye = glm::vec3(0.0f, 0.8f, 2.2f);
  cam.forward = glm::normalize(glm::vec3(0.3f, -0.25f, -1.0f));
  cam.yfov = 1.2f;
  const int w = 32, h = 32;
  for (bool map : {false, true}) {
    if (map) scene.sky = map_sky();
    EngineSetup s(scene, 8.0f);
    auto v = vulkan(s);
    const ImageRGB image = v->render_reference(cam, w, h, 4, 2, 7);
    int hits = 0, misses = 0, wrong = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const Ray r = camera_ray(cam, w, h, x + 0.5f, y + 0.5f);
        const bool hit = s.rays.intersect(r).valid();
        const glm::vec3 got = image.pixels[static_cast<std::size_t>(y) * w + x];
        glm::vec3 want = s.scene.sky.radiance(r.direction);
        if (hit && map) continue;  // the map's light on the plane is noisy
        if (hit) want *= rho;
        (hit ? hits : misses) += 1;
        const float err = glm::length(got - want), scale = glm::length(want) + 1e-6f;
        wrong += err > 1e-4f * scale ? 1 : 0;
      }
    EXPECT_GT(misses, w * h / 8) << "map " << map;
    if (!map) {
      EXPECT_GT(hits, w * h / 8);
    }
    EXPECT_LE(wrong, w * h / 100) << "map " << map << ": " << hits << " hits, " << misses
                                  << " misses";
    expect_no_validation_messages(*v);
  }
}

// A floor (y = 0, [-1, 1]^2) under a sun straight down (E = W where it is not shadowed) and a
// Mask plane at y = 0.5 over all of it, facing the floor. Under z < 0 the plane's base colour
// texture is a stripe of alpha 0 one texel of four wide, repeating once per unit of x (bilinear:
// alpha < 0.5 exactly where frac(x) < 0.25); under z > 0 its base alpha is 0.3, below the cutoff
// everywhere. With `mask` false the same plane is Opaque: the floor gets nothing.
Scene masked_sun(bool mask) {
  Scene s;
  const std::uint32_t floor = test::add_material(s, glm::vec3(0.5f));
  test::add_quad_object(s, "floor", {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, floor);
  Texture stripe;
  stripe.name = "stripe";
  stripe.width = 4;
  stripe.height = 1;
  for (int x = 0; x < 4; ++x)
    for (std::uint8_t c : {std::uint8_t{200}, std::uint8_t{200}, std::uint8_t{200},
                           static_cast<std::uint8_t>(x == 0 ? 0 : 255)})
      stripe.rgba8.push_back(c);
  s.textures = {stripe};
  const std::uint32_t striped = test::add_material(s, glm::vec3(0.7f));
  const std::uint32_t faint = test::add_material(s, glm::vec3(0.7f));
  s.materials[striped].base_color_texture = 0;
  s.materials[faint].base_alpha = 0.3f;
  for (std::uint32_t m : {striped, faint}) {
    s.materials[m].alpha_mode = mask ? Material::AlphaMode::Mask : Material::AlphaMode::Opaque;
    s.materials[m].alpha_cutoff = 0.5f;
  }
  // u = x + 2 across the striped half (4 periods over [-2, 2]).
  const int a = test::add_quad_object(s, "mask-z", {-2, 0.5f, -2}, {2, 0.5f, -2}, {2, 0.5f, 0},
                                      {-2, 0.5f, 0}, striped);
  s.meshes[s.nodes[a].mesh].uv0 = {{0, 0}, {4, 0}, {4, 0}, {0, 0}};
  test::add_quad_object(s, "mask+z", {-2, 0.5f, 0}, {2, 0.5f, 0}, {2, 0.5f, 2}, {-2, 0.5f, 2},
                        faint);
  Light sun;
  sun.type = Light::Type::Directional;
  sun.intensity = 2.0f;
  s.lights = {sun};
  Node n;
  n.name = "sun";
  n.light = 0;
  n.local = glm::rotate(glm::mat4(1.0f), -0.5f * kPi, glm::vec3(1, 0, 0));  // -Z -> -Y
  s.add_node(n);
  return s;
}

// The Mask plane lets the sun through exactly its cut-out parts: every floor texel receives W
// where the point of the plane straight above is cut out and 0 elsewhere (texels within half a
// texel of a hole's edge are not judged), in the direct pass and in the reference path
// tracer's lightmaps; over the floor the lit share is the holes' share, 5/8 (a quarter of one
// half, all of the other), within the texels that straddle an edge (3 stripe edges half the
// floor long and the halves' seam: at most 1.25 texel widths of share; bound 2). The same
// plane Opaque casts a full shadow.
TEST(VulkanCutOut, AMaskPlaneLetsThroughExactlyItsHoles) {
  for (bool mask : {true, false}) {
    EngineSetup s(masked_sun(mask), 40.0f);
    const std::size_t floor = 0;
    ASSERT_EQ(s.world.objects[floor].source->name, "floor");
    const TexelGBuffer& g = s.gbuffers[floor];
    const float texel = 2.0f / static_cast<float>(g.width);
    auto v = vulkan(s);
    VulkanBackend* vp = v.get();
    auto engine = s.engine(direct_only(1), std::move(v));
    engine->update();
    const auto direct = engine->lightmaps();
    const auto reference = vp->reference_lightmaps(s.gbuffers, 1, 0, 3);
    for (const auto* maps : {&direct, &reference}) {
      const std::vector<glm::vec3>& e = (*maps)[floor].texels;
      double lit = 0.0;
      int texels = 0, judged = 0, wrong = 0;
      for (std::size_t i = 0; i < g.size(); ++i) {
        if (!g.valid(i)) continue;
        const glm::vec3 p = g.position(s.world.objects[floor], i);
        const float f = p.x - std::floor(p.x);
        const bool hole = mask && (p.z > 0.0f || f < 0.25f);
        const float edge = std::min({std::fabs(p.z), std::fabs(f - 0.25f), f, 1.0f - f});
        lit += e[i].y / 2.0f;
        ++texels;
        if (edge < 0.5f * texel) continue;
        ++judged;
        wrong += std::fabs(e[i].y - (hole ? 2.0f : 0.0f)) > 1e-4f ? 1 : 0;
      }
      const double share = lit / texels, expected = mask ? 5.0 / 8.0 : 0.0;
      RecordProperty(std::string(mask ? "mask_" : "opaque_") +
                         (maps == &direct ? "direct_share" : "reference_share"),
                     std::to_string(share));
      EXPECT_GT(judged, texels / 2) << "texel size " << texel;
      EXPECT_EQ(wrong, 0) << (maps == &direct ? "direct pass" : "reference") << " mask " << mask;
      EXPECT_NEAR(share, expected, 2.0 * texel) << "mask " << mask;
    }
    expect_no_validation_messages(*vp);
  }
}

}  // namespace

}  // namespace irradcast::test_vulkan_sky

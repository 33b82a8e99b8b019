// The sky and the sun in the CPU estimators (docs/ENGINE.md "Sky and sun"): the engine's direct
// pass on Embree, the reference path tracer (with and without next-event estimation), the VPL
// method and the irradiance cache, against analytic irradiance and the reference lightmaps; and
// the tools' --sky / --sky-strength / --sun options (scene_options.h). The path tracer's two
// modes under a sky: tests/test_path_tracer.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "engine_setup.h"
#include "irradcast/common/error.h"
#include "irradcast/common/sky.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "scene_builders.h"
#include "scene_options.h"

namespace irradcast::test_sky_engine {

using test::EngineSetup;

namespace {

// A 2 x 2 plane at y = 0 facing +y.
Scene open_plane(glm::vec3 albedo) {
  Scene s;
  const std::uint32_t m = test::add_material(s, albedo);
  test::add_quad_object(s, "plane", {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, m);
  return s;
}

Sky constant_sky(glm::vec3 color, float strength = 1.0f) {
  Sky sky;
  sky.color = color;
  sky.strength = strength;
  return sky;
}

// A small map: a dim blue gradient (brighter toward the zenith) with a bright warm patch up and
// toward +X, so importance sampling and the map's orientation both matter.
Sky map_sky() {
  Sky sky;
  sky.map = ImageRGB(32, 16);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x) {
      const float up = 1.0f - static_cast<float>(y) / 16.0f;
      sky.map.at(x, y) = glm::vec3(0.2f, 0.3f, 0.6f) * (0.3f + up);
    }
  for (int y = 3; y < 6; ++y)
    for (int x = 21; x < 25; ++x) sky.map.at(x, y) = glm::vec3(8.0f, 6.0f, 4.0f);
  sky.source = "test map";
  return sky;
}

// A floor with a block on it (shadows, a bounce off its sides) and a wall behind: open to the
// sky. Albedo 0.6.
Scene courtyard() {
  Scene s;
  const std::uint32_t m = test::add_material(s, glm::vec3(0.6f));
  test::add_quad_object(s, "floor", {-2, 0, -2}, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, m);
  test::add_block(s, "block", {-0.5f, 0.0f, -0.5f}, {0.5f, 1.0f, 0.5f}, m);
  test::add_quad_object(s, "wall", {-2, 0, -2}, {2, 0, -2}, {2, 2, -2}, {-2, 2, -2}, m);
  return s;
}

// Every valid texel of `maps` (object o's texels through gbuffers) as (object, index).
template <typename F>
void for_valid(const EngineSetup& s, F&& f) {
  for (std::size_t o = 0; o < s.gbuffers.size(); ++o)
    for (std::size_t i = 0; i < s.gbuffers[o].size(); ++i)
      if (s.gbuffers[o].valid(i)) f(o, i);
}

// Relative MSE over all valid texels (luminance): sum (a - r)^2 / sum r^2.
double lightmap_rel_mse(const EngineSetup& s, const std::vector<Lightmap>& a,
                        const std::vector<Lightmap>& ref) {
  double num = 0.0, den = 0.0;
  for_valid(s, [&](std::size_t o, std::size_t i) {
    const double x = luminance(a[o].texels[i]), r = luminance(ref[o].texels[i]);
    num += (x - r) * (x - r);
    den += r * r;
  });
  return num / den;
}

// Ratio of the mean luminance over valid texels.
double mean_ratio(const EngineSetup& s, const std::vector<Lightmap>& a,
                  const std::vector<Lightmap>& ref) {
  double x = 0.0, r = 0.0;
  for_valid(s, [&](std::size_t o, std::size_t i) {
    x += luminance(a[o].texels[i]);
    r += luminance(ref[o].texels[i]);
  });
  return x / r;
}

std::vector<Lightmap> reference(const EngineSetup& s, int bounces, int spp) {
  PathTracer tracer(s.world, s.rays, s.lights, PathTracerOptions{bounces, true, 17});
  return reference_lightmaps(s.world, tracer, s.gbuffers, spp);
}

EngineParams params(Method m = Method::Cells, int bounces = 2) {
  EngineParams p;
  p.method = m;
  p.indirect_bounces = bounces;
  return p;
}

// The cells method without probes (tracing range infinite): unbiased.
EngineParams unbiased(int bounces = 2) {
  EngineParams p = params(Method::Cells, bounces);
  p.tracing_range = std::numeric_limits<float>::infinity();
  return p;
}

}  // namespace

// White furnace, open: a plane under a constant sky of radiance L sees the whole upper
// hemisphere, so E = pi L at every texel and every sample (the cosine ray always escapes).
// The engine's direct pass (default cells parameters), the unbiased engine's whole lightmaps (no
// bounce light: the sky is direct light only) and the path tracer (NEE and pure paths) all exact
// to float rounding (1e-5).
TEST(SkyEngine, OpenPlaneUnderAConstantSkyReceivesPiL) {
  const glm::vec3 L(1.0f, 0.5f, 0.25f);
  Scene scene = open_plane(glm::vec3(0.5f));
  scene.sky = constant_sky(L, 2.0f);
  EngineSetup s(std::move(scene), 16.0f);
  ASSERT_FALSE(s.lights.empty());
  ASSERT_TRUE(s.lights.emissive_triangles().empty());
  ASSERT_TRUE(s.world.lights.empty());
  const glm::vec3 expected = kPi * 2.0f * L;
  auto engine = s.engine(params());
  auto exact = s.engine(unbiased());
  for (int u = 0; u < 2; ++u) {
    const UpdateStats us = engine->update();
    EXPECT_GE(us.direct.rays, engine->texel_count() * 8u);  // direct_samples sky rays each
    exact->update();
  }
  // The default cells' whole lightmaps too: their scatter rays leave the scene, and a ray that
  // leaves brings nothing (it once read a probe that saw the lit plane: 1.5-1.65 x pi L).
  const auto direct = engine->component(0), total = exact->lightmaps(), cells = engine->lightmaps();
  std::size_t texels = 0;
  for_valid(s, [&](std::size_t o, std::size_t i) {
    ++texels;
    for (int c = 0; c < 3; ++c) {
      ASSERT_NEAR(direct[o].texels[i][c], expected[c], 1e-5f * expected[c]);
      ASSERT_NEAR(total[o].texels[i][c], expected[c], 1e-5f * expected[c]);
      ASSERT_NEAR(cells[o].texels[i][c], expected[c], 1e-5f * expected[c]);
    }
  });
  EXPECT_GT(texels, 50u);
  for (bool nee : {true, false}) {
    PathTracer tracer(s.world, s.rays, s.lights, PathTracerOptions{2, nee, 5});
    Rng rng(3, 4);
    for (int k = 0; k < 64; ++k) {
      const glm::vec3 p(rng.next_float() * 1.6f - 0.8f, 0.0f, rng.next_float() * 1.6f - 0.8f);
      const glm::vec3 e = tracer.irradiance(p, {0, 1, 0}, {0, 1, 0}, 2, rng);
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(e[c], expected[c], 1e-5f * expected[c]) << nee;
    }
  }
  // A camera ray that misses everything shows the sky.
  PathTracer tracer(s.world, s.rays, s.lights);
  Rng rng(1, 1);
  Ray up;
  up.origin = glm::vec3(0, 1, 0);
  up.direction = glm::vec3(0, 1, 0);
  EXPECT_EQ(tracer.radiance(up, rng), 2.0f * L);
}

// White furnace, closed: the inward-facing box under a bright sky receives nothing inside, in
// every component, from the engine and the path tracer.
TEST(SkyEngine, ClosedBoxUnderASkyIsBlackInside) {
  Scene scene = test::closed_box(glm::vec3(0.8f), glm::vec3(0.0f));
  scene.sky = constant_sky(glm::vec3(5.0f));
  EngineSetup s(std::move(scene), 16.0f);
  ASSERT_TRUE(s.lights.has_sky());
  for (Method m : {Method::Cells, Method::Vpl, Method::IrradianceCache}) {
    auto engine = s.engine(params(m));
    for (int u = 0; u < 2; ++u) engine->update();
    const auto maps = engine->lightmaps();
    for_valid(s, [&](std::size_t o, std::size_t i) {
      ASSERT_EQ(maps[o].texels[i], glm::vec3(0.0f)) << method_name(m) << " object " << o;
    });
  }
  const auto ref = reference(s, 2, 4);
  for_valid(s, [&](std::size_t o, std::size_t i) { ASSERT_EQ(ref[o].texels[i], glm::vec3(0.0f)); });
  CameraPose inside;  // at the centre, looking down -Z
  const ImageRGB view = PathTracer(s.world, s.rays, s.lights).render(inside, 8, 8, 2);
  for (const glm::vec3& px : view.pixels) ASSERT_EQ(px, glm::vec3(0.0f));
}

// A sun (the --sun light: a directional light on a node of its own) on an open plane:
// E = W cos(theta) at every texel, the same in every update (a delta light: no noise).
TEST(SkyEngine, SunOnAPlaneGivesWCosThetaExactly) {
  Scene scene = open_plane(glm::vec3(0.5f));
  const glm::vec3 d = glm::normalize(glm::vec3(1.0f, -2.0f, 0.5f));
  tools::add_sun(scene, d, 3.0f);
  EngineSetup s(std::move(scene), 16.0f);
  ASSERT_EQ(s.world.lights.size(), 1u);
  EXPECT_NEAR(glm::length(s.world.lights[0].direction - d), 0.0f, 1e-6f);
  const float expected = 3.0f * -d.y;
  auto engine = s.engine(params());
  std::vector<Lightmap> first;
  for (int u = 0; u < 4; ++u) {
    engine->update();
    const auto direct = engine->component(0);
    if (u == 0) first = direct;
    for_valid(s, [&](std::size_t o, std::size_t i) {
      ASSERT_NEAR(direct[o].texels[i].x, expected, 1e-5f * expected);
      ASSERT_EQ(direct[o].texels[i], first[o].texels[i]) << "update " << u;
    });
  }
}

// The sun through an opening: a floor under a thick roof with a 1 x 1 hole, the sun straight
// down. Floor texels under the hole (a texel away from its edge) get exactly W direct, those
// under the roof exactly 0 direct, in every update (a delta light: no noise). The shadowed floor
// gets bounce light only (two bounces: the lit patch lights the roof's underside, which lights
// the floor). A lightmap holds the lit patch as the texels whose centres it covers (n_lit texels
// of 1 / density^2 each, not exactly 1 m^2: measured 0.77 at this density), and the lightmap
// methods' bounces read it, so their mean in the shadow is compared with the reference's times
// that factor; VPL's paths do not read the lightmaps and are compared with the reference alone.
// Measured: unbiased 1.004, irradiance cache 1.000, VPL 1.09, cells (probes) 1.11.
TEST(SkyEngine, SunThroughAnOpeningCastsHardShadows) {
  Scene scene;
  const std::uint32_t m = test::add_material(scene, glm::vec3(0.6f));
  test::add_quad_object(scene, "floor", {-2, 0, -2}, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, m);
  // The roof: four slabs around the hole [-0.5, 0.5]^2 at y in [1, 1.2].
  test::add_block(scene, "roof-a", {-2.0f, 1.0f, -2.0f}, {2.0f, 1.2f, -0.5f}, m);
  test::add_block(scene, "roof-b", {-2.0f, 1.0f, 0.5f}, {2.0f, 1.2f, 2.0f}, m);
  test::add_block(scene, "roof-c", {-2.0f, 1.0f, -0.5f}, {-0.5f, 1.2f, 0.5f}, m);
  test::add_block(scene, "roof-d", {0.5f, 1.0f, -0.5f}, {2.0f, 1.2f, 0.5f}, m);
  const float W = 4.0f;
  tools::add_sun(scene, {0.0f, -1.0f, 0.0f}, W);
  EngineSetup s(std::move(scene), 32.0f);
  const auto ref = reference(s, 2, 64);
  const TexelGBuffer& g = s.gbuffers[0];  // the floor
  const float density = s.atlas.objects[0].texels_per_unit;
  auto ring = [&](std::size_t i) {
    const glm::vec3 p = g.position(s.world.objects[0], i);
    return std::max(std::fabs(p.x), std::fabs(p.z));
  };
  struct Case {
    const char* name;
    EngineParams p;
    bool reads_lightmaps;
    double bound;  // on the ratio to the (scaled) reference
  };
  for (const Case& c :
       {Case{"unbiased", unbiased(), true, 0.05}, Case{"cells", params(), true, 0.2},
        Case{"irradiance-cache", params(Method::IrradianceCache), true, 0.05},
        Case{"vpl", params(Method::Vpl), false, 0.15}}) {
    auto engine = s.engine(c.p);
    int lit = 0, shadowed = 0, lit_texels = 0;
    for (int u = 0; u < 8; ++u) {
      engine->update();
      const auto direct = engine->component(0);
      lit = shadowed = lit_texels = 0;
      for (std::size_t i = 0; i < g.size(); ++i) {
        if (!g.valid(i)) continue;
        const float r = ring(i);
        lit_texels += direct[0].texels[i].x > 0.0f ? 1 : 0;
        if (r < 0.4f) {
          ++lit;
          ASSERT_NEAR(direct[0].texels[i].x, W, 1e-5f * W);
        } else if (r > 0.6f && r < 1.9f) {
          ++shadowed;
          ASSERT_EQ(direct[0].texels[i], glm::vec3(0.0f));
        }
      }
    }
    EXPECT_GT(lit, 20);
    EXPECT_GT(shadowed, 200);
    const auto total = engine->lightmaps();
    double shadow_engine = 0.0, shadow_ref = 0.0;
    for (std::size_t i = 0; i < g.size(); ++i)
      if (g.valid(i) && ring(i) > 0.6f && ring(i) < 1.9f) {
        shadow_engine += total[0].texels[i].x;
        shadow_ref += ref[0].texels[i].x;
      }
    ASSERT_GT(shadow_ref, 0.0);
    const double patch = lit_texels / (density * density);  // the lit area the lightmap holds
    const double ratio = shadow_engine / (shadow_ref * (c.reads_lightmaps ? patch : 1.0));
    RecordProperty(std::string(c.name) + "_shadow_ratio", std::to_string(ratio));
    std::printf("shadowed floor, %s / reference: %.4f (lit patch in the lightmap %.3f m^2)\n",
                c.name, ratio, patch);
    EXPECT_NEAR(ratio, 1.0, c.bound) << c.name;
  }
}

// A map sky over the courtyard, against the reference lightmaps (256 paths per texel): the
// direct pass alone (no bounces) and the whole lightmaps (2 bounces) of the unbiased engine, VPL
// and the irradiance cache: relative MSE over all valid texels, the mean, and the mean of the
// bounce light alone. Bounds from the measured values with room for the reference's noise.
// The default cells (probes at a tracing range of 0.3) too: measured rel MSE 0.0045, bounce
// ratio 1.07 (+38 % bounce light before scatter rays that leave the scene stopped reading
// probes).
TEST(SkyEngine, MapSkyMatchesTheReferenceLightmaps) {
  Scene scene = courtyard();
  scene.sky = map_sky();
  EngineSetup s(std::move(scene), 24.0f);
  ASSERT_TRUE(s.lights.sky_distribution().valid());
  const auto ref0 = reference(s, 0, 256);
  const auto ref2 = reference(s, 2, 256);
  {
    auto engine = s.engine(params(Method::Cells, 0));
    for (int u = 0; u < 16; ++u) engine->update();
    const double e = lightmap_rel_mse(s, engine->lightmaps(), ref0);
    const double mean = mean_ratio(s, engine->lightmaps(), ref0);
    std::printf("map sky, direct only: rel MSE %.5f, mean ratio %.4f\n", e, mean);
    RecordProperty("direct_rel_mse", std::to_string(e));
    EXPECT_LT(e, 0.01);
    EXPECT_NEAR(mean, 1.0, 0.02);
  }
  struct Case {
    const char* name;
    EngineParams p;
    double rel_mse, mean, bounce;  // bounds
  };
  for (const Case& c : {Case{"unbiased", unbiased(), 0.01, 0.02, 0.05},
                        Case{"vpl", params(Method::Vpl), 0.012, 0.03, 0.2},
                        Case{"irradiance-cache", params(Method::IrradianceCache), 0.01, 0.02, 0.1},
                        Case{"cells", params(), 0.01, 0.02, 0.15}}) {
    auto engine = s.engine(c.p);
    for (int u = 0; u < 16; ++u) engine->update();
    const auto total = engine->lightmaps(), d = engine->component(0);
    const double e = lightmap_rel_mse(s, total, ref2);
    const double mean = mean_ratio(s, total, ref2);
    double eb = 0.0, rb = 0.0;
    for_valid(s, [&](std::size_t o, std::size_t i) {
      eb += luminance(total[o].texels[i] - d[o].texels[i]);
      rb += luminance(ref2[o].texels[i] - ref0[o].texels[i]);
    });
    std::printf("map sky, %s: rel MSE %.5f, mean ratio %.4f, bounce ratio %.4f (%s)\n", c.name, e,
                mean, eb / rb, engine->method_summary().c_str());
    RecordProperty(std::string(c.name) + "_rel_mse", std::to_string(e));
    RecordProperty(std::string(c.name) + "_bounce_ratio", std::to_string(eb / rb));
    EXPECT_LT(e, c.rel_mse) << c.name;
    EXPECT_NEAR(mean, 1.0, c.mean) << c.name;
    EXPECT_NEAR(eb / rb, 1.0, c.bounce) << c.name;
  }
}

// Sky-less scenes draw no sky random numbers: the path tracer's estimate with a disabled sky
// (strength 0) is bit-identical to one without any.
TEST(SkyEngine, ADisabledSkyChangesNothing) {
  Scene a = courtyard(), b = courtyard();
  tools::add_sun(a, {0.3f, -1.0f, 0.2f}, 2.0f);
  tools::add_sun(b, {0.3f, -1.0f, 0.2f}, 2.0f);
  b.sky = constant_sky(glm::vec3(1.0f), 0.0f);
  EngineSetup sa(std::move(a), 8.0f), sb(std::move(b), 8.0f);
  ASSERT_FALSE(sb.lights.has_sky());
  auto ea = sa.engine(params()), eb = sb.engine(params());
  ea->update();
  eb->update();
  const auto ma = ea->lightmaps(), mb = eb->lightmaps();
  for (std::size_t o = 0; o < ma.size(); ++o) ASSERT_EQ(ma[o].texels, mb[o].texels);
}

// The tools' options: parsing, the errors that name the option, and what they put in the scene.
TEST(SkyEngine, SceneOptionsParseAndRefuseBadValues) {
  {
    tools::SceneOptions o;
    o.sky = "0.5,1,2";
    o.sky_strength = 3.0f;
    o.sun = "0,-2,0,5";
    Scene scene = open_plane(glm::vec3(0.5f));
    o.apply(scene);
    EXPECT_EQ(scene.sky.color, glm::vec3(0.5f, 1.0f, 2.0f));
    EXPECT_EQ(scene.sky.strength, 3.0f);
    ASSERT_EQ(scene.lights.size(), 1u);
    EXPECT_EQ(scene.lights[0].type, Light::Type::Directional);
    EXPECT_EQ(scene.lights[0].intensity, 5.0f);
    const World w = World::build(scene);
    ASSERT_EQ(w.lights.size(), 1u);
    EXPECT_NEAR(glm::length(w.lights[0].direction - glm::vec3(0, -1, 0)), 0.0f, 1e-6f);
    const std::string line = o.describe(scene);
    EXPECT_NE(line.find("sun"), std::string::npos) << line;
    EXPECT_NE(line.find("sky 0.5,1,2 x 3"), std::string::npos) << line;
  }
  // A map larger than the sky takes is refused from its header, before its pixels are read.
  const std::string big =
      (std::filesystem::temp_directory_path() / "irradcast_sky_big.exr").string();
  write_exr(big, ImageRGB(kMaxSkyWidth + 1, 2));
  const std::string tiny =
      (std::filesystem::temp_directory_path() / "irradcast_sky_ok.exr").string();
  write_exr(tiny, ImageRGB(4, 2));
  {
    tools::SceneOptions o;
    o.sky = tiny;
    o.sky_strength = 0.5f;
    Scene scene = open_plane(glm::vec3(0.5f));
    o.apply(scene);
    EXPECT_EQ(scene.sky.map.width, 4);
    EXPECT_EQ(scene.sky.source, tiny);
    EXPECT_NE(o.describe(scene).find("sky map"), std::string::npos);
  }
  struct Case {
    std::string sky, sun;
    float strength;
    std::string expect;
  };
  for (const Case& c : std::vector<Case>{{"1,2", "", 1.0f, "--sky"},
                                         {"1,2,x", "", 1.0f, "--sky"},
                                         {"1,-2,3", "", 1.0f, "--sky"},
                                         {"1,nan,3", "", 1.0f, "--sky"},
                                         {"sky.png", "", 1.0f, "--sky"},
                                         {"/nonexistent/sky.exr", "", 1.0f, "--sky"},
                                         {"1,1,1", "", -1.0f, "--sky-strength"},
                                         {"1,1,1", "", NAN, "--sky-strength"},
                                         {"", "", 2.0f, "--sky-strength"},
                                         {"", "0,0,0,1", 1.0f, "--sun"},
                                         {"", "0,-1,0", 1.0f, "--sun"},
                                         {"", "0,-1,0,-3", 1.0f, "--sun"},
                                         {"", "0,-1,0,inf", 1.0f, "--sun"},
                                         {"", "0,-1e30,1e30,1", 1.0f, "--sun"},
                                         {big, "", 1.0f, "4097x2"}}) {
    tools::SceneOptions o;
    o.sky = c.sky;
    o.sun = c.sun;
    o.sky_strength = c.strength;
    Scene scene = open_plane(glm::vec3(0.5f));
    try {
      o.apply(scene);
      ADD_FAILURE() << c.sky << " " << c.sun << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(c.expect), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find("--sky") == std::string::npos &&
                    std::string(e.what()).find("--sun") == std::string::npos,
                false)
          << e.what();
    }
  }
  std::filesystem::remove(big);
  std::filesystem::remove(tiny);
}

}  // namespace irradcast::test_sky_engine

// Light leaks of the default method (radiance cells with probes) through closed walls, the case
// users report against other lightmappers: a thick-walled box (solid blocks) with a small window
// and a sun outside gets light inside only through the window, and the outside of a closed
// building lit from within (rooms:2) stays black. Both are checked on lightmaps, texel by texel,
// against exact values or the reference path tracer's lightmaps of the same texels.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <glm/gtc/matrix_transform.hpp>

#include "engine_setup.h"
#include "irradcast/common/builtin.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "scene_builders.h"

namespace irradcast::test_leaks {

using namespace irradcast::test;

namespace {

// The sun's direction of travel: from +x, 31 degrees above the horizon, through the window.
const glm::vec3 kSunTravel = glm::normalize(glm::vec3(-1.0f, -0.6f, 0.0f));
constexpr float kSunIrradiance = 3.0f;  // W: E = W cos(theta) on a sunlit surface
constexpr float kWall = 0.4f;           // wall, floor and roof thickness
constexpr float kOuter = 2.0f;          // the box is [-2, 2] x [0, 3] x [-2, 2]
constexpr float kHeight = 3.0f;
constexpr float kIn = kOuter - kWall;  // interior: [-1.6, 1.6] x [0.4, 2.6] x [-1.6, 1.6]
constexpr float kTop = kHeight - kWall;

// A sunlit ground (12 x 12, albedo 0.8) with a closed box of solid blocks on it; with
// `window`, a 0.6 x 0.6 opening in the +x wall that lets the sun fall onto the interior floor.
Scene leak_box(bool window) {
  Scene s;
  const std::uint32_t ground = add_material(s, glm::vec3(0.8f));
  const std::uint32_t wall = add_material(s, glm::vec3(0.6f));
  add_quad_object(s, "ground", {-6, 0, -6}, {-6, 0, 6}, {6, 0, 6}, {6, 0, -6}, ground);
  add_block(s, "floor", {-kOuter, 0, -kOuter}, {kOuter, kWall, kOuter}, wall);
  add_block(s, "roof", {-kOuter, kHeight - kWall, -kOuter}, {kOuter, kHeight, kOuter}, wall);
  add_block(s, "wall-x", {-kOuter, kWall, -kOuter}, {-kIn, kTop, kOuter}, wall);
  add_block(s, "wall-z", {-kIn, kWall, -kOuter}, {kIn, kTop, -kIn}, wall);
  add_block(s, "wall+z", {-kIn, kWall, kIn}, {kIn, kTop, kOuter}, wall);
  if (!window) {
    add_block(s, "wall+x", {kIn, kWall, -kOuter}, {kOuter, kTop, kOuter}, wall);
  } else {  // around the opening y in [1.6, 2.2], z in [-0.3, 0.3]
    add_block(s, "sill", {kIn, kWall, -kOuter}, {kOuter, 1.6f, kOuter}, wall);
    add_block(s, "lintel", {kIn, 2.2f, -kOuter}, {kOuter, kTop, kOuter}, wall);
    add_block(s, "jamb-z", {kIn, 1.6f, -kOuter}, {kOuter, 2.2f, -0.3f}, wall);
    add_block(s, "jamb+z", {kIn, 1.6f, 0.3f}, {kOuter, 2.2f, kOuter}, wall);
  }
  s.lights.push_back(Light{});
  Light& sun = s.lights.back();
  sun.name = "sun";
  sun.type = Light::Type::Directional;
  sun.intensity = kSunIrradiance;
  Node node;
  node.name = "sun";
  node.light = 0;
  // A light shines along its node's -Z.
  node.local = glm::inverse(glm::lookAt(glm::vec3(0.0f), kSunTravel, glm::vec3(0, 1, 0)));
  s.add_node(node);
  return s;
}

bool interior(glm::vec3 p) {
  const float e = 1e-3f;
  return std::abs(p.x) < kIn + e && std::abs(p.z) < kIn + e && p.y > kWall - e &&
         p.y < kHeight - kWall + e;
}

// Mean irradiance (RGB mean) of the valid texels that `keep(position, normal)` selects, and
// their count.
struct Group {
  double mean = 0.0, max = 0.0;
  std::size_t texels = 0;
};
Group group(const EngineSetup& s, const std::vector<Lightmap>& maps,
            const std::function<bool(glm::vec3, glm::vec3)>& keep) {
  Group g;
  double sum = 0.0;
  for (std::size_t o = 0; o < maps.size(); ++o)
    for (std::size_t i = 0; i < maps[o].texels.size(); ++i) {
      if (!s.gbuffers[o].valid(i)) continue;
      const TexelPoint p = s.gbuffers[o].point(s.world.objects[o], i);
      if (!keep(p.position, p.normal)) continue;
      const glm::vec3 e = maps[o].texels[i];
      const double v = (e.x + e.y + e.z) / 3.0;
      sum += v;
      g.max = std::max(g.max, v);
      ++g.texels;
    }
  g.mean = g.texels ? sum / static_cast<double>(g.texels) : 0.0;
  return g;
}

std::vector<Lightmap> bake(const EngineSetup& s, int updates, EngineParams p = {}) {
  auto engine = s.engine(p);  // the default method: cells, probes, range 0.3
  for (int u = 0; u < updates; ++u) engine->update();
  return engine->lightmaps();
}

}  // namespace

TEST(Leaks, ClosedBoxUnderTheSunIsBlackInside) {
  EngineSetup s(leak_box(false), 48.0f);
  const std::vector<Lightmap> maps = bake(s, 2);
  const Group inside = group(s, maps, [](glm::vec3 p, glm::vec3) { return interior(p); });
  const Group ground = group(s, maps, [](glm::vec3 p, glm::vec3 n) {
    return n.y > 0.9f && p.y < 1e-3f && std::abs(p.x) > 3.0f;
  });
  ASSERT_GT(inside.texels, 300u);
  // No path leads inside: any light there is a leak.
  EXPECT_EQ(inside.max, 0.0) << "mean " << inside.mean;
  // The ground (partly in the box's shadow) is lit as the unbiased mode lights it: the sun and
  // the little the box reflects; rays that leave the scene bring nothing (measured 1.361 against
  // 1.345 at 2 updates; before such rays stopped reading probes it was over 1.389).
  EngineParams unbiased;
  unbiased.tracing_range = std::numeric_limits<float>::infinity();
  const Group traced = group(s, bake(s, 2, unbiased), [](glm::vec3 p, glm::vec3 n) {
    return n.y > 0.9f && p.y < 1e-3f && std::abs(p.x) > 3.0f;
  });
  EXPECT_NEAR(ground.mean, traced.mean, 0.02 * traced.mean);
}

TEST(Leaks, BoxWithAWindowIsLitOnlyThroughIt) {
  EngineSetup s(leak_box(true), 48.0f);
  const std::vector<Lightmap> maps = bake(s, 8);
  EngineParams unbiased;
  unbiased.tracing_range = std::numeric_limits<float>::infinity();
  const std::vector<Lightmap> traced = bake(s, 8, unbiased);
  PathTracer tracer(s.world, s.rays, s.lights, PathTracerOptions{2, true, 7});
  const std::vector<Lightmap> ref = reference_lightmaps(s.world, tracer, s.gbuffers, 128);
  struct Case {
    const char* name;
    std::function<bool(glm::vec3, glm::vec3)> keep;
    double vs_unbiased, vs_reference;  // relative tolerances on the group mean (0: not checked)
  };
  const std::vector<Case> cases = {
      // Direct sun only: nothing above the roof, so no indirect light (E = W cos theta).
      {"roof top", [](glm::vec3 p, glm::vec3 n) { return n.y > 0.9f && p.y > kHeight - 1e-3f; },
       0.01, 0.01},
      // The outside wall in the box's shadow: only the ground's light. Its rays that reach the
      // range read probes outside the box (measured 1.29 of the unbiased mode, which is within
      // 1 % of the path tracer): the probe approximation of the sunlit ground 3-6 m away.
      {"shadowed outside wall",
       [](glm::vec3 p, glm::vec3 n) { return n.x < -0.9f && p.x < -kOuter + 1e-3f; }, 0.4, 0.4},
      // Inside: the sun's patch on the floor and the light it and the window send on; the
      // interior sees no probe (all of them stand outside the box or in its walls), so it is
      // traced as in the unbiased mode. Measured 1.02 and 1.20 of the reference.
      {"interior floor", [](glm::vec3 p, glm::vec3 n) { return interior(p) && n.y > 0.9f; }, 0.03,
       0.10},
      {"interior walls and ceiling",
       [](glm::vec3 p, glm::vec3 n) { return interior(p) && n.y < 0.9f; }, 0.03, 0.25},
  };
  for (const Case& c : cases) {
    const Group e = group(s, maps, c.keep), u = group(s, traced, c.keep), r = group(s, ref, c.keep);
    ASSERT_GT(r.texels, 20u) << c.name;
    ASSERT_GT(u.mean, 0.0) << c.name;
    RecordProperty(std::string(c.name) + " vs unbiased", std::to_string(e.mean / u.mean));
    RecordProperty(std::string(c.name) + " vs reference", std::to_string(e.mean / r.mean));
    EXPECT_NEAR(e.mean / u.mean, 1.0, c.vs_unbiased) << c.name << ": " << e.mean << " / " << u.mean;
    if (c.vs_reference > 0.0) {
      EXPECT_NEAR(e.mean / r.mean, 1.0, c.vs_reference)
          << c.name << ": " << e.mean << " / " << r.mean;
    }
  }
  const Group roof = group(s, maps, cases[0].keep);
  EXPECT_NEAR(roof.mean, kSunIrradiance * -kSunTravel.y, 0.01 * kSunIrradiance);
}

TEST(Leaks, ClosedBuildingLitFromInsideIsBlackOutside) {
  // rooms:2 has lights only inside and no opening to the outside, so its roof and outer walls
  // get no light at all (the path tracer shows them black).
  EngineSetup s(make_rooms(RoomsOptions{}), 24.0f);
  const std::vector<Lightmap> maps = bake(s, 2);
  const Bounds b = s.world.bounds;
  const Group outside = group(s, maps, [&](glm::vec3 p, glm::vec3 n) {
    return (n.y > 0.9f && p.y > b.hi.y - 1e-3f) || (n.x < -0.9f && p.x < b.lo.x + 1e-3f) ||
           (n.x > 0.9f && p.x > b.hi.x - 1e-3f) || (n.z < -0.9f && p.z < b.lo.z + 1e-3f) ||
           (n.z > 0.9f && p.z > b.hi.z - 1e-3f);
  });
  const Group all = group(s, maps, [](glm::vec3, glm::vec3) { return true; });
  ASSERT_GT(outside.texels, 200u);
  EXPECT_GT(all.mean, 0.0);
  EXPECT_EQ(outside.max, 0.0) << "mean " << outside.mean << " (all texels: " << all.mean << ")";
}

TEST(Leaks, RaysThatLeaveTheSceneWithinTheRangeReadNoProbe) {
  // Cornell's short block faces the open front of the box (0.07-0.11 m away): most of its rays
  // leave the scene's bounds within the tracing range (0.17 m). They hit nothing; reading a probe
  // for them (the probes' view into the lit box) made that face 2.3x the reference (measured
  // with the lightmap bench, 24 updates).
  EngineSetup s(make_cornell_box(), 24.0f);
  const std::vector<Lightmap> maps = bake(s, 8);
  PathTracer tracer(s.world, s.rays, s.lights, PathTracerOptions{2, true, 7});
  const std::vector<Lightmap> ref = reference_lightmaps(s.world, tracer, s.gbuffers, 128);
  // Only the short block's front face has this normal, (0.29, 0, -0.96).
  auto front = [](glm::vec3, glm::vec3 n) { return n.x > 0.2f && n.z < -0.9f; };
  const Group e = group(s, maps, front), r = group(s, ref, front);
  ASSERT_GT(r.texels, 20u);
  ASSERT_GT(r.mean, 0.0);
  RecordProperty("short block front vs reference", std::to_string(e.mean / r.mean));
  // Measured 1.16 here (1.14 at the bench's density); the probes' parallax remains.
  EXPECT_NEAR(e.mean / r.mean, 1.0, 0.25) << e.mean << " / " << r.mean;
}

}  // namespace irradcast::test_leaks

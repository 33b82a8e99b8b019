#include <gtest/gtest.h>

#include <cstdio>

#include "client_pass_scenes.h"
#include "irradcast/client/client_passes.h"
#include "irradcast/client/frame_gbuffer.h"
#include "irradcast/client/ssao.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"

namespace irradcast::test_ssao {

using test::BlockOnFloor;
using test::validate_error;

namespace {

constexpr int kW = 256, kH = 192;

struct FloorStats {
  double contact_mean = 0.0, open_min = 1.0;
  int contact = 0, open = 0;
};

// Visibility of floor pixels at the block's foot (within `band` of its sides) and of open floor
// (farther than twice the SSAO radius from it).
FloorStats floor_stats(const FrameGBuffer& g, const std::vector<float>& vis, float band,
                       float open_from) {
  FloorStats s;
  for (std::size_t i = 0; i < g.size(); ++i) {
    if (!g.hit(i) || std::abs(g.position[i].y) > 1e-3f) continue;
    const float d = test::footprint_distance(g.position[i]);
    if (d > 1e-3f && d < band) {
      s.contact_mean += vis[i];
      ++s.contact;
    } else if (d > open_from && std::abs(g.position[i].x) < 4.5f &&
               std::abs(g.position[i].z) < 4.5f) {
      s.open_min = std::min<double>(s.open_min, vis[i]);
      ++s.open;
    }
  }
  if (s.contact) s.contact_mean /= s.contact;
  return s;
}

}  // namespace

TEST(Ssao, TraceFrameMatchesComposeExactly) {
  BlockOnFloor b;
  const CameraPose cam = BlockOnFloor::orbit(30.0f);
  ImageRGB ref = compose(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  FrameGBuffer g = trace_frame(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  ImageRGB img = resolve_frame(g, {});
  ASSERT_EQ(img.pixels.size(), ref.pixels.size());
  for (std::size_t i = 0; i < ref.pixels.size(); ++i) ASSERT_EQ(img.pixels[i], ref.pixels[i]);
  // And with every pass off, ClientPasses is compose().
  ClientPasses off;
  ImageRGB img2 = off.compose(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  for (std::size_t i = 0; i < ref.pixels.size(); ++i) ASSERT_EQ(img2.pixels[i], ref.pixels[i]);
}

TEST(Ssao, ProjectionInvertsCameraRays) {
  BlockOnFloor b;
  const CameraPose cam = BlockOnFloor::orbit(75.0f);
  FrameGBuffer g = trace_frame(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  int checked = 0;
  for (int y = 0; y < kH; y += 7)
    for (int x = 0; x < kW; x += 7) {
      const std::size_t i = g.index(x, y);
      if (!g.hit(i)) continue;
      const glm::vec3 s = g.projection.project(g.position[i]);
      EXPECT_NEAR(s.x, x + 0.5f, 1e-2f);
      EXPECT_NEAR(s.y, y + 0.5f, 1e-2f);
      EXPECT_NEAR(s.z, g.depth[i], 1e-3f * g.depth[i]);
      ++checked;
    }
  EXPECT_GT(checked, 500);
}

// The contact where the block stands on the floor darkens: on average by at least 20 % within
// 0.05 units of the block and 12 % within 0.15 units (the lightmap texel here is ~0.16 units,
// so the lightmap cannot hold it), while open floor farther than twice the radius keeps at
// least 99 % of its irradiance. (Measured: 0.76-0.77, 0.84-0.85 and 1.0.)
TEST(Ssao, DarkensTheContactAndLeavesOpenFloor) {
  BlockOnFloor b;
  SsaoParams p;  // radius 0.04 of the largest extent (10): 0.4 units
  const float r = p.world_radius(b.world.bounds);
  EXPECT_NEAR(r, 0.4f, 1e-4f);
  for (float deg : {20.0f, 45.0f, 200.0f}) {
    const CameraPose cam = BlockOnFloor::orbit(deg);
    FrameGBuffer g = trace_frame(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
    std::vector<float> vis;
    EXPECT_EQ(ssao(g, p, r, 0, vis), g.size());
    FloorStats s = floor_stats(g, vis, 0.15f, 2.0f * r);
    FloorStats s5 = floor_stats(g, vis, 0.05f, 2.0f * r);
    std::printf(
        "[ssao] %.0f deg: contact mean %.3f within 0.05 (%d px), %.3f within 0.15 (%d "
        "px), open floor min %.4f over %d px\n",
        deg, s5.contact_mean, s5.contact, s.contact_mean, s.contact, s.open_min, s.open);
    ASSERT_GT(s5.contact, 30);
    EXPECT_LE(s5.contact_mean, 0.80);
    ASSERT_GT(s.contact, 50);
    ASSERT_GT(s.open, 2000);
    EXPECT_LE(s.contact_mean, 0.88);
    EXPECT_GE(s.open_min, 0.99);
  }
}

// The radiance follows: SSAO multiplies albedo / pi * E only, and the image elsewhere is
// compose()'s within 1 %.
TEST(Ssao, MultipliesTheLightmapTermNotEmission) {
  BlockOnFloor b;
  const CameraPose cam = BlockOnFloor::orbit(45.0f);
  ClientPassOptions o;
  o.ssao = true;
  ClientPasses passes(o);
  ClientFrameStats st;
  ImageRGB on = passes.compose(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH, &st);
  ImageRGB off = compose(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  EXPECT_EQ(st.ssao_pixels, static_cast<std::size_t>(kW) * kH);
  const std::vector<float>& vis = passes.visibility();
  for (std::size_t i = 0; i < off.pixels.size(); ++i) {
    const glm::vec3 expected = off.pixels[i] * vis[i];
    for (int c = 0; c < 3; ++c) ASSERT_NEAR(on.pixels[i][c], expected[c], 1e-5f);
  }
  // Emission is not attenuated: an emissive block keeps its emission at the contact.
  Scene s;
  const std::uint32_t floor = test::add_material(s, glm::vec3(0.8f));
  const std::uint32_t lamp = test::add_material(s, glm::vec3(0.0f), glm::vec3(5.0f));
  test::add_quad_object(s, "floor", {-5, 0, -5}, {-5, 0, 5}, {5, 0, 5}, {5, 0, -5}, floor);
  test::add_block(s, "lamp", {-1, 0, -1}, {1, 2, 1}, lamp);
  World w = World::build(s);
  RayScene rays(w);
  AtlasOptions ao;
  ao.texels_per_scene = 64.0f;
  Atlas atlas = build_atlas(w, ao);
  std::vector<Lightmap> maps;
  for (const ObjectLightmap& ol : atlas.objects)
    maps.emplace_back(ol.width, ol.height, glm::vec3(3.0f));
  ImageRGB lit = passes.compose(w, rays, atlas, maps, cam, kW, kH);
  ImageRGB plain = compose(w, rays, atlas, maps, cam, kW, kH);
  int emissive = 0;
  for (std::size_t i = 0; i < plain.pixels.size(); ++i)
    if (plain.pixels[i].x > 4.0f) {  // the lamp's faces: albedo 0, emission 5
      ++emissive;
      ASSERT_EQ(lit.pixels[i], plain.pixels[i]);
    }
  EXPECT_GT(emissive, 500);
}

// Geometry-aware: a block floating 1.5 units above the floor (gap > radius 0.4) is a depth
// discontinuity on screen; the floor next to its silhouette stays unoccluded (>= 0.99).
TEST(Ssao, IgnoresSamplesAcrossDepthDiscontinuities) {
  BlockOnFloor b(1.5f);
  SsaoParams p;
  const float r = p.world_radius(b.world.bounds);
  const CameraPose cam = BlockOnFloor::orbit(30.0f);
  FrameGBuffer g = trace_frame(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  std::vector<float> vis;
  ssao(g, p, r, 0, vis);
  int near_silhouette = 0;
  double worst = 1.0;
  for (int y = 1; y + 1 < kH; ++y)
    for (int x = 1; x + 1 < kW; ++x) {
      const std::size_t i = g.index(x, y);
      if (!g.hit(i) || std::abs(g.position[i].y) > 1e-3f) continue;
      bool next_to_block = false;  // a neighbour pixel on the block
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const std::size_t j = g.index(x + dx, y + dy);
          if (g.hit(j) && g.position[j].y > 1.0f) next_to_block = true;
        }
      if (!next_to_block) continue;
      ++near_silhouette;
      worst = std::min<double>(worst, vis[i]);
    }
  std::printf("[ssao] floating block: %d floor px at the silhouette, min visibility %.4f\n",
              near_silhouette, worst);
  EXPECT_GT(near_silhouette, 50);
  EXPECT_GE(worst, 0.99);
}

TEST(Ssao, StrengthZeroIsNoOcclusionAndStrengthScales) {
  BlockOnFloor b;
  const CameraPose cam = BlockOnFloor::orbit(45.0f);
  FrameGBuffer g = trace_frame(b.world, *b.rays, b.atlas, b.lightmaps, cam, kW, kH);
  SsaoParams p;
  const float r = p.world_radius(b.world.bounds);
  std::vector<float> v1, v0, v2;
  ssao(g, p, r, 0, v1);
  p.strength = 0.0f;
  ssao(g, p, r, 0, v0);
  p.strength = 2.0f;
  ssao(g, p, r, 0, v2);
  for (std::size_t i = 0; i < g.size(); ++i) {
    ASSERT_EQ(v0[i], 1.0f);
    ASSERT_NEAR(v2[i], std::max(0.0f, 1.0f - 2.0f * (1.0f - v1[i])), 1e-5f);
  }
}

TEST(Ssao, RejectsBadParameters) {
  SsaoParams p;
  p.radius = 0.0f;
  EXPECT_NE(validate_error(p).find("radius 0"), std::string::npos) << validate_error(p);
  p.radius = std::nanf("");
  EXPECT_NE(validate_error(p).find("radius"), std::string::npos);
  p.radius = 1.5f;
  EXPECT_NE(validate_error(p).find("radius 1.5"), std::string::npos);
  p = {};
  p.strength = -1.0f;
  EXPECT_NE(validate_error(p).find("strength -1"), std::string::npos) << validate_error(p);
  p = {};
  p.directions = 0;
  EXPECT_NE(validate_error(p).find("directions 0"), std::string::npos);
  ClientPassOptions o;
  o.ssao = true;
  o.ssao_params.radius = -0.1f;
  EXPECT_THROW(ClientPasses{o}, Error);
}

}  // namespace irradcast::test_ssao

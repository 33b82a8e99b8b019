#include <gtest/gtest.h>

#include "irradcast/client/client_passes.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "scene_builders.h"

namespace irradcast::test_compositor {

namespace {

// One quad facing the camera, with a hand-made lightmap layout (one chart filling an 8 x 8 map).
struct QuadScene {
  QuadScene(glm::vec3 albedo, glm::vec3 emission) {
    std::uint32_t m = test::add_material(scene, albedo, emission);
    test::add_quad_object(scene, "quad", {-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}, m);
    world = World::build(scene);
    rays = std::make_unique<RayScene>(world);
    ObjectLightmap lm;
    lm.width = lm.height = 8;
    glm::vec2 c[4] = {{0.5f, 0.5f}, {7.5f, 0.5f}, {7.5f, 7.5f}, {0.5f, 7.5f}};
    lm.corner_uv = {c[0], c[1], c[2], c[0], c[2], c[3]};
    atlas.objects.push_back(lm);
    camera.eye = glm::vec3(0, 0, 3);
    camera.forward = glm::vec3(0, 0, -1);
    camera.yfov = glm::radians(60.0f);
  }
  Scene scene;
  World world;
  std::unique_ptr<RayScene> rays;
  Atlas atlas;
  CameraPose camera;
};

}  // namespace

TEST(Compositor, ConstantLightmapGivesAlbedoOverPiTimesE) {
  const glm::vec3 albedo(0.5f, 0.25f, 0.75f), e(2.0f, 3.0f, 4.0f);
  QuadScene q(albedo, glm::vec3(0.0f));
  std::vector<Lightmap> maps = {Lightmap(8, 8, e)};
  ComposeStats stats;
  ImageRGB img = compose(q.world, *q.rays, q.atlas, maps, q.camera, 64, 48, &stats);
  EXPECT_EQ(stats.rays, 64u * 48u);
  const glm::vec3 expected = albedo / 3.14159265358979f * e;
  int hits = 0, misses = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      Ray r = camera_ray(q.camera, img.width, img.height, x + 0.5f, y + 0.5f);
      Hit h = q.rays->intersect(r);
      if (h.valid()) {
        ++hits;
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(img.at(x, y)[c], expected[c]);
      } else {
        ++misses;
        EXPECT_EQ(img.at(x, y), glm::vec3(0.0f));
      }
    }
  EXPECT_GT(hits, 500);
  EXPECT_GT(misses, 100);
}

TEST(Compositor, EmissionIsAddedOnTheFrontSideOnly) {
  const glm::vec3 albedo(0.5f), le(1.0f, 2.0f, 3.0f);
  QuadScene q(albedo, le);
  std::vector<Lightmap> maps = {Lightmap(8, 8, glm::vec3(0.0f))};
  ImageRGB front = compose(q.world, *q.rays, q.atlas, maps, q.camera, 8, 8);
  EXPECT_EQ(front.at(4, 4), le);
  CameraPose back = q.camera;
  back.eye = glm::vec3(0, 0, -3);
  back.forward = glm::vec3(0, 0, 1);
  ImageRGB behind = compose(q.world, *q.rays, q.atlas, maps, back, 8, 8);
  EXPECT_EQ(behind.at(4, 4), glm::vec3(0.0f));
}

TEST(Compositor, BilinearLookupFollowsTheLightmapGradient) {
  QuadScene q(glm::vec3(1.0f), glm::vec3(0.0f));
  Lightmap map(8, 8);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) map.texels[y * 8 + x] = glm::vec3(static_cast<float>(x));
  std::vector<Lightmap> maps = {map};
  ImageRGB img = compose(q.world, *q.rays, q.atlas, maps, q.camera, 64, 64);
  // Along a row across the quad, E = x texel index grows linearly from left to right, so
  // radiance rises monotonically.
  float prev = -1.0f;
  int row = 32, rising = 0;
  for (int x = 0; x < 64; ++x) {
    float v = img.at(x, row).x;
    if (v == 0.0f) continue;
    EXPECT_GE(v, prev);
    if (v > prev) ++rising;
    prev = v;
  }
  EXPECT_GT(rising, 10);
}

TEST(Compositor, RejectsMismatchedLightmaps) {
  QuadScene q(glm::vec3(1.0f), glm::vec3(0.0f));
  std::vector<Lightmap> none;
  EXPECT_THROW(compose(q.world, *q.rays, q.atlas, none, q.camera, 8, 8), Error);
}

TEST(Compositor, MissesShowTheSkyInTheirDirection) {
  QuadScene q(glm::vec3(0.5f), glm::vec3(0.0f));
  // A map with a different value in every texel, so a wrong direction shows.
  ImageRGB map(16, 8);
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) map.at(x, y) = glm::vec3(0.1f + x, 0.2f + y, 0.5f + x * y);
  q.scene.sky.map = map;
  q.scene.sky.strength = 1.5f;
  const glm::vec3 e(1.0f);
  std::vector<Lightmap> maps = {Lightmap(8, 8, e)};
  const ImageRGB img = compose(q.world, *q.rays, q.atlas, maps, q.camera, 64, 48);
  int misses = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      Ray r = camera_ray(q.camera, img.width, img.height, x + 0.5f, y + 0.5f);
      if (q.rays->intersect(r).valid()) {
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(img.at(x, y)[c], 0.5f / 3.14159265f);
        continue;
      }
      ++misses;
      const glm::vec3 want = q.scene.sky.radiance(r.direction);
      ASSERT_GT(want.x, 0.0f);
      EXPECT_EQ(img.at(x, y), want) << x << ", " << y;
    }
  EXPECT_GT(misses, 100);
  // A constant sky: its colour times the strength on every miss.
  q.scene.sky.map = ImageRGB{};
  q.scene.sky.color = glm::vec3(0.3f, 0.6f, 0.9f);
  const ImageRGB flat = compose(q.world, *q.rays, q.atlas, maps, q.camera, 64, 48);
  EXPECT_EQ(flat.at(0, 0), glm::vec3(0.3f, 0.6f, 0.9f) * 1.5f);
}

TEST(Compositor, ClientPassesShowTheSameSkyUnoccluded) {
  // SSAO and reprojection skip misses: the sky pixels of the viewer's passes are compose()'s,
  // exactly, frame after frame (never darkened, never blended with an old frame).
  QuadScene q(glm::vec3(0.8f), glm::vec3(0.0f));
  ImageRGB map(16, 8);
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) map.at(x, y) = glm::vec3(1.0f + x, 2.0f + y, 0.25f);
  q.scene.sky.map = map;
  std::vector<Lightmap> maps = {Lightmap(8, 8, glm::vec3(3.0f))};
  const ImageRGB plain = compose(q.world, *q.rays, q.atlas, maps, q.camera, 48, 32);
  ClientPassOptions o;
  o.ssao = true;
  o.reproject = true;
  ClientPasses passes(o);
  for (int frame = 0; frame < 3; ++frame) {
    CameraPose cam = q.camera;
    cam.eye.x += 0.01f * static_cast<float>(frame);
    const ImageRGB want = compose(q.world, *q.rays, q.atlas, maps, cam, 48, 32);
    const ImageRGB got = passes.compose(q.world, *q.rays, q.atlas, maps, cam, 48, 32);
    int sky = 0;
    for (int y = 0; y < got.height; ++y)
      for (int x = 0; x < got.width; ++x)
        if (!q.rays->intersect(camera_ray(cam, 48, 32, x + 0.5f, y + 0.5f)).valid()) {
          ++sky;
          ASSERT_EQ(got.at(x, y), want.at(x, y))
              << "frame " << frame << " pixel " << x << ", " << y;
          ASSERT_GT(got.at(x, y).x, 0.0f);
        }
    EXPECT_GT(sky, 100);
  }
  EXPECT_NE(plain.at(0, 0), glm::vec3(0.0f));
}

}  // namespace irradcast::test_compositor

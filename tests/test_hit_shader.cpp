// HitShader::shade_block against HitShader::shade, bit for bit, on both of its paths (AVX-512,
// where the CPU has it, and SSE2): every hit lane of every primary packet of a frame, on a scene
// built to reach the edge cases (texture uvs far outside [0, 1] and lightmap coordinates outside
// the map, so the wrap and the clamping; two objects and an emitter, so packets on both paths) and
// on the textured Sponza.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <memory>

#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/hit_shader.h"
#include "irradcast/common/primary_hits.h"
#include "scene_builders.h"
#include "testdata.h"

namespace irradcast::test_hit_shader {
namespace {

// A value in [0, 4) from an integer hash (lightmap texels that differ texel to texel).
float hashed(std::uint32_t i) {
  i ^= i >> 16;
  i *= 0x7feb352dU;
  i ^= i >> 15;
  i *= 0x846ca68bU;
  i ^= i >> 16;
  return static_cast<float>(i & 0xffff) / 16384.0f;
}

std::vector<Lightmap> hashed_lightmaps(const Atlas& atlas) {
  std::vector<Lightmap> maps;
  std::uint32_t n = 0;
  for (const ObjectLightmap& o : atlas.objects) {
    Lightmap m(o.width, o.height);
    for (glm::vec3& t : m.texels) {
      t = glm::vec3(hashed(n), hashed(n + 1), hashed(n + 2));
      n += 3;
    }
    maps.push_back(std::move(m));
  }
  return maps;
}

// The Sponza (sample data) with hashed lightmaps.
struct HashedSponza {
  HashedSponza() {
    ::setenv("IRRADCAST_TESTDATA", test::testdata_dir().c_str(), 1);
    scene = load_scene("sponza");
    world = World::build(scene);
    rays = std::make_unique<RayScene>(world);
    atlas = build_atlas(world);
    maps = hashed_lightmaps(atlas);
  }
  Scene scene;
  World world;
  std::unique_ptr<RayScene> rays;
  Atlas atlas;
  std::vector<Lightmap> maps;
};

struct PathCounts {
  std::atomic<int> lanes{0}, sse2_differs{0}, avx512_differs{0};
};

// At least min_lanes compared, and no lane differs on either path.
void expect_same_bits(const PathCounts& n, int min_lanes) {
  EXPECT_GT(n.lanes, min_lanes);
  EXPECT_EQ(n.sse2_differs, 0);
  EXPECT_EQ(n.avx512_differs, 0);
}

bool same_bits(const BlockShade& s, int k, const HitShade& r) {
  for (int c = 0; c < 3; ++c) {
    const float d = s.diffuse[c][k], e = s.emission[c][k];
    if (std::memcmp(&d, &r.diffuse[c], sizeof d) != 0) return false;
    if (std::memcmp(&e, &r.emission[c], sizeof e) != 0) return false;
  }
  return true;
}

// Every hit lane of a width x height frame through shade_block with AVX-512 on and off, each
// against shade().
void compare_paths(const World& world, const RayScene& rays, const Atlas& atlas,
                   const std::vector<Lightmap>& maps, const CameraPose& camera, int width,
                   int height, PathCounts& n) {
  HitShader avx(world, atlas, maps), sse2(world, atlas, maps);
  sse2.set_avx512(false);
  ASSERT_FALSE(sse2.avx512());
  ASSERT_EQ(avx.avx512(), HitShader::cpu_has_avx512());
  trace_primary_blocks(rays, camera, width, height, [&](const PrimaryBlock& b) {
    BlockShade a, s;
    avx.shade_block(b, a);
    sse2.shade_block(b, s);
    for (int k = 0; k < PrimaryBlock::kLanes; ++k) {
      if (!b.active[k] || !b.hit(k)) continue;
      const HitShade r = sse2.shade(b.direction(k), b.hit_at(k));
      ++n.lanes;
      if (!same_bits(s, k, r)) ++n.sse2_differs;
      if (!same_bits(a, k, r)) ++n.avx512_differs;
    }
  });
}

TEST(HitShader, BothPathsMatchShadeAtWrappedUvsAndClampedTexels) {
  Scene scene;
  // A textured quad whose uvs run from -1234.3 to 2345.7 across and -2.3 to 2.6 up (the texture
  // repeats; 5 x 3 texels, odd so that the wrap matters), next to an emitter, both facing +z.
  Texture tex;
  tex.width = 5;
  tex.height = 3;
  for (int i = 0; i < tex.width * tex.height * 4; ++i)
    tex.rgba8.push_back(static_cast<std::uint8_t>(hashed(static_cast<std::uint32_t>(i)) * 64.0f));
  scene.textures.push_back(tex);
  const std::uint32_t textured = test::add_material(scene, glm::vec3(0.9f, 0.7f, 0.5f));
  scene.materials[textured].base_color_texture = 0;
  const std::uint32_t emitter = test::add_material(scene, glm::vec3(0.5f), glm::vec3(2, 1, 3));
  test::add_quad_object(scene, "textured", {-2, -1, 0}, {0.5f, -1, 0}, {0.5f, 1, 0}, {-2, 1, 0},
                        textured);
  scene.meshes[0].uv0 = {{-1234.3f, -2.3f}, {2345.7f, -2.3f}, {2345.7f, 2.6f}, {-1234.3f, 2.6f}};
  test::add_quad_object(scene, "emitter", {0.5f, -1, 0}, {2, -1, 0}, {2, 1, 0}, {0.5f, 1, 0},
                        emitter);
  const World world = World::build(scene);
  const RayScene rays(world);
  // Both objects' lightmap coordinates reach past their 8 x 6 maps on every side.
  Atlas atlas;
  for (int o = 0; o < 2; ++o) {
    ObjectLightmap lm;
    lm.width = 8;
    lm.height = 6;
    const glm::vec2 c[4] = {{-3.2f, -2.7f}, {11.4f, -2.7f}, {11.4f, 9.1f}, {-3.2f, 9.1f}};
    lm.corner_uv = {c[0], c[1], c[2], c[0], c[2], c[3]};
    atlas.objects.push_back(lm);
  }
  const std::vector<Lightmap> maps = hashed_lightmaps(atlas);
  CameraPose camera;
  camera.eye = glm::vec3(0, 0, 3);
  camera.forward = glm::vec3(0, 0, -1);
  camera.yfov = glm::radians(60.0f);
  PathCounts n;
  compare_paths(world, rays, atlas, maps, camera, 160, 120, n);
  expect_same_bits(n, 5000);
}

TEST(HitShader, BothPathsMatchShadeOnTheTexturedSponza) {
  IRRADCAST_NEED_TESTDATA();
  const HashedSponza sp;
  PathCounts n;
  CameraPose camera = default_camera(sp.scene, sp.world);
  compare_paths(sp.world, *sp.rays, sp.atlas, sp.maps, camera, 256, 144, n);
  // Turned towards the walls and arches (more materials per packet).
  camera.forward = glm::normalize(glm::vec3(0.3f, 0.2f, 1.0f));
  compare_paths(sp.world, *sp.rays, sp.atlas, sp.maps, camera, 256, 144, n);
  expect_same_bits(n, 60000);
}

// compose() (HitShader::shade_stream, three packets in flight per tile) against shade() per pixel,
// bit for bit, at image sizes whose tiles hold one, two, three and many packets.
TEST(HitShader, ComposeMatchesShadeAtEverySizeOfTile) {
  IRRADCAST_NEED_TESTDATA();
  const HashedSponza sp;
  const HitShader shader(sp.world, sp.atlas, sp.maps);
  const CameraPose camera = default_camera(sp.scene, sp.world);
  const int sizes[][2] = {{1, 1}, {4, 4}, {8, 4}, {12, 4}, {5, 9}, {13, 7}, {200, 120}};
  for (const auto& size : sizes) {
    const int w = size[0], h = size[1];
    const ImageRGB img = compose(sp.world, *sp.rays, sp.atlas, sp.maps, camera, w, h);
    ImageRGB ref(w, h);
    for_each_primary_ray(
        *sp.rays, camera, w, h,
        [&](int x, int y, const Ray& r, const Hit& hit) {
          const HitShade s = shader.shade(r.direction, hit);
          ref.at(x, y) = s.diffuse + s.emission;
        },
        [&](int x, int y, glm::vec3 d) { ref.at(x, y) = sp.scene.sky.radiance(d); });
    ASSERT_EQ(img.pixels.size(), ref.pixels.size());
    EXPECT_EQ(
        std::memcmp(img.pixels.data(), ref.pixels.data(), img.pixels.size() * sizeof(glm::vec3)), 0)
        << w << " x " << h;
  }
}

}  // namespace
}  // namespace irradcast::test_hit_shader

#include "irradcast/common/compositor.h"

#include <emmintrin.h>

#include <chrono>

#include "irradcast/common/error.h"
#include "irradcast/common/hit_shader.h"
#include "irradcast/common/primary_hits.h"

namespace irradcast {
namespace {

// Row j of a packet whose 4 lanes all hit, diffuse + emission, stored as 4 consecutive RGB
// pixels at `out` (the last one 12 bytes, so nothing past the 4 pixels is written).
void store_row(const BlockShade& s, int j, glm::vec3* out) {
  const int k0 = 4 * j;
  __m128 r = _mm_add_ps(_mm_load_ps(s.diffuse[0] + k0), _mm_load_ps(s.emission[0] + k0));
  __m128 g = _mm_add_ps(_mm_load_ps(s.diffuse[1] + k0), _mm_load_ps(s.emission[1] + k0));
  __m128 b = _mm_add_ps(_mm_load_ps(s.diffuse[2] + k0), _mm_load_ps(s.emission[2] + k0));
  __m128 z = _mm_setzero_ps();
  _MM_TRANSPOSE4_PS(r, g, b, z);  // now one pixel each: (r, g, b, 0)
  float* f = &out->x;
  _mm_storeu_ps(f, r);
  _mm_storeu_ps(f + 3, g);
  _mm_storeu_ps(f + 6, b);
  _mm_storel_pi(reinterpret_cast<__m64*>(f + 9), z);
  _mm_store_ss(f + 11, _mm_movehl_ps(z, z));
}

}  // namespace

ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                 const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                 int height, ComposeStats* stats, const DynamicView* dynamic) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  auto start = std::chrono::steady_clock::now();
  const HitShader shader(world, atlas, lightmaps);
  const Sky* sky = world.scene && world.scene->sky.enabled() ? &world.scene->sky : nullptr;
  ImageRGB image(width, height);
  trace_primary_tiles(rays, camera, width, height, [&](PacketStream& packets) {
    shader.shade_stream(packets, [&](const PrimaryBlock& b, const BlockShade& s) {
      for (int j = 0; j < PrimaryBlock::kHeight; ++j) {
        const int k0 = j * PrimaryBlock::kWidth;
        if (b.x0 + 4 <= width && b.active[k0] && b.hit(k0) && b.hit(k0 + 1) && b.hit(k0 + 2) &&
            b.hit(k0 + 3)) {
          store_row(s, j, &image.at(b.x0, b.y0 + j));
          continue;
        }
        for (int k = k0; k < k0 + PrimaryBlock::kWidth; ++k) {
          if (!b.active[k]) continue;
          glm::vec3& p = image.at(b.x(k), b.y(k));
          if (b.hit(k))
            p = glm::vec3(s.diffuse[0][k], s.diffuse[1][k], s.diffuse[2][k]) +
                glm::vec3(s.emission[0][k], s.emission[1][k], s.emission[2][k]);
          else if (sky)
            p = sky->radiance(b.direction(k));
        }
      }
    });
  });
  if (dynamic && dynamic->rays)
    trace_dynamic(world, rays, *dynamic, camera, width, height, [&](const DynamicPixel& d) {
      image.pixels[d.index] = d.shade.diffuse + d.shade.emission;
    });
  if (stats) {
    stats->rays = static_cast<std::uint64_t>(width) * height;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return image;
}

}  // namespace irradcast

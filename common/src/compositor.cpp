#include "irradcast/compositor.h"

#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>

#include "irradcast/camera.h"
#include "irradcast/error.h"
#include "irradcast/sampling.h"

namespace irradcast {

ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                 const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                 int height, ComposeStats* stats) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  if (atlas.objects.size() != world.objects.size() || lightmaps.size() != world.objects.size())
    throw Error("compositor: lightmaps do not match the scene's objects");
  auto start = std::chrono::steady_clock::now();
  ImageRGB image(width, height);
  // Packets cover 4 x 2 pixel blocks; tiles of 16 x 8 pixels are the unit of parallel work.
  constexpr int kBw = 4, kBh = 2;
  tbb::parallel_for(
      tbb::blocked_range2d<int>(0, (height + kBh - 1) / kBh, 4, 0, (width + kBw - 1) / kBw, 4),
      [&](const tbb::blocked_range2d<int>& r) {
        Ray packet[8];
        Hit hits[8];
        int px[8], py[8];
        for (int by = r.rows().begin(); by < r.rows().end(); ++by) {
          for (int bx = r.cols().begin(); bx < r.cols().end(); ++bx) {
            int n = 0;
            for (int j = 0; j < kBh; ++j)
              for (int i = 0; i < kBw; ++i) {
                int x = bx * kBw + i, y = by * kBh + j;
                if (x >= width || y >= height) continue;
                px[n] = x;
                py[n] = y;
                packet[n++] = camera_ray(camera, width, height, static_cast<float>(x) + 0.5f,
                                         static_cast<float>(y) + 0.5f);
              }
            rays.intersect8(packet, n, hits);
            for (int k = 0; k < n; ++k) {
              const Hit& h = hits[k];
              if (!h.valid()) continue;
              glm::vec2 uv = atlas.objects[h.object].uv(h.triangle, h.u, h.v);
              glm::vec3 e = lightmaps[h.object].bilinear(uv);
              glm::vec3 albedo = world.albedo(h.object, h.triangle, h.u, h.v);
              glm::vec3 le(0.0f);
              const Material& m = world.material(h.object, h.triangle);
              if (m.is_emissive()) {
                // Emission is one-sided unless the material is double-sided.
                glm::vec3 ng = world.objects[h.object].geometric_normal(h.triangle);
                if (m.double_sided || glm::dot(ng, packet[k].direction) < 0.0f)
                  le = world.emission(h.object, h.triangle, h.u, h.v);
              }
              image.at(px[k], py[k]) = albedo * kInvPi * e + le;
            }
          }
        }
      });
  if (stats) {
    stats->rays = static_cast<std::uint64_t>(width) * height;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return image;
}

}  // namespace irradcast

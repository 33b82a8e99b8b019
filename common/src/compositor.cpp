#include "irradcast/common/compositor.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>

#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "irradcast/common/primary_hits.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

HitShade shade_hit(const World& world, const Atlas& atlas, const std::vector<Lightmap>& lightmaps,
                   const Ray& ray, const Hit& h) {
  HitShade s;
  const glm::vec2 uv = atlas.objects[h.object].uv(h.triangle, h.u, h.v);
  const glm::vec3 e = lightmaps[h.object].bilinear(uv);
  const glm::vec3 albedo = world.albedo(h.object, h.triangle, h.u, h.v);
  const Material& m = world.material(h.object, h.triangle);
  if (m.is_emissive()) {
    const glm::vec3 ng = world.objects[h.object].geometric_normal(h.triangle);
    if (m.double_sided || glm::dot(ng, ray.direction) < 0.0f)
      s.emission = world.emission(h.object, h.triangle, h.u, h.v);
  }
  s.diffuse = albedo * kInvPi * e;
  return s;
}

ImageRGB sky_background(const Sky& sky, const CameraPose& camera, int width, int height) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  ImageRGB image(width, height);
  if (!sky.enabled()) return image;
  tbb::parallel_for(tbb::blocked_range<int>(0, height, 8), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y)
      for (int x = 0; x < width; ++x)
        image.at(x, y) =
            sky.radiance(camera_ray(camera, width, height, static_cast<float>(x) + 0.5f,
                                    static_cast<float>(y) + 0.5f)
                             .direction);
  });
  return image;
}

ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                 const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                 int height, ComposeStats* stats) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  if (atlas.objects.size() != world.objects.size() || lightmaps.size() != world.objects.size())
    throw Error("compositor: lightmaps do not match the scene's objects");
  auto start = std::chrono::steady_clock::now();
  ImageRGB image = world.scene ? sky_background(world.scene->sky, camera, width, height)
                               : ImageRGB(width, height);
  for_each_primary_hit(rays, camera, width, height,
                       [&](int x, int y, const Ray& ray, const Hit& h) {
                         const HitShade s = shade_hit(world, atlas, lightmaps, ray, h);
                         image.at(x, y) = s.diffuse + s.emission;
                       });
  if (stats) {
    stats->rays = static_cast<std::uint64_t>(width) * height;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return image;
}

}  // namespace irradcast

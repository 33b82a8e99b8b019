#include "irradcast/common/compositor.h"

#include <chrono>

#include "irradcast/common/error.h"
#include "irradcast/common/hit_shader.h"
#include "irradcast/common/primary_hits.h"

namespace irradcast {

ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                 const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                 int height, ComposeStats* stats) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  auto start = std::chrono::steady_clock::now();
  const HitShader shader(world, atlas, lightmaps);
  const Sky* sky = world.scene && world.scene->sky.enabled() ? &world.scene->sky : nullptr;
  ImageRGB image(width, height);
  for_each_primary_ray(
      rays, camera, width, height,
      [&](int x, int y, const Ray& ray, const Hit& h) {
        const HitShade s = shader.shade(ray.direction, h);
        image.at(x, y) = s.diffuse + s.emission;
      },
      [&](int x, int y, glm::vec3 direction) {
        if (sky) image.at(x, y) = sky->radiance(direction);
      });
  if (stats) {
    stats->rays = static_cast<std::uint64_t>(width) * height;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return image;
}

}  // namespace irradcast

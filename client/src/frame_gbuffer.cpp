#include "irradcast/client/frame_gbuffer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>

#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/hit_shader.h"
#include "irradcast/common/primary_hits.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

ScreenProjection::ScreenProjection(const CameraPose& pose, int width, int height) {
  // The same frame as camera_ray().
  eye_ = pose.eye;
  forward_ = pose.forward;
  right_ = glm::normalize(glm::cross(pose.forward, pose.up));
  up_ = glm::cross(right_, pose.forward);
  half_w_ = 0.5f * static_cast<float>(width);
  half_h_ = 0.5f * static_cast<float>(height);
  aspect_ = static_cast<float>(width) / static_cast<float>(height);
  th_ = std::tan(0.5f * pose.yfov);
  focal_px_ = half_h_ / th_;
}

glm::vec3 ScreenProjection::project(glm::vec3 p) const {
  const glm::vec3 d = p - eye_;
  const float z = glm::dot(d, forward_);
  if (!(z > 0.0f)) return {0.0f, 0.0f, z};
  const float sx = glm::dot(d, right_) / z, sy = glm::dot(d, up_) / z;
  return {(sx / (th_ * aspect_) + 1.0f) * half_w_, (1.0f - sy / th_) * half_h_, z};
}

FrameGBuffer trace_frame(const World& world, const RayScene& rays, const Atlas& atlas,
                         const std::vector<Lightmap>& lightmaps, const CameraPose& camera,
                         int width, int height, const DynamicView* dynamic) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  const HitShader shader(world, atlas, lightmaps);
  FrameGBuffer g;
  g.width = width;
  g.height = height;
  g.camera = camera;
  g.projection = ScreenProjection(camera, width, height);
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  g.position.assign(n, glm::vec3(0.0f));
  g.normal.assign(n, glm::vec3(0.0f));
  g.depth.assign(n, 0.0f);
  g.diffuse.assign(n, glm::vec3(0.0f));
  g.emission.assign(n, glm::vec3(0.0f));
  const Sky* sky = world.scene && world.scene->sky.enabled() ? &world.scene->sky : nullptr;
  // The pixels and the shading of compose(). Misses keep the sky's radiance in `emission`
  // (black without a sky): not diffuse, so SSAO never darkens it, and no depth, so SSAO and
  // reprojection skip it as they skip any miss.
  for_each_primary_ray(
      rays, camera, width, height,
      [&](int x, int y, const Ray& ray, const Hit& h) {
        const std::size_t idx = g.index(x, y);
        const glm::vec3 p = ray.origin + h.t * ray.direction;
        glm::vec3 ns = world.objects[h.object].shading_normal(h.triangle, h.u, h.v);
        if (glm::dot(ns, ray.direction) > 0.0f) ns = -ns;
        g.position[idx] = p;
        g.normal[idx] = ns;
        g.depth[idx] = std::max(glm::dot(p - camera.eye, camera.forward), 1e-30f);
        const HitShade s = shader.shade(ray.direction, h);
        g.diffuse[idx] = s.diffuse;
        g.emission[idx] = s.emission;
      },
      [&](int x, int y, glm::vec3 direction) {
        if (sky) g.emission[g.index(x, y)] = sky->radiance(direction);
      });
  if (dynamic && dynamic->rays)
    trace_dynamic(world, rays, *dynamic, camera, width, height, [&](const DynamicPixel& d) {
      g.position[d.index] = d.position;
      g.normal[d.index] = d.normal;
      g.depth[d.index] = d.depth;
      g.diffuse[d.index] = d.shade.diffuse;
      g.emission[d.index] = d.shade.emission;
    });
  return g;
}

ImageRGB resolve_frame(const FrameGBuffer& g, const std::vector<float>& visibility) {
  if (!visibility.empty() && visibility.size() != g.size())
    throw Error("resolve_frame: " + std::to_string(visibility.size()) + " visibility values for " +
                std::to_string(g.size()) + " pixels");
  ImageRGB image(g.width, g.height);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, g.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        if (!g.hit(i)) {
                          image.pixels[i] = g.emission[i];  // the sky
                          continue;
                        }
                        const float v = visibility.empty() ? 1.0f : visibility[i];
                        image.pixels[i] = g.diffuse[i] * v + g.emission[i];
                      }
                    });
  return image;
}

}  // namespace irradcast

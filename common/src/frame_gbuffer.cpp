#include "irradcast/frame_gbuffer.h"

#include <tbb/blocked_range.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <cmath>

#include "irradcast/camera.h"
#include "irradcast/error.h"
#include "irradcast/sampling.h"

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
                         int width, int height) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  if (atlas.objects.size() != world.objects.size() || lightmaps.size() != world.objects.size())
    throw Error("compositor: lightmaps do not match the scene's objects");
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
  // The packet layout and the shading of compose(): 4 x 2 pixel packets, 16 x 8 pixel tiles.
  constexpr int kBw = 4, kBh = 2;
  tbb::parallel_for(
      tbb::blocked_range2d<int>(0, (height + kBh - 1) / kBh, 4, 0, (width + kBw - 1) / kBw, 4),
      [&](const tbb::blocked_range2d<int>& r) {
        Ray packet[8];
        Hit hits[8];
        int px[8], py[8];
        for (int by = r.rows().begin(); by < r.rows().end(); ++by) {
          for (int bx = r.cols().begin(); bx < r.cols().end(); ++bx) {
            int cnt = 0;
            for (int j = 0; j < kBh; ++j)
              for (int i = 0; i < kBw; ++i) {
                int x = bx * kBw + i, y = by * kBh + j;
                if (x >= width || y >= height) continue;
                px[cnt] = x;
                py[cnt] = y;
                packet[cnt++] = camera_ray(camera, width, height, static_cast<float>(x) + 0.5f,
                                           static_cast<float>(y) + 0.5f);
              }
            rays.intersect8(packet, cnt, hits);
            for (int k = 0; k < cnt; ++k) {
              const Hit& h = hits[k];
              if (!h.valid()) continue;
              const std::size_t idx = g.index(px[k], py[k]);
              const WorldObject& obj = world.objects[h.object];
              const glm::vec3 p = packet[k].origin + h.t * packet[k].direction;
              glm::vec3 ns = obj.shading_normal(h.triangle, h.u, h.v);
              if (glm::dot(ns, packet[k].direction) > 0.0f) ns = -ns;
              g.position[idx] = p;
              g.normal[idx] = ns;
              g.depth[idx] = std::max(glm::dot(p - camera.eye, camera.forward), 1e-30f);
              glm::vec2 uv = atlas.objects[h.object].uv(h.triangle, h.u, h.v);
              glm::vec3 e = lightmaps[h.object].bilinear(uv);
              glm::vec3 albedo = world.albedo(h.object, h.triangle, h.u, h.v);
              const Material& m = world.material(h.object, h.triangle);
              if (m.is_emissive()) {
                glm::vec3 ng = obj.geometric_normal(h.triangle);
                if (m.double_sided || glm::dot(ng, packet[k].direction) < 0.0f)
                  g.emission[idx] = world.emission(h.object, h.triangle, h.u, h.v);
              }
              g.diffuse[idx] = albedo * kInvPi * e;
            }
          }
        }
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
                        if (!g.hit(i)) continue;
                        const float v = visibility.empty() ? 1.0f : visibility[i];
                        image.pixels[i] = g.diffuse[i] * v + g.emission[i];
                      }
                    });
  return image;
}

}  // namespace irradcast

// A pinhole camera's primary rays, one through each pixel centre (camera_ray()'s rays, bit for
// bit, from PinholeRays), traced in coherent 4 x 4 pixel Embree packets (rtcIntersect16 on
// RayScene::embree_scene()) over tiles of packets in parallel. Used by compose() and by the client
// passes' frame G-buffer, so both see exactly the same pixels; the shading they share is HitShader
// (hit_shader.h).
#pragma once

#include <functional>

#include <glm/glm.hpp>

#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// One packet: up to 16 pixels (lanes with active false lie outside the image), their rays from
// `origin` and their hits.
struct PrimaryBlock {
  static constexpr int kWidth = 4, kHeight = 4, kLanes = kWidth * kHeight;
  glm::vec3 origin{0.0f};
  int x[kLanes], y[kLanes];
  bool active[kLanes];
  glm::vec3 direction[kLanes];
  Hit hits[kLanes];
};

// block(b) for every packet of the image; concurrently for different packets.
void trace_primary_blocks(const RayScene& rays, const CameraPose& camera, int width, int height,
                          const std::function<void(const PrimaryBlock&)>& block);

// hit(x, y, ray, hit) for every pixel whose primary ray hits and miss(x, y, direction) for every
// other; concurrently for different pixels.
template <typename HitBody, typename MissBody>
void for_each_primary_ray(const RayScene& rays, const CameraPose& camera, int width, int height,
                          HitBody&& hit, MissBody&& miss) {
  trace_primary_blocks(rays, camera, width, height, [&](const PrimaryBlock& b) {
    for (int k = 0; k < PrimaryBlock::kLanes; ++k) {
      if (!b.active[k]) continue;
      if (b.hits[k].valid()) {
        Ray ray;
        ray.origin = b.origin;
        ray.direction = b.direction[k];
        hit(b.x[k], b.y[k], ray, b.hits[k]);
      } else {
        miss(b.x[k], b.y[k], b.direction[k]);
      }
    }
  });
}

}  // namespace irradcast

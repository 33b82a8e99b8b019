// A pinhole camera's primary rays, one through each pixel centre (camera_ray()'s rays, bit for
// bit, from PinholeRays, set up 4 lanes at a time with SSE), traced in coherent 4 x 4 pixel Embree
// packets (rtcIntersect16 on RayScene::embree_scene()) over tiles of packets in parallel; each
// packet's rays and hits are kept in SoA (PrimaryBlock), as Embree returns them. A tile's packets
// come one at a time from a PacketStream (trace_primary_tiles), so a consumer can keep several in
// flight (HitShader::shade_stream), or one block at a time (trace_primary_blocks). Used by compose()
// and by the client passes' frame G-buffer, so both see exactly the same pixels; the shading they
// share is HitShader (hit_shader.h).
#pragma once

#include <cstdint>
#include <functional>

#include <glm/glm.hpp>

#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// One packet: 4 x 4 pixels, lane k at (x0 + k % 4, y0 + k / 4); lanes outside the image are
// inactive. Rays from `origin` along the unit dir_*; a lane that hits has object >= 0.
struct PrimaryBlock {
  static constexpr int kWidth = 4, kHeight = 4, kLanes = kWidth * kHeight;
  glm::vec3 origin{0.0f};
  int x0 = 0, y0 = 0;
  // -1 inside the image, 0 outside; Embree's valid mask (aligned as rtcIntersect16 needs).
  alignas(64) std::int32_t active[kLanes];
  alignas(16) float dir_x[kLanes], dir_y[kLanes], dir_z[kLanes];
  alignas(16) std::int32_t object[kLanes];  // -1: a miss (or an inactive lane)
  alignas(16) std::uint32_t triangle[kLanes];
  alignas(16) float u[kLanes], v[kLanes], t[kLanes];

  int x(int k) const { return x0 + k % kWidth; }
  int y(int k) const { return y0 + k / kWidth; }
  glm::vec3 direction(int k) const { return {dir_x[k], dir_y[k], dir_z[k]}; }
  bool hit(int k) const { return object[k] >= 0; }
  Hit hit_at(int k) const {
    Hit h;
    h.object = object[k];
    h.triangle = triangle[k];
    h.u = u[k];
    h.v = v[k];
    h.t = t[k];
    return h;
  }
};

// The packets of one tile of the image, in order; next(b) traces the next one into b (false at
// the end). A consumer that holds two blocks can start one packet's memory loads before it traces
// the next (HitShader::shade_stream).
class PacketStream {
 public:
  virtual bool next(PrimaryBlock& b) = 0;

 protected:
  ~PacketStream() = default;
};

// tile(packets) for every tile of packets of the image; concurrently for different tiles.
void trace_primary_tiles(const RayScene& rays, const CameraPose& camera, int width, int height,
                         const std::function<void(PacketStream&)>& tile);

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
      if (b.hit(k)) {
        Ray ray;
        ray.origin = b.origin;
        ray.direction = b.direction(k);
        hit(b.x(k), b.y(k), ray, b.hit_at(k));
      } else {
        miss(b.x(k), b.y(k), b.direction(k));
      }
    }
  });
}

}  // namespace irradcast

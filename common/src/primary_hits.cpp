#include "irradcast/common/primary_hits.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <vector>

#include "irradcast/common/pinhole.h"

namespace irradcast {
namespace {

// The block's 16 rays from its origin through RayScene's Embree scene, one coherent packet;
// inactive lanes get a miss.
void intersect_block(RTCScene scene, PrimaryBlock& b) {
  alignas(64) int valid[16];
  alignas(64) RTCRayHit16 rh;
  const float tmax = Ray{}.tmax;
  for (int i = 0; i < 16; ++i) {
    valid[i] = b.active[i] ? -1 : 0;
    rh.ray.org_x[i] = b.origin.x;
    rh.ray.org_y[i] = b.origin.y;
    rh.ray.org_z[i] = b.origin.z;
    rh.ray.dir_x[i] = b.direction[i].x;
    rh.ray.dir_y[i] = b.direction[i].y;
    rh.ray.dir_z[i] = b.direction[i].z;
    rh.ray.tnear[i] = 0.0f;
    rh.ray.tfar[i] = tmax;
    rh.ray.time[i] = 0.0f;
    rh.ray.mask[i] = 0xFFFFFFFFu;
    rh.ray.id[i] = static_cast<unsigned>(i);
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect16(valid, scene, &ctx, &rh);
  for (int i = 0; i < 16; ++i) {
    Hit& h = b.hits[i];
    h = Hit{};
    if (!b.active[i] || rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) continue;
    h.object = static_cast<int>(rh.hit.geomID[i]);
    h.triangle = rh.hit.primID[i];
    h.u = rh.hit.u[i];
    h.v = rh.hit.v[i];
    h.t = rh.ray.tfar[i];
  }
}

}  // namespace

void trace_primary_blocks(const RayScene& rays, const CameraPose& camera, int width, int height,
                          const std::function<void(const PrimaryBlock&)>& block) {
  constexpr int kBw = PrimaryBlock::kWidth, kBh = PrimaryBlock::kHeight;
  const PinholeRays pin(camera, width, height);
  // The image-plane offsets per column and per row (camera_ray's expressions, once each).
  std::vector<float> sx(static_cast<std::size_t>(width)), sy(static_cast<std::size_t>(height));
  for (int x = 0; x < width; ++x) sx[static_cast<std::size_t>(x)] = pin.sx(x + 0.5f);
  for (int y = 0; y < height; ++y) sy[static_cast<std::size_t>(y)] = pin.sy(y + 0.5f);
  tbb::parallel_for(
      tbb::blocked_range2d<int>(0, (height + kBh - 1) / kBh, 2, 0, (width + kBw - 1) / kBw, 4),
      [&](const tbb::blocked_range2d<int>& r) {
        PrimaryBlock b;
        b.origin = pin.eye;
        for (int by = r.rows().begin(); by < r.rows().end(); ++by)
          for (int bx = r.cols().begin(); bx < r.cols().end(); ++bx) {
            for (int j = 0; j < kBh; ++j)
              for (int i = 0; i < kBw; ++i) {
                const int k = j * kBw + i, x = bx * kBw + i, y = by * kBh + j;
                b.x[k] = x;
                b.y[k] = y;
                b.active[k] = x < width && y < height;
                b.direction[k] = b.active[k] ? pin.direction(sx[static_cast<std::size_t>(x)],
                                                             sy[static_cast<std::size_t>(y)])
                                             : pin.forward;
              }
            intersect_block(rays.embree_scene(), b);
            block(b);
          }
      });
}

}  // namespace irradcast

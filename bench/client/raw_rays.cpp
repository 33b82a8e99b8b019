#include "raw_rays.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <atomic>

#include "irradcast/common/pinhole.h"

namespace irradcast::bench {
namespace {

constexpr int kBw = 4, kBh = 4;

// One 4 x 4 packet at block (bx, by); returns its hits.
int trace_block(RTCScene scene, const PinholeRays& pin, int width, int height, int bx, int by) {
  alignas(64) int valid[16];
  alignas(64) RTCRayHit16 rh;
  for (int j = 0; j < kBh; ++j)
    for (int i = 0; i < kBw; ++i) {
      const int k = j * kBw + i, x = bx * kBw + i, y = by * kBh + j;
      valid[k] = x < width && y < height ? -1 : 0;
      const glm::vec3 d =
          pin.direction(pin.sx(static_cast<float>(x) + 0.5f), pin.sy(static_cast<float>(y) + 0.5f));
      rh.ray.org_x[k] = pin.eye.x;
      rh.ray.org_y[k] = pin.eye.y;
      rh.ray.org_z[k] = pin.eye.z;
      rh.ray.dir_x[k] = d.x;
      rh.ray.dir_y[k] = d.y;
      rh.ray.dir_z[k] = d.z;
      rh.ray.tnear[k] = 0.0f;
      rh.ray.tfar[k] = 3.4e38f;
      rh.ray.time[k] = 0.0f;
      rh.ray.mask[k] = 0xFFFFFFFFu;
      rh.ray.id[k] = static_cast<unsigned>(k);
      rh.ray.flags[k] = 0;
      rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
    }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect16(valid, scene, &ctx, &rh);
  int hits = 0;
  for (int k = 0; k < 16; ++k) hits += valid[k] && rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
  return hits;
}

}  // namespace

std::uint64_t trace_raw_primary(RTCSceneTy* scene, const CameraPose& camera, int width,
                                int height) {
  const PinholeRays pin(camera, width, height);
  std::atomic<std::uint64_t> hits{0};
  tbb::parallel_for(
      tbb::blocked_range2d<int>(0, (height + kBh - 1) / kBh, 2, 0, (width + kBw - 1) / kBw, 4),
      [&](const tbb::blocked_range2d<int>& r) {
        std::uint64_t local = 0;
        for (int by = r.rows().begin(); by < r.rows().end(); ++by)
          for (int bx = r.cols().begin(); bx < r.cols().end(); ++bx)
            local += static_cast<std::uint64_t>(trace_block(scene, pin, width, height, bx, by));
        hits += local;
      });
  return hits.load();
}

}  // namespace irradcast::bench

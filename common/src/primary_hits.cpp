#include "irradcast/common/primary_hits.h"

#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <vector>

#include "irradcast/common/pinhole.h"

namespace irradcast {

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
            rays.intersect16(b.origin, b.direction, b.active, b.hits);
            block(b);
          }
      });
}

}  // namespace irradcast

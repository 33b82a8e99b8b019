// A pinhole camera's primary rays, one through each pixel centre, traced in 4 x 2 pixel Embree
// packets over 16 x 8 pixel tiles in parallel, and the shading every client frame shares. Used
// by compose() and by the client passes' frame G-buffer, so both see exactly the same pixels.
#pragma once

#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// body(x, y, ray, hit) for every pixel whose primary ray hits; concurrently for different
// pixels.
template <typename Body>
void for_each_primary_hit(const RayScene& rays, const CameraPose& camera, int width, int height,
                          Body&& body) {
  constexpr int kBw = 4, kBh = 2;
  tbb::parallel_for(
      tbb::blocked_range2d<int>(0, (height + kBh - 1) / kBh, 4, 0, (width + kBw - 1) / kBw, 4),
      [&](const tbb::blocked_range2d<int>& r) {
        Ray packet[8];
        Hit hits[8];
        int px[8], py[8];
        for (int by = r.rows().begin(); by < r.rows().end(); ++by)
          for (int bx = r.cols().begin(); bx < r.cols().end(); ++bx) {
            int n = 0;
            for (int j = 0; j < kBh; ++j)
              for (int i = 0; i < kBw; ++i) {
                const int x = bx * kBw + i, y = by * kBh + j;
                if (x >= width || y >= height) continue;
                px[n] = x;
                py[n] = y;
                packet[n++] = camera_ray(camera, width, height, static_cast<float>(x) + 0.5f,
                                         static_cast<float>(y) + 0.5f);
              }
            rays.intersect8(packet, n, hits);
            for (int k = 0; k < n; ++k)
              if (hits[k].valid()) body(px[k], py[k], packet[k], hits[k]);
          }
      });
}

// What a viewer sees at a hit: the lightmap term albedo / pi * E (E read bilinearly) and the
// emission (one-sided unless the material is double-sided).
struct HitShade {
  glm::vec3 diffuse{0.0f};
  glm::vec3 emission{0.0f};
};
HitShade shade_hit(const World& world, const Atlas& atlas, const std::vector<Lightmap>& lightmaps,
                   const Ray& ray, const Hit& h);

}  // namespace irradcast

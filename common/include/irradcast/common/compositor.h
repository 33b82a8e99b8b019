// The compositor: a viewer's own frame from the shared irradiance. One primary ray per pixel
// (Embree 8-wide packets), at the hit a bilinear lightmap lookup gives E, and the outgoing
// radiance is albedo / pi * E + emission; a ray that misses shows the sky (Scene::sky, black
// without one). Used by irradcast-bake and by every client.
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sky.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct ComposeStats {
  std::uint64_t rays = 0;
  double seconds = 0.0;
};

// The background of a frame: per pixel the sky's radiance in the direction of its primary ray
// (the rays of compose(): pixel centres). All black when the sky is not enabled.
ImageRGB sky_background(const Sky& sky, const CameraPose& camera, int width, int height);

// Linear radiance, no exposure, no tone map. `lightmaps` and `atlas.objects` are indexed like
// world.objects. Misses show world.scene's sky (sky_background).
ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                 const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                 int height, ComposeStats* stats = nullptr);

}  // namespace irradcast

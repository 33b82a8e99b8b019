// The compositor: a viewer's own frame from the shared irradiance. One primary ray per pixel
// (coherent 16-wide Embree packets, primary_hits.h), at the hit a bilinear lightmap lookup gives
// E, and the outgoing radiance is albedo / pi * E + emission (hit_shader.h); a ray that misses
// shows the sky (Scene::sky, black without one) in its direction. Used by irradcast-bake and by
// every client.
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/dynamic_view.h"
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

// Linear radiance, no exposure, no tone map. `lightmaps` and `atlas.objects` are indexed like
// world.objects. Misses show world.scene's sky. With `dynamic`, the dynamic objects are drawn
// over the static scene where they are nearer (dynamic_view.h); without, the image is the static
// scene's alone.
ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                 const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                 int height, ComposeStats* stats = nullptr, const DynamicView* dynamic = nullptr);

}  // namespace irradcast

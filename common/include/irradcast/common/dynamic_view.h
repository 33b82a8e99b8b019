// Dynamic objects in a viewer's frame (docs/DYNAMIC.md "Drawing them"): they are not in the
// static scene the lightmaps cover, so a viewer traces them in their own ray scene
// (RaySceneContent::Dynamic, moved by refitting one object's BVH) and keeps a hit where no static
// surface is nearer. A hit is shaded like a static one, albedo / pi x E + emission, with E read
// from the irradiance volume the server streams (irradiance_volume.h) at the hit's position and
// normal instead of from a lightmap, plus the direct light of the scene's punctual lights (sun,
// lamps), which the viewer traces itself: one shadow ray per light against the static scene,
// since a probe grid cannot follow their sharp shadow edges. Used by compose() and by the client
// passes' G-buffer.
#pragma once

#include <cstddef>
#include <functional>

#include <glm/glm.hpp>

#include "irradcast/common/hit_shader.h"
#include "irradcast/common/irradiance_volume.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// What a frame needs to draw the dynamic objects.
struct DynamicView {
  const RayScene* rays = nullptr;            // the world's RaySceneContent::Dynamic scene
  const IrradianceVolume* volume = nullptr;  // null: not received yet (only emission shows)
};

// A pixel where a dynamic object is the nearest primary hit.
struct DynamicPixel {
  std::size_t index = 0;     // y * width + x
  glm::vec3 position{0.0f};  // world space
  glm::vec3 normal{0.0f};    // unit shading normal, turned towards the eye
  float depth = 0.0f;        // along the view axis
  HitShade shade;
};

// The shade of a dynamic object at hit h of a ray along `direction`, whose point is p and whose
// shading normal is n (on the side of the ray's origin, as the path tracer turns it): albedo
// (textures included) / pi x the volume's E(p, n), and the emission (one-sided unless the material
// is double-sided).
HitShade shade_dynamic(const World& world, const IrradianceVolume* volume, glm::vec3 direction,
                       const Hit& h, glm::vec3 p, glm::vec3 n);

// out(pixel) for every pixel of a camera_ray() image (one ray through each pixel centre, as
// compose()) whose ray hits a dynamic object before any surface of `static_rays`; called
// concurrently for different pixels, in no particular order. Nothing when view.rays is null.
// Throws irradcast::Error on a bad image size.
void trace_dynamic(const World& world, const RayScene& static_rays, const DynamicView& view,
                   const CameraPose& camera, int width, int height,
                   const std::function<void(const DynamicPixel&)>& out);

}  // namespace irradcast

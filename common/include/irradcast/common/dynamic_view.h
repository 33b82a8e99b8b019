// Dynamic objects in a viewer's frame (docs/DYNAMIC.md "Drawing them"): they are not in the
// static scene the lightmaps cover, so a viewer traces them in their own ray scene
// (RaySceneContent::Dynamic, moved by refitting one object's BVH) and keeps a hit where no static
// surface is nearer. A hit is shaded like a static one, albedo / pi x E + emission, with E read
// from the irradiance volume the server streams (irradiance_volume.h) at the hit's position and
// normal instead of from a lightmap, plus the direct light that a probe grid cannot follow, which
// the viewer traces itself against the static scene: the punctual lights' (sun, lamps: one shadow
// ray per light, their shadow edges are sharp) and, given the scene's LightSampler, the emissive
// surfaces' (kEmitterSamples shadow rays per pixel, in place of the volume's `emitted`
// coefficients: near an area light its light changes within a fraction of a probe spacing; a
// sphere by the Cornell box's light read 2.3x bright on top, one by its red wall 7 % dark over
// all). Used by compose() and by the client passes' G-buffer.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>

#include <glm/glm.hpp>

#include "irradcast/common/hit_shader.h"
#include "irradcast/common/irradiance_volume.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// What a frame needs to draw the dynamic objects.
struct DynamicView {
  static constexpr int kEmitterSamples = 8;  // shadow rays per pixel to the emissive surfaces
  const RayScene* rays = nullptr;            // the world's RaySceneContent::Dynamic scene
  const IrradianceVolume* volume = nullptr;  // null: not received yet (only emission shows)
  // The static scene's emitters (LightSampler(world)): their direct light traced per pixel. Null:
  // read from the volume (as the browser page does, which cannot trace the static scene).
  const LightSampler* lights = nullptr;
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
// (textures included) / pi x E, and the emission (one-sided unless the material is
// double-sided). E: the volume's at (p, n) (without its emitters' part where view.lights is
// set), the punctual lights' direct light, and with view.lights the emitters' direct light from
// kEmitterSamples stratified samples, drawn from `seed` (a pixel keeps its pattern from frame to
// frame: a still object does not flicker).
HitShade shade_dynamic(const World& world, const RayScene& static_rays, const DynamicView& view,
                       glm::vec3 direction, const Hit& h, glm::vec3 p, glm::vec3 n,
                       std::uint64_t seed);

// out(pixel) for every pixel of a camera_ray() image (one ray through each pixel centre, as
// compose()) whose ray hits a dynamic object before any surface of `static_rays`; called
// concurrently for different pixels, in no particular order. Nothing when view.rays is null.
// Throws irradcast::Error on a bad image size.
void trace_dynamic(const World& world, const RayScene& static_rays, const DynamicView& view,
                   const CameraPose& camera, int width, int height,
                   const std::function<void(const DynamicPixel&)>& out);

}  // namespace irradcast

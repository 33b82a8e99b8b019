// The screen-space G-buffer of one client frame (seed 002's deferred camera G-buffer): per pixel
// the world position, normal and view depth of the primary hit, with the shading that
// compose() would give it split into the lightmap term albedo / pi * E and the emission. The
// client passes (ssao.h, reprojection.h) read it; radiance = diffuse * visibility + emission.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/common/dynamic_view.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// Maps world points to the pixels of a camera_ray() image (the inverse of camera_ray).
class ScreenProjection {
 public:
  ScreenProjection() = default;
  ScreenProjection(const CameraPose& pose, int width, int height);
  // (px, py, z): image-plane position in pixels (pixel centres at +0.5) and the depth along the
  // view axis; z <= 0 for points behind the eye (px, py are then meaningless).
  glm::vec3 project(glm::vec3 p) const;
  // Pixels per world unit at view depth z (focal length in pixels / z).
  float pixels_per_unit(float z) const { return focal_px_ / z; }
  glm::vec3 eye() const { return eye_; }
  glm::vec3 forward() const { return forward_; }

 private:
  glm::vec3 eye_{0.0f}, forward_{0.0f, 0.0f, -1.0f}, right_{1.0f, 0.0f, 0.0f}, up_{0, 1, 0};
  float half_w_ = 1.0f, half_h_ = 1.0f;  // image half size in pixels
  float th_ = 1.0f, aspect_ = 1.0f, focal_px_ = 1.0f;
};

struct FrameGBuffer {
  int width = 0;
  int height = 0;
  CameraPose camera;
  ScreenProjection projection;
  std::vector<glm::vec3> position;  // world space; unset on misses
  std::vector<glm::vec3> normal;    // unit shading normal, turned towards the eye
  std::vector<float> depth;         // view-axis depth; 0 on misses
  std::vector<glm::vec3> diffuse;   // albedo / pi * E (the term SSAO attenuates)
  std::vector<glm::vec3> emission;  // added after SSAO; on misses the sky

  std::size_t size() const { return depth.size(); }
  bool hit(std::size_t i) const { return depth[i] > 0.0f; }
  std::size_t index(int x, int y) const {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
           static_cast<std::size_t>(x);
  }
};

// One primary ray per pixel (Embree packets, as compose()) and the lightmap lookup at each hit;
// with `dynamic`, the dynamic objects where they are nearer (dynamic_view.h), so that SSAO sees
// them. For the same inputs, diffuse + emission equals compose()'s pixel exactly. Throws
// irradcast::Error like compose() on a bad size or lightmaps that do not match the scene.
FrameGBuffer trace_frame(const World& world, const RayScene& rays, const Atlas& atlas,
                         const std::vector<Lightmap>& lightmaps, const CameraPose& camera,
                         int width, int height, const DynamicView* dynamic = nullptr);

// radiance = diffuse * visibility + emission per pixel (the sky on misses: never occluded);
// `visibility` empty means 1 everywhere.
ImageRGB resolve_frame(const FrameGBuffer& g, const std::vector<float>& visibility);

}  // namespace irradcast

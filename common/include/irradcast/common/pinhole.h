// A pinhole camera's image plane with the per-frame terms (basis, tan of the half field of
// view, aspect) computed once: the primary rays of camera_ray(), which uses it, bit for bit,
// without the per-pixel cross products and tangent. Shared by the compositor's packets and the
// client bench's raw Embree rays.
#pragma once

#include <cmath>

#include <glm/glm.hpp>

#include "irradcast/common/world.h"

namespace irradcast {

struct PinholeRays {
  glm::vec3 eye, forward, right, up;
  float th, aspect, width, height;

  PinholeRays(const CameraPose& pose, int w, int h)
      : eye(pose.eye),
        forward(pose.forward),
        right(glm::normalize(glm::cross(pose.forward, pose.up))),
        up(glm::cross(right, pose.forward)),
        th(std::tan(0.5f * pose.yfov)),
        aspect(static_cast<float>(w) / static_cast<float>(h)),
        width(static_cast<float>(w)),
        height(static_cast<float>(h)) {}

  // The image-plane offsets of the point (px, py), in pixels (pixel centres at +0.5).
  float sx(float px) const { return (2.0f * px / width - 1.0f) * th * aspect; }
  float sy(float py) const { return (1.0f - 2.0f * py / height) * th; }
  // The unit direction through the image-plane offsets (sx, sy).
  glm::vec3 direction(float sx, float sy) const {
    return glm::normalize(forward + sx * right + sy * up);
  }
};

}  // namespace irradcast

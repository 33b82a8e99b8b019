// Camera poses: from a scene's glTF camera or a command-line spec, and primary ray generation.
#pragma once

#include <string>

#include <glm/glm.hpp>

#include "irradcast/common/ray_scene.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// "eye=x,y,z:target=x,y,z:fov=deg" with optional ":up=x,y,z"; fields not given keep the values
// of `base`. Throws irradcast::Error with the offending part on a bad spec.
CameraPose parse_camera(const std::string& spec, const CameraPose& base);

// The scene's first camera; without one, a view of the whole scene from the front (+Z side).
CameraPose default_camera(const Scene& scene, const World& world);

// Primary ray through the point (px, py) of the image plane, in pixels (pixel centres at +0.5).
Ray camera_ray(const CameraPose& pose, int width, int height, float px, float py);

}  // namespace irradcast

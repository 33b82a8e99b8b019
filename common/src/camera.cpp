#include "irradcast/common/camera.h"

#include <cmath>
#include <sstream>
#include <vector>

#include "irradcast/common/error.h"
#include "irradcast/common/pinhole.h"

namespace irradcast {
namespace {

glm::vec3 parse_vec3(const std::string& field, const std::string& value) {
  std::vector<float> v;
  std::stringstream ss(value);
  std::string part;
  while (std::getline(ss, part, ',')) {
    try {
      std::size_t used = 0;
      float f = std::stof(part, &used);
      if (used != part.size() || !std::isfinite(f)) throw std::invalid_argument(part);
      v.push_back(f);
    } catch (const std::exception&) {
      throw Error("camera spec: '" + field + "=" + value + "' is not three numbers x,y,z");
    }
  }
  if (v.size() != 3) throw Error("camera spec: '" + field + "=" + value + "' needs x,y,z");
  return {v[0], v[1], v[2]};
}

}  // namespace

CameraPose parse_camera(const std::string& spec, const CameraPose& base) {
  CameraPose pose = base;
  glm::vec3 target = base.eye + base.forward;
  bool has_target = false;
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ':')) {
    if (item.empty()) continue;
    auto eq = item.find('=');
    if (eq == std::string::npos)
      throw Error("camera spec: '" + item +
                  "' is not key=value (expected eye=, target=, fov=, up=)");
    std::string key = item.substr(0, eq), value = item.substr(eq + 1);
    if (key == "eye") {
      pose.eye = parse_vec3(key, value);
    } else if (key == "target") {
      target = parse_vec3(key, value);
      has_target = true;
    } else if (key == "up") {
      pose.up = parse_vec3(key, value);
    } else if (key == "fov") {
      float deg = 0.0f;
      try {
        std::size_t used = 0;
        deg = std::stof(value, &used);
        if (used != value.size()) throw std::invalid_argument(value);
      } catch (const std::exception&) {
        throw Error("camera spec: fov '" + value + "' is not a number of degrees");
      }
      if (!(deg > 0.0f && deg < 180.0f))
        throw Error("camera spec: fov " + value + " must be between 0 and 180 degrees");
      pose.yfov = glm::radians(deg);
    } else {
      throw Error("camera spec: unknown key '" + key + "' (expected eye, target, fov, up)");
    }
  }
  if (has_target || pose.eye != base.eye) {
    glm::vec3 f = target - pose.eye;
    if (!(glm::length(f) > 0.0f)) throw Error("camera spec: eye and target are the same point");
    pose.forward = glm::normalize(f);
  }
  if (!(glm::length(glm::cross(pose.forward, pose.up)) > 1e-6f))
    throw Error("camera spec: the up vector is parallel to the view direction");
  pose.up = glm::normalize(pose.up);
  return pose;
}

CameraPose default_camera(const Scene& scene, const World& world) {
  int node = scene.first_camera_node();
  if (node >= 0) return camera_pose(scene, node);
  CameraPose pose;
  glm::vec3 c = world.bounds.center();
  float r = 0.5f * glm::length(world.bounds.extent());
  pose.yfov = glm::radians(45.0f);
  pose.eye = c + glm::vec3(0.0f, 0.0f, r / std::tan(0.5f * pose.yfov) + r);
  pose.forward = glm::vec3(0.0f, 0.0f, -1.0f);
  return pose;
}

Ray camera_ray(const CameraPose& pose, int width, int height, float px, float py) {
  const PinholeRays pin(pose, width, height);
  Ray r;
  r.origin = pose.eye;
  r.direction = pin.direction(pin.sx(px), pin.sy(py));
  return r;
}

}  // namespace irradcast

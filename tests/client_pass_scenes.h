// Scenes and helpers shared by the SSAO and reprojection tests: a block standing on a floor
// (a contact), with constant lightmaps, so every darkening comes from the client passes.
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/error.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "scene_builders.h"

namespace irradcast::test {

// The message of the Error that p.validate() throws, or "" when it accepts p.
template <class Params>
std::string validate_error(const Params& p) {
  try {
    p.validate();
  } catch (const Error& e) {
    return e.what();
  }
  return {};
}

struct BlockOnFloor {
  // A 10 x 10 floor at y = 0 and a block [-1, 1] x [0, height] x [-1, 1] (lifted by `gap`).
  explicit BlockOnFloor(float gap = 0.0f, float height = 2.0f) {
    const std::uint32_t m = add_material(scene, glm::vec3(0.8f));
    add_quad_object(scene, "floor", {-5, 0, -5}, {-5, 0, 5}, {5, 0, 5}, {5, 0, -5}, m);
    add_block(scene, "block", {-1, gap, -1}, {1, gap + height, 1}, m);
    world = World::build(scene);
    rays = std::make_unique<RayScene>(world);
    AtlasOptions ao;
    ao.texels_per_scene = 64.0f;
    atlas = build_atlas(world, ao);
    for (const ObjectLightmap& o : atlas.objects)
      lightmaps.emplace_back(o.width, o.height, glm::vec3(kE));
  }
  // The camera on a circle of radius 7 at height 4 around the block, looking at its foot.
  static CameraPose orbit(float degrees) {
    const float a = glm::radians(degrees);
    CameraPose c;
    c.eye = glm::vec3(7.0f * std::sin(a), 4.0f, 7.0f * std::cos(a));
    c.forward = glm::normalize(glm::vec3(0.0f, 0.3f, 0.0f) - c.eye);
    c.yfov = glm::radians(50.0f);
    return c;
  }
  static constexpr float kE = 3.0f;
  Scene scene;
  World world;
  std::unique_ptr<RayScene> rays;
  Atlas atlas;
  std::vector<Lightmap> lightmaps;
};

// Distance in the floor plane from (x, z) to the block's footprint [-1, 1]^2.
inline float footprint_distance(glm::vec3 p) {
  const float dx = std::max(std::abs(p.x) - 1.0f, 0.0f), dz = std::max(std::abs(p.z) - 1.0f, 0.0f);
  return std::sqrt(dx * dx + dz * dz);
}

}  // namespace irradcast::test

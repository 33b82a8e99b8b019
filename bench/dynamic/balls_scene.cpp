#include "balls_scene.h"

#include <cmath>

#include "irradcast/common/builtin.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/shapes.h"

namespace irradcast::bench {
namespace {

// The Cornell box with `n` small dynamic spheres ball0..ball{n-1} in a grid above its floor.
Scene cornell_with_balls(int n) {
  Scene s = make_cornell_box();
  Material m;
  m.base_color = glm::vec3(0.8f);
  s.materials.push_back(m);
  s.meshes.push_back(
      uv_sphere("ball", 0.01f, 8, 16, static_cast<std::uint32_t>(s.materials.size() - 1)));
  const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<float>(n))));
  for (int i = 0; i < n; ++i) {
    Node node;
    node.name = "ball" + std::to_string(i);
    node.mesh = static_cast<int>(s.meshes.size() - 1);
    node.dynamic = true;
    node.local[3] = glm::vec4(0.1f + 0.35f * float(i % side) / float(side), 0.05f,
                              0.1f + 0.35f * float(i / side) / float(side), 1.0f);
    s.add_node(std::move(node));
  }
  return s;
}

}  // namespace

void write_balls_gltf(int n, const std::string& path) {
  save_gltf(cornell_with_balls(n), path);
}

}  // namespace irradcast::bench

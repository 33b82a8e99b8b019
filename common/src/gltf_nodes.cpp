// glTF import: cameras (perspective only), KHR_lights_punctual lights, and the node hierarchy
// (transforms, mesh / camera / light references, one parent per node, no cycles, the default
// scene's roots).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "gltf_import.h"

namespace irradcast::gltf_import {

void Loader::convert_cameras(Scene& scene) {
  for (std::size_t i = 0; i < m_.cameras.size(); ++i) {
    const tinygltf::Camera& gc = m_.cameras[i];
    const std::string what = "camera " + std::to_string(i) + quoted(gc.name);
    if (gc.type != "perspective") {
      warn(what + " is " + (gc.type.empty() ? "of no type" : clean(gc.type)) +
           "; only perspective cameras are supported, it is skipped");
      camera_map_.push_back(-1);
      continue;
    }
    const auto& p = gc.perspective;
    if (!std::isfinite(p.yfov) || p.yfov <= 0.0 || p.yfov >= 3.14159265)
      fail(what + " has an invalid yfov " + std::to_string(p.yfov));
    if (!std::isfinite(p.znear) || p.znear < 0.0 || !std::isfinite(p.zfar) || p.zfar < 0.0 ||
        !std::isfinite(p.aspectRatio) || p.aspectRatio < 0.0)
      fail(what + " has an invalid znear, zfar or aspectRatio");
    Camera cam;
    cam.name = gc.name;
    cam.yfov = static_cast<float>(p.yfov);
    cam.aspect_ratio = static_cast<float>(p.aspectRatio);
    if (p.znear > 0.0) cam.znear = static_cast<float>(p.znear);
    cam.zfar = static_cast<float>(p.zfar);
    camera_map_.push_back(static_cast<int>(scene.cameras.size()));
    scene.cameras.push_back(cam);
  }
}

void Loader::convert_lights(Scene& scene) {
  for (std::size_t i = 0; i < m_.lights.size(); ++i) {
    const tinygltf::Light& gl = m_.lights[i];
    const std::string what = "light " + std::to_string(i) + quoted(gl.name);
    Light light;
    light.name = gl.name;
    if (gl.type == "point") {
      light.type = Light::Type::Point;
    } else if (gl.type == "spot") {
      light.type = Light::Type::Spot;
    } else if (gl.type == "directional") {
      light.type = Light::Type::Directional;
    } else {
      warn(what + " has unknown type \"" + clean(gl.type) + "\"; it is skipped");
      light_map_.push_back(-1);
      continue;
    }
    if (!gl.color.empty()) {
      if (gl.color.size() != 3 || !std::isfinite(gl.color[0]) || !std::isfinite(gl.color[1]) ||
          !std::isfinite(gl.color[2]))
        fail(what + " has an invalid color");
      light.color = glm::vec3(gl.color[0], gl.color[1], gl.color[2]);
    }
    if (!std::isfinite(gl.intensity) || gl.intensity < 0.0)
      fail(what + " has an invalid intensity " + std::to_string(gl.intensity));
    light.intensity = static_cast<float>(gl.intensity);
    if (!std::isfinite(gl.range) || gl.range < 0.0)
      fail(what + " has an invalid range " + std::to_string(gl.range));
    light.range = static_cast<float>(gl.range);
    if (light.type == Light::Type::Spot) {
      const double inner = gl.spot.innerConeAngle, outer = gl.spot.outerConeAngle;
      if (!std::isfinite(inner) || !std::isfinite(outer) || inner < 0.0 || outer > 1.5707964 ||
          inner > outer)
        fail(what + " has invalid spot cone angles (inner " + std::to_string(inner) + ", outer " +
             std::to_string(outer) + ")");
      light.inner_cone_angle = static_cast<float>(inner);
      light.outer_cone_angle = static_cast<float>(outer);
    }
    light_map_.push_back(static_cast<int>(scene.lights.size()));
    scene.lights.push_back(light);
  }
}

void Loader::convert_nodes(Scene& scene) {
  scene.nodes.resize(m_.nodes.size());
  for (std::size_t i = 0; i < m_.nodes.size(); ++i) link_node(i, scene);
  check_cycles(scene);
  pick_roots(scene);
}

// The node's local transform: its matrix, or translation * rotation * scale.
glm::mat4 Loader::node_transform(const tinygltf::Node& gn, const std::string& what) const {
  auto all_finite = [](const std::vector<double>& v) {
    return std::all_of(v.begin(), v.end(), [](double d) { return std::isfinite(d); });
  };
  if (!gn.matrix.empty()) {
    if (gn.matrix.size() != 16 || !all_finite(gn.matrix)) fail(what + " has an invalid matrix");
    float f[16];
    for (int k = 0; k < 16; ++k) f[k] = static_cast<float>(gn.matrix[k]);
    return glm::make_mat4(f);  // glTF matrices are column-major, like glm
  }
  glm::mat4 t(1.0f), r(1.0f), s(1.0f);
  if (!gn.translation.empty()) {
    if (gn.translation.size() != 3 || !all_finite(gn.translation))
      fail(what + " has an invalid translation");
    t[3] = glm::vec4(gn.translation[0], gn.translation[1], gn.translation[2], 1.0);
  }
  if (!gn.rotation.empty()) {
    if (gn.rotation.size() != 4 || !all_finite(gn.rotation))
      fail(what + " has an invalid rotation");
    glm::quat q(static_cast<float>(gn.rotation[3]), static_cast<float>(gn.rotation[0]),
                static_cast<float>(gn.rotation[1]), static_cast<float>(gn.rotation[2]));
    float len = glm::length(q);
    if (!(len > 0.0f)) fail(what + " has a zero rotation quaternion");
    r = glm::mat4_cast(q / len);
  }
  if (!gn.scale.empty()) {
    if (gn.scale.size() != 3 || !all_finite(gn.scale)) fail(what + " has an invalid scale");
    s[0][0] = static_cast<float>(gn.scale[0]);
    s[1][1] = static_cast<float>(gn.scale[1]);
    s[2][2] = static_cast<float>(gn.scale[2]);
  }
  return t * r * s;
}

// Node i: name, transform, mesh / camera / light, and children (each gets i as its parent).
void Loader::link_node(std::size_t i, Scene& scene) const {
  const std::size_t count = m_.nodes.size();
  const tinygltf::Node& gn = m_.nodes[i];
  const std::string what = "node " + std::to_string(i) + quoted(gn.name);
  Node& node = scene.nodes[i];
  node.name = gn.name;
  node.local = node_transform(gn, what);
  if (gn.mesh >= 0) {
    if (static_cast<std::size_t>(gn.mesh) >= m_.meshes.size())
      fail(what + " refers to mesh " + std::to_string(gn.mesh) + ", which does not exist");
    // A mesh with no triangles is not an object: drop the reference.
    if (!scene.meshes[gn.mesh].triangles.empty()) node.mesh = gn.mesh;
  }
  if (gn.camera >= 0) {
    if (static_cast<std::size_t>(gn.camera) >= m_.cameras.size())
      fail(what + " refers to camera " + std::to_string(gn.camera) + ", which does not exist");
    node.camera = camera_map_[gn.camera];
  }
  auto ext = gn.extensions.find("KHR_lights_punctual");
  if (ext != gn.extensions.end() && ext->second.Has("light")) {
    const tinygltf::Value& l = ext->second.Get("light");
    if (!l.IsInt() || l.GetNumberAsInt() < 0 ||
        static_cast<std::size_t>(l.GetNumberAsInt()) >= m_.lights.size())
      fail(what + " refers to a KHR_lights_punctual light that does not exist");
    node.light = light_map_[l.GetNumberAsInt()];
  }
  // KHR_node_visibility: a hidden node hides its subtree (Scene::visible_nodes).
  auto vis = gn.extensions.find("KHR_node_visibility");
  if (vis != gn.extensions.end() && vis->second.Has("visible")) {
    const tinygltf::Value& v = vis->second.Get("visible");
    if (!v.IsBool()) fail(what + " has a KHR_node_visibility \"visible\" that is not a boolean");
    node.visible = v.Get<bool>();
  }
  // "extras": {"irradcast": {"dynamic": true}}: the node and its subtree are dynamic.
  if (gn.extras.IsObject() && gn.extras.Has("irradcast")) {
    const tinygltf::Value& ours = gn.extras.Get("irradcast");
    if (ours.IsObject() && ours.Has("dynamic")) {
      const tinygltf::Value& d = ours.Get("dynamic");
      if (!d.IsBool()) fail(what + " has an extras.irradcast.dynamic that is not a boolean");
      node.dynamic = d.Get<bool>();
    }
  }
  for (int c : gn.children) {
    if (c < 0 || static_cast<std::size_t>(c) >= count)
      fail(what + " has child " + std::to_string(c) + ", which does not exist");
    if (scene.nodes[c].parent >= 0 || static_cast<std::size_t>(c) == i)
      fail("node " + std::to_string(c) + " has more than one parent (" +
           std::to_string(scene.nodes[c].parent) + " and " + std::to_string(i) + ")");
    scene.nodes[c].parent = static_cast<int>(i);
    node.children.push_back(c);
  }
}

// With one parent per node, a cycle is a parent chain that comes back to itself. Each node is
// walked up once: a walk stops at a node known to reach a root (linear in the node count;
// iterative, so a chain of any depth needs no stack).
void Loader::check_cycles(const Scene& scene) const {
  enum : std::uint8_t { kUnknown, kOnWalk, kReachesRoot };
  const std::size_t count = scene.nodes.size();
  std::vector<std::uint8_t> state(count, kUnknown);
  std::vector<int> walk;
  for (std::size_t i = 0; i < count; ++i) {
    walk.clear();
    int n = static_cast<int>(i);
    while (n >= 0 && state[static_cast<std::size_t>(n)] == kUnknown) {
      state[static_cast<std::size_t>(n)] = kOnWalk;
      walk.push_back(n);
      n = scene.nodes[static_cast<std::size_t>(n)].parent;
    }
    // Earlier walks all end in kReachesRoot: a kOnWalk node is on this walk, i.e. a cycle.
    if (n >= 0 && state[static_cast<std::size_t>(n)] == kOnWalk)
      fail("node " + std::to_string(n) + " is part of a cycle in the hierarchy");
    for (int w : walk) state[static_cast<std::size_t>(w)] = kReachesRoot;
  }
}

// The roots: the default scene's nodes (each once, none with a parent), or every parentless node
// when the file has no scenes. The default scene also names the Scene.
void Loader::pick_roots(Scene& scene) const {
  const std::size_t count = scene.nodes.size();
  if (m_.scenes.empty()) {
    for (std::size_t i = 0; i < count; ++i)
      if (scene.nodes[i].parent < 0) scene.roots.push_back(static_cast<int>(i));
    return;
  }
  const int s = m_.defaultScene >= 0 ? m_.defaultScene : 0;
  if (static_cast<std::size_t>(s) >= m_.scenes.size())
    fail("the default scene " + std::to_string(s) + " does not exist");
  const tinygltf::Scene& gs = m_.scenes[s];
  scene.name = gs.name;
  std::vector<bool> listed(count, false);
  for (int r : gs.nodes) {
    if (r < 0 || static_cast<std::size_t>(r) >= count)
      fail("scene " + std::to_string(s) + " refers to node " + std::to_string(r) +
           ", which does not exist");
    if (scene.nodes[r].parent >= 0)
      fail("scene " + std::to_string(s) + " lists node " + std::to_string(r) +
           " as a root, but it has a parent");
    if (!listed[static_cast<std::size_t>(r)]) scene.roots.push_back(r);
    listed[static_cast<std::size_t>(r)] = true;
  }
}

}  // namespace irradcast::gltf_import

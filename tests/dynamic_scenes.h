// Scenes with dynamic nodes for the tests (docs/DYNAMIC.md).
#pragma once

#include <string>

#include <glm/glm.hpp>

#include "irradcast/common/builtin.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/scene_edit.h"
#include "scene_builders.h"

namespace irradcast::test {

// A mesh of `s` on a new node under `parent` (-1: a root).
inline int add_child_block(Scene& s, const std::string& name, int parent, glm::vec3 lo,
                           glm::vec3 hi, std::uint32_t material) {
  Scene tmp;
  tmp.materials = s.materials;
  test::add_block(tmp, name.c_str(), lo, hi, material);
  Mesh merged;
  merged.name = name;
  for (const Mesh& m : tmp.meshes) {
    const auto base = static_cast<std::uint32_t>(merged.positions.size());
    merged.positions.insert(merged.positions.end(), m.positions.begin(), m.positions.end());
    merged.normals.insert(merged.normals.end(), m.normals.begin(), m.normals.end());
    merged.uv0.insert(merged.uv0.end(), m.uv0.begin(), m.uv0.end());
    for (const glm::uvec3& t : m.triangles) merged.triangles.push_back(t + glm::uvec3(base));
    merged.triangle_material.insert(merged.triangle_material.end(), m.triangle_material.begin(),
                                    m.triangle_material.end());
  }
  s.meshes.push_back(std::move(merged));
  Node n;
  n.name = name;
  n.parent = parent;
  n.mesh = static_cast<int>(s.meshes.size() - 1);
  return s.add_node(std::move(n));
}

// The Cornell box with a dynamic prop: a glowing block "prop" hanging in the room, a white
// block under it, and a point light on the prop, all dynamic (the flag is on "prop" only).
inline Scene cornell_with_prop() {
  Scene s = make_cornell_box();
  const std::uint32_t glow =
      test::add_material(s, glm::vec3(0.5f), glm::vec3(4.0f, 2.0f, 1.0f), 1.0f);
  const std::uint32_t white = test::add_material(s, glm::vec3(0.9f));
  Node rig;  // a static node with no mesh: the prop hangs under it
  rig.name = "rig";
  const int rig_node = s.add_node(std::move(rig));
  const int prop =
      add_child_block(s, "prop", rig_node, {0.10f, 0.30f, 0.08f}, {0.20f, 0.40f, 0.16f}, glow);
  s.nodes[static_cast<std::size_t>(prop)].dynamic = true;
  add_child_block(s, "prop_base", prop, {0.08f, 0.25f, 0.06f}, {0.22f, 0.28f, 0.18f}, white);
  Light bulb;
  bulb.name = "bulb";
  bulb.intensity = 5.0f;
  s.lights.push_back(bulb);
  Node lamp;
  lamp.name = "lamp";
  lamp.parent = prop;
  lamp.light = static_cast<int>(s.lights.size() - 1);
  lamp.local[3] = glm::vec4(0.15f, 0.45f, 0.12f, 1.0f);
  s.add_node(std::move(lamp));
  return s;
}

inline SceneEdit move(const std::string& node, glm::vec3 by) {
  SceneEdit e;
  EditOp op;
  op.kind = EditOp::Kind::Move;
  op.target = node;
  op.vector = by;
  e.ops.push_back(op);
  return e;
}

}  // namespace irradcast::test

// Small procedural scenes for the tests.
#pragma once

#include <array>
#include <string>

#include "irradcast/common/scene.h"

namespace irradcast::test {

// Adds a mesh with the quad a-b-c-d (counter-clockwise seen from its normal side) and a node.
inline int add_quad_object(Scene& s, const char* name, glm::vec3 a, glm::vec3 b, glm::vec3 c,
                           glm::vec3 d, std::uint32_t material) {
  Mesh m;
  m.name = name;
  m.positions = {a, b, c, d};
  glm::vec3 n = glm::normalize(glm::cross(b - a, c - a));
  m.normals = {n, n, n, n};
  m.uv0 = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  m.triangle_material = {material, material};
  s.meshes.push_back(m);
  Node node;
  node.name = name;
  node.mesh = static_cast<int>(s.meshes.size() - 1);
  return s.add_node(node);
}

inline std::uint32_t add_material(Scene& s, glm::vec3 albedo, glm::vec3 emission = glm::vec3(0),
                                  float strength = 1.0f) {
  Material m;
  m.base_color = albedo;
  m.emissive = emission;
  m.emissive_strength = strength;
  s.materials.push_back(m);
  return static_cast<std::uint32_t>(s.materials.size() - 1);
}

// A closed axis-aligned block [lo, hi] whose six faces face outward.
inline void add_block(Scene& s, const char* name, glm::vec3 lo, glm::vec3 hi,
                      std::uint32_t material) {
  const std::string n(name);
  add_quad_object(s, (n + "-z").c_str(), {lo.x, lo.y, lo.z}, {lo.x, hi.y, lo.z}, {hi.x, hi.y, lo.z},
                  {hi.x, lo.y, lo.z}, material);
  add_quad_object(s, (n + "+z").c_str(), {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z},
                  {lo.x, hi.y, hi.z}, material);
  add_quad_object(s, (n + "-x").c_str(), {lo.x, lo.y, lo.z}, {lo.x, lo.y, hi.z}, {lo.x, hi.y, hi.z},
                  {lo.x, hi.y, lo.z}, material);
  add_quad_object(s, (n + "+x").c_str(), {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {hi.x, hi.y, hi.z},
                  {hi.x, lo.y, hi.z}, material);
  add_quad_object(s, (n + "-y").c_str(), {lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, lo.y, hi.z},
                  {lo.x, lo.y, hi.z}, material);
  add_quad_object(s, (n + "+y").c_str(), {lo.x, hi.y, lo.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z},
                  {hi.x, hi.y, lo.z}, material);
}

// A closed cube [-1,1]^3 whose six faces all face inward, every face with `material`.
inline Scene closed_box(glm::vec3 albedo, glm::vec3 emission) {
  Scene s;
  std::uint32_t mat = add_material(s, albedo, emission);
  const std::array<glm::vec3, 8> p = {
      glm::vec3(-1, -1, -1), glm::vec3(1, -1, -1), glm::vec3(1, 1, -1), glm::vec3(-1, 1, -1),
      glm::vec3(-1, -1, 1),  glm::vec3(1, -1, 1),  glm::vec3(1, 1, 1),  glm::vec3(-1, 1, 1)};
  // Each face wound so that its normal points into the box.
  add_quad_object(s, "z-", p[0], p[1], p[2], p[3], mat);
  add_quad_object(s, "z+", p[4], p[7], p[6], p[5], mat);
  add_quad_object(s, "x-", p[0], p[3], p[7], p[4], mat);
  add_quad_object(s, "x+", p[1], p[5], p[6], p[2], mat);
  add_quad_object(s, "y-", p[0], p[4], p[5], p[1], mat);
  add_quad_object(s, "y+", p[3], p[2], p[6], p[7], mat);
  return s;
}

}  // namespace irradcast::test

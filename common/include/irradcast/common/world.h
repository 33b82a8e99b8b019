// World-space view of a Scene: every object's triangles transformed by its node, the scene
// bounds, the lights placed by their nodes and the cameras as poses. Everything that traces
// rays works on this; it is rebuilt (or updated per object) when the scene changes.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/scene.h"

namespace irradcast {

struct Bounds {
  glm::vec3 lo{1e30f};
  glm::vec3 hi{-1e30f};
  void extend(glm::vec3 p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  bool empty() const { return lo.x > hi.x; }
  glm::vec3 extent() const { return empty() ? glm::vec3(0.0f) : hi - lo; }
  float max_extent() const {
    glm::vec3 e = extent();
    return glm::max(e.x, glm::max(e.y, e.z));
  }
  glm::vec3 center() const { return 0.5f * (lo + hi); }
};

struct WorldObject {
  int object = -1;  // index into Scene::objects()
  int node = -1;
  int mesh = -1;
  std::vector<glm::vec3> positions;  // world space
  std::vector<glm::vec3> normals;    // world space, unit; empty if the mesh has none
  // Per triangle, its unit geometric normal (geometric_normal), worked out once per placement:
  // every texel and hit of the triangle reads it.
  std::vector<glm::vec3> face_normals;
  const Mesh* source = nullptr;  // uv0 / uv1 / triangles / materials live here
  glm::mat4 transform{1.0f};     // object to world (the node's world matrix)
  bool visible = true;           // false: hidden by an edit (no rays hit it, no texels lit)
  bool dynamic = false;          // a dynamic node's (Node::dynamic): not in the static scene
  // Part of the static scene as it is now: what the engine lights, its rays hit and its lightmaps
  // cover.
  bool in_static_scene() const { return visible && !dynamic; }

  const std::vector<glm::uvec3>& triangles() const { return source->triangles; }
  // Unit geometric normal of triangle t (counter-clockwise winding) and twice its area.
  glm::vec3 geometric_normal(std::uint32_t t) const;
  // geometric_normal() worked out from the positions (what face_normals holds).
  glm::vec3 face_normal(std::uint32_t t) const;
  float area(std::uint32_t t) const;
  // Interpolated shading normal at barycentrics (u, v) (geometric if the mesh has no normals),
  // flipped to the geometric normal's side.
  glm::vec3 shading_normal(std::uint32_t t, float u, float v) const;
  glm::vec3 position(std::uint32_t t, float u, float v) const;
  glm::vec2 uv(int set, std::uint32_t t, float u, float v) const;  // (0,0) if the set is absent
};

struct WorldLight {
  int node = -1;  // the node that places it
  Light::Type type = Light::Type::Point;
  glm::vec3 position{0.0f};
  glm::vec3 direction{0.0f, 0.0f, -1.0f};  // direction the light travels (spot/directional)
  glm::vec3 intensity{1.0f};               // colour x intensity
  float range = 0.0f;
  float cos_inner = 1.0f;
  float cos_outer = 0.0f;
};

struct CameraPose {
  glm::vec3 eye{0.0f};
  glm::vec3 forward{0.0f, 0.0f, -1.0f};
  glm::vec3 up{0.0f, 1.0f, 0.0f};
  float yfov = 0.6911112f;  // radians
};

struct World {
  const Scene* scene = nullptr;
  std::vector<WorldObject> objects;
  std::vector<WorldLight> lights;  // of the static scene (none of a dynamic node)
  Bounds bounds;                   // of the static scene's objects, hidden ones included

  static World build(const Scene& scene);
  // After an edit of `scene` (the same Scene this World was built from): places every object
  // and light again. Object and light counts never change; only what moved is recomputed.
  // The bounds stay as built (the probe grid, ray offsets, tracing range and distant points
  // of an engine are sized from them). Returns the objects whose transform or visibility
  // changed.
  std::vector<int> update(const Scene& scene);

  // Albedo and emitted radiance at a surface point (textures sampled at the point's UVs).
  glm::vec3 albedo(int object, std::uint32_t t, float u, float v) const;
  glm::vec3 emission(int object, std::uint32_t t, float u, float v) const;
  const Material& material(int object, std::uint32_t t) const;
};

// The pose of the camera on a node (glTF cameras look down their local -Z, up +Y).
CameraPose camera_pose(const Scene& scene, int node);

}  // namespace irradcast

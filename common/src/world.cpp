#include "irradcast/world.h"

#include <cmath>

#include <glm/gtc/matrix_inverse.hpp>

namespace irradcast {

glm::vec3 WorldObject::geometric_normal(std::uint32_t t) const {
  const glm::uvec3& tri = source->triangles[t];
  glm::vec3 n =
      glm::cross(positions[tri.y] - positions[tri.x], positions[tri.z] - positions[tri.x]);
  float len = glm::length(n);
  return len > 0.0f ? n / len : glm::vec3(0.0f, 0.0f, 1.0f);
}

float WorldObject::area(std::uint32_t t) const {
  const glm::uvec3& tri = source->triangles[t];
  return 0.5f * glm::length(glm::cross(positions[tri.y] - positions[tri.x],
                                       positions[tri.z] - positions[tri.x]));
}

glm::vec3 WorldObject::shading_normal(std::uint32_t t, float u, float v) const {
  glm::vec3 ng = geometric_normal(t);
  if (normals.empty()) return ng;
  const glm::uvec3& tri = source->triangles[t];
  glm::vec3 n = (1.0f - u - v) * normals[tri.x] + u * normals[tri.y] + v * normals[tri.z];
  float len = glm::length(n);
  if (!(len > 1e-12f)) return ng;
  n /= len;
  return glm::dot(n, ng) < 0.0f ? -n : n;
}

glm::vec3 WorldObject::position(std::uint32_t t, float u, float v) const {
  const glm::uvec3& tri = source->triangles[t];
  return (1.0f - u - v) * positions[tri.x] + u * positions[tri.y] + v * positions[tri.z];
}

glm::vec2 WorldObject::uv(int set, std::uint32_t t, float u, float v) const {
  const std::vector<glm::vec2>& uvs = set == 1 ? source->uv1 : source->uv0;
  if (uvs.empty()) return glm::vec2(0.0f);
  const glm::uvec3& tri = source->triangles[t];
  return (1.0f - u - v) * uvs[tri.x] + u * uvs[tri.y] + v * uvs[tri.z];
}

World World::build(const Scene& scene) {
  World w;
  w.scene = &scene;
  std::vector<glm::mat4> mats = scene.world_matrices();
  std::vector<Object> objects = scene.objects();
  w.objects.reserve(objects.size());
  for (std::size_t i = 0; i < objects.size(); ++i) {
    const Object& o = objects[i];
    const Mesh& mesh = scene.meshes[o.mesh];
    WorldObject wo;
    wo.object = static_cast<int>(i);
    wo.node = o.node;
    wo.mesh = o.mesh;
    wo.source = &mesh;
    const glm::mat4& m = mats[o.node];
    glm::mat3 nm = glm::inverseTranspose(glm::mat3(m));
    wo.positions.reserve(mesh.positions.size());
    for (const glm::vec3& p : mesh.positions) {
      glm::vec3 q = glm::vec3(m * glm::vec4(p, 1.0f));
      wo.positions.push_back(q);
      w.bounds.extend(q);
    }
    if (!mesh.normals.empty()) {
      wo.normals.reserve(mesh.normals.size());
      for (const glm::vec3& n : mesh.normals) {
        glm::vec3 q = nm * n;
        float len = glm::length(q);
        wo.normals.push_back(len > 0.0f ? q / len : glm::vec3(0.0f));
      }
    }
    w.objects.push_back(std::move(wo));
  }
  for (int i = 0; i < static_cast<int>(scene.nodes.size()); ++i) {
    const Node& node = scene.nodes[i];
    if (node.light < 0) continue;
    const Light& l = scene.lights[node.light];
    const glm::mat4& m = mats[i];
    WorldLight wl;
    wl.type = l.type;
    wl.position = glm::vec3(m[3]);
    glm::vec3 d = -glm::vec3(m[2]);  // lights shine down their local -Z
    float len = glm::length(d);
    wl.direction = len > 0.0f ? d / len : glm::vec3(0.0f, 0.0f, -1.0f);
    wl.intensity = l.color * l.intensity;
    wl.range = l.range;
    wl.cos_inner = std::cos(l.inner_cone_angle);
    wl.cos_outer = std::cos(l.outer_cone_angle);
    w.lights.push_back(wl);
  }
  return w;
}

const Material& World::material(int object, std::uint32_t t) const {
  static const Material fallback{};
  const Mesh& mesh = *objects[object].source;
  std::uint32_t m = t < mesh.triangle_material.size() ? mesh.triangle_material[t] : ~0u;
  return m < scene->materials.size() ? scene->materials[m] : fallback;
}

glm::vec3 World::albedo(int object, std::uint32_t t, float u, float v) const {
  const Material& mat = material(object, t);
  glm::vec3 a = mat.base_color;
  if (mat.base_color_texture >= 0) {
    glm::vec2 uv = objects[object].uv(mat.base_color_uv, t, u, v);
    a *= glm::vec3(scene->textures[mat.base_color_texture].sample_srgb(uv));
  }
  return a;
}

glm::vec3 World::emission(int object, std::uint32_t t, float u, float v) const {
  const Material& mat = material(object, t);
  if (!mat.is_emissive()) return glm::vec3(0.0f);
  glm::vec3 e = mat.emission();
  if (mat.emissive_texture >= 0) {
    glm::vec2 uv = objects[object].uv(mat.emissive_uv, t, u, v);
    e *= glm::vec3(scene->textures[mat.emissive_texture].sample_srgb(uv));
  }
  return e;
}

CameraPose camera_pose(const Scene& scene, int node) {
  CameraPose pose;
  if (node < 0) return pose;
  glm::mat4 m = scene.world_matrices()[node];
  pose.eye = glm::vec3(m[3]);
  glm::vec3 f = -glm::vec3(m[2]);
  glm::vec3 u = glm::vec3(m[1]);
  if (glm::length(f) > 0.0f) pose.forward = glm::normalize(f);
  if (glm::length(u) > 0.0f) pose.up = glm::normalize(u);
  int cam = scene.nodes[node].camera;
  if (cam >= 0) pose.yfov = scene.cameras[cam].yfov;
  return pose;
}

}  // namespace irradcast

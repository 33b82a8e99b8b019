#include "irradcast/common/world.h"

#include "irradcast/common/cutout.h"

#include <cmath>

#include <glm/gtc/matrix_inverse.hpp>

namespace irradcast {

glm::vec3 WorldObject::geometric_normal(std::uint32_t t) const {
  if (t < face_normals.size()) return face_normals[t];
  return face_normal(t);
}

glm::vec3 WorldObject::face_normal(std::uint32_t t) const {
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

namespace {

void place_object(WorldObject& wo, const glm::mat4& m) {
  const Mesh& mesh = *wo.source;
  wo.transform = m;
  glm::mat3 nm = glm::inverseTranspose(glm::mat3(m));
  wo.positions.resize(mesh.positions.size());
  for (std::size_t i = 0; i < mesh.positions.size(); ++i)
    wo.positions[i] = glm::vec3(m * glm::vec4(mesh.positions[i], 1.0f));
  wo.normals.resize(mesh.normals.size());
  for (std::size_t i = 0; i < mesh.normals.size(); ++i) {
    glm::vec3 q = nm * mesh.normals[i];
    float len = glm::length(q);
    wo.normals[i] = len > 0.0f ? q / len : glm::vec3(0.0f);
  }
  wo.face_normals.clear();
  const auto triangles = static_cast<std::uint32_t>(mesh.triangles.size());
  wo.face_normals.reserve(triangles);
  for (std::uint32_t t = 0; t < triangles; ++t) wo.face_normals.push_back(wo.face_normal(t));
}

void place_lights(World& w, const Scene& scene, const std::vector<glm::mat4>& mats,
                  const std::vector<bool>& visible) {
  w.lights.clear();
  const std::vector<bool> dynamic = scene.dynamic_nodes();
  for (int i = 0; i < static_cast<int>(scene.nodes.size()); ++i) {
    const Node& node = scene.nodes[i];
    if (node.light < 0 || !visible[i] || dynamic[i]) continue;
    const Light& l = scene.lights[node.light];
    const glm::mat4& m = mats[i];
    WorldLight wl;
    wl.node = i;
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
}

void compute_bounds(World& w) {
  w.bounds = Bounds{};
  for (const WorldObject& o : w.objects)
    if (!o.dynamic)
      for (const glm::vec3& p : o.positions) w.bounds.extend(p);
}

}  // namespace

World World::build(const Scene& scene) {
  World w;
  w.scene = &scene;
  std::vector<glm::mat4> mats = scene.world_matrices();
  std::vector<bool> visible = scene.visible_nodes();
  const std::vector<bool> dynamic = scene.dynamic_nodes();
  std::vector<Object> objects = scene.objects();
  w.objects.reserve(objects.size());
  for (std::size_t i = 0; i < objects.size(); ++i) {
    const Object& o = objects[i];
    WorldObject wo;
    wo.object = static_cast<int>(i);
    wo.node = o.node;
    wo.mesh = o.mesh;
    wo.source = &scene.meshes[o.mesh];
    wo.visible = visible[o.node];
    wo.dynamic = dynamic[o.node];
    place_object(wo, mats[o.node]);
    w.objects.push_back(std::move(wo));
  }
  // Hidden objects count for the bounds: the probe grid and ray offsets are sized once, and an
  // object hidden at load may be shown later. Dynamic ones do not: the static scene is the
  // scene without them.
  compute_bounds(w);
  place_lights(w, scene, mats, visible);
  return w;
}

std::vector<int> World::update(const Scene& s) {
  scene = &s;
  std::vector<glm::mat4> mats = s.world_matrices();
  std::vector<bool> visible = s.visible_nodes();
  std::vector<int> changed;
  for (WorldObject& o : objects) {
    const glm::mat4& m = mats[o.node];
    const bool vis = visible[o.node];
    if (m == o.transform && vis == o.visible) continue;
    o.visible = vis;
    if (m != o.transform) place_object(o, m);
    changed.push_back(o.object);
  }
  place_lights(*this, s, mats, visible);
  return changed;
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
  // A cut-out point emits nothing (cutout.h).
  if (mat.cut_out() && cut_out(*this, object, t, u, v)) return glm::vec3(0.0f);
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

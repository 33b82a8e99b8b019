// The scene model: what a glTF 2.0 file (or a built-in generator) describes, kept close to glTF's
// own structure (nodes with a hierarchy, meshes, materials, textures, lights, cameras) so that it
// can be exported again and edited live. World-space views of it live in world.h.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/sky.h"

namespace irradcast {

// An 8-bit RGBA image as glTF stores it. Colour textures (baseColor, emissive) are sRGB encoded;
// sample() decodes them to linear.
struct Texture {
  std::string name;
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgba8;  // width * height * 4

  // Bilinear, wrap mode REPEAT, sRGB decoded to linear RGB; alpha is linear.
  glm::vec4 sample_srgb(glm::vec2 uv) const;
};

// The linear value of each 8-bit sRGB code, as sample_srgb decodes them.
const std::array<float, 256>& srgb_to_linear_table();

// Lambertian material: albedo = baseColor (factor x texture); emission is radiance
// (emissiveFactor x emissiveTexture x KHR_materials_emissive_strength).
struct Material {
  std::string name;
  glm::vec3 base_color{0.8f};
  int base_color_texture = -1;  // index into Scene::textures, -1 = none
  int base_color_uv = 0;        // TEXCOORD set the texture uses (0 or 1)
  glm::vec3 emissive{0.0f};
  int emissive_texture = -1;
  int emissive_uv = 0;
  float emissive_strength = 1.0f;
  bool double_sided = false;
  // glTF alphaMode: Opaque ignores alpha; Mask cuts out every point whose alpha (the base
  // colour factor's alpha x the base colour texture's alpha) is below alpha_cutoff: rays pass
  // through it and it holds no lightmap estimate. glTF's BLEND loads as Mask at 0.5.
  enum class AlphaMode { Opaque, Mask };
  AlphaMode alpha_mode = AlphaMode::Opaque;
  float alpha_cutoff = 0.5f;
  float base_alpha = 1.0f;  // the base colour factor's alpha

  bool cut_out() const { return alpha_mode == AlphaMode::Mask; }
  glm::vec3 emission() const { return emissive * emissive_strength; }
  bool is_emissive() const {
    return emissive_strength > 0.0f &&
           (emissive.x > 0.0f || emissive.y > 0.0f || emissive.z > 0.0f);
  }
};

// One glTF mesh with all of its triangle primitives merged, in object space.
struct Mesh {
  std::string name;
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;  // per vertex; empty = use the geometric normal
  std::vector<glm::vec2> uv0;      // TEXCOORD_0; empty if absent
  std::vector<glm::vec2> uv1;      // TEXCOORD_1 (lightmap UVs); empty if absent
  std::vector<glm::uvec3> triangles;
  std::vector<std::uint32_t> triangle_material;  // index into Scene::materials, per triangle

  std::size_t triangle_count() const { return triangles.size(); }
};

// KHR_lights_punctual. Intensity is in the extension's units (candela for point and spot, lux for
// directional), treated radiometrically: a point light gives irradiance I cos(theta) / d^2.
struct Light {
  enum class Type { Point, Spot, Directional };
  std::string name;
  Type type = Type::Point;
  glm::vec3 color{1.0f};
  float intensity = 1.0f;
  float range = 0.0f;  // 0 = infinite
  float inner_cone_angle = 0.0f;
  float outer_cone_angle = 0.7853982f;  // pi / 4
};

// A glTF perspective camera. aspect_ratio 0 means "take it from the image".
struct Camera {
  std::string name;
  float yfov = 0.6911112f;  // radians
  float aspect_ratio = 0.0f;
  float znear = 0.01f;
  float zfar = 0.0f;  // 0 = infinite
};

struct Node {
  std::string name;
  glm::mat4 local{1.0f};  // local transform (TRS composed or the glTF matrix)
  int parent = -1;
  std::vector<int> children;
  int mesh = -1;
  int camera = -1;
  int light = -1;
  // Hidden nodes (and everything under them) are not part of the lit scene: their meshes cast
  // no shadows and get no light, their lights are off. A scene edit shows or hides them.
  bool visible = true;
  // Dynamic nodes (and everything under them) move freely and cheaply (docs/DYNAMIC.md): their
  // meshes get no lightmap and take no part in the static scene the engine lights (they neither
  // occlude nor reflect its light), and their lights are off; viewers draw them lit by the probe
  // volume. glTF: "extras": {"irradcast": {"dynamic": true}}, or --dynamic NAME.
  bool dynamic = false;
};

// A mesh placed in the world by a node: the unit that gets its own lightmap.
struct Object {
  std::string name;
  int node = -1;
  int mesh = -1;
};

// The largest coordinate magnitude the ray tracer takes (Embree treats larger ones as invalid).
constexpr float kMaxCoordinate = 1e18f;

// A triangle rays can hit and texels can cover: corners finite and within +-kMaxCoordinate, and
// an area (computed as WorldObject::area does) that is finite and not zero.
bool usable_triangle(glm::vec3 a, glm::vec3 b, glm::vec3 c);

struct Scene {
  std::string name;
  std::vector<Node> nodes;
  std::vector<int> roots;  // nodes of the default scene without a parent
  std::vector<Mesh> meshes;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<Light> lights;
  std::vector<Camera> cameras;
  // Light from where rays leave the scene; none (black) unless a tool or an edit sets one.
  Sky sky;

  // Adds a node (and links it under parent, or makes it a root). Returns its index.
  int add_node(Node node);

  // World matrix of every node (product of the locals up the hierarchy).
  std::vector<glm::mat4> world_matrices() const;
  // Every node that carries a mesh, in node order: the scene's objects (hidden ones included,
  // so that object indices and lightmaps stay fixed when an edit hides one).
  std::vector<Object> objects() const;
  // Per node: visible itself and every ancestor visible.
  std::vector<bool> visible_nodes() const;
  // Per node: dynamic itself or under a dynamic ancestor.
  std::vector<bool> dynamic_nodes() const;
  // Index of the first node with a camera, or -1.
  int first_camera_node() const;

  std::size_t triangle_count() const;  // over all objects (instanced meshes count each time)
};

// Drops what would break the ray tracer: every triangle that is not usable_triangle() in object
// space or in the world space of any node that places its mesh, and the lights and cameras of
// nodes whose world transform is not finite. A mesh that loses triangles also loses the vertices
// no triangle uses any more; a node whose mesh is left with no triangle drops it (it is then no
// object, as with the glTF loader's empty meshes). Logs one warning line (counts, and the first
// meshes concerned) naming `label`. Throws irradcast::Error if triangles were dropped and the
// scene has no object left. Returns the number of triangles dropped.
std::size_t drop_degenerate_triangles(Scene& scene, const std::string& label);

}  // namespace irradcast

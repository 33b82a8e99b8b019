// glTF 2.0 export: the JSON is written with nlohmann::json, the binary data goes into one buffer
// (the GLB BIN chunk, or a base64 data URI in a .gltf), textures are encoded as PNG.
#include <stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"

namespace irradcast {
namespace {

using nlohmann::json;

constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;
constexpr int kUnsignedShort = 5123;
constexpr int kUnsignedInt = 5125;
constexpr int kFloat = 5126;

std::string base64(const std::vector<unsigned char>& data) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((data.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < data.size(); i += 3) {
    std::uint32_t v = (data[i] << 16) | (data[i + 1] << 8) | data[i + 2];
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += table[v & 63];
  }
  if (i + 1 == data.size()) {
    std::uint32_t v = data[i] << 16;
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == data.size()) {
    std::uint32_t v = (data[i] << 16) | (data[i + 1] << 8);
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

bool finite(glm::vec3 v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

json vec(glm::vec3 v) {
  return json::array({v.x, v.y, v.z});
}

class Writer {
 public:
  Writer(const Scene& scene, std::string path) : s_(scene), path_(std::move(path)) {}

  // Builds the glTF JSON; the binary payload is left in bin_.
  json build();
  const std::vector<unsigned char>& bin() const { return bin_; }

 private:
  [[noreturn]] void fail(const std::string& problem) const { throw Error(path_ + ": " + problem); }

  int add_view(const void* data, std::size_t size, int target) {
    while (bin_.size() % 4 != 0) bin_.push_back(0);
    json view = {{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", size}};
    if (target) view["target"] = target;
    const auto* bytes = static_cast<const unsigned char*>(data);
    bin_.insert(bin_.end(), bytes, bytes + size);
    views_.push_back(view);
    return static_cast<int>(views_.size()) - 1;
  }
  int add_accessor(int view, int component_type, std::size_t count, const char* type,
                   json min = nullptr, json max = nullptr) {
    json acc = {
        {"bufferView", view}, {"componentType", component_type}, {"count", count}, {"type", type}};
    if (!min.is_null()) acc["min"] = std::move(min);
    if (!max.is_null()) acc["max"] = std::move(max);
    accessors_.push_back(std::move(acc));
    return static_cast<int>(accessors_.size()) - 1;
  }

  void write_textures(json& root);
  void write_materials(json& root);
  void write_meshes(json& root);
  void write_nodes(json& root);

  const Scene& s_;
  std::string path_;
  std::vector<unsigned char> bin_;
  json views_ = json::array();
  json accessors_ = json::array();
  std::vector<int> texture_map_;  // Scene texture -> glTF texture (-1 = not written)
  std::vector<int> mesh_map_;     // Scene mesh -> glTF mesh (-1 = not written)
  std::vector<std::string> extensions_used_;
};

void Writer::write_textures(json& root) {
  json images = json::array(), textures = json::array();
  texture_map_.assign(s_.textures.size(), -1);
  for (std::size_t i = 0; i < s_.textures.size(); ++i) {
    const Texture& t = s_.textures[i];
    if (t.width <= 0 || t.height <= 0 ||
        t.rgba8.size() !=
            static_cast<std::size_t>(t.width) * static_cast<std::size_t>(t.height) * 4)
      continue;  // not a valid image: materials using it lose the texture
    std::vector<unsigned char> png;
    auto sink = [](void* context, void* data, int size) {
      auto* out = static_cast<std::vector<unsigned char>*>(context);
      const auto* bytes = static_cast<const unsigned char*>(data);
      out->insert(out->end(), bytes, bytes + size);
    };
    if (!stbi_write_png_to_func(sink, &png, t.width, t.height, 4, t.rgba8.data(), t.width * 4))
      fail("cannot encode texture " + std::to_string(i) + " as PNG");
    json image = {{"bufferView", add_view(png.data(), png.size(), 0)}, {"mimeType", "image/png"}};
    if (!t.name.empty()) image["name"] = t.name;
    images.push_back(std::move(image));
    json texture = {{"sampler", 0}, {"source", images.size() - 1}};
    if (!t.name.empty()) texture["name"] = t.name;
    textures.push_back(std::move(texture));
    texture_map_[i] = static_cast<int>(textures.size()) - 1;
  }
  if (!textures.empty()) {
    root["images"] = std::move(images);
    root["textures"] = std::move(textures);
    root["samplers"] = json::array(
        {{{"magFilter", 9729}, {"minFilter", 9987}, {"wrapS", 10497}, {"wrapT", 10497}}});
  }
}

void Writer::write_materials(json& root) {
  json materials = json::array();
  bool strength_used = false;
  auto tex = [&](int index, int uv) -> json {
    if (index < 0 || static_cast<std::size_t>(index) >= texture_map_.size() ||
        texture_map_[index] < 0)
      return nullptr;
    json info = {{"index", texture_map_[index]}};
    if (uv == 1) info["texCoord"] = 1;
    return info;
  };
  for (std::size_t i = 0; i < s_.materials.size(); ++i) {
    const Material& m = s_.materials[i];
    if (!finite(m.base_color) || !finite(m.emissive) || !std::isfinite(m.emissive_strength) ||
        !std::isfinite(m.base_alpha) || !std::isfinite(m.alpha_cutoff))
      fail("material " + std::to_string(i) + " has non-finite values");
    json mat = json::object();
    if (!m.name.empty()) mat["name"] = m.name;
    glm::vec3 base = glm::clamp(m.base_color, glm::vec3(0.0f), glm::vec3(1.0f));
    const float alpha = std::clamp(m.base_alpha, 0.0f, 1.0f);
    json pbr = {{"baseColorFactor", {base.x, base.y, base.z, alpha}},
                {"metallicFactor", 0.0f},
                {"roughnessFactor", 1.0f}};
    if (json t = tex(m.base_color_texture, m.base_color_uv); !t.is_null())
      pbr["baseColorTexture"] = std::move(t);
    mat["pbrMetallicRoughness"] = std::move(pbr);
    // emissiveFactor is limited to [0, 1]: brighter emission moves into the strength.
    glm::vec3 emissive = glm::max(m.emissive, glm::vec3(0.0f));
    float strength = std::max(m.emissive_strength, 0.0f);
    float peak = std::max(emissive.x, std::max(emissive.y, emissive.z));
    if (peak > 1.0f) {
      emissive /= peak;
      strength *= peak;
    }
    if (peak > 0.0f) mat["emissiveFactor"] = vec(emissive);
    if (json t = tex(m.emissive_texture, m.emissive_uv); !t.is_null())
      mat["emissiveTexture"] = std::move(t);
    if (strength != 1.0f) {
      mat["extensions"]["KHR_materials_emissive_strength"] = {{"emissiveStrength", strength}};
      strength_used = true;
    }
    if (m.double_sided) mat["doubleSided"] = true;
    if (m.cut_out()) {
      mat["alphaMode"] = "MASK";
      mat["alphaCutoff"] = std::max(m.alpha_cutoff, 0.0f);
    }
    materials.push_back(std::move(mat));
  }
  if (!materials.empty()) root["materials"] = std::move(materials);
  if (strength_used) extensions_used_.push_back("KHR_materials_emissive_strength");
}

void Writer::write_meshes(json& root) {
  json meshes = json::array();
  mesh_map_.assign(s_.meshes.size(), -1);
  for (std::size_t i = 0; i < s_.meshes.size(); ++i) {
    const Mesh& m = s_.meshes[i];
    const std::size_t n = m.positions.size();
    if (m.triangles.empty() || n == 0) continue;  // glTF meshes need at least one primitive
    const std::string what = "mesh " + std::to_string(i);
    if (n > 0xFFFFFFFEu) fail(what + " has too many vertices");
    glm::vec3 lo(INFINITY), hi(-INFINITY);
    for (const glm::vec3& p : m.positions) {
      if (!finite(p)) fail(what + " has non-finite positions");
      lo = glm::min(lo, p);
      hi = glm::max(hi, p);
    }
    for (const glm::uvec3& t : m.triangles)
      if (t.x >= n || t.y >= n || t.z >= n)
        fail(what + " has a triangle index out of range (" + std::to_string(n) + " vertices)");

    // Vertex attributes, shared by every primitive of the mesh.
    json attributes;
    attributes["POSITION"] =
        add_accessor(add_view(m.positions.data(), n * sizeof(glm::vec3), kArrayBuffer), kFloat, n,
                     "VEC3", vec(lo), vec(hi));
    if (m.normals.size() == n) {
      std::vector<glm::vec3> normals(m.normals);
      for (glm::vec3& v : normals) {
        float len = glm::length(v);
        v = finite(v) && len > 0.0f ? v / len : glm::vec3(0.0f, 0.0f, 1.0f);
      }
      attributes["NORMAL"] = add_accessor(
          add_view(normals.data(), n * sizeof(glm::vec3), kArrayBuffer), kFloat, n, "VEC3");
    }
    if (m.uv0.size() == n)
      attributes["TEXCOORD_0"] = add_accessor(
          add_view(m.uv0.data(), n * sizeof(glm::vec2), kArrayBuffer), kFloat, n, "VEC2");
    if (m.uv1.size() == n)
      attributes["TEXCOORD_1"] = add_accessor(
          add_view(m.uv1.data(), n * sizeof(glm::vec2), kArrayBuffer), kFloat, n, "VEC2");

    // One primitive per material, in order of first use.
    std::vector<long> order;
    std::map<long, std::vector<std::uint32_t>> by_material;
    for (std::size_t t = 0; t < m.triangles.size(); ++t) {
      long mat = -1;
      if (t < m.triangle_material.size() && m.triangle_material[t] < s_.materials.size())
        mat = m.triangle_material[t];
      auto [it, inserted] = by_material.try_emplace(mat);
      if (inserted) order.push_back(mat);
      it->second.insert(it->second.end(), {m.triangles[t].x, m.triangles[t].y, m.triangles[t].z});
    }
    json primitives = json::array();
    for (long mat : order) {
      const std::vector<std::uint32_t>& idx = by_material[mat];
      int view;
      int type;
      if (n < 0xFFFF) {
        std::vector<std::uint16_t> small(idx.begin(), idx.end());
        view = add_view(small.data(), small.size() * 2, kElementArrayBuffer);
        type = kUnsignedShort;
      } else {
        view = add_view(idx.data(), idx.size() * 4, kElementArrayBuffer);
        type = kUnsignedInt;
      }
      json prim = {{"attributes", attributes},
                   {"indices", add_accessor(view, type, idx.size(), "SCALAR")},
                   {"mode", 4}};
      if (mat >= 0) prim["material"] = mat;
      primitives.push_back(std::move(prim));
    }
    json mesh = {{"primitives", std::move(primitives)}};
    if (!m.name.empty()) mesh["name"] = m.name;
    meshes.push_back(std::move(mesh));
    mesh_map_[i] = static_cast<int>(meshes.size()) - 1;
  }
  if (!meshes.empty()) root["meshes"] = std::move(meshes);
}

void Writer::write_nodes(json& root) {
  bool hidden = false;
  const int count = static_cast<int>(s_.nodes.size());
  // glTF needs a forest: every node at most one parent, no cycles. Follow the children lists
  // from the roots, keeping the first parent found for each node.
  std::vector<int> parent(count, -2);  // -2 = not reached yet
  std::vector<std::vector<int>> kids(count);
  std::vector<int> scene_roots;
  auto walk = [&](int start) {
    parent[start] = -1;
    std::vector<int> stack{start};
    while (!stack.empty()) {
      int u = stack.back();
      stack.pop_back();
      for (int c : s_.nodes[u].children) {
        if (c < 0 || c >= count || parent[c] != -2) continue;
        parent[c] = u;
        kids[u].push_back(c);
        stack.push_back(c);
      }
    }
  };
  for (int r : s_.roots) {
    if (r < 0 || r >= count || parent[r] != -2) continue;
    walk(r);
    scene_roots.push_back(r);
  }
  for (int i = 0; i < count; ++i)
    if (parent[i] == -2) walk(i);  // outside the scene: written, but not listed in it

  json nodes = json::array();
  for (int i = 0; i < count; ++i) {
    const Node& node = s_.nodes[i];
    json out = json::object();
    if (!node.name.empty()) out["name"] = node.name;
    if (node.local != glm::mat4(1.0f)) {
      json matrix = json::array();
      for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) {
          if (!std::isfinite(node.local[c][r]))
            fail("node " + std::to_string(i) + " has a non-finite transform");
          matrix.push_back(node.local[c][r]);
        }
      out["matrix"] = std::move(matrix);
    }
    if (!kids[i].empty()) out["children"] = kids[i];
    if (node.mesh >= 0 && static_cast<std::size_t>(node.mesh) < mesh_map_.size() &&
        mesh_map_[node.mesh] >= 0)
      out["mesh"] = mesh_map_[node.mesh];
    if (node.camera >= 0 && static_cast<std::size_t>(node.camera) < s_.cameras.size())
      out["camera"] = node.camera;
    if (node.light >= 0 && static_cast<std::size_t>(node.light) < s_.lights.size())
      out["extensions"]["KHR_lights_punctual"] = {{"light", node.light}};
    if (!node.visible) {  // hidden by an edit: the node and its subtree
      out["extensions"]["KHR_node_visibility"] = {{"visible", false}};
      hidden = true;
    }
    if (node.dynamic) out["extras"]["irradcast"] = {{"dynamic", true}};
    nodes.push_back(std::move(out));
  }
  if (!nodes.empty()) root["nodes"] = std::move(nodes);
  if (hidden) extensions_used_.push_back("KHR_node_visibility");
  json scene = {{"nodes", scene_roots}};
  if (!s_.name.empty()) scene["name"] = s_.name;
  root["scenes"] = json::array({scene});
  root["scene"] = 0;
}

json Writer::build() {
  json root;
  root["asset"] = {{"version", "2.0"}, {"generator", "irradcast"}};
  write_textures(root);
  write_materials(root);
  write_meshes(root);

  if (!s_.cameras.empty()) {
    json cameras = json::array();
    for (std::size_t i = 0; i < s_.cameras.size(); ++i) {
      const Camera& c = s_.cameras[i];
      if (!std::isfinite(c.yfov) || !std::isfinite(c.znear) || !std::isfinite(c.zfar) ||
          !std::isfinite(c.aspect_ratio) || c.yfov <= 0.0f)
        fail("camera " + std::to_string(i) + " has invalid parameters");
      float znear = c.znear > 0.0f ? c.znear : 0.01f;
      json p = {{"yfov", c.yfov}, {"znear", znear}};
      if (c.aspect_ratio > 0.0f) p["aspectRatio"] = c.aspect_ratio;
      if (c.zfar > znear) p["zfar"] = c.zfar;
      json cam = {{"type", "perspective"}, {"perspective", std::move(p)}};
      if (!c.name.empty()) cam["name"] = c.name;
      cameras.push_back(std::move(cam));
    }
    root["cameras"] = std::move(cameras);
  }

  if (!s_.lights.empty()) {
    json lights = json::array();
    for (std::size_t i = 0; i < s_.lights.size(); ++i) {
      const Light& l = s_.lights[i];
      if (!finite(l.color) || !std::isfinite(l.intensity) || !std::isfinite(l.range) ||
          !std::isfinite(l.inner_cone_angle) || !std::isfinite(l.outer_cone_angle))
        fail("light " + std::to_string(i) + " has non-finite parameters");
      json light = {{"color", vec(glm::max(l.color, glm::vec3(0.0f)))},
                    {"intensity", std::max(l.intensity, 0.0f)}};
      switch (l.type) {
        case Light::Type::Point:
          light["type"] = "point";
          break;
        case Light::Type::Directional:
          light["type"] = "directional";
          break;
        case Light::Type::Spot: {
          light["type"] = "spot";
          float outer = std::clamp(l.outer_cone_angle, 1e-6f, 1.5707963f);
          float inner = std::clamp(l.inner_cone_angle, 0.0f, outer);
          light["spot"] = {{"innerConeAngle", inner}, {"outerConeAngle", outer}};
          break;
        }
      }
      if (l.range > 0.0f && l.type != Light::Type::Directional) light["range"] = l.range;
      if (!l.name.empty()) light["name"] = l.name;
      lights.push_back(std::move(light));
    }
    root["extensions"]["KHR_lights_punctual"] = {{"lights", std::move(lights)}};
    extensions_used_.push_back("KHR_lights_punctual");
  }

  write_nodes(root);
  if (!extensions_used_.empty()) root["extensionsUsed"] = extensions_used_;
  if (!views_.empty()) {
    root["bufferViews"] = views_;
    root["accessors"] = accessors_;
  }
  return root;
}

void put_u32(std::string& out, std::uint32_t v) {
  char b[4];
  std::memcpy(b, &v, 4);
  out.append(b, 4);
}

}  // namespace

void save_gltf(const Scene& scene, const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext != ".gltf" && ext != ".glb")
    throw Error(path + ": unsupported extension \"" + ext + "\" (use .gltf or .glb)");
  const bool binary = ext == ".glb";

  Writer writer(scene, path);
  json root = writer.build();
  const std::vector<unsigned char>& bin = writer.bin();
  if (!bin.empty()) {
    json buffer = {{"byteLength", bin.size()}};
    if (!binary) buffer["uri"] = "data:application/octet-stream;base64," + base64(bin);
    root["buffers"] = json::array({buffer});
  }

  std::string out;
  if (binary) {
    std::string text = root.dump();
    while (text.size() % 4 != 0) text += ' ';
    std::size_t bin_padded = (bin.size() + 3) / 4 * 4;
    std::size_t total = 12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin_padded);
    if (total > 0xFFFFFFFFu) throw Error(path + ": scene too large for a GLB file (4 GiB)");
    out.reserve(total);
    out.append("glTF", 4);
    put_u32(out, 2);
    put_u32(out, static_cast<std::uint32_t>(total));
    put_u32(out, static_cast<std::uint32_t>(text.size()));
    put_u32(out, 0x4E4F534Au);  // "JSON"
    out += text;
    if (!bin.empty()) {
      put_u32(out, static_cast<std::uint32_t>(bin_padded));
      put_u32(out, 0x004E4942u);  // "BIN\0"
      out.append(reinterpret_cast<const char*>(bin.data()), bin.size());
      out.append(bin_padded - bin.size(), '\0');
    }
  } else {
    out = root.dump(1);
    out += '\n';
  }

  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) throw Error(path + ": cannot open the file for writing");
  file.write(out.data(), static_cast<std::streamsize>(out.size()));
  file.close();
  if (!file) throw Error(path + ": write failed");
}

}  // namespace irradcast

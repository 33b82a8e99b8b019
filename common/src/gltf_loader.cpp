// glTF 2.0 import: tinygltf parses the JSON / GLB container and loads buffers and images; every
// index, range and value is validated here before any memory is read.
#include <tiny_gltf.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <nlohmann/json.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/log.h"

namespace irradcast {
namespace {

// Accessors without a bufferView (zeros, optionally overridden by sparse values) are allocated
// from their declared count alone: cap it so a hostile file cannot ask for gigabytes.
constexpr std::size_t kMaxUnbackedElements = std::size_t{1} << 24;

// Collapses tinygltf's multi-line messages into one line.
std::string one_line(const std::string& text) {
  std::string out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty()) continue;
    if (!out.empty()) out += "; ";
    out += line;
  }
  for (char& c : out)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = ' ';
  return out;
}

// A name from the file, safe for a one-line message: control characters replaced, length capped.
std::string clean(const std::string& text) {
  std::string out = text.substr(0, 80);
  for (char& c : out)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  if (text.size() > 80) out += "...";
  return out;
}

std::string quoted(const std::string& name) {
  return name.empty() ? "" : " (\"" + clean(name) + "\")";
}

// a + b <= limit without overflow.
bool fits(std::size_t a, std::size_t b, std::size_t limit) {
  return a <= limit && b <= limit - a;
}

int component_size(int component_type) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return 4;
    default:
      return 0;
  }
}

const char* component_name(int component_type) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
      return "BYTE";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return "UNSIGNED_BYTE";
    case TINYGLTF_COMPONENT_TYPE_SHORT:
      return "SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return "UNSIGNED_SHORT";
    case TINYGLTF_COMPONENT_TYPE_INT:
      return "INT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
      return "UNSIGNED_INT";
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return "FLOAT";
    case TINYGLTF_COMPONENT_TYPE_DOUBLE:
      return "DOUBLE";
    default:
      return "unknown";
  }
}

const char* type_name(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR:
      return "SCALAR";
    case TINYGLTF_TYPE_VEC2:
      return "VEC2";
    case TINYGLTF_TYPE_VEC3:
      return "VEC3";
    case TINYGLTF_TYPE_VEC4:
      return "VEC4";
    case TINYGLTF_TYPE_MAT2:
      return "MAT2";
    case TINYGLTF_TYPE_MAT3:
      return "MAT3";
    case TINYGLTF_TYPE_MAT4:
      return "MAT4";
    default:
      return "unknown";
  }
}

// One component at p (little-endian, as glTF stores it), normalized if asked.
double load_component(const unsigned char* p, int component_type, bool normalized) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      std::int8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? std::max(v / 127.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return normalized ? p[0] / 255.0 : p[0];
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      std::int16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      std::uint32_t v;
      std::memcpy(&v, p, 4);
      return normalized ? v / 4294967295.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default:
      return 0.0;
  }
}

// What a caller accepts from an accessor.
struct AccessorKind {
  int type;                          // TINYGLTF_TYPE_*
  int components;                    // components per element
  std::vector<int> component_types;  // allowed
  bool require_normalized_ints;      // integer components must be normalized (TEXCOORD_n)
};

class Loader {
 public:
  Loader(std::string path, const tinygltf::Model& model, LoadReport* report)
      : path_(std::move(path)), m_(model), report_(report) {}

  Scene run();

  [[noreturn]] void fail(const std::string& problem) const { throw Error(path_ + ": " + problem); }
  void warn(const std::string& message) {
    log::warn("gltf", path_ + ": " + message);
    if (report_) report_->warnings.push_back(message);
  }

 private:
  // Validated bytes of a bufferView: [data, data + length).
  struct View {
    const unsigned char* data = nullptr;
    std::size_t length = 0;
    std::size_t stride = 0;  // 0 = tightly packed
  };
  View view(int index, const std::string& what) const;

  template <class T>
  std::vector<T> read_accessor(int index, const std::string& what, const AccessorKind& kind) const;

  void convert_materials(Scene& scene);
  int texture(int index, int tex_coord, const std::string& what, Scene& scene, int* uv_set);
  int image(int index, Scene& scene);
  void convert_meshes(Scene& scene);
  void convert_mesh(int index, Scene& scene);
  void convert_cameras(Scene& scene);
  void convert_lights(Scene& scene);
  void convert_nodes(Scene& scene);

  int default_material(Scene& scene) {
    if (default_material_ < 0) {
      Material def;
      def.name = "default";
      def.base_color = glm::vec3(1.0f);  // glTF's default baseColorFactor
      default_material_ = static_cast<int>(scene.materials.size());
      scene.materials.push_back(def);
    }
    return default_material_;
  }

  std::string path_;
  const tinygltf::Model& m_;
  LoadReport* report_;
  int default_material_ = -1;
  std::map<int, int> image_to_texture_;  // glTF image -> Scene::textures index (-1 = unusable)
  std::vector<int> camera_map_;          // glTF camera -> Scene::cameras index (-1 = skipped)
  std::vector<int> light_map_;           // glTF light -> Scene::lights index (-1 = skipped)
};

Loader::View Loader::view(int index, const std::string& what) const {
  if (index < 0 || static_cast<std::size_t>(index) >= m_.bufferViews.size())
    fail(what + " refers to bufferView " + std::to_string(index) + ", which does not exist");
  const tinygltf::BufferView& bv = m_.bufferViews[index];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= m_.buffers.size())
    fail("bufferView " + std::to_string(index) + " refers to buffer " + std::to_string(bv.buffer) +
         ", which does not exist");
  const tinygltf::Buffer& buf = m_.buffers[bv.buffer];
  if (!fits(bv.byteOffset, bv.byteLength, buf.data.size()))
    fail("bufferView " + std::to_string(index) + " (byteOffset " + std::to_string(bv.byteOffset) +
         ", byteLength " + std::to_string(bv.byteLength) + ") runs past the end of buffer " +
         std::to_string(bv.buffer) + " (" + std::to_string(buf.data.size()) + " bytes)");
  return View{buf.data.data() + bv.byteOffset, bv.byteLength, bv.byteStride};
}

template <class T>
std::vector<T> Loader::read_accessor(int index, const std::string& what,
                                     const AccessorKind& kind) const {
  if (index < 0 || static_cast<std::size_t>(index) >= m_.accessors.size())
    fail(what + " refers to accessor " + std::to_string(index) + ", which does not exist");
  const tinygltf::Accessor& acc = m_.accessors[index];
  const std::string name = "accessor " + std::to_string(index) + " (" + what + ")";
  if (acc.type != kind.type)
    fail(name + " has type " + type_name(acc.type) + ", expected " + type_name(kind.type));
  if (std::find(kind.component_types.begin(), kind.component_types.end(), acc.componentType) ==
      kind.component_types.end()) {
    std::string allowed;
    for (int ct : kind.component_types)
      allowed += std::string(allowed.empty() ? "" : " or ") + component_name(ct);
    fail(name + " has bad component type " + std::to_string(acc.componentType) + " (" +
         component_name(acc.componentType) + "), expected " + allowed);
  }
  const bool is_int = acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT;
  if (kind.require_normalized_ints && is_int && !acc.normalized)
    fail(name + " has integer components that are not normalized");
  const bool normalized = is_int && acc.normalized && kind.require_normalized_ints;
  const std::size_t comp = static_cast<std::size_t>(component_size(acc.componentType));
  const std::size_t ncomp = static_cast<std::size_t>(kind.components);
  const std::size_t elem = comp * ncomp;
  const std::size_t count = acc.count;

  std::vector<T> out;
  if (acc.bufferView >= 0) {
    View v = view(acc.bufferView, name);
    const std::size_t stride = v.stride ? v.stride : elem;
    if (stride < elem)
      fail(name + ": bufferView " + std::to_string(acc.bufferView) + " has byteStride " +
           std::to_string(stride) + ", smaller than the element size " + std::to_string(elem));
    if (count > 0) {
      // byteOffset + (count - 1) * stride + elem <= view length, without overflow.
      std::size_t span = 0;
      if (__builtin_mul_overflow(count - 1, stride, &span) ||
          !fits(acc.byteOffset, span, v.length) || !fits(acc.byteOffset + span, elem, v.length))
        fail(name + " reads past the end of bufferView " + std::to_string(acc.bufferView) + " (" +
             std::to_string(count) + " elements of " + std::to_string(elem) + " bytes, stride " +
             std::to_string(stride) + ", byteOffset " + std::to_string(acc.byteOffset) +
             ", bufferView byteLength " + std::to_string(v.length) + ")");
    }
    out.resize(count * ncomp);
    const unsigned char* base = v.data + acc.byteOffset;
    for (std::size_t i = 0; i < count; ++i)
      for (std::size_t c = 0; c < ncomp; ++c)
        out[i * ncomp + c] = static_cast<T>(
            load_component(base + i * stride + c * comp, acc.componentType, normalized));
  } else {
    if (count > kMaxUnbackedElements)
      fail(name + " has no bufferView and a count of " + std::to_string(count) +
           ", which is too large");
    out.assign(count * ncomp, T(0));
  }

  if (acc.sparse.isSparse) {
    const auto& sp = acc.sparse;
    if (sp.count < 1 || static_cast<std::size_t>(sp.count) > count)
      fail(name + " has a sparse count of " + std::to_string(sp.count) + " (accessor count " +
           std::to_string(count) + ")");
    const std::size_t n = static_cast<std::size_t>(sp.count);
    const int ict = sp.indices.componentType;
    if (ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
      fail(name + " has sparse indices of bad component type " + std::to_string(ict) + " (" +
           component_name(ict) + "), expected UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT");
    const std::size_t isize = static_cast<std::size_t>(component_size(ict));
    if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0)
      fail(name + " has a negative sparse byteOffset");
    View iv = view(sp.indices.bufferView, name + " sparse indices");
    View vv = view(sp.values.bufferView, name + " sparse values");
    const std::size_t ioff = static_cast<std::size_t>(sp.indices.byteOffset);
    const std::size_t voff = static_cast<std::size_t>(sp.values.byteOffset);
    // n <= count, and count * elem fits in memory already (out was allocated), so no overflow.
    if (!fits(ioff, n * isize, iv.length))
      fail(name + " sparse indices read past the end of bufferView " +
           std::to_string(sp.indices.bufferView));
    if (!fits(voff, n * elem, vv.length))
      fail(name + " sparse values read past the end of bufferView " +
           std::to_string(sp.values.bufferView));
    for (std::size_t k = 0; k < n; ++k) {
      const double target = load_component(iv.data + ioff + k * isize, ict, false);
      if (target >= static_cast<double>(count))
        fail(name + " has sparse index " + std::to_string(static_cast<std::uint64_t>(target)) +
             " out of range (accessor count " + std::to_string(count) + ")");
      const std::size_t t = static_cast<std::size_t>(target);
      for (std::size_t c = 0; c < ncomp; ++c)
        out[t * ncomp + c] = static_cast<T>(
            load_component(vv.data + voff + k * elem + c * comp, acc.componentType, normalized));
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Materials and textures

int Loader::image(int index, Scene& scene) {
  auto it = image_to_texture_.find(index);
  if (it != image_to_texture_.end()) return it->second;
  const tinygltf::Image& img = m_.images[index];
  const std::string label =
      "image " + std::to_string(index) + quoted(img.name.empty() ? img.uri : img.name);
  int result = -1;
  const std::size_t w = img.width > 0 ? static_cast<std::size_t>(img.width) : 0;
  const std::size_t h = img.height > 0 ? static_cast<std::size_t>(img.height) : 0;
  const std::size_t c = img.component > 0 ? static_cast<std::size_t>(img.component) : 0;
  const std::size_t bytes = img.bits == 16 ? 2 : 1;
  if (img.image.empty()) {
    warn(label + " could not be loaded; its textures are ignored");
  } else if (w == 0 || h == 0 || c < 1 || c > 4 || (img.bits != 8 && img.bits != 16) ||
             w > (std::size_t{1} << 16) || h > (std::size_t{1} << 16) ||
             img.image.size() < w * h * c * bytes) {
    warn(label + " has an unsupported pixel layout (" + std::to_string(img.width) + "x" +
         std::to_string(img.height) + ", " + std::to_string(img.component) + " channels, " +
         std::to_string(img.bits) + " bits); its textures are ignored");
  } else {
    Texture tex;
    tex.name = img.name.empty() ? img.uri : img.name;
    if (tex.name.rfind("data:", 0) == 0) tex.name.clear();
    tex.width = img.width;
    tex.height = img.height;
    tex.rgba8.resize(w * h * 4);
    const unsigned char* src = img.image.data();
    auto channel = [&](std::size_t pixel, std::size_t ch) -> std::uint8_t {
      const unsigned char* p = src + (pixel * c + ch) * bytes;
      if (bytes == 1) return p[0];
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return static_cast<std::uint8_t>((v + 128u) / 257u);
    };
    for (std::size_t i = 0; i < w * h; ++i) {
      std::uint8_t* d = &tex.rgba8[i * 4];
      if (c <= 2) {
        d[0] = d[1] = d[2] = channel(i, 0);
        d[3] = c == 2 ? channel(i, 1) : 255;
      } else {
        d[0] = channel(i, 0);
        d[1] = channel(i, 1);
        d[2] = channel(i, 2);
        d[3] = c == 4 ? channel(i, 3) : 255;
      }
    }
    result = static_cast<int>(scene.textures.size());
    scene.textures.push_back(std::move(tex));
  }
  image_to_texture_[index] = result;
  return result;
}

int Loader::texture(int index, int tex_coord, const std::string& what, Scene& scene, int* uv_set) {
  if (index < 0) return -1;
  if (static_cast<std::size_t>(index) >= m_.textures.size())
    fail(what + " refers to texture " + std::to_string(index) + ", which does not exist");
  if (tex_coord != 0 && tex_coord != 1) {
    warn(what + " uses TEXCOORD_" + std::to_string(tex_coord) +
         "; only TEXCOORD_0 and TEXCOORD_1 are supported, the texture is ignored");
    return -1;
  }
  const tinygltf::Texture& t = m_.textures[index];
  if (t.source < 0) {
    warn("texture " + std::to_string(index) +
         " has no source image (extension image formats are not supported); it is ignored");
    return -1;
  }
  if (static_cast<std::size_t>(t.source) >= m_.images.size())
    fail("texture " + std::to_string(index) + " refers to image " + std::to_string(t.source) +
         ", which does not exist");
  int result = image(t.source, scene);
  if (result >= 0) *uv_set = tex_coord;
  return result;
}

void Loader::convert_materials(Scene& scene) {
  auto finite3 = [](const std::vector<double>& v) {
    return v.size() >= 3 && std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
  };
  for (std::size_t i = 0; i < m_.materials.size(); ++i) {
    const tinygltf::Material& gm = m_.materials[i];
    const std::string what = "material " + std::to_string(i) + quoted(gm.name);
    Material mat;
    mat.name = gm.name;
    const auto& pbr = gm.pbrMetallicRoughness;
    mat.base_color = glm::vec3(1.0f);
    if (!pbr.baseColorFactor.empty()) {
      if (!finite3(pbr.baseColorFactor)) fail(what + " has an invalid baseColorFactor");
      mat.base_color =
          glm::vec3(pbr.baseColorFactor[0], pbr.baseColorFactor[1], pbr.baseColorFactor[2]);
    }
    mat.base_color_texture = texture(pbr.baseColorTexture.index, pbr.baseColorTexture.texCoord,
                                     what + " baseColorTexture", scene, &mat.base_color_uv);
    mat.emissive = glm::vec3(0.0f);
    if (!gm.emissiveFactor.empty()) {
      if (!finite3(gm.emissiveFactor)) fail(what + " has an invalid emissiveFactor");
      mat.emissive = glm::vec3(gm.emissiveFactor[0], gm.emissiveFactor[1], gm.emissiveFactor[2]);
    }
    mat.emissive_texture = texture(gm.emissiveTexture.index, gm.emissiveTexture.texCoord,
                                   what + " emissiveTexture", scene, &mat.emissive_uv);
    auto ext = gm.extensions.find("KHR_materials_emissive_strength");
    if (ext != gm.extensions.end() && ext->second.Has("emissiveStrength")) {
      const tinygltf::Value& s = ext->second.Get("emissiveStrength");
      if (!s.IsNumber() || !std::isfinite(s.GetNumberAsDouble()) || s.GetNumberAsDouble() < 0.0)
        fail(what + " has an invalid KHR_materials_emissive_strength emissiveStrength");
      mat.emissive_strength = static_cast<float>(s.GetNumberAsDouble());
    }
    mat.double_sided = gm.doubleSided;
    scene.materials.push_back(std::move(mat));
  }
}

// ---------------------------------------------------------------------------------------------
// Meshes

// The vertices of one primitive (or several primitives sharing the same attribute accessors).
struct Block {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;  // empty = compute
  std::vector<glm::vec2> uv0, uv1;
};

void Loader::convert_meshes(Scene& scene) {
  for (std::size_t i = 0; i < m_.meshes.size(); ++i) convert_mesh(static_cast<int>(i), scene);
}

void Loader::convert_mesh(int index, Scene& scene) {
  const tinygltf::Mesh& gm = m_.meshes[index];
  Mesh mesh;
  mesh.name = gm.name;
  std::vector<Block> blocks;
  std::vector<std::size_t> block_base;  // first vertex of each block in the merged mesh
  std::size_t vertex_total = 0;
  std::map<std::tuple<int, int, int, int>, std::size_t> block_of;  // attribute accessors -> block

  const AccessorKind vec3_float{TINYGLTF_TYPE_VEC3, 3, {TINYGLTF_COMPONENT_TYPE_FLOAT}, false};
  const AccessorKind texcoord{TINYGLTF_TYPE_VEC2,
                              2,
                              {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                               TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT},
                              true};
  const AccessorKind index_kind{
      TINYGLTF_TYPE_SCALAR,
      1,
      {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
       TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT},
      false};

  for (std::size_t p = 0; p < gm.primitives.size(); ++p) {
    const tinygltf::Primitive& prim = gm.primitives[p];
    const std::string what =
        "mesh " + std::to_string(index) + quoted(gm.name) + " primitive " + std::to_string(p);
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE ||
        mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP) {
      static const char* names[] = {"POINTS", "LINES", "LINE_LOOP", "LINE_STRIP"};
      warn(what + " has mode " + names[mode] + "; only triangles are supported, it is skipped");
      continue;
    }
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        mode != TINYGLTF_MODE_TRIANGLE_FAN)
      fail(what + " has an unknown mode " + std::to_string(mode));

    auto attr = [&](const char* key) {
      auto it = prim.attributes.find(key);
      return it == prim.attributes.end() ? -1 : it->second;
    };
    const int pos_acc = attr("POSITION");
    if (pos_acc < 0) fail(what + " has no POSITION attribute");
    const auto key =
        std::make_tuple(pos_acc, attr("NORMAL"), attr("TEXCOORD_0"), attr("TEXCOORD_1"));

    std::size_t b;
    auto found = block_of.find(key);
    if (found != block_of.end()) {
      b = found->second;
    } else {
      Block block;
      std::vector<float> pos = read_accessor<float>(pos_acc, what + " POSITION", vec3_float);
      const std::size_t n = pos.size() / 3;
      for (float f : pos)
        if (!std::isfinite(f)) fail(what + " has non-finite (NaN or infinite) POSITION values");
      block.positions.resize(n);
      for (std::size_t v = 0; v < n; ++v)
        block.positions[v] = glm::vec3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]);
      auto check_count = [&](std::size_t got, const char* name) {
        if (got != n)
          fail(what + " attribute " + name + " has " + std::to_string(got) +
               " elements but POSITION has " + std::to_string(n));
      };
      if (std::get<1>(key) >= 0) {
        std::vector<float> nrm =
            read_accessor<float>(std::get<1>(key), what + " NORMAL", vec3_float);
        check_count(nrm.size() / 3, "NORMAL");
        bool finite = std::all_of(nrm.begin(), nrm.end(), [](float f) { return std::isfinite(f); });
        if (!finite) {
          warn(what + " has non-finite NORMAL values; normals are recomputed");
        } else {
          block.normals.resize(n);
          for (std::size_t v = 0; v < n; ++v)
            block.normals[v] = glm::vec3(nrm[3 * v], nrm[3 * v + 1], nrm[3 * v + 2]);
        }
      }
      auto read_uv = [&](int acc, const char* name, std::vector<glm::vec2>& dst) {
        if (acc < 0) return;
        std::vector<float> uv = read_accessor<float>(acc, what + " " + name, texcoord);
        check_count(uv.size() / 2, name);
        bool finite = std::all_of(uv.begin(), uv.end(), [](float f) { return std::isfinite(f); });
        if (!finite) {
          warn(what + " has non-finite " + name + " values; they are set to 0");
          for (float& f : uv)
            if (!std::isfinite(f)) f = 0.0f;
        }
        dst.resize(n);
        for (std::size_t v = 0; v < n; ++v) dst[v] = glm::vec2(uv[2 * v], uv[2 * v + 1]);
      };
      read_uv(std::get<2>(key), "TEXCOORD_0", block.uv0);
      read_uv(std::get<3>(key), "TEXCOORD_1", block.uv1);
      if (!fits(vertex_total, n, std::numeric_limits<std::uint32_t>::max()))
        fail("mesh " + std::to_string(index) + quoted(gm.name) + " has too many vertices");
      b = blocks.size();
      block_of[key] = b;
      block_base.push_back(vertex_total);
      vertex_total += n;
      blocks.push_back(std::move(block));
    }
    const std::size_t n = blocks[b].positions.size();
    const std::uint32_t base = static_cast<std::uint32_t>(block_base[b]);

    std::vector<std::uint32_t> idx;
    if (prim.indices >= 0) {
      idx = read_accessor<std::uint32_t>(prim.indices, what + " indices", index_kind);
      for (std::size_t k = 0; k < idx.size(); ++k)
        if (idx[k] >= n)
          fail(what + " index " + std::to_string(idx[k]) + " (at position " + std::to_string(k) +
               ") is out of range: the primitive has " + std::to_string(n) + " vertices");
    } else {
      idx.resize(n);
      for (std::size_t k = 0; k < n; ++k) idx[k] = static_cast<std::uint32_t>(k);
    }

    int material;
    if (prim.material >= 0) {
      if (static_cast<std::size_t>(prim.material) >= m_.materials.size())
        fail(what + " refers to material " + std::to_string(prim.material) +
             ", which does not exist");
      material = prim.material;
    } else {
      material = default_material(scene);
    }

    auto emit = [&](std::uint32_t a, std::uint32_t b2, std::uint32_t c, bool drop_degenerate) {
      if (drop_degenerate && (a == b2 || b2 == c || a == c)) return;
      mesh.triangles.emplace_back(base + a, base + b2, base + c);
      mesh.triangle_material.push_back(static_cast<std::uint32_t>(material));
    };
    const std::size_t count = idx.size();
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      if (count % 3 != 0)
        warn(what + " has " + std::to_string(count) +
             " indices, not a multiple of 3; the trailing ones are ignored");
      for (std::size_t k = 0; k + 2 < count; k += 3) emit(idx[k], idx[k + 1], idx[k + 2], false);
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      for (std::size_t k = 0; k + 2 < count; ++k) {
        if (k % 2 == 0)
          emit(idx[k], idx[k + 1], idx[k + 2], true);
        else
          emit(idx[k], idx[k + 2], idx[k + 1], true);
      }
    } else {  // fan
      for (std::size_t k = 0; k + 2 < count; ++k) emit(idx[k + 1], idx[k + 2], idx[0], true);
    }
  }

  // Merge the blocks; attributes some blocks lack are filled (zeros for UVs, smooth normals).
  bool any_normals = false, missing_normals = false, any_uv0 = false, any_uv1 = false;
  for (const Block& bl : blocks) {
    (bl.normals.empty() ? missing_normals : any_normals) = true;
    any_uv0 |= !bl.uv0.empty();
    any_uv1 |= !bl.uv1.empty();
  }
  if (!mesh.triangles.empty()) {
    mesh.positions.reserve(vertex_total);
    for (const Block& bl : blocks)
      mesh.positions.insert(mesh.positions.end(), bl.positions.begin(), bl.positions.end());
    auto merge = [&](bool any, std::vector<glm::vec2> Block::*member, std::vector<glm::vec2>& dst) {
      if (!any) return;
      dst.reserve(vertex_total);
      for (const Block& bl : blocks) {
        const auto& src = bl.*member;
        if (src.empty())
          dst.insert(dst.end(), bl.positions.size(), glm::vec2(0.0f));
        else
          dst.insert(dst.end(), src.begin(), src.end());
      }
    };
    merge(any_uv0, &Block::uv0, mesh.uv0);
    merge(any_uv1, &Block::uv1, mesh.uv1);
    if (any_normals) {
      std::vector<glm::vec3> computed;
      if (missing_normals) {
        computed.assign(vertex_total, glm::vec3(0.0f));
        for (const glm::uvec3& t : mesh.triangles) {
          glm::vec3 n = glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                                   mesh.positions[t.z] - mesh.positions[t.x]);
          computed[t.x] += n;
          computed[t.y] += n;
          computed[t.z] += n;
        }
        for (glm::vec3& n : computed) {
          float len = glm::length(n);
          n = len > 0.0f && std::isfinite(len) ? n / len : glm::vec3(0.0f, 0.0f, 1.0f);
        }
      }
      mesh.normals.reserve(vertex_total);
      for (std::size_t b = 0; b < blocks.size(); ++b) {
        const Block& bl = blocks[b];
        if (bl.normals.empty())
          mesh.normals.insert(mesh.normals.end(), computed.begin() + block_base[b],
                              computed.begin() + block_base[b] + bl.positions.size());
        else
          mesh.normals.insert(mesh.normals.end(), bl.normals.begin(), bl.normals.end());
      }
    }
  } else if (!gm.primitives.empty()) {
    warn("mesh " + std::to_string(index) + quoted(gm.name) +
         " has no triangles; nodes using it get no mesh");
  }
  scene.meshes.push_back(std::move(mesh));
}

// ---------------------------------------------------------------------------------------------
// Cameras, lights, nodes

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
  const std::size_t count = m_.nodes.size();
  scene.nodes.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    const tinygltf::Node& gn = m_.nodes[i];
    const std::string what = "node " + std::to_string(i) + quoted(gn.name);
    Node& node = scene.nodes[i];
    node.name = gn.name;
    auto all_finite = [](const std::vector<double>& v) {
      return std::all_of(v.begin(), v.end(), [](double d) { return std::isfinite(d); });
    };
    if (!gn.matrix.empty()) {
      if (gn.matrix.size() != 16 || !all_finite(gn.matrix)) fail(what + " has an invalid matrix");
      float f[16];
      for (int k = 0; k < 16; ++k) f[k] = static_cast<float>(gn.matrix[k]);
      node.local = glm::make_mat4(f);  // glTF matrices are column-major, like glm
    } else {
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
      node.local = t * r * s;
    }
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
  {
    enum : std::uint8_t { kUnknown, kOnWalk, kReachesRoot };
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

Scene Loader::run() {
  Scene scene;
  convert_materials(scene);
  convert_meshes(scene);
  convert_cameras(scene);
  convert_lights(scene);
  convert_nodes(scene);
  if (scene.name.empty()) scene.name = std::filesystem::path(path_).stem().string();
  return scene;
}

std::uint32_t read_u32(const unsigned char* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

// tinygltf decodes images stored in bufferViews without checking that the view lies inside its
// buffer: check that on the raw JSON first. (Buffers end up exactly byteLength bytes long.)
void check_image_views(const std::string& path, const nlohmann::json& j) {
  if (!j.contains("images") || !j["images"].is_array()) return;
  auto fail = [&](const std::string& problem) { throw Error(path + ": " + problem); };
  auto uint_field = [&](const nlohmann::json& o, const char* key, std::uint64_t fallback,
                        const std::string& what) -> std::uint64_t {
    if (!o.contains(key)) return fallback;
    if (!o[key].is_number_unsigned() &&
        !(o[key].is_number_integer() && o[key].get<std::int64_t>() >= 0))
      fail(what + " has an invalid " + key);
    return o[key].get<std::uint64_t>();
  };
  const nlohmann::json& images = j["images"];
  for (std::size_t i = 0; i < images.size(); ++i) {
    const nlohmann::json& img = images[i];
    if (!img.is_object() || !img.contains("bufferView")) continue;
    const std::string what = "image " + std::to_string(i);
    const std::uint64_t v = uint_field(img, "bufferView", 0, what);
    if (!j.contains("bufferViews") || !j["bufferViews"].is_array() ||
        v >= j["bufferViews"].size() || !j["bufferViews"][v].is_object())
      fail(what + " refers to bufferView " + std::to_string(v) + ", which does not exist");
    const nlohmann::json& view = j["bufferViews"][v];
    const std::string vwhat = "bufferView " + std::to_string(v);
    const std::uint64_t b = uint_field(view, "buffer", ~std::uint64_t{0}, vwhat);
    const std::uint64_t offset = uint_field(view, "byteOffset", 0, vwhat);
    const std::uint64_t len = uint_field(view, "byteLength", 0, vwhat);
    if (!j.contains("buffers") || !j["buffers"].is_array() || b >= j["buffers"].size() ||
        !j["buffers"][b].is_object())
      fail(vwhat + " refers to buffer " + std::to_string(b) + ", which does not exist");
    const std::uint64_t size =
        uint_field(j["buffers"][b], "byteLength", 0, "buffer " + std::to_string(b));
    if (offset > size || len > size - offset || len > 0x7fffffffu)
      fail(vwhat + " (byteOffset " + std::to_string(offset) + ", byteLength " +
           std::to_string(len) + ") of " + what + " runs past the end of buffer " +
           std::to_string(b) + " (" + std::to_string(size) + " bytes)");
  }
}

// ---------------------------------------------------------------------------------------------
// External files. Every buffer and image URI must name a regular file inside the scene file's
// folder (or the root the caller gives), after following symlinks: a scene must not make the
// server read (and send to every client) a file elsewhere, nor block on a FIFO or a device.
// check_uris() refuses such a URI by name before tinygltf runs; tinygltf then reads files only
// through the callbacks below, which apply the same rule (and never look in the working
// directory, which tinygltf tries after the base folder).

namespace fs = std::filesystem;

struct FileGuard {
  std::string base;     // the folder tinygltf joins URIs to (absolute)
  fs::path root;        // every file read must resolve to a path under this (canonical)
  std::string refused;  // the first file a callback refused, and why
};

// What tinygltf (dlib::urldecode) makes of a URI before it joins it to the folder: %XX decoded,
// '+' read as a space.
std::string decode_uri(const std::string& uri) {
  auto hex = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return 0;  // as tinygltf does
  };
  std::string out;
  for (std::size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '+') {
      out += ' ';
    } else if (uri[i] == '%' && uri.size() > i + 2) {
      out += static_cast<char>((hex(uri[i + 1]) << 4) | hex(uri[i + 2]));
      i += 2;
    } else {
      out += uri[i];
    }
  }
  return out;
}

// Why `file` may not be read ("" if it may): it must resolve, symlinks followed, to a path under
// `root` that is a regular file. A file that does not exist is left to tinygltf ("not found").
std::string refusal(const fs::path& file, const fs::path& root) {
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(file, ec);
  if (ec) return "it cannot be resolved (" + ec.message() + ")";
  const fs::path rel = resolved.lexically_relative(root);
  if (rel.empty() || *rel.begin() == "..")
    return "it resolves to " + clean(resolved.string()) + ", outside " + clean(root.string());
  const fs::file_status st = fs::status(resolved, ec);
  if (!fs::exists(st)) return "";
  if (!fs::is_regular_file(st)) return "it is not a regular file";
  return "";
}

bool guarded_file_exists(const std::string& file, void* user) {
  auto* g = static_cast<FileGuard*>(user);
  const std::string prefix = g->base.back() == '/' ? g->base : g->base + "/";
  if (file.compare(0, prefix.size(), prefix) != 0) return false;  // e.g. "./uri": never the cwd
  const std::string why = refusal(file, g->root);
  if (!why.empty()) {
    if (g->refused.empty()) g->refused = "'" + clean(file.substr(prefix.size())) + "': " + why;
    return false;
  }
  std::error_code ec;
  return fs::is_regular_file(file, ec);
}

std::string no_expansion(const std::string& file, void*) {
  return file;
}

bool guarded_read(std::vector<unsigned char>* out, std::string* err, const std::string& file,
                  void* user) {
  auto fail = [&](const std::string& why) {
    if (err) *err = why;
    return false;
  };
  if (!guarded_file_exists(file, user)) return fail("refused or not found");
  std::error_code ec;
  const fs::path resolved = fs::canonical(file, ec);
  if (ec) return fail(ec.message());
  // O_NONBLOCK: should the file have become a FIFO since the check, opening it does not block.
  const int fd =
      ::open(resolved.c_str(), O_RDONLY | O_NONBLOCK | O_NOFOLLOW | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) return fail(std::strerror(errno));
  struct stat st {};
  std::string why;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode))
    why = "not a regular file";
  else if (st.st_size > 0x7fffffff)
    why = "file too large";
  if (why.empty()) {
    out->resize(static_cast<std::size_t>(st.st_size));
    std::size_t got = 0;
    while (got < out->size()) {
      const ssize_t n = ::read(fd, out->data() + got, out->size() - got);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      got += static_cast<std::size_t>(n);
    }
    if (got != out->size()) why = "read error";
  }
  ::close(fd);
  if (!why.empty()) {
    auto* g = static_cast<FileGuard*>(user);
    if (g->refused.empty()) g->refused = "'" + clean(file) + "': " + why;
    return fail(why);
  }
  return true;
}

bool no_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err = "writing files is disabled";
  return false;
}

// Refuses, by name, a buffer or image URI that would read a file outside the root or one that
// is not a regular file.
void check_uris(const std::string& path, const nlohmann::json& j, const FileGuard& g) {
  for (const char* kind : {"buffers", "images"}) {
    if (!j.contains(kind) || !j[kind].is_array()) continue;
    const nlohmann::json& items = j[kind];
    for (std::size_t i = 0; i < items.size(); ++i) {
      if (!items[i].is_object() || !items[i].contains("uri") || !items[i]["uri"].is_string())
        continue;
      const std::string uri = items[i]["uri"].get<std::string>();
      if (tinygltf::IsDataURI(uri)) continue;
      const std::string file = decode_uri(uri);
      if (file.empty()) continue;
      const std::string why = fs::path(file).is_absolute()
                                  ? "it is an absolute path"
                                  : refusal(fs::path(g.base) / file, g.root);
      if (!why.empty())
        throw Error(path + ": " + (kind[0] == 'b' ? "buffer " : "image ") + std::to_string(i) +
                    " URI '" + clean(uri) + "' is refused: " + why +
                    " (a scene may only read regular files under its folder)");
    }
  }
}

}  // namespace

Scene load_gltf(const std::string& path, LoadReport* report, const std::string& root) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw Error(path + ": " +
                (std::filesystem::exists(path, ec) ? "not a regular file" : "file not found"));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open file");
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
  if (in.bad()) throw Error(path + ": read error");
  if (bytes.size() > 0x7fffffffu) throw Error(path + ": file too large");

  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  if (bytes.empty()) throw Error(path + ": empty file");
  std::size_t length = bytes.size();
  if (binary) {
    // Check the GLB container before tinygltf looks inside.
    if (bytes.size() < 20) throw Error(path + ": truncated GLB header");
    const std::uint32_t version = read_u32(&bytes[4]);
    const std::uint32_t declared = read_u32(&bytes[8]);
    if (version != 2)
      throw Error(path + ": unsupported GLB version " + std::to_string(version) + " (expected 2)");
    if (declared > bytes.size() || declared < 20)
      throw Error(path + ": GLB header declares " + std::to_string(declared) +
                  " bytes but the file has " + std::to_string(bytes.size()));
    length = declared;
    const std::uint32_t json_len = read_u32(&bytes[12]);
    const std::uint32_t json_type = read_u32(&bytes[16]);
    if (json_type != 0x4E4F534Au) throw Error(path + ": the first GLB chunk is not JSON");
    if (json_len > length - 20)
      throw Error(path + ": the GLB JSON chunk runs past the end of the file");
    std::size_t next = 20 + static_cast<std::size_t>(json_len);
    if (next + 8 <= length) {
      const std::uint32_t bin_len = read_u32(&bytes[next]);
      if (bin_len > length - next - 8)
        throw Error(path + ": the GLB BIN chunk runs past the end of the file");
    }
  } else if (ext == ".glb") {
    throw Error(path + ": not a binary glTF file (no 'glTF' magic)");
  }

  FileGuard guard;
  guard.base = fs::absolute(path, ec).parent_path().string();
  if (ec || guard.base.empty()) throw Error(path + ": cannot resolve the file's folder");
  if (root.empty()) {
    guard.root = fs::canonical(guard.base, ec);
    if (ec) throw Error(path + ": cannot resolve the file's folder: " + ec.message());
  } else {
    guard.root = fs::canonical(root, ec);
    if (ec || !fs::is_directory(guard.root, ec))
      throw Error("scene root '" + clean(root) + "': not a directory");
  }
  {
    const char* text = reinterpret_cast<const char*>(binary ? &bytes[20] : bytes.data());
    const std::size_t text_length = binary ? read_u32(&bytes[12]) : length;
    // Only the top-level arrays the checks read are kept (a scene's nodes and meshes can be
    // hundreds of thousands of objects that tinygltf parses anyway).
    const auto wanted = [](int depth, nlohmann::json::parse_event_t event, nlohmann::json& parsed) {
      if (depth != 1 || event != nlohmann::json::parse_event_t::key) return true;
      const std::string& key = parsed.get_ref<const std::string&>();
      return key == "buffers" || key == "bufferViews" || key == "images";
    };
    const nlohmann::json j = nlohmann::json::parse(text, text + text_length, wanted, false);
    if (!j.is_discarded() && j.is_object()) {  // tinygltf reports broken JSON itself
      check_uris(path, j, guard);
      check_image_views(path, j);
    }
  }

  tinygltf::Model model;
  tinygltf::TinyGLTF gltf;
  gltf.SetFsCallbacks(
      tinygltf::FsCallbacks{&guarded_file_exists, &no_expansion, &guarded_read, &no_write, &guard});
  std::string err, warn;
  const std::string& base = guard.base;
  bool ok = false;
  try {
    if (binary)
      ok = gltf.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(),
                                     static_cast<unsigned int>(length), base);
    else
      ok =
          gltf.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(bytes.data()),
                                   static_cast<unsigned int>(length), base);
  } catch (const std::exception& e) {
    throw Error(path + ": invalid glTF: " + one_line(e.what()));
  }
  bytes = {};
  if (!guard.refused.empty())
    throw Error(path + ": the file " + guard.refused +
                " (a scene may only read regular files under its folder)");
  if (!ok || !err.empty()) {
    std::string msg = one_line(err);
    if (msg.empty()) msg = one_line(warn);
    throw Error(path + ": invalid glTF: " + (msg.empty() ? "parse failed" : msg));
  }
  Loader loader(path, model, report);
  if (!warn.empty()) loader.warn(one_line(warn));
  return loader.run();
}

}  // namespace irradcast

// glTF import: materials and textures. Base colour and emission (factors, textures on
// TEXCOORD_0 or TEXCOORD_1, KHR_materials_emissive_strength), alphaMode (MASK with its
// alphaCutoff; BLEND loads as MASK at 0.5 with one warning per file); each used image is
// converted once to an RGBA8 Scene texture (8- or 16-bit, 1 to 4 channels), an unusable one is
// warned about.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "gltf_import.h"

namespace irradcast::gltf_import {
namespace {

// The decoded image (w x h pixels of c channels of `bytes` bytes each) as an RGBA8 texture:
// grey (+ alpha) spread to RGB, missing alpha opaque, 16-bit channels rounded to 8 bits.
Texture to_rgba8(const tinygltf::Image& img, std::size_t w, std::size_t h, std::size_t c,
                 std::size_t bytes) {
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
  return tex;
}

// The material's alphaMode, alphaCutoff and base colour alpha into `mat` (`what` names it in
// errors). BLEND becomes Mask at 0.5; returns true for it, so the caller can warn once per file.
bool convert_alpha(Loader& loader, const tinygltf::Material& gm, const std::string& what,
                   Material& mat) {
  const auto& factor = gm.pbrMetallicRoughness.baseColorFactor;
  if (factor.size() >= 4) {
    if (!std::isfinite(factor[3])) loader.fail(what + " has an invalid baseColorFactor alpha");
    mat.base_alpha = std::clamp(static_cast<float>(factor[3]), 0.0f, 1.0f);  // glTF: [0, 1]
  }
  if (gm.alphaMode.empty() || gm.alphaMode == "OPAQUE") return false;
  mat.alpha_mode = Material::AlphaMode::Mask;
  if (gm.alphaMode == "BLEND") {
    mat.alpha_cutoff = 0.5f;
    return true;
  }
  if (gm.alphaMode != "MASK")
    loader.fail(what + " has an unknown alphaMode" + quoted(gm.alphaMode) +
                " (OPAQUE, MASK or BLEND)");
  if (!std::isfinite(gm.alphaCutoff) || gm.alphaCutoff < 0.0 || gm.alphaCutoff > 1e30)
    loader.fail(what + " has an invalid alphaCutoff (a finite number >= 0)");
  mat.alpha_cutoff = static_cast<float>(gm.alphaCutoff);
  return false;
}

}  // namespace

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
    result = static_cast<int>(scene.textures.size());
    scene.textures.push_back(to_rgba8(img, w, h, c, bytes));
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
  std::vector<std::string> blended;  // BLEND materials, for one warning
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
    if (convert_alpha(*this, gm, what, mat)) blended.push_back(std::to_string(i) + quoted(gm.name));
    scene.materials.push_back(std::move(mat));
  }
  if (!blended.empty()) {
    std::string list;
    for (std::size_t k = 0; k < blended.size() && k < 8; ++k) list += (k ? ", " : "") + blended[k];
    if (blended.size() > 8) list += " and " + std::to_string(blended.size() - 8) + " more";
    warn("alphaMode BLEND is not supported; treated as MASK with alphaCutoff 0.5 (material" +
         std::string(blended.size() > 1 ? "s " : " ") + list + ")");
  }
}

}  // namespace irradcast::gltf_import

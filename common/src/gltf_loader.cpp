// glTF 2.0 import, the entry point: reads the file, checks the GLB container and, on the raw
// JSON, the external-file URIs and image bufferViews; tinygltf then parses the JSON / GLB and
// loads buffers and images (through the guarded file callbacks, gltf_files.cpp), and the Loader
// converts the model, validating every index, range and value before any memory is read.
#include <tiny_gltf.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gltf_import.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"

namespace irradcast {
namespace gltf_import {

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

namespace {

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

std::vector<unsigned char> read_whole_file(const std::string& path) {
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
  return bytes;
}

// Checks the GLB container (if the file starts with the 'glTF' magic) before tinygltf looks
// inside. Returns the bytes tinygltf gets: the length the GLB header declares, or the whole file.
std::size_t check_container(const std::string& path, const std::vector<unsigned char>& bytes,
                            bool binary) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (bytes.empty()) throw Error(path + ": empty file");
  if (!binary) {
    if (ext == ".glb") throw Error(path + ": not a binary glTF file (no 'glTF' magic)");
    return bytes.size();
  }
  if (bytes.size() < 20) throw Error(path + ": truncated GLB header");
  const std::uint32_t version = read_u32(&bytes[4]);
  const std::uint32_t declared = read_u32(&bytes[8]);
  if (version != 2)
    throw Error(path + ": unsupported GLB version " + std::to_string(version) + " (expected 2)");
  if (declared > bytes.size() || declared < 20)
    throw Error(path + ": GLB header declares " + std::to_string(declared) +
                " bytes but the file has " + std::to_string(bytes.size()));
  const std::size_t length = declared;
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
  return length;
}

// The checks tinygltf needs done first, on the raw JSON: URIs (check_uris) and image bufferViews.
void precheck_json(const std::string& path, const std::vector<unsigned char>& bytes, bool binary,
                   std::size_t length, const FileGuard& guard) {
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

// tinygltf's parse of the first `length` bytes, reading external files through `guard`.
// Returns tinygltf's warnings (one line); throws on its errors and on a refused file.
std::string parse_model(const std::string& path, const std::vector<unsigned char>& bytes,
                        bool binary, std::size_t length, FileGuard& guard, tinygltf::Model& model) {
  tinygltf::TinyGLTF gltf;
  gltf.SetFsCallbacks(guarded_callbacks(&guard));
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
  if (!guard.refused.empty())
    throw Error(path + ": the file " + guard.refused +
                " (a scene may only read regular files under its folder)");
  if (!ok || !err.empty()) {
    std::string msg = one_line(err);
    if (msg.empty()) msg = one_line(warn);
    throw Error(path + ": invalid glTF: " + (msg.empty() ? "parse failed" : msg));
  }
  return warn;
}

}  // namespace
}  // namespace gltf_import

Scene load_gltf(const std::string& path, GltfLoadReport* report, const std::string& root) {
  using namespace gltf_import;
  std::vector<unsigned char> bytes = read_whole_file(path);
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  const std::size_t length = check_container(path, bytes, binary);
  FileGuard guard = make_file_guard(path, root);
  precheck_json(path, bytes, binary, length, guard);
  tinygltf::Model model;
  const std::string warn = parse_model(path, bytes, binary, length, guard, model);
  bytes = {};
  Loader loader(path, model, report);
  if (!warn.empty()) loader.warn(one_line(warn));
  return loader.run();
}

}  // namespace irradcast

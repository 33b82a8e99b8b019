// glTF import internals shared by the loader's files: message helpers, the external-file guard
// (gltf_files.cpp), and the Loader that converts a parsed tinygltf::Model into a Scene
// (accessors in gltf_accessors.cpp, materials and textures in gltf_materials.cpp, meshes in
// gltf_meshes.cpp, cameras, lights and nodes in gltf_nodes.cpp). The entry point load_gltf()
// is in gltf_loader.cpp.
#pragma once

#include <tiny_gltf.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/log.h"
#include "irradcast/common/scene.h"

namespace irradcast::gltf_import {

// Collapses tinygltf's multi-line messages into one line.
std::string one_line(const std::string& text);

// A name from the file, safe for a one-line message: control characters replaced, length capped.
std::string clean(const std::string& text);

// " (\"name\")" for a non-empty name, else "".
std::string quoted(const std::string& name);

// a + b <= limit without overflow.
inline bool fits(std::size_t a, std::size_t b, std::size_t limit) {
  return a <= limit && b <= limit - a;
}

// ---------------------------------------------------------------------------------------------
// External files (gltf_files.cpp). Every buffer and image URI must name a regular file inside
// the scene file's folder (or the root the caller gives), after following symlinks.

struct FileGuard {
  std::string base;            // the folder tinygltf joins URIs to (absolute)
  std::filesystem::path root;  // every file read must resolve to a path under this (canonical)
  std::string refused;         // the first file a callback refused, and why
};

// The guard for the scene file `path`: its folder, and `root` (or that folder) as the root.
FileGuard make_file_guard(const std::string& path, const std::string& root);

// Refuses, by name, a buffer or image URI in the raw JSON `j` that would read a file outside the
// root or one that is not a regular file.
void check_uris(const std::string& path, const nlohmann::json& j, const FileGuard& g);

// Why `file` may not be read ("" if it may): it must resolve, symlinks followed, to a path under
// `root` that is a regular file (a file that does not exist is not refused here).
std::string refusal(const std::filesystem::path& file, const std::filesystem::path& root);

// tinygltf's file-system callbacks, reading only what `guard` allows (and never writing).
tinygltf::FsCallbacks guarded_callbacks(FileGuard* guard);

// ---------------------------------------------------------------------------------------------
// Conversion of a parsed model.

// What a caller accepts from an accessor.
struct AccessorKind {
  int type;                          // TINYGLTF_TYPE_*
  int components;                    // components per element
  std::vector<int> component_types;  // allowed
  bool require_normalized_ints;      // integer components must be normalized (TEXCOORD_n)
};

struct MeshBlocks;  // gltf_meshes.cpp

class Loader {
 public:
  Loader(std::string path, const tinygltf::Model& model, GltfLoadReport* report)
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

  // gltf_accessors.cpp (instantiated for float and std::uint32_t).
  template <class T>
  std::vector<T> read_accessor(int index, const std::string& what, const AccessorKind& kind) const;
  template <class T>
  void read_sparse(const tinygltf::Accessor& acc, const std::string& name, bool normalized,
                   std::size_t ncomp, std::vector<T>& out) const;

  // gltf_materials.cpp
  void convert_materials(Scene& scene);
  int texture(int index, int tex_coord, const std::string& what, Scene& scene, int* uv_set);
  int image(int index, Scene& scene);

  // gltf_meshes.cpp
  void convert_meshes(Scene& scene);
  void convert_mesh(int index, Scene& scene);
  std::size_t primitive_block(const tinygltf::Primitive& prim, const std::string& what,
                              const std::string& mesh_label, MeshBlocks& blocks);
  std::vector<std::uint32_t> primitive_indices(const tinygltf::Primitive& prim,
                                               const std::string& what, std::size_t n);
  int primitive_material(const tinygltf::Primitive& prim, const std::string& what, Scene& scene);
  void emit_triangles(int mode, const std::vector<std::uint32_t>& idx, std::uint32_t base,
                      int material, const std::string& what, Mesh& mesh);

  // gltf_nodes.cpp
  void convert_cameras(Scene& scene);
  void convert_lights(Scene& scene);
  void convert_nodes(Scene& scene);
  glm::mat4 node_transform(const tinygltf::Node& gn, const std::string& what) const;
  void link_node(std::size_t i, Scene& scene) const;
  void check_cycles(const Scene& scene) const;
  void pick_roots(Scene& scene) const;

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
  GltfLoadReport* report_;
  int default_material_ = -1;
  std::map<int, int> image_to_texture_;  // glTF image -> Scene::textures index (-1 = unusable)
  std::vector<int> camera_map_;          // glTF camera -> Scene::cameras index (-1 = skipped)
  std::vector<int> light_map_;           // glTF light -> Scene::lights index (-1 = skipped)
};

}  // namespace irradcast::gltf_import

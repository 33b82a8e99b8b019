// glTF 2.0 import and export (.gltf with external or embedded buffers, and .glb), via tinygltf.
#pragma once

#include <string>
#include <vector>

#include "irradcast/common/scene.h"

namespace irradcast {

// What load_gltf noticed but did not refuse (named apart from the load generator's LoadReport:
// two types of one name in one namespace share their implicit functions' symbols).
struct GltfLoadReport {
  std::vector<std::string> warnings;  // e.g. skipped line / point primitives
};

// Loads a glTF 2.0 file (.gltf with external or data-URI buffers, or .glb, told apart by content).
// Throws irradcast::Error with a one-line message "PATH: problem" for any bad input (missing file,
// broken JSON, missing or short buffer, accessor past its bufferView, index out of range,
// non-finite positions, bad component types, ...). Warnings (skipped line / point primitives,
// orthographic cameras, undecodable images) are logged and returned in *report if given.
//
// External files (buffer and image URIs that are not data: URIs) must resolve, symlinks followed,
// to regular files under `root`: by default the folder of `path`; a non-empty `root` (a
// directory, e.g. --scene-root) replaces it. A URI that leads elsewhere (`../`, percent-encoded
// or not, an absolute path, a symlink pointing out) or to a FIFO, device or directory is an
// Error naming the URI and why; no other file is ever opened (tinygltf reads through our
// callbacks, which apply the same rule).
//
// Mapping: Scene::nodes and Scene::meshes are index for index the glTF nodes and meshes (a mesh
// that ends up with no triangles is kept, but nodes drop their reference to it); the roots are
// the default scene's nodes. Scene::materials are the glTF materials in order, plus one default
// material (base colour 1) appended if a primitive has none; alphaMode MASK keeps its
// alphaCutoff (finite and >= 0, else an Error), BLEND loads as MASK at 0.5 with one warning
// naming the materials, and the base colour factor's alpha is kept (clamped to [0, 1]).
// Scene::textures holds each used glTF image once, as RGBA8. Lights and cameras keep glTF order
// minus the skipped ones.
Scene load_gltf(const std::string& path, GltfLoadReport* report = nullptr,
                const std::string& root = "");

// Writes the scene as valid glTF 2.0: .glb (binary) or .gltf (JSON with the buffer embedded as a
// data URI), chosen by the extension. Node matrices, one primitive per material, PNG textures,
// KHR_lights_punctual, KHR_materials_emissive_strength (emission brighter than glTF's [0, 1]
// emissiveFactor moves into the strength), alphaMode MASK with its alphaCutoff, perspective
// cameras. Meshes without triangles are not written. Throws irradcast::Error on another extension,
// invalid scene data (non-finite values, triangle index out of range) or if the file cannot be
// written.
void save_gltf(const Scene& scene, const std::string& path);

// The path of the file `name` in the folder `root`, confined the way glTF URIs are
// (gltf_files.cpp): `name` is relative and resolves, symlinks followed, to an existing regular
// file under `root`. Throws irradcast::Error naming `what` and the reason otherwise. Used for the
// sky files a client may name in an edit (irradcast-server --sky-dir).
std::string confined_file(const std::string& root, const std::string& name,
                          const std::string& what);

}  // namespace irradcast

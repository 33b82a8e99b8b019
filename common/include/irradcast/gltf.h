// glTF 2.0 import and export (.gltf with external or embedded buffers, and .glb), via tinygltf.
#pragma once

#include <string>
#include <vector>

#include "irradcast/scene.h"

namespace irradcast {

struct LoadReport {
  std::vector<std::string> warnings;  // e.g. skipped line / point primitives
};

// Loads a glTF 2.0 file. Throws irradcast::Error with a one-line message naming the file and the
// problem for any bad input (missing file, broken JSON, missing or short buffer, index out of
// range, non-finite positions, ...). Warnings are logged and returned in *report if given.
Scene load_gltf(const std::string& path, LoadReport* report = nullptr);

// Writes the scene as valid glTF 2.0: .glb (binary) or .gltf (JSON with the buffer embedded as a
// data URI), chosen by the extension. Throws irradcast::Error if the file cannot be written.
void save_gltf(const Scene& scene, const std::string& path);

}  // namespace irradcast

// The scene of irradcast-bench-poses: the Cornell box with small dynamic spheres (its own file:
// gltf.h and load_generator.h both declare an irradcast::LoadReport).
#pragma once

#include <string>

namespace irradcast::bench {

// Writes the Cornell box with `n` dynamic spheres ball0..ball{n-1} in a grid above its floor as
// glTF to `path`.
void write_balls_gltf(int n, const std::string& path);

}  // namespace irradcast::bench

// Built-in meshes for things that are not in a scene file: a sphere for tests and the dynamic
// objects of the built-in scenes (docs/DYNAMIC.md), a capsule for viewers' avatars. Centred on the
// origin of their node, with smooth normals and TEXCOORD_0, every triangle of one material.
#pragma once

#include <cstdint>
#include <string>

#include "irradcast/common/scene.h"

namespace irradcast {

// A UV sphere: `rings` bands from pole to pole (>= 2) and `segments` around (>= 3); u runs
// around the +Y axis from +X, v from the north pole (0) to the south (1), as equirectangular
// textures expect. Counter-clockwise seen from outside. Throws irradcast::Error on bad counts or
// a radius that is not finite and positive.
Mesh uv_sphere(const std::string& name, float radius, int rings, int segments,
               std::uint32_t material);

// A capsule along +Y: a cylinder of `length` between two hemispheres of `radius` (height
// length + 2 radius), `rings` bands from pole to pole (even, >= 2) and `segments` around, UVs as
// uv_sphere's with v running along the profile. Throws irradcast::Error as uv_sphere does, and on
// a length that is not finite and >= 0.
Mesh capsule(const std::string& name, float radius, float length, int rings, int segments,
             std::uint32_t material);

}  // namespace irradcast

// Cut-out materials (glTF alphaMode MASK; BLEND loads as MASK at 0.5): the alpha of a surface
// point and whether it is cut out. Everything that traces rays or places lightmap samples asks
// these: RayScene's Embree filters reject hits on cut-out points (so every ray passes through the
// holes), the texel G-buffer gives a texel whose sample is cut out no estimate, and
// World::emission is 0 at cut-out points (so light sampling and paths that hit emitters agree).
#pragma once

#include <cstdint>

#include "irradcast/common/world.h"

namespace irradcast {

// Alpha at a surface point of `object` (triangle t, barycentrics u, v): the base colour factor's
// alpha x the base colour texture's alpha (at the material's base_color_uv set).
float surface_alpha(const World& world, int object, std::uint32_t t, float u, float v);
// The point is cut out: its material is Mask and its alpha is below the material's cutoff.
bool cut_out(const World& world, int object, std::uint32_t t, float u, float v);
// Some triangle of the object has a Mask material (only such objects can have cut-out points).
bool has_cut_outs(const World& world, int object);

}  // namespace irradcast

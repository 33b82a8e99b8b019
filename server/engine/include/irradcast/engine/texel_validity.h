// Hidden texels: lightmap texels whose surface point is buried inside other geometry (a wall
// face running into a pillar, the strip of a wall behind a floor slab). Nothing can see them,
// but their rays start inside solid matter, so whatever they compute is wrong, and a bilinear
// lookup at the edge of the visible part of their chart would blend that in. Lightmappers call
// this texel validity (Unity's "backface tolerance"): a texel whose hemisphere rays mostly hit the
// back of single-sided surfaces is inside something.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/ray_scene.h"

namespace irradcast {

struct TexelValidityOptions {
  int rays = 16;                 // fixed cosine-distributed hemisphere directions per texel
  float hidden_fraction = 0.5f;  // hidden when more than this fraction hit back faces
};

// Marks every valid texel that is inside geometry as TexelKind::Hidden, so that it is no longer
// valid(): passes skip it and dilation fills it from its visible neighbours. Back faces of
// double-sided materials do not count (they are meant to be seen). Deterministic, parallel.
// Returns the number of texels marked.
std::size_t mark_hidden_texels(const RayScene& rays, std::vector<TexelGBuffer>& gbuffers,
                               const TexelValidityOptions& options = {});
// Only the objects with which[o] != 0 (after an edit: the G-buffers rasterized again).
std::size_t mark_hidden_texels(const RayScene& rays, std::vector<TexelGBuffer>& gbuffers,
                               const std::vector<std::uint8_t>& which,
                               const TexelValidityOptions& options = {});

}  // namespace irradcast

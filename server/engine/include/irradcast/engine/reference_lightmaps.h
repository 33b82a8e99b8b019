// Reference lightmaps: every valid texel's irradiance estimated by the reference path tracer
// (independent paths per texel, 1 direct + K indirect bounces), then dilated into the gutters.
// Slow and unbiased: the ground truth the GI engine's lightmaps are measured against, and what
// irradcast-bake writes until the engine exists.
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/engine/path_tracer.h"

namespace irradcast {

struct ReferenceLightmapStats {
  std::uint64_t rays = 0;
  double seconds = 0.0;
};

std::vector<Lightmap> reference_lightmaps(const World& world, const PathTracer& tracer,
                                          const std::vector<TexelGBuffer>& gbuffers,
                                          int samples_per_texel,
                                          ReferenceLightmapStats* stats = nullptr);

}  // namespace irradcast

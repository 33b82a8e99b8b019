// The lightmap denoiser (EngineParams::denoise, docs/DENOISER.md): an edge-avoiding a-trous
// filter over the scene's texels that removes Monte Carlo noise and never light. Iteration i
// (i = 0 .. iterations-1) averages each texel with the texels within radius * 2^i of its own
// texel sizes in world space, taking from iteration 1 on only every 2^i-th texel of each
// lightmap row and column (the a-trous holes, so every iteration costs about the same). World
// space makes a chart's neighbours across its seams (in another chart, elsewhere in the
// lightmap, or in another object's lightmap) count like those beside it. It is guided by each
// texel's world position, normal and chart, and weighted by the per-texel standard error the
// engine tracks:
//   - geometry: a neighbour counts only when its normal is within `normal_cos` of the texel's and
//     each lies within `plane` x 2^i texel sizes of the other's tangent plane (no averaging across
//     a crease, a step or two sides of a wall); a Gaussian in world distance;
//   - range: a Gaussian in the luminance difference over `range_sigmas` times its expected noise
//     sqrt(var_p + var_q), the variances those of the previous iteration's values (propagated:
//     sum w^2 var / (sum w)^2), so differences beyond the noise (shadow edges, light steps) stay;
//   - confidence: a result whose luminance lies further than `confidence` standard errors from
//     the texel's own mean (its standard error pooled over its first geometric neighbourhood)
//     keeps the texel's own mean;
//   - a texel without a noise estimate (standard error 0: fewer than two samples) keeps its
//     value and is nobody's neighbour.
// As the means converge their standard errors shrink and the filter fades to the identity.
// Pure function of its input (deterministic, parallel over texels); the engine applies it to a
// copy of its means when it publishes (Engine::published_lightmaps), never to the means.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/pass_data.h"

namespace irradcast {

struct DenoiseOptions {
  float radius = 3.0f;        // first neighbourhood radius, in the texel's own texel sizes
  int iterations = 2;         // a-trous iterations, the radius doubling each time (radius 3, 2
                              // iterations and confidence 5 measured best on the Sponza at the
                              // default atlas density; docs/DENOISER.md)
  float normal_cos = 0.9f;    // smallest cosine between the normals of neighbours
  float plane = 0.5f;         // largest distance from the other's tangent plane, texel sizes
  float range_sigmas = 2.0f;  // range kernel width, in standard deviations of the difference
  float confidence = 5.0f;    // z: a result outside mean +- z se keeps the texel's own mean
};

// What the filter reads per texel besides the values: the texels (position, normal, object and
// texel index, as SurfaceTexels), each texel's chart (unique over the scene) and each object's
// texel size in world units and lightmap width.
struct DenoiseGuide {
  std::vector<std::uint32_t> chart;  // per texel: a scene-wide chart id
  std::vector<float> texel_size;     // per object: world units per texel
  std::vector<int> width;            // per object: lightmap width (texel index = y * width + x)
};

// The guide of the engine's texels: charts from the atlas (the chart of the triangle each
// texel samples, numbered over the scene), texel sizes from the atlas' densities.
DenoiseGuide denoise_guide(const SurfaceTexels& texels, const Atlas& atlas,
                           const std::vector<TexelGBuffer>& gbuffers);

struct DenoiseStats {
  std::size_t filtered = 0;  // texels that took the filtered value
  std::size_t kept = 0;      // texels whose filtered value left their confidence interval
  std::size_t unknown = 0;   // texels without a noise estimate (kept)
  std::size_t seams = 0;     // filtered texels with a neighbour in another chart
};

// The filtered values of `value` (one per texel), with `standard_error` the standard error of
// each value (luminance; 0 = unknown). Sizes must match `texels` (throws irradcast::Error).
std::vector<glm::vec3> denoise(const SurfaceTexels& texels, const DenoiseGuide& guide,
                               const std::vector<glm::vec3>& value,
                               const std::vector<float>& standard_error,
                               const DenoiseOptions& options = {}, DenoiseStats* stats = nullptr);

}  // namespace irradcast

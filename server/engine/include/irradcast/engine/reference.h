// The reference path tracer (path_tracer.h) behind one interface, on the CPU (PathTracer with
// Embree, reference_lightmaps.h) or on the Vulkan device (reference.comp): per-texel reference
// lightmaps, and the reference render of a view. backend_select.h's make_reference picks one
// with the same rule as the engine's backend.
#pragma once

#include <string>
#include <vector>

#include "irradcast/common/image.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/reference_lightmaps.h"

namespace irradcast {

class ReferenceRenderer {
 public:
  virtual ~ReferenceRenderer() = default;
  // What it runs on, as TraceBackend::describe() ("embree", "vulkan on ...").
  virtual std::string describe() const = 0;
  // Every valid texel's irradiance from `samples` paths, dilated into the gutters.
  virtual std::vector<Lightmap> lightmaps(const std::vector<TexelGBuffer>& gbuffers, int samples,
                                          ReferenceLightmapStats* stats = nullptr) = 0;
  // The view: `samples` paths per pixel through the pixel centres, with a progress line.
  virtual ImageRGB render(const CameraPose& camera, int width, int height, int samples,
                          ReferenceLightmapStats* stats = nullptr) = 0;
};

}  // namespace irradcast

// The implementations of ReferenceRenderer (irradcast/engine/reference.h), made by
// make_reference (backend_select.h).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/reference.h"
#include "vulkan_backend.h"

namespace irradcast {

// PathTracer on the CPU (Embree): reference_lightmaps and PathTracer::render.
class CpuReference final : public ReferenceRenderer {
 public:
  // Everything passed must outlive it.
  CpuReference(const World& world, const RayScene& rays, const LightSampler& lights,
               const PathTracerOptions& options);
  std::string describe() const override { return "embree"; }
  std::vector<Lightmap> lightmaps(const std::vector<TexelGBuffer>& gbuffers, int samples,
                                  ReferenceLightmapStats* stats) override;
  ImageRGB render(const CameraPose& camera, int width, int height, int samples,
                  ReferenceLightmapStats* stats) override;

 private:
  const World* world_;
  PathTracer tracer_;
};

// The Vulkan backend's reference.comp (VulkanBackend::reference_lightmaps, render_reference).
class VulkanReference final : public ReferenceRenderer {
 public:
  VulkanReference(std::unique_ptr<VulkanBackend> backend, const PathTracerOptions& options);
  std::string describe() const override;
  std::vector<Lightmap> lightmaps(const std::vector<TexelGBuffer>& gbuffers, int samples,
                                  ReferenceLightmapStats* stats) override;
  ImageRGB render(const CameraPose& camera, int width, int height, int samples,
                  ReferenceLightmapStats* stats) override;

 private:
  std::unique_ptr<VulkanBackend> backend_;
  PathTracerOptions options_;
};

}  // namespace irradcast

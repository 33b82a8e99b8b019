// The reference path tracer's two implementations (reference.h): the CPU's PathTracer and the
// Vulkan backend's reference.comp.
#include "reference_renderers.h"

#include "irradcast/common/progress.h"

namespace irradcast {

CpuReference::CpuReference(const World& world, const RayScene& rays, const LightSampler& lights,
                           const PathTracerOptions& options)
    : world_(&world), tracer_(world, rays, lights, options) {}

std::vector<Lightmap> CpuReference::lightmaps(const std::vector<TexelGBuffer>& gbuffers,
                                              int samples, ReferenceLightmapStats* stats) {
  return reference_lightmaps(*world_, tracer_, gbuffers, samples, stats);
}

ImageRGB CpuReference::render(const CameraPose& camera, int width, int height, int samples,
                              ReferenceLightmapStats* stats) {
  PathTracer::RenderStats rs;
  Progress progress("reference", static_cast<std::uint64_t>(samples), "spp");
  ImageRGB image = tracer_.render(
      camera, width, height, samples, [&](int, int) { progress.advance(1); }, &rs);
  progress.finish();
  if (stats) {
    stats->rays = rs.rays;
    stats->seconds = rs.seconds;
  }
  return image;
}

VulkanReference::VulkanReference(std::unique_ptr<VulkanBackend> backend,
                                 const PathTracerOptions& options)
    : backend_(std::move(backend)), options_(options) {}

std::string VulkanReference::describe() const {
  return backend_->describe();
}

std::vector<Lightmap> VulkanReference::lightmaps(const std::vector<TexelGBuffer>& gbuffers,
                                                 int samples, ReferenceLightmapStats* stats) {
  return backend_->reference_lightmaps(gbuffers, samples, options_.indirect_bounces, options_.seed,
                                       stats);
}

ImageRGB VulkanReference::render(const CameraPose& camera, int width, int height, int samples,
                                 ReferenceLightmapStats* stats) {
  return backend_->render_reference(camera, width, height, samples, options_.indirect_bounces,
                                    options_.seed, stats);
}

}  // namespace irradcast

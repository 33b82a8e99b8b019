// The GPU backend: the engine's three passes as Vulkan compute shaders (shaders/*.comp, compiled
// to SPIR-V at build time and embedded), tracing rays through a BVH in storage buffers built by
// build_gpu_bvh. No ray-tracing extensions, so Mesa's lavapipe and real GPUs run the same code.
// Same estimators, sample counts and ray offsets as EmbreeBackend; its own random numbers, so
// the two agree within Monte Carlo noise, not bit for bit. The reference path tracer's lightmaps
// run here too (reference.comp).
#pragma once

#include <memory>
#include <string>

#include "irradcast/common/image.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "irradcast/engine/trace_backend.h"
#include "irradcast/engine/vulkan_device.h"

namespace irradcast {

class VulkanBackend final : public TraceBackend {
 public:
  // Opens the device, builds the BVH and uploads the scene. `rays` (for its ray offset) and
  // `lights` must outlive the backend. Throws irradcast::Error naming what failed.
  // force_staging: device-local buffers filled and read through staging copies, as on a
  // discrete GPU, even where device memory is host-visible (tests that path on lavapipe).
  VulkanBackend(const World& world, const RayScene& rays, const LightSampler& lights,
                VulkanContextOptions options = {}, bool force_staging = false);
  ~VulkanBackend() override;

  std::string name() const override { return "vulkan"; }
  std::string describe() const override;
  // Uploads the scene again: BVH (rebuilt with Embree's builder over the new world), materials,
  // lights, and the engine data on the next pass.
  void scene_changed() override;
  const VulkanDeviceInfo& device() const;
  // Validation layer messages so far (0 unless options.validation).
  std::uint64_t validation_messages() const;
  std::vector<std::string> validation_log() const;

  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override;
  PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                           std::vector<glm::vec3>& out) override;
  // The gather folds its estimates into running means kept in device memory (one region per
  // bounce, zeroed for a new ProbeMeans), then the scatter reads them: one submission, no probe
  // data crossing to the host. Bit for bit what the default computes on the host.
  BounceResult probe_bounce(const PassInput& in, const RadianceField& prev, float weight,
                            ProbeMeans& means, std::vector<glm::vec3>& out) override;
  // Off: probe_bounce runs TraceBackend's default (gather, means on the host, scatter: two
  // submissions), for irradcast-bench-backend's before/after comparison. On by default.
  void set_resident_probes(bool on);
  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override;

  // The reference path tracer's lightmaps (reference_lightmaps with PathTracer, next-event
  // estimation) on the device: `samples` paths per valid texel, `indirect_bounces` bounces,
  // dilated into the gutters. Same estimator as the CPU's; its own random numbers.
  std::vector<Lightmap> reference_lightmaps(const std::vector<TexelGBuffer>& gbuffers, int samples,
                                            int indirect_bounces, std::uint64_t seed,
                                            ReferenceLightmapStats* stats = nullptr);
  // The reference path tracer's view (PathTracer::render): `samples` paths per pixel through
  // the pixel centres, `indirect_bounces` bounces.
  ImageRGB render_reference(const CameraPose& camera, int width, int height, int samples,
                            int indirect_bounces, std::uint64_t seed,
                            ReferenceLightmapStats* stats = nullptr);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace irradcast

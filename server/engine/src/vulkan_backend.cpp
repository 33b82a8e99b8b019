// The Vulkan backend's TraceBackend side (vulkan_backend.h): construction, the scene change,
// the device description, and the direct, probe gather and scatter passes, and the probe bounce
// with the probes' running means resident on the device.
#include "vulkan_backend.h"

#include <string>

#include "irradcast/common/error.h"
#include "vulkan_backend_impl.h"

namespace irradcast {

namespace {

// The gather's rays: one per texel of every usable probe.
std::uint64_t probe_rays(const PassInput& in) {
  std::size_t usable = 0;
  for (std::uint8_t u : in.probes.usable) usable += u ? 1 : 0;
  return usable * in.probes.texels_per_probe();
}

}  // namespace

VulkanBackend::VulkanBackend(const World& world, const RayScene& rays, const LightSampler& lights,
                             VulkanContextOptions options, bool force_staging)
    : impl_(std::make_unique<Impl>(world, rays, lights, options, force_staging)) {}

VulkanBackend::~VulkanBackend() = default;

void VulkanBackend::scene_changed() {
  std::lock_guard lock(impl_->mutex);
  Impl::ForgetOnThrow guard{impl_.get()};
  impl_->engine_key = EngineKey{};
  impl_->prev_key = Impl::PrevKey{};
  impl_->upload_scene();
}

std::string VulkanBackend::describe() const {
  const VulkanDeviceInfo& d = device();
  return "vulkan on " + d.name + " (" + d.type + ", Vulkan " + d.api_version + ")";
}

const VulkanDeviceInfo& VulkanBackend::device() const {
  return impl_->context.device();
}

std::uint64_t VulkanBackend::validation_messages() const {
  return impl_->context.validation_messages();
}

std::vector<std::string> VulkanBackend::validation_log() const {
  return impl_->context.validation_log();
}

PassResult VulkanBackend::direct(const PassInput& in, std::vector<glm::vec3>& out) {
  return impl_->timed_pass(in, nullptr, [&]() -> std::uint64_t {
    PushConstants pc = impl_->constants(in);
    pc.samples = static_cast<std::uint32_t>(in.params.direct_samples);
    const auto items = static_cast<std::uint32_t>(in.unit_texels.size());
    double traced = 0.0;  // the shader counts the area and sky shadow rays it traced
    impl_->run(kDirectPipeline, pc, items, out, in.texels.size(), &traced, &in.unit_texels);
    return static_cast<std::uint64_t>(in.unit_texels.size()) * impl_->punctual_count +
           static_cast<std::uint64_t>(traced);
  });
}

PassResult VulkanBackend::gather_probes(const PassInput& in, const RadianceField& prev,
                                        std::vector<glm::vec3>& out) {
  return impl_->timed_pass(in, &prev, [&]() -> std::uint64_t {
    PushConstants pc = impl_->constants(in);
    const std::size_t items = in.probes.count() * in.probes.texels_per_probe();
    if (items > 0xFFFFFFFFu) throw Error("Vulkan backend: too many probe texels for one pass");
    impl_->run(kGatherPipeline, pc, static_cast<std::uint32_t>(items), out, items);
    return probe_rays(in);
  });
}

// The gather into the device's running means and the scatter reading them, in one submission:
// the previous bounce's lightmaps (when new) and the means' zeroing (when new) first, then the
// gather, a barrier, the scatter and the read-back of its result. The two dispatches' device
// times come from a timestamp between them; the wall time is split in their proportion, the
// uploads go to the gather, the read-back and the submission to the scatter.
BounceResult VulkanBackend::probe_bounce(const PassInput& in, const RadianceField& prev,
                                         float weight, ProbeMeans& means,
                                         std::vector<glm::vec3>& out) {
  if (!impl_->resident_probes) return TraceBackend::probe_bounce(in, prev, weight, means, out);
  const std::size_t per_bounce = in.probes.count() * in.probes.texels_per_probe();
  const int bounces = in.params.indirect_bounces;
  if (in.bounce < 1 || static_cast<int>(in.bounce) > bounces)
    throw Error("Vulkan backend: probe bounce " + std::to_string(in.bounce) + " of " +
                std::to_string(bounces));
  if (per_bounce * static_cast<std::size_t>(bounces) > 0xFFFFFFFFu)
    throw Error("Vulkan backend: too many probe texels for one pass");
  std::uint64_t gather_rays = 0;
  PassResult all = impl_->timed_pass(in, &prev, [&]() -> std::uint64_t {
    const bool fresh = impl_->resident_means(means.id, per_bounce, bounces);
    impl_->prepare_result(in.texels.size());
    if (impl_->descriptors_dirty) impl_->update_descriptors();
    impl_->begin();
    if (fresh) {
      // Running means start from zero, as the host's do.
      vkCmdFillBuffer(impl_->commands, impl_->device_buffers[kProbeRadiance].buffer, 0,
                      VK_WHOLE_SIZE, 0u);
      impl_->barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                     VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                     VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    }
    PushConstants pc = impl_->constants(in);
    pc.flags |= kFlagProbeMean;
    pc.probe_offset = static_cast<std::uint32_t>((in.bounce - 1) * per_bounce);
    pc.probe_weight = weight;
    impl_->dispatch(kGatherPipeline, pc, static_cast<std::uint32_t>(per_bounce));
    impl_->barrier(VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                   VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
    impl_->mark();
    pc.flags &= ~static_cast<std::uint32_t>(kFlagProbeMean);
    pc.samples = static_cast<std::uint32_t>(in.params.indirect_samples);
    const auto items = static_cast<std::uint32_t>(in.unit_texels.size());
    impl_->dispatch(kScatterPipeline, pc, items);
    impl_->read_back(in.texels.size());
    impl_->submit();
    impl_->take_results(out, in.texels.size());
    gather_rays = probe_rays(in);
    return static_cast<std::uint64_t>(items) * pc.samples;
  });
  BounceResult r;
  const double device = all.device_seconds;
  const double share =
      impl_->intervals.size() == 2 && device > 0.0 ? impl_->intervals[0] / device : 0.5;
  r.probes.rays = gather_rays;
  r.probes.seconds = all.seconds * share;
  r.probes.device_seconds = impl_->intervals.size() == 2 ? impl_->intervals[0] : device * share;
  r.probes.bytes_up = all.bytes_up;
  r.scatter = all;
  r.scatter.seconds = all.seconds - r.probes.seconds;
  r.scatter.device_seconds = device - r.probes.device_seconds;
  r.scatter.bytes_up = 0;
  return r;
}

void VulkanBackend::set_resident_probes(bool on) {
  std::lock_guard lock(impl_->mutex);
  impl_->resident_probes = on;
  impl_->means_key = Impl::MeansKey{};
}

PassResult VulkanBackend::scatter(const PassInput& in, const RadianceField& prev,
                                  const std::vector<glm::vec3>& probe_radiance,
                                  std::vector<glm::vec3>& out) {
  return impl_->timed_pass(in, &prev, [&]() -> std::uint64_t {
    impl_->means_key = Impl::MeansKey{};  // the probes' resident means are overwritten
    impl_->write(kProbeRadiance, probe_radiance.size() * sizeof(glm::vec4), [&](void* dst) {
      auto* v = static_cast<glm::vec4*>(dst);
      for (std::size_t i = 0; i < probe_radiance.size(); ++i)
        v[i] = glm::vec4(probe_radiance[i], 0.0f);
    });
    PushConstants pc = impl_->constants(in);
    pc.samples = static_cast<std::uint32_t>(in.params.indirect_samples);
    const auto items = static_cast<std::uint32_t>(in.unit_texels.size());
    impl_->run(kScatterPipeline, pc, items, out, in.texels.size());
    return static_cast<std::uint64_t>(in.unit_texels.size()) * pc.samples;
  });
}

}  // namespace irradcast

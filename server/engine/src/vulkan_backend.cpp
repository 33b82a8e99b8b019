// The Vulkan backend's TraceBackend side (vulkan_backend.h): construction, the scene change,
// the device description, and the direct, probe gather and scatter passes.
#include "irradcast/engine/vulkan_backend.h"

#include <string>

#include "irradcast/common/error.h"
#include "vulkan_backend_impl.h"

namespace irradcast {
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
    double sky_rays = 0.0;  // the shader counts them (a map's rays depend on the sample)
    impl_->run(kDirectPipeline, pc, items, out, in.texels.size(),
               (pc.flags & kFlagSky) ? &sky_rays : nullptr, &in.unit_texels);
    return static_cast<std::uint64_t>(in.unit_texels.size()) *
               (impl_->punctual_count + (impl_->emissive_count > 0 ? pc.samples : 0u)) +
           static_cast<std::uint64_t>(sky_rays);
  });
}

PassResult VulkanBackend::gather_probes(const PassInput& in, const RadianceField& prev,
                                        std::vector<glm::vec3>& out) {
  return impl_->timed_pass(in, &prev, [&]() -> std::uint64_t {
    PushConstants pc = impl_->constants(in);
    const std::size_t items = in.probes.count() * in.probes.texels_per_probe();
    if (items > 0xFFFFFFFFu) throw Error("Vulkan backend: too many probe texels for one pass");
    impl_->run(kGatherPipeline, pc, static_cast<std::uint32_t>(items), out, items);
    std::size_t usable = 0;
    for (std::uint8_t u : in.probes.usable) usable += u ? 1 : 0;
    return usable * in.probes.texels_per_probe();
  });
}

PassResult VulkanBackend::scatter(const PassInput& in, const RadianceField& prev,
                                  const std::vector<glm::vec3>& probe_radiance,
                                  std::vector<glm::vec3>& out) {
  return impl_->timed_pass(in, &prev, [&]() -> std::uint64_t {
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

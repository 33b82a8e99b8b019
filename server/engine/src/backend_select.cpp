// The choice of backend (backend_select.h): the engine's TraceBackend and the reference path
// tracer's ReferenceRenderer, by the same rule.
#include "irradcast/engine/backend_select.h"

#include "embree_backend.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "reference_renderers.h"
#include "vulkan_backend.h"

namespace irradcast {

int auto_vulkan_device(const std::vector<VulkanDeviceInfo>& devices) {
  auto rank = [](const std::string& type) {
    return type == "discrete GPU"     ? 0
           : type == "integrated GPU" ? 1
           : type == "virtual GPU"    ? 2
                                      : 3;
  };
  int chosen = -1;
  for (std::size_t i = 0; i < devices.size(); ++i) {
    const VulkanDeviceInfo& d = devices[i];
    if (!d.compute || d.type == "CPU") continue;
    if (chosen < 0 || rank(d.type) < rank(devices[static_cast<std::size_t>(chosen)].type))
      chosen = static_cast<int>(i);
  }
  return chosen;
}

BackendKind parse_backend(const std::string& name) {
  if (name == "auto") return BackendKind::Auto;
  if (name == "vulkan") return BackendKind::Vulkan;
  if (name == "embree") return BackendKind::Embree;
  throw Error("unknown backend '" + name + "' (expected auto, vulkan or embree)");
}

namespace {

// The device the options pick: a Vulkan backend, or null for Embree; `reason` says which and
// why. Logs the choice.
std::unique_ptr<VulkanBackend> choose_vulkan(const BackendOptions& options, const World& world,
                                             const RayScene& rays, const LightSampler& lights,
                                             std::string& reason) {
  std::unique_ptr<VulkanBackend> v;
  VulkanContextOptions vo;
  vo.device = options.vulkan_device;
  vo.validation = options.vulkan_validation;
  if (options.kind == BackendKind::Vulkan) {
    try {
      v = std::make_unique<VulkanBackend>(world, rays, lights, vo);
      reason = v->describe() + " (--backend vulkan)";
    } catch (const Error& e) {
      throw Error(std::string("--backend vulkan: ") + e.what());
    }
  } else if (options.kind == BackendKind::Auto) {
    std::string why;
    try {
      // Find a GPU first: opening lavapipe only to put it aside would cost its start-up.
      int chosen = options.vulkan_device;
      if (chosen < 0) chosen = auto_vulkan_device(list_vulkan_devices());
      if (chosen < 0) {
        why =
            "no Vulkan GPU (only CPU implementations such as lavapipe, which are slower than "
            "Embree on the same cores; --backend vulkan uses them)";
      } else {
        vo.device = chosen;
        v = std::make_unique<VulkanBackend>(world, rays, lights, vo);
        reason = v->describe() + " (--backend auto)";
      }
    } catch (const std::exception& e) {  // Error, or bad_alloc on a huge scene
      why = e.what();
    }
    if (!v) reason = "embree (--backend auto: " + why + ")";
  } else {
    reason = "embree (--backend embree)";
  }
  log::info("engine", "backend: " + reason);
  return v;
}

}  // namespace

BackendChoice make_backend(const BackendOptions& options, const World& world, const RayScene& rays,
                           const LightSampler& lights) {
  BackendChoice c;
  c.backend = choose_vulkan(options, world, rays, lights, c.reason);
  if (!c.backend) c.backend = std::make_unique<EmbreeBackend>(rays, lights);
  return c;
}

std::unique_ptr<ReferenceRenderer> make_reference(const BackendOptions& options, const World& world,
                                                  const RayScene& rays, const LightSampler& lights,
                                                  const PathTracerOptions& tracer) {
  // Objects seen by camera rays only are the CPU path tracer's alone (reference.comp traces the
  // static scene).
  if (tracer.camera_only) return std::make_unique<CpuReference>(world, rays, lights, tracer);
  std::string reason;
  std::unique_ptr<VulkanBackend> v = choose_vulkan(options, world, rays, lights, reason);
  if (v) return std::make_unique<VulkanReference>(std::move(v), tracer);
  return std::make_unique<CpuReference>(world, rays, lights, tracer);
}

}  // namespace irradcast

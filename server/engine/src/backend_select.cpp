#include "irradcast/engine/backend_select.h"

#include "irradcast/engine/embree_backend.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/engine/vulkan_backend.h"

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

BackendChoice make_backend(const BackendOptions& options, const World& world, const RayScene& rays,
                           const LightSampler& lights) {
  BackendChoice c;
  VulkanContextOptions vo;
  vo.device = options.vulkan_device;
  vo.validation = options.vulkan_validation;
  if (options.kind == BackendKind::Vulkan) {
    try {
      auto v = std::make_unique<VulkanBackend>(world, rays, lights, vo);
      c.reason = v->describe() + " (--backend vulkan)";
      c.backend = std::move(v);
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
        auto v = std::make_unique<VulkanBackend>(world, rays, lights, vo);
        c.reason = v->describe() + " (--backend auto)";
        c.backend = std::move(v);
      }
    } catch (const std::exception& e) {  // Error, or bad_alloc on a huge scene
      why = e.what();
    }
    if (!c.backend) c.reason = "embree (--backend auto: " + why + ")";
  } else {
    c.reason = "embree (--backend embree)";
  }
  if (!c.backend) c.backend = std::make_unique<EmbreeBackend>(rays, lights);
  log::info("engine", "backend: " + c.reason);
  return c;
}

}  // namespace irradcast

// The Vulkan side of the engine's GPU backend (issue 6), first part: finding a device and
// opening it. A VulkanContext is an instance (with the Khronos validation layer and a debug
// messenger that counts what it reports, when asked), one physical device with a compute queue,
// a logical device and that queue. No ray-tracing extensions are used or needed: the passes
// will be compute shaders over a BVH in storage buffers, so Mesa's lavapipe (CPU) and real GPUs
// run the same code.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace irradcast {

struct VulkanDeviceInfo {
  std::uint32_t index = 0;  // in the instance's physical device list
  std::string name;
  std::string type;         // "integrated GPU", "discrete GPU", "virtual GPU", "CPU", "other"
  std::string api_version;  // "1.3.230"
  std::string driver;       // driver name and info (VK_KHR_driver_properties), if known
  std::uint32_t vendor_id = 0, device_id = 0;
  bool compute = false;             // has a queue family with compute
  std::uint64_t device_memory = 0;  // bytes of device-local heaps
  std::uint32_t max_workgroup_invocations = 0;
  std::uint64_t max_storage_buffer_range = 0;
};

// Every physical device the loader finds. Throws irradcast::Error with the reason when there is
// no Vulkan at all (no loader, no driver: "vkCreateInstance: VK_ERROR_INCOMPATIBLE_DRIVER").
std::vector<VulkanDeviceInfo> list_vulkan_devices();

// One line per device, for --list-devices.
std::string describe(const VulkanDeviceInfo& d);

struct VulkanContextOptions {
  int device = -1;          // index into list_vulkan_devices(); -1 = the best with compute
  bool validation = false;  // enable VK_LAYER_KHRONOS_validation and count its messages
};

class VulkanContext {
 public:
  // Throws irradcast::Error naming what failed (no device, no compute queue, the validation
  // layer asked for but not installed, device creation).
  explicit VulkanContext(VulkanContextOptions options = {});
  ~VulkanContext();
  VulkanContext(const VulkanContext&) = delete;
  VulkanContext& operator=(const VulkanContext&) = delete;

  const VulkanDeviceInfo& device() const;
  std::uint32_t queue_family() const;
  // Validation messages (warnings and errors) reported so far; 0 without validation.
  std::uint64_t validation_messages() const;
  std::vector<std::string> validation_log() const;

  struct Impl;
  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace irradcast

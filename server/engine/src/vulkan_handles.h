// Internal to irradcast_server: the raw Vulkan handles behind a VulkanContext, for the backend
// that records and submits work on it (the public header stays free of vulkan.h).
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>

#include "irradcast/engine/vulkan_device.h"

namespace irradcast {

struct VulkanHandles {
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  std::uint32_t queue_family = 0;
};

VulkanHandles vulkan_handles(const VulkanContext& context);

// Throws irradcast::Error "Vulkan: <what>: <result name>" unless r is VK_SUCCESS.
void vk_check(VkResult r, const char* what);

}  // namespace irradcast

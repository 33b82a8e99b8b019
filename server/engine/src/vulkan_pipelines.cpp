// The Vulkan backend's device objects (vulkan_backend_impl.h): the limits it checks, the
// descriptor set over the storage buffers, the compute pipelines of the embedded SPIR-V shaders,
// the command buffer, its fence and timestamp queries; and their release.
#include "vulkan_backend_impl.h"

#include <array>
#include <utility>

#include "direct.spv.h"
#include "gather.spv.h"
#include "irradcast/common/error.h"
#include "reference.spv.h"
#include "scatter.spv.h"

namespace irradcast {

VulkanBackend::Impl::Impl(const World& w, const RayScene& r, const LightSampler& l,
                          VulkanContextOptions o, bool force_staging)
    : context(o), vk(vulkan_handles(context)), world(&w), rays(&r), lights(&l) {
  vkGetPhysicalDeviceMemoryProperties(vk.physical, &memory);
  vkGetPhysicalDeviceProperties(vk.physical, &properties);
  discrete = properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU || force_staging;
  staging_only = force_staging;
  if (properties.limits.maxPerStageDescriptorStorageBuffers < kBindings)
    throw Error("Vulkan: " + context.device().name + " allows " +
                std::to_string(properties.limits.maxPerStageDescriptorStorageBuffers) +
                " storage buffers per shader stage; the passes need " +
                std::to_string(static_cast<int>(kBindings)));
  if (properties.apiVersion < VK_API_VERSION_1_1)
    throw Error("Vulkan: " + context.device().name + " supports Vulkan " +
                context.device().api_version + "; the passes need 1.1");
  max_groups = std::min<std::uint32_t>(properties.limits.maxComputeWorkGroupCount[0], 65535u);
  max_buffer =
      std::min<VkDeviceSize>(properties.limits.maxStorageBufferRange, VkDeviceSize{1} << 32);
  try {
    create_pipelines();
    create_commands();
    for (int b = 0; b < kBindings; ++b) create(device_buffers[b], 16, false);
    upload_scene();
  } catch (...) {
    release();  // ~Impl does not run for a constructor that throws
    throw;
  }
}

void VulkanBackend::Impl::release() {
  if (vk.device == VK_NULL_HANDLE) return;
  vkDeviceWaitIdle(vk.device);
  for (int b = 0; b < kBindings; ++b) {
    destroy(device_buffers[b]);
    destroy(staging[b]);
  }
  if (fence) vkDestroyFence(vk.device, fence, nullptr);
  if (timestamps) vkDestroyQueryPool(vk.device, timestamps, nullptr);
  timestamps = VK_NULL_HANDLE;
  if (command_pool) vkDestroyCommandPool(vk.device, command_pool, nullptr);
  for (VkPipeline& p : pipelines) {
    if (p) vkDestroyPipeline(vk.device, p, nullptr);
    p = VK_NULL_HANDLE;
  }
  if (pipeline_layout) vkDestroyPipelineLayout(vk.device, pipeline_layout, nullptr);
  if (descriptor_pool) vkDestroyDescriptorPool(vk.device, descriptor_pool, nullptr);
  if (set_layout) vkDestroyDescriptorSetLayout(vk.device, set_layout, nullptr);
  fence = VK_NULL_HANDLE;
  command_pool = VK_NULL_HANDLE;
  pipeline_layout = VK_NULL_HANDLE;
  descriptor_pool = VK_NULL_HANDLE;
  set_layout = VK_NULL_HANDLE;
}

void VulkanBackend::Impl::create_pipelines() {
  std::array<VkDescriptorSetLayoutBinding, kBindings> layout_bindings{};
  for (int b = 0; b < kBindings; ++b) {
    layout_bindings[b].binding = static_cast<std::uint32_t>(b);
    layout_bindings[b].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    layout_bindings[b].descriptorCount = 1;
    layout_bindings[b].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
  }
  VkDescriptorSetLayoutCreateInfo sl{};
  sl.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  sl.bindingCount = kBindings;
  sl.pBindings = layout_bindings.data();
  vk_check(vkCreateDescriptorSetLayout(vk.device, &sl, nullptr, &set_layout),
           "vkCreateDescriptorSetLayout");
  VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(PushConstants)};
  VkPipelineLayoutCreateInfo pl{};
  pl.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  pl.setLayoutCount = 1;
  pl.pSetLayouts = &set_layout;
  pl.pushConstantRangeCount = 1;
  pl.pPushConstantRanges = &range;
  vk_check(vkCreatePipelineLayout(vk.device, &pl, nullptr, &pipeline_layout),
           "vkCreatePipelineLayout");
  VkDescriptorPoolSize size{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, kBindings};
  VkDescriptorPoolCreateInfo dp{};
  dp.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  dp.maxSets = 1;
  dp.poolSizeCount = 1;
  dp.pPoolSizes = &size;
  vk_check(vkCreateDescriptorPool(vk.device, &dp, nullptr, &descriptor_pool),
           "vkCreateDescriptorPool");
  VkDescriptorSetAllocateInfo da{};
  da.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
  da.descriptorPool = descriptor_pool;
  da.descriptorSetCount = 1;
  da.pSetLayouts = &set_layout;
  vk_check(vkAllocateDescriptorSets(vk.device, &da, &descriptor_set), "vkAllocateDescriptorSets");

  const std::pair<const std::uint32_t*, std::size_t> code[kPipelines] = {
      {irradcast_direct_spv, sizeof(irradcast_direct_spv)},
      {irradcast_gather_spv, sizeof(irradcast_gather_spv)},
      {irradcast_scatter_spv, sizeof(irradcast_scatter_spv)},
      {irradcast_reference_spv, sizeof(irradcast_reference_spv)}};
  for (int p = 0; p < kPipelines; ++p) {
    VkShaderModuleCreateInfo sm{};
    sm.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
    sm.codeSize = code[p].second;
    sm.pCode = code[p].first;
    VkShaderModule module = VK_NULL_HANDLE;
    vk_check(vkCreateShaderModule(vk.device, &sm, nullptr, &module), "vkCreateShaderModule");
    VkComputePipelineCreateInfo cp{};
    cp.sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO;
    cp.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    cp.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    cp.stage.module = module;
    cp.stage.pName = "main";
    cp.layout = pipeline_layout;
    VkResult r =
        vkCreateComputePipelines(vk.device, VK_NULL_HANDLE, 1, &cp, nullptr, &pipelines[p]);
    vkDestroyShaderModule(vk.device, module, nullptr);
    vk_check(r, "vkCreateComputePipelines");
  }
}

void VulkanBackend::Impl::create_commands() {
  VkCommandPoolCreateInfo cp{};
  cp.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  cp.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  cp.queueFamilyIndex = vk.queue_family;
  vk_check(vkCreateCommandPool(vk.device, &cp, nullptr, &command_pool), "vkCreateCommandPool");
  VkCommandBufferAllocateInfo ca{};
  ca.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ca.commandPool = command_pool;
  ca.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ca.commandBufferCount = 1;
  vk_check(vkAllocateCommandBuffers(vk.device, &ca, &commands), "vkAllocateCommandBuffers");
  VkFenceCreateInfo fi{};
  fi.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  vk_check(vkCreateFence(vk.device, &fi, nullptr, &fence), "vkCreateFence");
  // Timestamps around each submission, where the compute queue has them.
  std::uint32_t families = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(vk.physical, &families, nullptr);
  std::vector<VkQueueFamilyProperties> family(families);
  vkGetPhysicalDeviceQueueFamilyProperties(vk.physical, &families, family.data());
  const std::uint32_t valid_bits =
      vk.queue_family < families ? family[vk.queue_family].timestampValidBits : 0;
  if (valid_bits == 0 || properties.limits.timestampPeriod <= 0.0f) return;
  timestamp_mask = valid_bits >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << valid_bits) - 1;
  timestamp_ns = properties.limits.timestampPeriod;
  VkQueryPoolCreateInfo qi{};
  qi.sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO;
  qi.queryType = VK_QUERY_TYPE_TIMESTAMP;
  qi.queryCount = kTimestamps;
  vk_check(vkCreateQueryPool(vk.device, &qi, nullptr, &timestamps), "vkCreateQueryPool");
}

void VulkanBackend::Impl::update_descriptors() {
  std::array<VkDescriptorBufferInfo, kBindings> infos{};
  std::array<VkWriteDescriptorSet, kBindings> writes{};
  for (int b = 0; b < kBindings; ++b) {
    infos[b] = VkDescriptorBufferInfo{device_buffers[b].buffer, 0, VK_WHOLE_SIZE};
    writes[b].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    writes[b].dstSet = descriptor_set;
    writes[b].dstBinding = static_cast<std::uint32_t>(b);
    writes[b].descriptorCount = 1;
    writes[b].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[b].pBufferInfo = &infos[b];
  }
  vkUpdateDescriptorSets(vk.device, kBindings, writes.data(), 0, nullptr);
  descriptors_dirty = false;
}

}  // namespace irradcast

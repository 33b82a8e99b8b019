// The Vulkan backend's storage buffers and submission (vulkan_backend_impl.h): memory types,
// buffers (device-local with staging, or host-visible written in place), uploads, and the
// pieces of one submission (begin, dispatches, read-back, submit with its fence wait and the
// device time from two timestamps).
#include "vulkan_backend_impl.h"

#include <algorithm>
#include <vector>

#include "irradcast/common/error.h"

namespace irradcast {

int VulkanBackend::Impl::memory_type(std::uint32_t allowed, VkMemoryPropertyFlags want) const {
  for (std::uint32_t i = 0; i < memory.memoryTypeCount; ++i)
    if ((allowed & (1u << i)) && (memory.memoryTypes[i].propertyFlags & want) == want)
      return static_cast<int>(i);
  return -1;
}

// A storage buffer the shaders read: device-local on a discrete GPU (filled through staging),
// host-visible device memory elsewhere (written in place). Staging buffers are host memory.
void VulkanBackend::Impl::create(Buffer& b, VkDeviceSize size, bool staging_buffer,
                                 bool read_back) {
  if (!staging_buffer && size > max_buffer)
    throw Error("Vulkan: a " + std::to_string(size >> 20) + " MiB storage buffer exceeds " +
                context.device().name + "'s limit of " + std::to_string(max_buffer >> 20) +
                " MiB (maxStorageBufferRange); use --backend embree or a lower lightmap density");
  VkBufferCreateInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
  bi.size = size;
  bi.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
             VK_BUFFER_USAGE_TRANSFER_DST_BIT;
  bi.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  vk_check(vkCreateBuffer(vk.device, &bi, nullptr, &b.buffer), "vkCreateBuffer");
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(vk.device, b.buffer, &req);
  const VkMemoryPropertyFlags host =
      VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
  const VkMemoryPropertyFlags local = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
  const VkMemoryPropertyFlags cached = VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
  std::vector<VkMemoryPropertyFlags> prefs;
  if (staging_buffer)
    prefs = {host | cached, host};
  else if (discrete)
    prefs = {local, host};
  else
    // The result is read by the host: cached memory reads fast there (integrated GPUs often
    // have an uncached host-visible device-local type too, which is slow to read).
    prefs = read_back ? std::vector<VkMemoryPropertyFlags>{local | host | cached, host | cached,
                                                           local | host, host, local}
                      : std::vector<VkMemoryPropertyFlags>{local | host, host, local};
  VkResult last = VK_ERROR_OUT_OF_DEVICE_MEMORY;
  for (VkMemoryPropertyFlags want : prefs) {
    int type = memory_type(req.memoryTypeBits, want);
    if (type < 0) continue;
    VkMemoryAllocateInfo ai{};
    ai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = static_cast<std::uint32_t>(type);
    VkDeviceMemory allocated = VK_NULL_HANDLE;
    last = vkAllocateMemory(vk.device, &ai, nullptr, &allocated);
    if (last != VK_SUCCESS) continue;
    b.memory = allocated;
    vk_check(vkBindBufferMemory(vk.device, b.buffer, b.memory, 0), "vkBindBufferMemory");
    b.size = size;
    const VkMemoryPropertyFlags got = memory.memoryTypes[type].propertyFlags;
    if ((got & host) == host && (staging_buffer || !staging_only))
      vk_check(vkMapMemory(vk.device, b.memory, 0, VK_WHOLE_SIZE, 0, &b.mapped), "vkMapMemory");
    return;
  }
  vkDestroyBuffer(vk.device, b.buffer, nullptr);
  b.buffer = VK_NULL_HANDLE;
  vk_check(last, ("vkAllocateMemory (" + std::to_string(size >> 20) + " MiB)").c_str());
}

void VulkanBackend::Impl::destroy(Buffer& b) {
  if (b.memory) {
    if (b.mapped) vkUnmapMemory(vk.device, b.memory);
    vkFreeMemory(vk.device, b.memory, nullptr);
  }
  if (b.buffer) vkDestroyBuffer(vk.device, b.buffer, nullptr);
  b = Buffer{};
}

void VulkanBackend::Impl::ensure(int binding, VkDeviceSize bytes) {
  Buffer& b = device_buffers[binding];
  if (b.size >= bytes) return;
  destroy(b);
  create(b, bytes, false, binding == kResult);
  descriptors_dirty = true;
}

// Writes `bytes` into a binding: in place when mapped, else into its staging buffer with a
// copy recorded before the next dispatch.
void VulkanBackend::Impl::write(int binding, VkDeviceSize bytes,
                                const std::function<void(void*)>& fill) {
  stats.bytes_up += bytes;
  bytes = std::max<VkDeviceSize>(bytes, 16);
  ensure(binding, bytes);
  if (device_buffers[binding].mapped) {
    fill(device_buffers[binding].mapped);
    return;
  }
  if (staging[binding].size < bytes) {
    destroy(staging[binding]);
    create(staging[binding], bytes, true);
  }
  fill(staging[binding].mapped);
  uploads.emplace_back(binding, bytes);
}

void VulkanBackend::Impl::begin() {
  if (descriptors_dirty) update_descriptors();
  VkCommandBufferBeginInfo info{};
  info.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
  info.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  vk_check(vkResetCommandBuffer(commands, 0), "vkResetCommandBuffer");
  vk_check(vkBeginCommandBuffer(commands, &info), "vkBeginCommandBuffer");
  next_query = 0;
  if (timestamps) {
    vkCmdResetQueryPool(commands, timestamps, 0, kTimestamps);
    vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, timestamps, next_query++);
  }
  for (auto [binding, bytes] : uploads) {
    VkBufferCopy region{0, 0, bytes};
    vkCmdCopyBuffer(commands, staging[binding].buffer, device_buffers[binding].buffer, 1, &region);
  }
  if (!uploads.empty())
    barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
            VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  readback_pending = false;
}

void VulkanBackend::Impl::mark() {
  if (timestamps && next_query + 1 < kTimestamps)
    vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, timestamps, next_query++);
}

void VulkanBackend::Impl::dispatch(PipelineId pipeline, PushConstants pc, std::uint32_t count) {
  vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipelines[pipeline]);
  vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_layout, 0, 1,
                          &descriptor_set, 0, nullptr);
  pc.count = count;
  const std::uint64_t chunk = std::uint64_t{max_groups} * 64u;
  for (std::uint64_t base = 0; base < count; base += chunk) {
    pc.base = static_cast<std::uint32_t>(base);
    vkCmdPushConstants(commands, pipeline_layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc), &pc);
    const std::uint64_t items = std::min<std::uint64_t>(chunk, count - base);
    vkCmdDispatch(commands, static_cast<std::uint32_t>((items + 63u) / 64u), 1, 1);
  }
}

void VulkanBackend::Impl::read_back(std::size_t out_size) {
  const VkDeviceSize result_bytes = std::max<VkDeviceSize>(out_size * sizeof(glm::vec4), 16);
  stats.bytes_down += out_size * sizeof(glm::vec4);
  if (device_buffers[kResult].mapped == nullptr) {
    barrier(VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
            VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    VkBufferCopy region{0, 0, result_bytes};
    vkCmdCopyBuffer(commands, device_buffers[kResult].buffer, staging[kResult].buffer, 1, &region);
    barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
            VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    readback_pending = true;
  } else {
    barrier(VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
            VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
  }
}

void VulkanBackend::Impl::submit() {
  if (timestamps)
    vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, timestamps, next_query++);
  vk_check(vkEndCommandBuffer(commands), "vkEndCommandBuffer");
  VkSubmitInfo info{};
  info.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
  info.commandBufferCount = 1;
  info.pCommandBuffers = &commands;
  vk_check(vkResetFences(vk.device, 1, &fence), "vkResetFences");
  vk_check(vkQueueSubmit(vk.queue, 1, &info, fence), "vkQueueSubmit");
  vk_check(vkWaitForFences(vk.device, 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
  ++stats.submissions;
  // Scene and engine data are written once: their staging copies are not needed again.
  for (auto [binding, bytes] : uploads)
    if (binding != kPrev && binding != kProbeRadiance) destroy(staging[binding]);
  uploads.clear();
  intervals.clear();
  if (timestamps) {
    std::uint64_t ticks[kTimestamps] = {};
    const VkResult r = vkGetQueryPoolResults(vk.device, timestamps, 0, next_query, sizeof(ticks),
                                             ticks, sizeof(std::uint64_t),
                                             VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT);
    vk_check(r, "vkGetQueryPoolResults");
    for (std::uint32_t q = 1; q < next_query; ++q) {
      const std::uint64_t elapsed = (ticks[q] - ticks[q - 1]) & timestamp_mask;
      intervals.push_back(static_cast<double>(elapsed) * timestamp_ns * 1e-9);
      stats.device_seconds += intervals.back();
    }
  }
}

void VulkanBackend::Impl::take_results(std::vector<glm::vec3>& out, std::size_t out_size,
                                       double* w_sum,
                                       const std::vector<std::uint32_t>* w_at) const {
  const auto* src = static_cast<const glm::vec4*>(
      readback_pending ? staging[kResult].mapped : device_buffers[kResult].mapped);
  out.resize(out_size);
  for (std::size_t i = 0; i < out_size; ++i) out[i] = glm::vec3(src[i]);
  if (w_sum && w_at)
    for (std::uint32_t i : *w_at) *w_sum += i < out_size ? src[i].w : 0.0f;
  else if (w_sum)
    for (std::size_t i = 0; i < out_size; ++i) *w_sum += src[i].w;
}

void VulkanBackend::Impl::prepare_result(std::size_t out_size) {
  const VkDeviceSize result_bytes = std::max<VkDeviceSize>(out_size * sizeof(glm::vec4), 16);
  ensure(kResult, result_bytes);
  if (device_buffers[kResult].mapped == nullptr && staging[kResult].size < result_bytes) {
    destroy(staging[kResult]);
    create(staging[kResult], result_bytes, true);
  }
}

bool VulkanBackend::Impl::resident_means(std::uint64_t id, std::size_t per_bounce, int bounces) {
  const MeansKey key{id, per_bounce, bounces};
  if (key == means_key) return false;
  const VkDeviceSize bytes = static_cast<VkDeviceSize>(per_bounce) *
                             static_cast<VkDeviceSize>(std::max(bounces, 1)) * sizeof(glm::vec4);
  ensure(kProbeRadiance, std::max<VkDeviceSize>(bytes, 16));
  means_key = key;
  return true;
}

void VulkanBackend::Impl::run(PipelineId pipeline, PushConstants pc, std::uint32_t count,
                              std::vector<glm::vec3>& out, std::size_t out_size, double* w_sum,
                              const std::vector<std::uint32_t>* w_at) {
  prepare_result(out_size);
  begin();
  dispatch(pipeline, pc, count);
  read_back(out_size);
  submit();
  take_results(out, out_size, w_sum, w_at);
}

void VulkanBackend::Impl::barrier(VkPipelineStageFlags src_stage, VkAccessFlags src,
                                  VkPipelineStageFlags dst_stage, VkAccessFlags dst) {
  VkMemoryBarrier mb{};
  mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
  mb.srcAccessMask = src;
  mb.dstAccessMask = dst;
  vkCmdPipelineBarrier(commands, src_stage, dst_stage, 0, 1, &mb, 0, nullptr, 0, nullptr);
}

}  // namespace irradcast

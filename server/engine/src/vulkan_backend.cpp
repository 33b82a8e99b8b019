#include "irradcast/engine/vulkan_backend.h"

#include <vulkan/vulkan.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <exception>
#include <functional>
#include <mutex>
#include <string>

#include "direct.spv.h"
#include "gather.spv.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "irradcast/engine/gpu_bvh.h"
#include "irradcast/common/progress.h"
#include "reference.spv.h"
#include "scatter.spv.h"
#include "vulkan_handles.h"

namespace irradcast {
namespace {

using Clock = std::chrono::steady_clock;

// The storage buffers, in shaders/common.glsl's binding order.
enum Binding : int {
  kNodes,
  kTris,
  kTriAttr,
  kObjects,
  kMaterials,
  kTexHeaders,
  kTexTexels,
  kEmissive,
  kPunctual,
  kTexels,
  kUnits,
  kProbes,
  kProbeWeights,
  kPrev,
  kProbeRadiance,
  kResult,
  kTriNormals,
  kBindings
};

enum PipelineId : int {
  kDirectPipeline,
  kGatherPipeline,
  kScatterPipeline,
  kReferencePipeline,
  kPipelines
};

enum Flags : std::uint32_t {
  kFlagArea = 1,
  kFlagUnbiased = 2,
  kFlagFixed = 4,
  kFlagProbes = 8,
  kFlagCamera = 16
};

// shaders/common.glsl's push constant block (std430 offsets).
struct PushConstants {
  std::uint32_t base = 0, count = 0, update = 0, bounce = 0;
  std::uint32_t seed_lo = 0, seed_hi = 0, samples = 0, flags = 0;
  float epsilon = 0.0f, range = 0.0f, extent = 0.0f;
  std::uint32_t punctual_count = 0;
  float bounds_lo[3] = {0.0f, 0.0f, 0.0f};
  std::uint32_t emissive_count = 0;
  float bounds_hi[3] = {0.0f, 0.0f, 0.0f};
  std::int32_t probe_res = 0;
};
static_assert(sizeof(PushConstants) == 80);

struct Buffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkDeviceSize size = 0;
  void* mapped = nullptr;  // persistently mapped when host-visible and coherent
};

template <typename T>
std::uint32_t bits(T v) {
  static_assert(sizeof(T) == 4);
  std::uint32_t u;
  std::memcpy(&u, &v, 4);
  return u;
}

float as_float(std::uint32_t u) {
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

float as_float(std::int32_t i) {
  return as_float(static_cast<std::uint32_t>(i));
}

// What the engine's own data was last uploaded from (it does not change while an engine lives).
struct EngineKey {
  const void* atlas = nullptr;
  const void* texels = nullptr;
  std::size_t texel_count = 0;
  const void* units = nullptr;
  std::size_t unit_count = 0;
  const void* probes = nullptr;
  std::size_t probe_count = 0;
  const void* weights = nullptr;
  std::size_t weight_count = 0;
  std::uint64_t generation = 0;
  bool operator==(const EngineKey&) const = default;
};

}  // namespace

struct VulkanBackend::Impl {
  Impl(const World& w, const RayScene& r, const LightSampler& l, VulkanContextOptions o,
       bool force_staging)
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

  ~Impl() { release(); }

  void release() {
    if (vk.device == VK_NULL_HANDLE) return;
    vkDeviceWaitIdle(vk.device);
    for (int b = 0; b < kBindings; ++b) {
      destroy(device_buffers[b]);
      destroy(staging[b]);
    }
    if (fence) vkDestroyFence(vk.device, fence, nullptr);
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

  // ---- set-up

  void create_pipelines() {
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

  void create_commands() {
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
  }

  // ---- buffers

  int memory_type(std::uint32_t allowed, VkMemoryPropertyFlags want) const {
    for (std::uint32_t i = 0; i < memory.memoryTypeCount; ++i)
      if ((allowed & (1u << i)) && (memory.memoryTypes[i].propertyFlags & want) == want)
        return static_cast<int>(i);
    return -1;
  }

  // A storage buffer the shaders read: device-local on a discrete GPU (filled through staging),
  // host-visible device memory elsewhere (written in place). Staging buffers are host memory.
  void create(Buffer& b, VkDeviceSize size, bool staging_buffer, bool read_back = false) {
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

  void destroy(Buffer& b) {
    if (b.memory) {
      if (b.mapped) vkUnmapMemory(vk.device, b.memory);
      vkFreeMemory(vk.device, b.memory, nullptr);
    }
    if (b.buffer) vkDestroyBuffer(vk.device, b.buffer, nullptr);
    b = Buffer{};
  }

  void ensure(int binding, VkDeviceSize bytes) {
    Buffer& b = device_buffers[binding];
    if (b.size >= bytes) return;
    destroy(b);
    create(b, bytes, false, binding == kResult);
    descriptors_dirty = true;
  }

  // Writes `bytes` into a binding: in place when mapped, else into its staging buffer with a
  // copy recorded before the next dispatch.
  void write(int binding, VkDeviceSize bytes, const std::function<void(void*)>& fill) {
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

  template <typename T>
  void write(int binding, const std::vector<T>& data) {
    write(binding, data.size() * sizeof(T), [&](void* dst) {
      if (!data.empty()) std::memcpy(dst, data.data(), data.size() * sizeof(T));
    });
  }

  // ---- the scene and the engine's data

  void upload_scene() {
    const GpuBvh bvh = build_gpu_bvh(*world);
    write(kNodes, bvh.nodes);
    write(kTris, bvh.triangles);
    const Scene& scene = *world->scene;
    const int textures = static_cast<int>(scene.textures.size());
    auto texture = [&](int t) { return as_float(t >= 0 && t < textures ? t : -1); };
    std::vector<glm::vec4> mats;
    std::vector<Material> all(scene.materials.begin(), scene.materials.end());
    all.push_back(Material{});  // World::material's fallback
    for (const Material& m : all) {
      mats.emplace_back(m.base_color, texture(m.base_color_texture));
      mats.emplace_back(m.is_emissive() ? m.emission() : glm::vec3(0.0f),
                        texture(m.emissive_texture));
    }
    write(kMaterials, mats);
    std::vector<glm::uvec4> headers;
    std::vector<std::uint32_t> texels;
    for (const Texture& t : scene.textures) {
      headers.emplace_back(static_cast<std::uint32_t>(texels.size()), t.width, t.height, 0u);
      const std::size_t n = static_cast<std::size_t>(t.width) * t.height;
      const std::size_t at = texels.size();
      texels.resize(at + n);
      if (n > 0 && t.rgba8.size() >= 4 * n) std::memcpy(&texels[at], t.rgba8.data(), 4 * n);
    }
    write(kTexHeaders, headers);
    write(kTexTexels, texels);

    std::vector<glm::vec4> em;
    const auto& tris = lights->emissive_triangles();
    for (std::size_t k = 0; k < tris.size(); ++k) {
      const EmissiveTriangle& e = tris[k];
      const WorldObject& o = world->objects[e.object];
      const Material& m = world->material(e.object, e.triangle);
      em.emplace_back(e.p0, 0.0f);
      em.emplace_back(e.e1, 0.0f);
      em.emplace_back(e.e2, e.double_sided ? 1.0f : 0.0f);
      em.emplace_back(e.normal, e.area);
      em.emplace_back(lights->pick_cdf()[k], lights->pick_pdf()[k],
                      as_float(material_index(e.object, e.triangle)), 0.0f);
      const int set = m.emissive_uv;
      em.emplace_back(o.uv(set, e.triangle, 0.0f, 0.0f), o.uv(set, e.triangle, 1.0f, 0.0f));
      em.emplace_back(o.uv(set, e.triangle, 0.0f, 1.0f), glm::vec2(0.0f));
    }
    write(kEmissive, em);
    emissive_count = static_cast<std::uint32_t>(tris.size());

    std::vector<glm::vec4> pl;
    for (const WorldLight& l : world->lights) {
      float type = l.type == Light::Type::Directional ? 0.0f
                   : l.type == Light::Type::Spot      ? 2.0f
                                                      : 1.0f;
      pl.emplace_back(l.position, type);
      pl.emplace_back(l.direction, l.range);
      pl.emplace_back(l.intensity, l.cos_inner);
      pl.emplace_back(l.cos_outer, 0.0f, 0.0f, 0.0f);
    }
    write(kPunctual, pl);
    punctual_count = static_cast<std::uint32_t>(world->lights.size());

    // Per triangle (global index, objects in order): its entry in the emissive list or -1.
    std::vector<std::size_t> base;
    std::size_t triangles = 0;
    for (const WorldObject& o : world->objects) {
      base.push_back(triangles);
      triangles += o.triangles().size();
    }
    emissive_of.assign(triangles, -1);
    for (std::size_t k = 0; k < tris.size(); ++k)
      emissive_of[base[static_cast<std::size_t>(tris[k].object)] + tris[k].triangle] =
          static_cast<std::int32_t>(k);

    std::vector<glm::vec4> normals;
    for (const WorldObject& o : world->objects) {
      const bool has = !o.normals.empty();
      for (const glm::uvec3& t : o.triangles())
        for (int k = 0; k < 3; ++k)
          normals.emplace_back(has ? o.normals[t[k]] : glm::vec3(0.0f),
                               k == 0 && has ? 1.0f : 0.0f);
    }
    write(kTriNormals, normals);
    write_surfaces(nullptr);
  }

  std::uint32_t material_index(int object, std::uint32_t t) const {
    const Mesh& mesh = *world->objects[object].source;
    const std::size_t materials = world->scene->materials.size();
    std::uint32_t m = t < mesh.triangle_material.size() ? mesh.triangle_material[t] : ~0u;
    return m < materials ? m : static_cast<std::uint32_t>(materials);
  }

  // Per object: triangle base, lightmap offset and size; per triangle: lightmap and base-colour
  // uv corners, material. Without an atlas (the reference path tracer reads no lightmap) the
  // lightmap fields are zero.
  void write_surfaces(const Atlas* atlas) {
    std::vector<glm::uvec4> objects;
    std::vector<glm::vec4> attr;
    std::uint32_t lightmap_texels = 0;
    object_offsets.clear();
    const ObjectLightmap none;
    for (const WorldObject& o : world->objects) {
      const ObjectLightmap& lm = atlas ? atlas->objects[o.object] : none;
      objects.emplace_back(static_cast<std::uint32_t>(attr.size() / 4), lightmap_texels,
                           static_cast<std::uint32_t>(lm.width),
                           static_cast<std::uint32_t>(lm.height));
      object_offsets.push_back(lightmap_texels);
      lightmap_texels += static_cast<std::uint32_t>(lm.width * lm.height);
      const auto& tris = o.triangles();
      for (std::uint32_t t = 0; t < tris.size(); ++t) {
        const std::size_t c = 3 * static_cast<std::size_t>(t);
        const glm::vec2 zero(0.0f);
        glm::vec2 l0 = c + 2 < lm.corner_uv.size() ? lm.corner_uv[c] : zero;
        glm::vec2 l1 = c + 2 < lm.corner_uv.size() ? lm.corner_uv[c + 1] : zero;
        glm::vec2 l2 = c + 2 < lm.corner_uv.size() ? lm.corner_uv[c + 2] : zero;
        const int set = world->material(o.object, t).base_color_uv;
        attr.emplace_back(l0, l1);
        attr.emplace_back(l2, o.uv(set, t, 0.0f, 0.0f));
        attr.emplace_back(o.uv(set, t, 1.0f, 0.0f), o.uv(set, t, 0.0f, 1.0f));
        const std::size_t global = attr.size() / 4;
        attr.emplace_back(as_float(material_index(o.object, t)),
                          as_float(global < emissive_of.size() ? emissive_of[global] : -1), 0.0f,
                          0.0f);
      }
    }
    lightmap_total = lightmap_texels;
    write(kObjects, objects);
    write(kTriAttr, attr);
  }

  void prepare(const PassInput& in) {
    EngineKey key{&in.atlas,
                  in.texels.position.data(),
                  in.texels.size(),
                  in.unit_texels.data(),
                  in.unit_texels.size(),
                  in.probes.position.data(),
                  in.probes.count(),
                  in.probe_weights.data(),
                  in.probe_weights.size(),
                  in.generation};
    if (key == engine_key) return;
    if (in.atlas.objects.size() != world->objects.size())
      throw Error("Vulkan backend: the atlas has " + std::to_string(in.atlas.objects.size()) +
                  " objects, the world " + std::to_string(world->objects.size()));
    write_surfaces(&in.atlas);
    const SurfaceTexels& st = in.texels;
    write(kTexels, st.size() * 3 * sizeof(glm::vec4), [&](void* dst) {
      auto* v = static_cast<glm::vec4*>(dst);
      for (std::size_t i = 0; i < st.size(); ++i) {
        v[3 * i] = glm::vec4(st.position[i], 0.0f);
        v[3 * i + 1] = glm::vec4(st.normal[i], 0.0f);
        v[3 * i + 2] = glm::vec4(st.geo_normal[i], 0.0f);
      }
    });
    write(kUnits, in.unit_texels);
    std::vector<glm::vec4> probes;
    for (std::size_t p = 0; p < in.probes.count(); ++p)
      probes.emplace_back(in.probes.position[p], in.probes.usable[p] ? 1.0f : 0.0f);
    write(kProbes, probes);
    write(kProbeWeights, in.probe_weights.size() * 20 * sizeof(std::uint32_t), [&](void* dst) {
      auto* w = static_cast<std::uint32_t*>(dst);
      for (std::size_t i = 0; i < in.probe_weights.size(); ++i) {
        const ProbeWeights& pw = in.probe_weights[i];
        std::uint32_t* o = w + 20 * i;
        for (int k = 0; k < 8; ++k) {
          const bool used = k < pw.count;
          o[k] = used ? pw.probe[k] : 0u;
          o[8 + k] = used ? bits(pw.weight[k]) : 0u;
        }
        o[16] = pw.count;
        o[17] = o[18] = o[19] = 0;
      }
    });
    engine_key = key;
  }

  // The previous bounce's lightmaps: the gather and the scatter of one bounce read the same
  // ones, so the scatter does not upload them again.
  void write_previous(const RadianceField& prev, const PassInput& in) {
    const PrevKey key{prev.irradiance, in.update, in.bounce};
    if (key == prev_key) return;
    prev_key = key;
    const std::vector<Lightmap>& maps = *prev.irradiance;
    if (maps.size() != object_offsets.size())
      throw Error("Vulkan backend: " + std::to_string(maps.size()) + " lightmaps for " +
                  std::to_string(object_offsets.size()) + " objects");
    write(kPrev, static_cast<VkDeviceSize>(lightmap_total) * sizeof(glm::vec4), [&](void* dst) {
      auto* v = static_cast<glm::vec4*>(dst);
      for (std::size_t o = 0; o < maps.size(); ++o) {
        const std::size_t n = std::min<std::size_t>(
            maps[o].texels.size(),
            (o + 1 < object_offsets.size() ? object_offsets[o + 1] : lightmap_total) -
                object_offsets[o]);
        for (std::size_t i = 0; i < n; ++i)
          v[object_offsets[o] + i] = glm::vec4(maps[o].texels[i], 0.0f);
      }
    });
  }

  PushConstants constants(const PassInput& in) const {
    PushConstants pc;
    pc.update = in.update;
    pc.bounce = in.bounce;
    pc.seed_lo = static_cast<std::uint32_t>(in.params.seed);
    pc.seed_hi = static_cast<std::uint32_t>(in.params.seed >> 32);
    pc.epsilon = rays->epsilon();
    pc.extent = in.world.bounds.max_extent();
    pc.range = in.params.unbiased() ? 3.4e38f : in.params.tracing_range * pc.extent;
    pc.punctual_count = punctual_count;
    pc.emissive_count = emissive_count;
    for (int a = 0; a < 3; ++a) {
      pc.bounds_lo[a] = in.world.bounds.lo[a];
      pc.bounds_hi[a] = in.world.bounds.hi[a];
    }
    pc.probe_res = in.probes.resolution;
    if (emissive_count > 0) pc.flags |= kFlagArea;
    if (in.params.unbiased()) pc.flags |= kFlagUnbiased;
    if (in.params.distant_point == DistantPoint::FixedDistance) pc.flags |= kFlagFixed;
    if (!in.probe_weights.empty()) pc.flags |= kFlagProbes;
    return pc;
  }

  // Records the pending uploads, `count` items of one pass and the read-back of `count`
  // results, submits and waits; the results land in `out`.
  void run(PipelineId pipeline, PushConstants pc, std::uint32_t count, std::vector<glm::vec3>& out,
           std::size_t out_size, double* w_sum = nullptr) {
    const VkDeviceSize result_bytes = std::max<VkDeviceSize>(out_size * sizeof(glm::vec4), 16);
    ensure(kResult, result_bytes);
    const bool readback = device_buffers[kResult].mapped == nullptr;
    if (readback && staging[kResult].size < result_bytes) {
      destroy(staging[kResult]);
      create(staging[kResult], result_bytes, true);
    }
    if (descriptors_dirty) update_descriptors();

    VkCommandBufferBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vk_check(vkResetCommandBuffer(commands, 0), "vkResetCommandBuffer");
    vk_check(vkBeginCommandBuffer(commands, &begin), "vkBeginCommandBuffer");
    for (auto [binding, bytes] : uploads) {
      VkBufferCopy region{0, 0, bytes};
      vkCmdCopyBuffer(commands, staging[binding].buffer, device_buffers[binding].buffer, 1,
                      &region);
    }
    if (!uploads.empty())
      barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
              VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
    vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipelines[pipeline]);
    vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_layout, 0, 1,
                            &descriptor_set, 0, nullptr);
    pc.count = count;
    const std::uint64_t chunk = std::uint64_t{max_groups} * 64u;
    for (std::uint64_t base = 0; base < count; base += chunk) {
      pc.base = static_cast<std::uint32_t>(base);
      vkCmdPushConstants(commands, pipeline_layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc),
                         &pc);
      const std::uint64_t items = std::min<std::uint64_t>(chunk, count - base);
      vkCmdDispatch(commands, static_cast<std::uint32_t>((items + 63u) / 64u), 1, 1);
    }
    if (readback) {
      barrier(VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
              VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
      VkBufferCopy region{0, 0, result_bytes};
      vkCmdCopyBuffer(commands, device_buffers[kResult].buffer, staging[kResult].buffer, 1,
                      &region);
      barrier(VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
              VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    } else {
      barrier(VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
              VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    }
    vk_check(vkEndCommandBuffer(commands), "vkEndCommandBuffer");
    VkSubmitInfo submit{};
    submit.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    submit.commandBufferCount = 1;
    submit.pCommandBuffers = &commands;
    vk_check(vkResetFences(vk.device, 1, &fence), "vkResetFences");
    vk_check(vkQueueSubmit(vk.queue, 1, &submit, fence), "vkQueueSubmit");
    vk_check(vkWaitForFences(vk.device, 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    // Scene and engine data are written once: their staging copies are not needed again.
    for (auto [binding, bytes] : uploads)
      if (binding != kPrev && binding != kProbeRadiance) destroy(staging[binding]);
    uploads.clear();
    const auto* src = static_cast<const glm::vec4*>(readback ? staging[kResult].mapped
                                                             : device_buffers[kResult].mapped);
    out.resize(out_size);
    for (std::size_t i = 0; i < out_size; ++i) out[i] = glm::vec3(src[i]);
    if (w_sum)
      for (std::size_t i = 0; i < out_size; ++i) *w_sum += src[i].w;
  }

  // The reference path tracer over `items` items already in the texel buffer (texels, or with
  // camera set, primary rays): `samples` paths each, in batches of 16 (a progress line, no
  // long dispatch). Returns each item's mean.
  std::vector<glm::dvec3> paths(std::size_t items, int samples, int bounces, std::uint64_t seed,
                                bool camera, const char* what, const char* unit,
                                ReferenceLightmapStats* stats) {
    if (items > 0xFFFFFFFFu) throw Error("Vulkan backend: too many items for one pass");
    PushConstants pc;
    pc.seed_lo = static_cast<std::uint32_t>(seed);
    pc.seed_hi = static_cast<std::uint32_t>(seed >> 32);
    pc.bounce = static_cast<std::uint32_t>(bounces);
    pc.epsilon = rays->epsilon();
    pc.punctual_count = punctual_count;
    pc.emissive_count = emissive_count;
    if (emissive_count > 0) pc.flags |= kFlagArea;
    if (camera) pc.flags |= kFlagCamera;
    const int batch = 16;
    std::vector<glm::dvec3> sum(items, glm::dvec3(0.0));
    std::vector<glm::vec3> out;
    double ray_count = 0.0;
    Progress progress(what, static_cast<std::uint64_t>(samples), unit);
    for (int done = 0, chunk = 0; done < samples; done += batch, ++chunk) {
      const int n = std::min(batch, samples - done);
      pc.update = static_cast<std::uint32_t>(chunk);
      pc.samples = static_cast<std::uint32_t>(n);
      run(kReferencePipeline, pc, static_cast<std::uint32_t>(items), out, items, &ray_count);
      for (std::size_t k = 0; k < items; ++k) sum[k] += glm::dvec3(out[k]) * double(n);
      progress.advance(static_cast<std::uint64_t>(n));
    }
    progress.finish();
    for (glm::dvec3& v : sum) v /= double(samples);
    if (stats) stats->rays = static_cast<std::uint64_t>(ray_count);
    return sum;
  }

  void barrier(VkPipelineStageFlags src_stage, VkAccessFlags src, VkPipelineStageFlags dst_stage,
               VkAccessFlags dst) {
    VkMemoryBarrier mb{};
    mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    mb.srcAccessMask = src;
    mb.dstAccessMask = dst;
    vkCmdPipelineBarrier(commands, src_stage, dst_stage, 0, 1, &mb, 0, nullptr, 0, nullptr);
  }

  void update_descriptors() {
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

  VulkanContext context;
  VulkanHandles vk;
  const World* world;
  const RayScene* rays;
  const LightSampler* lights;
  VkPhysicalDeviceMemoryProperties memory{};
  VkPhysicalDeviceProperties properties{};
  bool discrete = false;
  bool staging_only = false;  // never write device buffers in place (tests the discrete path)
  VkDeviceSize max_buffer = VkDeviceSize{1} << 27;  // the largest storage buffer a shader may see
  std::uint32_t max_groups = 65535;
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
  VkPipelineLayout pipeline_layout = VK_NULL_HANDLE;
  VkDescriptorPool descriptor_pool = VK_NULL_HANDLE;
  VkDescriptorSet descriptor_set = VK_NULL_HANDLE;
  VkPipeline pipelines[kPipelines] = {};
  VkCommandPool command_pool = VK_NULL_HANDLE;
  VkCommandBuffer commands = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  Buffer device_buffers[kBindings];
  Buffer staging[kBindings];
  std::vector<std::pair<int, VkDeviceSize>> uploads;
  bool descriptors_dirty = true;
  std::uint32_t punctual_count = 0, emissive_count = 0;
  struct PrevKey {
    const void* maps = nullptr;
    std::uint32_t update = ~0u, bounce = ~0u;
    bool operator==(const PrevKey&) const = default;
  };

  // A pass that throws may leave buffers half written: upload everything again next time.
  struct ForgetOnThrow {
    Impl* impl;
    int exceptions = std::uncaught_exceptions();
    ~ForgetOnThrow() {
      if (std::uncaught_exceptions() > exceptions) {
        impl->engine_key = EngineKey{};
        impl->prev_key = PrevKey{};
        impl->uploads.clear();
      }
    }
  };

  EngineKey engine_key;
  PrevKey prev_key;
  std::vector<std::uint32_t> object_offsets;
  std::vector<std::int32_t> emissive_of;  // per triangle: index in the emissive list, or -1
  std::uint32_t lightmap_total = 0;
  std::mutex mutex;  // one pass at a time
};

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
  std::lock_guard lock(impl_->mutex);
  Impl::ForgetOnThrow guard{impl_.get()};
  const auto start = Clock::now();
  impl_->prepare(in);
  PushConstants pc = impl_->constants(in);
  pc.samples = static_cast<std::uint32_t>(in.params.direct_samples);
  const auto items = static_cast<std::uint32_t>(in.unit_texels.size());
  impl_->run(kDirectPipeline, pc, items, out, in.texels.size());
  PassResult r;
  r.rays = static_cast<std::uint64_t>(in.unit_texels.size()) *
           (impl_->punctual_count + (impl_->emissive_count > 0 ? pc.samples : 0u));
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

PassResult VulkanBackend::gather_probes(const PassInput& in, const RadianceField& prev,
                                        std::vector<glm::vec3>& out) {
  std::lock_guard lock(impl_->mutex);
  Impl::ForgetOnThrow guard{impl_.get()};
  const auto start = Clock::now();
  impl_->prepare(in);
  impl_->write_previous(prev, in);
  PushConstants pc = impl_->constants(in);
  const std::size_t items = in.probes.count() * in.probes.texels_per_probe();
  if (items > 0xFFFFFFFFu) throw Error("Vulkan backend: too many probe texels for one pass");
  impl_->run(kGatherPipeline, pc, static_cast<std::uint32_t>(items), out, items);
  std::size_t usable = 0;
  for (std::uint8_t u : in.probes.usable) usable += u ? 1 : 0;
  PassResult r;
  r.rays = usable * in.probes.texels_per_probe();
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

PassResult VulkanBackend::scatter(const PassInput& in, const RadianceField& prev,
                                  const std::vector<glm::vec3>& probe_radiance,
                                  std::vector<glm::vec3>& out) {
  std::lock_guard lock(impl_->mutex);
  Impl::ForgetOnThrow guard{impl_.get()};
  const auto start = Clock::now();
  impl_->prepare(in);
  impl_->write_previous(prev, in);
  impl_->write(kProbeRadiance, probe_radiance.size() * sizeof(glm::vec4), [&](void* dst) {
    auto* v = static_cast<glm::vec4*>(dst);
    for (std::size_t i = 0; i < probe_radiance.size(); ++i)
      v[i] = glm::vec4(probe_radiance[i], 0.0f);
  });
  PushConstants pc = impl_->constants(in);
  pc.samples = static_cast<std::uint32_t>(in.params.indirect_samples);
  const auto items = static_cast<std::uint32_t>(in.unit_texels.size());
  impl_->run(kScatterPipeline, pc, items, out, in.texels.size());
  PassResult r;
  r.rays = static_cast<std::uint64_t>(in.unit_texels.size()) * pc.samples;
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

}  // namespace irradcast

namespace irradcast {

std::vector<Lightmap> VulkanBackend::reference_lightmaps(const std::vector<TexelGBuffer>& gbuffers,
                                                         int samples, int indirect_bounces,
                                                         std::uint64_t seed,
                                                         ReferenceLightmapStats* stats) {
  if (samples <= 0) throw Error("samples per texel must be positive");
  if (indirect_bounces < 0) throw Error("indirect bounces must be >= 0");
  const World& world = *impl_->world;
  if (gbuffers.size() != world.objects.size())
    throw Error("reference lightmaps: G-buffers do not match the scene's objects");
  std::lock_guard lock(impl_->mutex);
  Impl::ForgetOnThrow guard{impl_.get()};
  const auto start = Clock::now();
  // The valid texels, with the geometric normal on the shading normal's side (as the CPU's
  // reference_lightmaps), in the engine's texel buffer: the engine's data goes up again after.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> where;  // (object, texel)
  for (std::size_t o = 0; o < gbuffers.size(); ++o)
    for (std::size_t i = 0; i < gbuffers[o].size(); ++i)
      if (gbuffers[o].valid(i))
        where.emplace_back(static_cast<std::uint32_t>(o), static_cast<std::uint32_t>(i));
  if (where.size() > 0xFFFFFFFFu) throw Error("Vulkan backend: too many texels for one pass");
  impl_->engine_key = EngineKey{};
  impl_->write(kTexels, where.size() * 3 * sizeof(glm::vec4), [&](void* dst) {
    auto* v = static_cast<glm::vec4*>(dst);
    for (std::size_t k = 0; k < where.size(); ++k) {
      const auto [o, i] = where[k];
      const TexelGBuffer& g = gbuffers[o];
      const glm::vec3 n = g.normal[i];
      glm::vec3 ng = world.objects[o].geometric_normal(static_cast<std::uint32_t>(g.triangle[i]));
      if (glm::dot(ng, n) < 0.0f) ng = -ng;
      v[3 * k] = glm::vec4(g.position[i], 0.0f);
      v[3 * k + 1] = glm::vec4(n, 0.0f);
      v[3 * k + 2] = glm::vec4(ng, 0.0f);
    }
  });
  const std::vector<glm::dvec3> sum =
      impl_->paths(where.size(), samples, indirect_bounces, seed, false,
                   "reference lightmaps (vulkan)", "samples per texel", stats);
  std::vector<Lightmap> maps(gbuffers.size());
  for (std::size_t o = 0; o < gbuffers.size(); ++o)
    maps[o] = Lightmap(gbuffers[o].width, gbuffers[o].height);
  for (std::size_t k = 0; k < where.size(); ++k)
    maps[where[k].first].texels[where[k].second] = glm::vec3(sum[k]);
  for (std::size_t o = 0; o < gbuffers.size(); ++o)
    dilate(maps[o].texels, maps[o].width, maps[o].height, gbuffers[o].kind);
  if (stats) stats->seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return maps;
}

ImageRGB VulkanBackend::render_reference(const CameraPose& camera, int width, int height,
                                         int samples, int indirect_bounces, std::uint64_t seed,
                                         ReferenceLightmapStats* stats) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  if (samples <= 0) throw Error("samples per pixel must be positive");
  if (indirect_bounces < 0) throw Error("indirect bounces must be >= 0");
  std::lock_guard lock(impl_->mutex);
  Impl::ForgetOnThrow guard{impl_.get()};
  const auto start = Clock::now();
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  impl_->engine_key = EngineKey{};
  impl_->write(kTexels, n * 3 * sizeof(glm::vec4), [&](void* dst) {
    auto* v = static_cast<glm::vec4*>(dst);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const std::size_t k = static_cast<std::size_t>(y) * width + x;
        // Through the pixel centre, like the compositor and PathTracer::render.
        const Ray r = camera_ray(camera, width, height, static_cast<float>(x) + 0.5f,
                                 static_cast<float>(y) + 0.5f);
        v[3 * k] = glm::vec4(r.origin, 0.0f);
        v[3 * k + 1] = glm::vec4(r.direction, 0.0f);
        v[3 * k + 2] = glm::vec4(0.0f);
      }
  });
  const std::vector<glm::dvec3> sum =
      impl_->paths(n, samples, indirect_bounces, seed, true, "reference (vulkan)", "spp", stats);
  ImageRGB image(width, height);
  for (std::size_t k = 0; k < n; ++k) image.pixels[k] = glm::vec3(sum[k]);
  if (stats) stats->seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return image;
}

}  // namespace irradcast

// The Vulkan backend's implementation (vulkan_backend.h), private to irradcast_engine: the
// storage buffers in the shaders' binding order, the push constants, and VulkanBackend::Impl,
// whose parts live in files of their own (in the manner of Filament's backend/src/vulkan/):
//   vulkan_pipelines.cpp     device limits, descriptor set, compute pipelines, commands
//   vulkan_buffers.cpp       storage and staging buffers, uploads, one pass's submission
//   vulkan_scene_upload.cpp  the scene, the surfaces, the engine's pass data, push constants
//   vulkan_reference.cpp     the reference path tracer (reference.comp)
//   vulkan_backend.cpp       the TraceBackend passes
#pragma once

#include <vulkan/vulkan.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <exception>
#include <functional>
#include <mutex>
#include <utility>
#include <vector>

#include "vulkan_backend.h"
#include "vulkan_handles.h"

namespace irradcast {

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
  kSky,
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
  kFlagCamera = 16,
  kFlagSky = 32,         // the scene has a sky (Sky::enabled)
  kFlagSkyMap = 64,      // ... a map with its sampling tables (SkyDistribution::valid)
  kFlagProbeMean = 128,  // the gather folds its estimates into the running means
  kFlagLightTree = 256,  // area lights are picked by the light hierarchy (LightSampler::pick)
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
  std::uint32_t probe_offset = 0;
  float probe_weight = 0.0f;
  std::uint32_t pad[2] = {0, 0};
};
static_assert(sizeof(PushConstants) == 96);

// Timestamps per submission: its start, marks between dispatches, its end.
constexpr std::uint32_t kTimestamps = 4;

struct Buffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkDeviceSize size = 0;
  void* mapped = nullptr;  // persistently mapped when host-visible and coherent
};

template <typename T>
inline std::uint32_t bits(T v) {
  static_assert(sizeof(T) == 4);
  std::uint32_t u;
  std::memcpy(&u, &v, 4);
  return u;
}

inline float as_float(std::uint32_t u) {
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

inline float as_float(std::int32_t i) {
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

struct VulkanBackend::Impl {
  // vulkan_pipelines.cpp: opens the device's objects and uploads the scene.
  Impl(const World& w, const RayScene& r, const LightSampler& l, VulkanContextOptions o,
       bool force_staging);
  ~Impl() { release(); }
  void release();
  void create_pipelines();
  void create_commands();
  void update_descriptors();

  // vulkan_buffers.cpp
  int memory_type(std::uint32_t allowed, VkMemoryPropertyFlags want) const;
  // A storage buffer the shaders read: device-local on a discrete GPU (filled through staging),
  // host-visible device memory elsewhere (written in place). Staging buffers are host memory.
  void create(Buffer& b, VkDeviceSize size, bool staging_buffer, bool read_back = false);
  void destroy(Buffer& b);
  void ensure(int binding, VkDeviceSize bytes);
  // Writes `bytes` into a binding: in place when mapped, else into its staging buffer with a
  // copy recorded before the next dispatch.
  void write(int binding, VkDeviceSize bytes, const std::function<void(void*)>& fill);
  template <typename T>
  void write(int binding, const std::vector<T>& data) {
    write(binding, data.size() * sizeof(T), [&](void* dst) {
      if (!data.empty()) std::memcpy(dst, data.data(), data.size() * sizeof(T));
    });
  }
  // One submission, in pieces: begin() starts the command buffer (a timestamp, then the
  // pending uploads and a barrier), dispatch() records one pipeline over `count` items,
  // read_back() the copy of `out_size` results to the host, and submit() submits, waits on the
  // fence and reads the device time. Each piece adds to the pass's counters (`stats`).
  void begin();
  // A timestamp between two dispatches of one submission: submit() then reports the device
  // time of each stretch in `intervals`.
  void mark();
  void dispatch(PipelineId pipeline, PushConstants pc, std::uint32_t count);
  void read_back(std::size_t out_size);
  void submit();
  // The results read back by the last submission: `out_size` of them into `out`. With
  // `w_sum`, the results' w are added to it: every result's, or only those at `w_at`.
  void take_results(std::vector<glm::vec3>& out, std::size_t out_size, double* w_sum = nullptr,
                    const std::vector<std::uint32_t>* w_at = nullptr) const;
  // The result buffer (and its staging copy) large enough for `out_size` results.
  void prepare_result(std::size_t out_size);
  // The running probe means of `id` (ProbeMeans) for `bounces` bounces of `per_bounce` probe
  // texels each in kProbeRadiance; returns true when they are new (to be zeroed first).
  bool resident_means(std::uint64_t id, std::size_t per_bounce, int bounces);
  // One pass in one submission: the pending uploads, `count` items of `pipeline`, the read-back
  // of `out_size` results into `out` (w_sum, w_at as for take_results).
  void run(PipelineId pipeline, PushConstants pc, std::uint32_t count, std::vector<glm::vec3>& out,
           std::size_t out_size, double* w_sum = nullptr,
           const std::vector<std::uint32_t>* w_at = nullptr);
  void barrier(VkPipelineStageFlags src_stage, VkAccessFlags src, VkPipelineStageFlags dst_stage,
               VkAccessFlags dst);

  // vulkan_scene_upload.cpp: the scene and the engine's data.
  void upload_scene();
  void upload_materials();
  void upload_lights();
  // The sky (kSky) and its flags: a constant's radiance, or the map with LightSampler's
  // sampling tables.
  void upload_sky();
  std::uint32_t material_index(int object, std::uint32_t t) const;
  // Per object: triangle base, lightmap offset and size; per triangle: lightmap and base-colour
  // uv corners, material. Without an atlas (the reference path tracer reads no lightmap) the
  // lightmap fields are zero.
  void write_surfaces(const Atlas* atlas);
  // The engine's pass data (texels, units, probes, probe weights), when it changed.
  void prepare(const PassInput& in);
  // The previous bounce's lightmaps: the gather and the scatter of one bounce read the same
  // ones, so the scatter does not upload them again.
  void write_previous(const RadianceField& prev, const PassInput& in);
  PushConstants constants(const PassInput& in) const;

  // vulkan_reference.cpp: the reference path tracer over `items` items already in the texel
  // buffer (texels, or with camera set, primary rays): `samples` paths each, in batches of 16
  // (a progress line, no long dispatch). Returns each item's mean.
  std::vector<glm::dvec3> paths(std::size_t items, int samples, int bounces, std::uint64_t seed,
                                bool camera, const char* what, const char* unit,
                                ReferenceLightmapStats* stats);

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
  VkQueryPool timestamps = VK_NULL_HANDLE;  // kTimestamps; none without timestamps
  double timestamp_ns = 0.0;                // nanoseconds per tick
  std::uint64_t timestamp_mask = 0;         // the queue's valid timestamp bits
  std::uint32_t next_query = 0;             // the next timestamp of this submission
  std::vector<double> intervals;            // device seconds between this submission's marks
  bool readback_pending = false;            // read_back() recorded a staging copy
  // Whose running probe means kProbeRadiance holds (probe_bounce), for how many probe texels
  // per bounce and bounces; anything else written there (scatter()) clears it.
  struct MeansKey {
    std::uint64_t id = 0;
    std::size_t per_bounce = 0;
    int bounces = 0;
    bool operator==(const MeansKey&) const = default;
  } means_key;
  bool resident_probes = true;  // probe_bounce on the device (false: TraceBackend's default)
  PassResult stats;             // the current pass's counters
  Buffer device_buffers[kBindings];
  Buffer staging[kBindings];
  std::vector<std::pair<int, VkDeviceSize>> uploads;
  bool descriptors_dirty = true;
  std::uint32_t punctual_count = 0, emissive_count = 0;
  std::uint32_t sky_flags = 0;  // kFlagSky, kFlagSkyMap
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
        impl->means_key = MeansKey{};
        impl->uploads.clear();
      }
    }
  };

  // One pass, under the lock and forgetting the uploads if it throws: prepare(in), then the
  // previous bounce's field when `prev` is given, then `body()`, which runs the pipeline and
  // returns the rays it traced. The result carries those rays and the pass's time.
  template <class Body>
  PassResult timed_pass(const PassInput& in, const RadianceField* prev, Body body) {
    std::lock_guard lock(mutex);
    ForgetOnThrow guard{this};
    const auto start = std::chrono::steady_clock::now();
    stats = PassResult{};
    prepare(in);
    if (prev) write_previous(*prev, in);
    stats.rays = body();
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
  }

  EngineKey engine_key;
  PrevKey prev_key;
  std::vector<std::uint32_t> object_offsets;
  std::vector<std::int32_t> emissive_of;  // per triangle: index in the emissive list, or -1
  std::uint32_t lightmap_total = 0;
  std::mutex mutex;  // one pass at a time
};

}  // namespace irradcast

// The Vulkan backend's reference path tracer (reference.comp): reference lightmaps and the
// reference view, in batches of samples with a progress line.
#include <chrono>

#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "irradcast/common/progress.h"
#include "vulkan_backend_impl.h"

namespace irradcast {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

// The reference path tracer over `items` items already in the texel buffer (texels, or with
// camera set, primary rays): `samples` paths each, in batches of 16 (a progress line, no
// long dispatch). Returns each item's mean.
std::vector<glm::dvec3> VulkanBackend::Impl::paths(std::size_t items, int samples, int bounces,
                                                   std::uint64_t seed, bool camera,
                                                   const char* what, const char* unit,
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
  if (!lights->tree().empty()) pc.flags |= kFlagLightTree;
  pc.flags |= sky_flags;
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
      const TexelPoint p = gbuffers[o].point(world.objects[o], i);
      v[3 * k] = glm::vec4(p.position, 0.0f);
      v[3 * k + 1] = glm::vec4(p.normal, 0.0f);
      v[3 * k + 2] = glm::vec4(p.geo_normal, 0.0f);
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

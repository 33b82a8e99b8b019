#include "irradcast/engine/path_tracer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>

#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "run_stats.h"

namespace irradcast {
namespace {

// Emitted radiance leaving the hit surface toward -dir (one-sided unless double-sided).
glm::vec3 emitted(const World& world, const Hit& h, glm::vec3 dir) {
  const Material& m = world.material(h.object, h.triangle);
  if (!m.is_emissive()) return glm::vec3(0.0f);
  glm::vec3 ng = world.objects[h.object].geometric_normal(h.triangle);
  if (!m.double_sided && glm::dot(ng, dir) >= 0.0f) return glm::vec3(0.0f);
  return world.emission(h.object, h.triangle, h.u, h.v);
}

}  // namespace

PathTracer::PathTracer(const World& world, const RayScene& rays, const LightSampler& lights,
                       PathTracerOptions options)
    : world_(&world), rays_(&rays), lights_(&lights), options_(options) {
  if (options_.indirect_bounces < 0) throw Error("indirect bounces must be >= 0");
}

glm::vec3 PathTracer::direct(glm::vec3 p, glm::vec3 n, glm::vec3 ng, Rng& rng,
                             std::uint64_t* ray_count) const {
  glm::vec3 e = lights_->punctual_irradiance(*rays_, p, n, ng);
  if (ray_count) *ray_count += world_->lights.size();
  if (!lights_->emissive_triangles().empty()) {
    glm::vec2 a = rng.next_2d();
    e += lights_->area_irradiance(*rays_, p, n, ng, glm::vec3(a, rng.next_float()));
    if (ray_count) *ray_count += 1;
  }
  if (lights_->has_sky()) {
    // Drawn only with a sky, so that sky-less paths keep their random numbers.
    const glm::vec2 a = rng.next_2d(), b = rng.next_2d();
    e += lights_->sky_irradiance(*rays_, p, n, ng, glm::vec4(a, b), ray_count);
  }
  return e;
}

glm::vec3 PathTracer::irradiance(glm::vec3 p, glm::vec3 n, glm::vec3 ng, int bounces, Rng& rng,
                                 std::uint64_t* ray_count) const {
  glm::vec3 e(0.0f);
  if (options_.next_event) e += direct(p, n, ng, rng, ray_count);
  // With next-event estimation the direct part is done and `bounces` more vertices follow;
  // without it, the cosine-sampled ray must also find the direct light, so one more level.
  int levels = options_.next_event ? bounces : bounces + 1;
  if (levels <= 0) return e;
  Frame frame(n);
  Ray ray;
  ray.direction = frame.to_world(cosine_hemisphere(rng.next_2d()));
  ray.origin = rays_->offset(p, ng, ray.direction);
  Hit h = rays_->intersect(ray);
  if (ray_count) *ray_count += 1;
  if (!h.valid()) {
    // Without next-event estimation the sky is found by the rays that leave the scene.
    if (!options_.next_event && lights_->has_sky())
      e += kPi * lights_->sky()->radiance(ray.direction);
    return e;
  }
  // Cosine-weighted sampling: E = pi * L_in, one sample.
  glm::vec3 l_in = reflected(h, -ray.direction, bounces - 1, rng, ray_count);
  if (!options_.next_event) l_in += emitted(*world_, h, ray.direction);
  return e + kPi * l_in;
}

glm::vec3 PathTracer::reflected(const Hit& h, glm::vec3 wo, int bounces, Rng& rng,
                                std::uint64_t* ray_count) const {
  // Only the no-NEE estimator goes one level deeper, to find the emitters; nothing reflects there.
  if (bounces < 0) return glm::vec3(0.0f);
  const WorldObject& o = world_->objects[h.object];
  glm::vec3 ng = o.geometric_normal(h.triangle);
  glm::vec3 n = o.shading_normal(h.triangle, h.u, h.v);
  // Surfaces reflect on both sides: turn the frame toward the viewer.
  if (glm::dot(ng, wo) < 0.0f) {
    ng = -ng;
    n = -n;
  }
  glm::vec3 p = o.position(h.triangle, h.u, h.v);
  glm::vec3 albedo = world_->albedo(h.object, h.triangle, h.u, h.v);
  return albedo * kInvPi * irradiance(p, n, ng, bounces, rng, ray_count);
}

glm::vec3 PathTracer::radiance(const Ray& ray, Rng& rng, std::uint64_t* ray_count) const {
  Hit h = rays_->intersect(ray);
  if (ray_count) *ray_count += 1;
  if (options_.camera_only) {
    const Hit d = options_.camera_only->intersect(ray);
    if (ray_count) *ray_count += 1;
    if (d.valid() && (!h.valid() || d.t < h.t)) h = d;
  }
  if (!h.valid())
    return lights_->has_sky() ? lights_->sky()->radiance(ray.direction) : glm::vec3(0.0f);
  return emitted(*world_, h, ray.direction) +
         reflected(h, -ray.direction, options_.indirect_bounces, rng, ray_count);
}

ImageRGB PathTracer::render(const CameraPose& camera, int width, int height, int spp,
                            const std::function<void(int, int)>& on_pass, RenderStats* stats,
                            const std::vector<std::uint8_t>* only) const {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  if (spp <= 0) throw Error("samples per pixel must be positive");
  if (only && only->size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw Error("path tracer: the pixel mask has " + std::to_string(only->size()) +
                " entries for a " + std::to_string(width) + " x " + std::to_string(height) +
                " image");
  auto start = std::chrono::steady_clock::now();
  const std::size_t n = static_cast<std::size_t>(width) * height;
  std::vector<glm::dvec3> sum(n, glm::dvec3(0.0));
  std::vector<Ray> primary(n);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      primary[static_cast<std::size_t>(y) * width + x] = camera_ray(
          camera, width, height, static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f);
  std::atomic<std::uint64_t> total_rays{0};
  for (int pass = 0; pass < spp; ++pass) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        std::uint64_t local = 0;
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          if (only && !(*only)[i]) continue;
                          Rng rng(mix64(options_.seed) ^ i, static_cast<std::uint64_t>(pass));
                          sum[i] += glm::dvec3(radiance(primary[i], rng, &local));
                        }
                        total_rays += local;
                      });
    if (on_pass) on_pass(pass + 1, spp);
  }
  ImageRGB image(width, height);
  for (std::size_t i = 0; i < n; ++i)
    image.pixels[i] = glm::vec3(sum[i] / static_cast<double>(spp));
  record_run(stats, total_rays.load(), start);
  return image;
}

}  // namespace irradcast

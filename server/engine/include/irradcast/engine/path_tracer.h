// The reference path tracer: per-viewpoint Monte Carlo path tracing of the same Lambertian scene
// with the same lights and the same bounce count as the GI engine (1 direct + K indirect), with
// next-event estimation at every vertex (area lights, punctual lights and the sky). It is the
// ground truth of the quality tests and the per-user baseline of the scaling benchmark.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/image.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct PathTracerOptions {
  int indirect_bounces = 2;  // K: paths carry 1 direct + K indirect bounces
  bool next_event = true;    // false: pure cosine-sampled paths that must hit the emitters or
                             // leave the scene to the sky (area lights and sky only; an
                             // independent estimator for cross-checks)
  std::uint64_t seed = 1;
  // Objects seen by camera rays only (a viewer's dynamic objects, RaySceneContent::Dynamic of
  // the same world): a primary ray that meets one first is shaded there, and every later ray
  // traces the static scene alone (they see the room; the room does not see them, nor they
  // themselves). Null: none.
  const RayScene* camera_only = nullptr;
};

class PathTracer {
 public:
  PathTracer(const World& world, const RayScene& rays, const LightSampler& lights,
             PathTracerOptions options = {});

  // One-sample estimate of the radiance arriving along `ray` (emission at the first hit plus
  // its reflected light with the configured bounces; the sky's radiance if it hits nothing).
  // Rays traced are added to *ray_count.
  glm::vec3 radiance(const Ray& ray, Rng& rng, std::uint64_t* ray_count = nullptr) const;

  // One-sample estimate of the irradiance at surface point p (unit normal n, geometric normal
  // ng) with `indirect_bounces` bounces of indirect light: what a lightmap texel should hold.
  glm::vec3 irradiance(glm::vec3 p, glm::vec3 n, glm::vec3 ng, int indirect_bounces, Rng& rng,
                       std::uint64_t* ray_count = nullptr) const;

  struct RenderStats {
    std::uint64_t rays = 0;
    double seconds = 0.0;
  };
  // Progressive render: `spp` passes of one path per pixel (through the pixel centre, like the
  // compositor, so the two differ only in their lighting). `on_pass(done, spp)` is called after
  // every pass. Deterministic for a given seed whatever the thread count. With `only`
  // (width x height flags), only the flagged pixels are rendered; the others stay black.
  ImageRGB render(const CameraPose& camera, int width, int height, int spp,
                  const std::function<void(int, int)>& on_pass = {},
                  RenderStats* stats = nullptr,
                  const std::vector<std::uint8_t>* only = nullptr) const;

  const PathTracerOptions& options() const { return options_; }

 private:
  // Radiance reflected from the surface hit (emission excluded), with `bounces` indirect
  // bounces left below it.
  glm::vec3 reflected(const Hit& hit, glm::vec3 wo, int bounces, Rng& rng,
                      std::uint64_t* ray_count) const;
  glm::vec3 direct(glm::vec3 p, glm::vec3 n, glm::vec3 ng, Rng& rng,
                   std::uint64_t* ray_count) const;

  const World* world_;
  const RayScene* rays_;
  const LightSampler* lights_;
  PathTracerOptions options_;
};

}  // namespace irradcast

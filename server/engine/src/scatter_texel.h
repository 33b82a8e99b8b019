// The scatter pass's work for one texel (EmbreeBackend::scatter runs it over every texel): the
// texel's rays drawn, traced and shaded in batches held as arrays, the hits and the misses each
// in a loop of their own with no branch on which rays hit. A ray's arithmetic then overlaps its
// neighbours' instead of waiting behind a mispredicted branch (whether a random ray hits, leaves
// the scene, which probe it picks), and the misses' divisions and square roots run four at a
// time. The result is bit for bit the sum of HitShader::diffuse / scatter_miss over the rays in
// order (the engine benchmark's `verify` column checks it against a scalar re-run).
#pragma once

#include <cstdint>

#include "irradcast/common/hit_shader.h"
#include "irradcast/engine/embree_backend.h"

namespace irradcast::embree_sampling {

class ScatterTexel {
 public:
  // All must outlive this object.
  ScatterTexel(const PassInput& in, const RayScene& rays, const RadianceField& prev,
               const ScatterMiss& miss, const HitShader& shader)
      : in_(&in), rays_(&rays), prev_(&prev), miss_(&miss), shader_(&shader) {}
  // Texel i's scattered irradiance: pi / N times the sum of its N rays' radiance.
  glm::vec3 operator()(std::uint32_t i) const;

  static constexpr int kBatch = 32;
  // One batch of a texel's rays as arrays, and what each brings.
  struct Batch {
    int count = 0;
    alignas(16) float dx[kBatch], dy[kBatch], dz[kBatch];  // directions
    alignas(16) float ox[kBatch], oy[kBatch], oz[kBatch];  // origins (offset off the surface)
    alignas(16) float exit[kBatch];                        // exit_distance of each ray
    Hit hit[kBatch];
    glm::vec3 radiance[kBatch];
  };

 private:
  void draw(Rng& rng, const Frame& frame, glm::vec3 p, glm::vec3 ng, Batch& b) const;
  void trace(float range, Batch& b) const;
  void shade_hits(Batch& b) const;
  void shade_misses(std::uint32_t i, glm::vec3 p, Batch& b, Rng& pick) const;

  const PassInput* in_;
  const RayScene* rays_;
  const RadianceField* prev_;
  const ScatterMiss* miss_;
  const HitShader* shader_;
};

}  // namespace irradcast::embree_sampling

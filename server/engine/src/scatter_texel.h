// The scatter pass's work for runs of texels (EmbreeBackend::scatter runs it over every texel):
// each texel's rays drawn, traced and shaded in batches held as arrays, the hits and the misses
// each in a loop of their own with no branch on which rays hit. A ray's arithmetic then overlaps
// its neighbours' instead of waiting behind a mispredicted branch (whether a random ray hits,
// leaves the scene, which probe it picks), and the misses' divisions and square roots run four at a
// time. The result is bit for bit the sum of HitShader::diffuse / scatter_miss over the rays in
// order (the engine benchmark's `verify` column checks it against a scalar re-run).
#pragma once

#include <cstdint>

#include "embree_backend.h"
#include "irradcast/common/hit_shader.h"

namespace irradcast::embree_sampling {

class ScatterTexel {
 public:
  // All must outlive this object.
  ScatterTexel(const PassInput& in, const RayScene& rays, const RadianceField& prev,
               const ScatterMiss& miss, const HitShader& shader)
      : in_(&in), rays_(&rays), prev_(&prev), miss_(&miss), shader_(&shader) {}
  // The scattered irradiance of texels[0 .. count), each pi / N times the sum of its N rays'
  // radiance, into out[texel].
  void run(const std::uint32_t* texels, std::size_t count, std::vector<glm::vec3>& out) const;

  static constexpr int kBatch = RayBatch::kSize;
  // One batch of a texel's rays, and what each brings.
  struct Batch {
    RayBatch rays;
    alignas(16) float exit[kBatch];  // exit_distance of each ray
    glm::vec3 radiance[kBatch];
  };

 private:
  struct Texel;  // the texel whose rays are drawn: its streams, frame and range
  void begin(std::uint32_t i, Texel& t) const;
  void draw(Texel& t, RayBatch& b) const;
  void shade_hits(Batch& b) const;
  // Texel i's probe weights and their running sums, worked out at its first miss that reads a
  // probe (a texel whose rays all hit within the tracing range reads none).
  void weigh(std::uint32_t i, Texel& t) const;
  void shade_misses(std::uint32_t i, Texel& t, Batch& b) const;
  void probe_lookups(int k, const int* idx, const std::uint32_t* probe, const float* ex,
                     const float* ey, const int* valid, Batch& b) const;

  const PassInput* in_;
  const RayScene* rays_;
  const RadianceField* prev_;
  const ScatterMiss* miss_;
  const HitShader* shader_;
};

}  // namespace irradcast::embree_sampling

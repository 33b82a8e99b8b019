// Direct lighting: emissive triangles (area lights, picked in proportion to their power),
// KHR_lights_punctual lights and the scene's sky (sky.h), with shadow rays. Shared by the reference
// path tracer and the engine's direct pass so both see exactly the same lights.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/light_cache.h"
#include "irradcast/common/light_tree.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/sky.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct EmissiveTriangle {
  int object = -1;
  std::uint32_t triangle = 0;
  glm::vec3 p0{0.0f}, e1{0.0f}, e2{0.0f};  // p = p0 + b1 e1 + b2 e2
  glm::vec3 normal{0.0f, 0.0f, 1.0f};      // unit geometric normal (front side emits)
  float area = 0.0f;
  bool double_sided = false;
  // The material's emission where it is the same at every point of the triangle (no emissive
  // texture, no cut-outs): World::emission's value, looked up once.
  bool uniform_emission = false;
  glm::vec3 emission{0.0f};
  float reach = 0.0f;  // the largest |coordinate| of its corners (the scale of rounding errors)
};

class LightSampler {
 public:
  explicit LightSampler(const World& world);

  bool empty() const { return triangles_.empty() && world_->lights.empty() && !has_sky(); }
  // The scene's sky lights it (Sky::enabled()).
  bool has_sky() const { return sky_ != nullptr; }
  const Sky* sky() const { return sky_; }
  // Importance sampling of the sky's map; !valid() for a constant sky.
  const SkyDistribution& sky_distribution() const { return sky_dist_; }
  const std::vector<EmissiveTriangle>& emissive_triangles() const { return triangles_; }
  float total_area_power() const { return total_power_; }
  // Per emissive triangle: cumulative pick probability (the last is 1) and pick probability.
  const std::vector<float>& pick_cdf() const { return cdf_; }
  const std::vector<float>& pick_pdf() const { return pick_pdf_; }

  // One-sample estimate of the direct irradiance at p (unit normal n, geometric normal ng for
  // the ray offset) from the area lights: picks a triangle (pick()) and a uniform point on it
  // (u.x picks, (u.y, u.z) place), traces a shadow ray. Unbiased; 0 when there are none.
  glm::vec3 area_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                            glm::vec3 u) const;
  // Same, with the triangle fixed (stratified samples per light, as the engine's direct pass
  // does): divides by the triangle's own area pdf only.
  glm::vec3 triangle_irradiance(const RayScene& rays, std::size_t index, glm::vec3 p, glm::vec3 n,
                                glm::vec3 ng, glm::vec2 u) const;
  // One-sample estimate of the direct irradiance at p from the sky (0 without one); the number of
  // shadow rays it traced goes to *rays.
  //   Constant sky: one cosine-weighted ray (u.x, u.y); if it leaves the scene, pi x radiance.
  //   Map: one ray toward a direction drawn by the map's luminance (u.x, u.y) and one
  //   cosine-weighted ray (u.z, u.w), combined by multiple importance sampling (balance
  //   heuristic): each that leaves the scene adds radiance x cos / (pdf_map + cos / pi).
  // A ray leaves the scene when nothing occludes it out to infinity. Unbiased.
  glm::vec3 sky_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                           glm::vec4 u, std::uint64_t* rays_traced = nullptr) const;
  // Exact direct irradiance at p from every punctual light (each with one shadow ray).
  glm::vec3 punctual_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n, glm::vec3 ng) const;

  // The steps of the estimates above, for a caller that traces the shadow rays itself
  // (bench/engine times them through raw Embree). A sample is its shadow ray and what it adds
  // when that ray is unoccluded: `irradiance` for a punctual light, triangle_emitted(s) for an
  // area light.
  struct ShadowSample {
    Ray shadow;
    glm::vec3 irradiance{0.0f};  // punctual light
    std::size_t triangle = 0;    // area light: the triangle, the barycentrics of the point and
    glm::vec2 b{0.0f};           // the geometric factor cos_x cos_y area / dist^2
    float factor = 0.0f;
  };
  // The area light that u (in [0, 1)) picks by power.
  std::size_t pick_triangle(float u) const;
  // The area light that u picks for the point p with normal n, and its probability: by power
  // (pick_triangle), or with more than kMaxFront emissive triangles by the light hierarchy
  // (light_tree.h: power, distance and orientation at p), mixed with p's region's `learned`
  // table where there is one (LightCache::pick). false: none can light p.
  bool pick(glm::vec3 p, glm::vec3 n, float u, std::size_t& index, float& pdf,
            const LightCache::Table* learned = nullptr) const;
  // The light hierarchy (empty with at most kMaxFront emissive triangles).
  const LightTree& tree() const { return tree_; }
  // triangle_irradiance before its shadow ray; false: no contribution (no ray).
  bool triangle_sample(const RayScene& rays, std::size_t index, glm::vec3 p, glm::vec3 n,
                       glm::vec3 ng, glm::vec2 u, ShadowSample& s) const;

  // The engine's direct pass picks among the area lights that can light p (normal n) only: every
  // emissive triangle but those wholly behind p's tangent plane and the one-sided ones p lies
  // behind (which add exactly 0 at every point), each with its pick probability renormalised
  // over them. The same expectation as picking among all, no sample drawn in vain, and lower
  // variance. For scenes with at most kMaxFront emissive triangles (a per-texel list; with more
  // front_lights returns false and the pass picks with pick(), by the light hierarchy).
  // shaders/direct.comp mirrors the list; with more lights it picks by the hierarchy
  // (lights.glsl's tree_pick), without the learned tables (LightCache).
  static constexpr int kMaxFront = 64;
  struct FrontLights {
    int count = 0;
    float total = 0.0f;              // the sum of their pick probabilities
    float cdf[kMaxFront];            // cumulative pick probability (not normalised)
    std::uint32_t index[kMaxFront];  // emissive triangle
  };
  bool front_lights(glm::vec3 p, glm::vec3 n, FrontLights& f) const;
  // One direct-pass sample: u.x picks the light (among *front, or among all when front is null:
  // pick(), with `learned`), (u.y, u.z) place the point; false: no contribution (no ray). Else
  // s's shadow ray and, when it is unoccluded, `weight` (the emitted irradiance over the pick
  // probability).
  bool direct_sample(const RayScene& rays, const FrontLights* front, glm::vec3 p, glm::vec3 n,
                     glm::vec3 ng, glm::vec3 u, ShadowSample& s, glm::vec3& weight,
                     const LightCache::Table* learned = nullptr) const;
  // The direct pass's samples first .. first + count - 1 of `samples` at p, stratified in the
  // pick: sample k's pick is (k + rng) / samples, then two numbers of rng place its point; each
  // as direct_sample, with lit[k] its result (of s[k] only the shadow ray is set). With front
  // lights, 4 samples at a time in SIMD lanes: the same operations, so the same bits.
  void direct_samples(const RayScene& rays, const FrontLights* front, glm::vec3 p, glm::vec3 n,
                      glm::vec3 ng, Rng& rng, int first, int count, int samples, ShadowSample* s,
                      glm::vec3* weight, bool* lit,
                      const LightCache::Table* learned = nullptr) const;
  glm::vec3 triangle_emitted(const ShadowSample& s) const;
  // One punctual light before its shadow ray; false: no contribution (no ray).
  static bool punctual_sample(const RayScene& rays, const WorldLight& l, glm::vec3 p, glm::vec3 n,
                              glm::vec3 ng, ShadowSample& s);

 private:
  // triangle_sample once the triangle is known not to be surely rejected.
  bool point_sample(const RayScene& rays, std::size_t index, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                    glm::vec2 u, ShadowSample& s) const;
  // Four samples' point_sample and weight in SIMD lanes (the first `lanes` are written).
  void sample_lanes(const RayScene& rays, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                    const std::uint32_t* li, const float* ux, const float* uy, const float* pdf,
                    int lanes, ShadowSample* s, glm::vec3* weight, bool* lit) const;
  // One sample: from `front`, else picked at `at` (the hierarchy at p) where given, else by pick().
  bool draw_direct(const RayScene& rays, const FrontLights* front, LightTree::At* at, glm::vec3 p,
                   glm::vec3 n, glm::vec3 ng, glm::vec3 u, ShadowSample& s, glm::vec3& weight,
                   const LightCache::Table* learned) const;

  const World* world_;
  std::vector<EmissiveTriangle> triangles_;
  // The triangles for front_lights' test, 4 at a time (structure of arrays), and per group of 4
  // the bit mask of its one-sided ones.
  std::vector<float> soa_;
  std::vector<int> one_sided_;
  std::vector<float> record_;  // sample_lanes' rows per triangle (lights.cpp's RecordRow)
  std::vector<float> cdf_;     // cumulative power, normalised to 1
  std::vector<float> pick_pdf_;
  float total_power_ = 0.0f;
  const Sky* sky_ = nullptr;  // the world's scene's sky when enabled
  SkyDistribution sky_dist_;
  LightTree tree_;
};

}  // namespace irradcast

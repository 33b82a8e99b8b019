// The CPU backend: the engine's passes on Embree rays, TBB across all cores.
#pragma once

#include <algorithm>

#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/trace_backend.h"

namespace irradcast {

// The backend's sampling, public so that a caller can regenerate exactly the rays a pass traces
// (bench/engine does, to time them through raw Embree).
namespace embree_sampling {

// Stream ids keep each pass's random numbers independent of the others'. kSky: the direct pass's
// sky samples, drawn only when the scene has a sky (so sky-less results do not change).
enum Stream : std::uint64_t { kDirect = 1, kProbe = 2, kScatter = 3, kProbePick = 4, kSky = 5 };

// The random stream of one texel (or probe) in one pass of one update.
Rng texel_rng(const EngineParams& p, std::uint64_t index, std::uint32_t update, Stream stream,
              std::uint32_t bounce);
// A probe's radiance in direction dir, bilinear in its octahedral map (res x res per probe).
glm::vec3 sample_probe(const std::vector<glm::vec3>& radiance, std::size_t probe, int res,
                       glm::vec3 dir);
// The same at the direction's octahedral coordinates enc (octahedral_encode(dir), in [0, 1]^2).
glm::vec3 sample_probe_at(const std::vector<glm::vec3>& radiance, std::size_t probe, int res,
                          glm::vec2 enc);
// How far a ray from p along d runs until it leaves the scene's bounds (slightly enlarged), and
// the point where it does.
float exit_distance(const Bounds& b, glm::vec3 p, glm::vec3 d);
// One axis of it: t lowered to where p + t d reaches the face of [lo, hi] it runs toward on that
// axis (t unchanged where d == 0). The face is chosen without a branch: directions are random.
inline float exit_axis(float t, float lo, float hi, float p, float d) {
  const float face = d > 0.0f ? hi : lo;
  const float ta = (face - p) / d;
  return d != 0.0f ? std::min(t, ta) : t;
}
glm::vec3 exit_point(const Bounds& b, glm::vec3 p, glm::vec3 d);
// The length of texel i's scatter rays: the tracing range, or unbounded where no probe stands in
// for what lies beyond it (the unbiased mode; a texel that sees no probe).
float scatter_range(const PassInput& in, std::uint32_t i);
// What a scatter ray of texel i from p along d that hit nothing within scatter_range() brings:
// nothing if it left the scene's bounds within that length (nothing lies out there: a sky is
// direct light, counted by the direct pass), else the radiance toward the distant point of one
// of the texel's probes, picked by weight with `pick`.
glm::vec3 scatter_miss(const PassInput& in, const std::vector<glm::vec3>& probe_radiance,
                       std::uint32_t i, glm::vec3 p, glm::vec3 d, Rng& pick);
class ScatterTexel;
// scatter_miss with what is the same for every miss of a pass worked out once (the enlarged
// bounds, the range, the distant point's mode): the same arithmetic, less of it per miss.
class ScatterMiss {
 public:
  ScatterMiss(const PassInput& in, const std::vector<glm::vec3>& probe_radiance);
  // Whether texel i's misses can bring anything (it reads probes); if not, they bring zero.
  bool reads_probes(std::uint32_t i) const { return in_->reads_probes(i); }
  // scatter_miss for a texel that reads_probes().
  glm::vec3 operator()(std::uint32_t i, glm::vec3 p, glm::vec3 d, Rng& pick) const;

 private:
  const PassInput* in_;
  const std::vector<glm::vec3>* radiance_;
  glm::vec3 lo_, hi_;  // the scene's bounds, enlarged as exit_distance enlarges them
  float range_, extent_;
  bool fixed_;
  friend class ScatterTexel;  // its batches run operator()'s arithmetic over many misses at once
};
// The direction of a probe's gather ray for octahedral texel t (res x res), jittered.
glm::vec3 probe_direction(std::size_t t, int res, glm::vec2 jitter);
// One of a texel's probes, chosen with probability equal to its weight (u uniform in [0, 1)).
int pick_probe(const ProbeWeights& w, float u);

}  // namespace embree_sampling

// How the direct pass traces the shadow rays of a texel's area-light samples: in packets of 8
// (RayScene::occluded8) or one by one. Packets halve their cost where a texel's rays converge on
// the few lights in front of it, and cost more than single rays where they fan out to lights all
// over a building (docs/bench/engine.md, "Shadow rays: packets or single").
enum class ShadowRays {
  // Packets for a texel whose lights in front of it (LightSampler::front_lights) belong to at
  // most EmbreeBackend::kPacketLights emissive objects, single rays for one with more, or whose
  // lights the light hierarchy picks (scenes with more than LightSampler::kMaxFront emissive
  // triangles). Decided by the scene alone, so the same seed gives the same lightmaps bit for bit.
  Auto,
  Packets,  // always (the direct pass from issue 22 until issue 33)
  Single,   // always (the direct pass before issue 22)
};
const char* shadow_rays_name(ShadowRays mode);  // "auto" | "packets" | "single"

class EmbreeBackend final : public TraceBackend {
 public:
  // ShadowRays::Auto's packets: a texel's rays toward at most this many light objects (measured
  // on rooms:1-12 and cornell: packets paid toward 1 or 2, single rays toward 3 or more).
  static constexpr int kPacketLights = 2;

  // `rays` and `lights` must outlive the backend.
  EmbreeBackend(const RayScene& rays, const LightSampler& lights)
      : rays_(&rays), lights_(&lights) {}
  std::string name() const override { return "embree"; }
  // How the direct pass traces its shadow rays (default Auto; the benchmarks force either way).
  // Embree's packet and single-ray kernels agree on all but about one shadow ray in millions (at
  // a triangle's edge), so a forced way can change a rare texel's estimate by one sample.
  void set_shadow_rays(ShadowRays mode) { shadow_rays_ = mode; }
  ShadowRays shadow_rays() const { return shadow_rays_; }
  // The last direct pass's shadow rays toward area lights: all of them, those traced in
  // packets, and those that ended occluded.
  std::uint64_t direct_area_rays() const { return direct_area_rays_.traced; }
  std::uint64_t direct_packet_rays() const { return direct_area_rays_.packed; }
  std::uint64_t direct_occluded_rays() const { return direct_area_rays_.occluded; }
  // Which lights light each region, learned from the direct passes so far (in scenes of 9
  // emissive triangles or more): the next direct pass picks with it, mixed with the lights in
  // front of the texel by power (LightCache::mix) or past LightSampler::kMaxFront with the light
  // hierarchy (LightCache::pick). Invalid until a pass has learned.
  const LightCache& light_cache() const { return cache_; }
  // Whether the direct pass learns and uses it (default on; off: the front list or the hierarchy
  // alone).
  void set_learn_lights(bool on) {
    learn_lights_ = on;
    cache_ = LightCache();
  }
  // Sets it (bench/engine runs two backends from one state, to compare their outputs).
  void set_light_cache(const LightCache& cache) { cache_ = cache; }
  void scene_changed() override { cache_ = LightCache(); }
  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override;
  PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                           std::vector<glm::vec3>& out) override;
  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override;

 private:
  // Texel i's direct irradiance from the sky (the mean of direct_samples sky_irradiance
  // estimates); adds the rays it traced to *traced.
  glm::vec3 sky_direct(const PassInput& in, std::uint32_t i, std::uint64_t* traced) const;
  // Texel i's direct irradiance from the area lights: the mean of direct_samples
  // LightSampler::direct_sample estimates of the lights in front of it, stratified in the light
  // pick (LightSampler::direct_samples), their shadow rays traced 8 to a packet
  // (RayScene::occluded8) or one by one (shadow_rays()); the shadow rays it traced are counted
  // in `rays` (traced; packed too when they went in packets; occluded when they ended so).
  // Where the pass learns, the texel's samples are picked with its region's learned table
  // (light_cache()), and what each of its shadow rays brought is added to *learned.
  struct AreaRays {
    std::uint64_t traced = 0, packed = 0, occluded = 0;
  };
  glm::vec3 area_direct(const PassInput& in, std::uint32_t i, AreaRays& rays,
                        LightCache::Record* learned) const;
  // The light cache for this pass: made for the scene's lights where it learns (9 emissive
  // triangles or more; anew when their number changed), else left invalid.
  void prepare_light_cache(const PassInput& in);
  // Whether the lights of `front` belong to at most kPacketLights emissive objects (counted as
  // changes of object along the list: an object listed apart twice counts twice).
  bool few_lights(const LightSampler::FrontLights& front) const;

  const RayScene* rays_;
  const LightSampler* lights_;
  ShadowRays shadow_rays_ = ShadowRays::Auto;
  std::vector<std::int32_t> light_object_;  // per emissive triangle, its object (direct())
  AreaRays direct_area_rays_;
  bool learn_lights_ = true;
  LightCache cache_;
};

}  // namespace irradcast

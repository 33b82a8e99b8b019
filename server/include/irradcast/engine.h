// The GI engine (seed 001, chapter 3): the scene's irradiance in scene space, computed into the
// per-object lightmaps by a direct pass and K indirect bounces, each bounce a probe gather and a
// radiance-cell scatter with a tracing range. Progressive: every update() adds one more estimate
// to running per-texel means, so quality improves for as long as it runs.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "irradcast/atlas.h"
#include "irradcast/engine_params.h"
#include "irradcast/gbuffer.h"
#include "irradcast/lightmap.h"
#include "irradcast/ray_scene.h"
#include "irradcast/trace_backend.h"
#include "irradcast/world.h"

namespace irradcast {

struct PassTiming {
  double seconds = 0.0;
  std::uint64_t rays = 0;
};

struct UpdateStats {
  PassTiming direct;
  std::vector<PassTiming> probes;   // per bounce (empty entries in unbiased mode)
  std::vector<PassTiming> scatter;  // per bounce
  double total_seconds = 0.0;
  std::uint64_t total_rays() const;
};

struct ProbeStats {
  std::size_t probes = 0;
  std::size_t relocated = 0;  // moved out of or away from geometry
  std::size_t unusable = 0;   // inside geometry with no free spot in their cell
};

class Engine {
 public:
  // The world, atlas, G-buffers and ray scene must outlive the engine. `rays` serves the
  // host-side set-up (probe placement and probe visibility); the passes run on `backend`.
  Engine(const World& world, const Atlas& atlas, const std::vector<TexelGBuffer>& gbuffers,
         const RayScene& rays, std::unique_ptr<TraceBackend> backend, EngineParams params);
  ~Engine();

  // One progressive update: direct pass, then per bounce probe gather (biased mode) + scatter.
  UpdateStats update();

  std::uint32_t updates() const { return updates_; }
  const EngineParams& params() const { return params_; }
  const ProbeGrid& probes() const { return probes_; }
  const ProbeStats& probe_stats() const { return probe_stats_; }
  std::size_t texel_count() const { return texels_.size(); }
  const TraceBackend& backend() const { return *backend_; }

  // Total irradiance E = E_direct + sum of the bounces, per object, dilated into the gutters.
  std::vector<Lightmap> lightmaps() const;
  // Irradiance of one component: 0 = direct, k = k-th indirect bounce.
  std::vector<Lightmap> component(int bounce) const;
  // Per texel: samples (updates) so far, and the relative standard error of its total estimate.
  double mean_relative_error() const;
  // Per texel, the standard error of the mean of its total estimate (luminance, in every
  // channel), as lightmaps like lightmaps(); empty before the second update. The tile store
  // uses it to tell a real change of a tile from Monte Carlo noise.
  std::vector<Lightmap> standard_error() const;

 private:
  void build_texels(const std::vector<TexelGBuffer>& gbuffers);
  void build_probes();
  void build_dispatch();
  std::vector<Lightmap> to_lightmaps(const std::vector<glm::vec3>& values) const;

  const World* world_;
  const Atlas* atlas_;
  const std::vector<TexelGBuffer>* gbuffers_;
  const RayScene* rays_;
  std::unique_ptr<TraceBackend> backend_;
  EngineParams params_;
  SurfaceTexels texels_;
  ProbeGrid probes_;
  ProbeStats probe_stats_;
  std::vector<ProbeWeights> probe_weights_;
  std::vector<std::uint32_t> unit_texels_, unit_offsets_;
  std::uint32_t updates_ = 0;
  // Running means: [0] direct, [k] bounce k; probe radiance per bounce.
  std::vector<std::vector<glm::vec3>> mean_;
  std::vector<std::vector<glm::vec3>> probe_mean_;
  // Welford statistics of each texel's total per-update estimate (luminance).
  std::vector<double> total_mean_, total_m2_;
};

}  // namespace irradcast

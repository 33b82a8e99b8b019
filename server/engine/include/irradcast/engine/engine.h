// The GI engine (seed 001, chapter 3): the scene's irradiance in scene space, computed into the
// per-object lightmaps by a direct pass on the trace backend and K indirect bounces of the
// indirect method (by default radiance cells: a probe gather and a scatter with a tracing
// range). Progressive: every update() adds one more estimate to running per-texel means, so
// quality improves for as long as it runs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/pass_data.h"
#include "irradcast/engine/trace_backend.h"

namespace irradcast {

struct DenoiseStats;   // denoise.h
class IndirectMethod;  // the engine's own (server/engine/src/indirect_method.h)
class DilationPlan;    // likewise (dilation_plan.h)

// One pass's cost as the backend reported it.
using PassTiming = PassResult;

struct UpdateStats {
  PassTiming direct;
  PassTiming prepare;               // VPL / irradiance cache: shooting VPLs, placing records
  std::vector<PassTiming> probes;   // per bounce (empty entries in unbiased mode)
  std::vector<PassTiming> scatter;  // per bounce
  double total_seconds = 0.0;
  std::uint64_t total_rays() const;
};

class Engine {
 public:
  // The world, atlas, G-buffers and ray scene must outlive the engine. `rays` serves the
  // host-side set-up (probe placement and probe visibility); the direct pass and the radiance
  // cells' bounces run on `backend`. Methods other than radiance cells (EngineParams::method)
  // run their bounces on the CPU with `rays` and need the scene's `lights` (which must outlive
  // the engine too).
  Engine(const World& world, const Atlas& atlas, const std::vector<TexelGBuffer>& gbuffers,
         const RayScene& rays, std::unique_ptr<TraceBackend> backend, EngineParams params,
         const LightSampler* lights = nullptr);
  ~Engine();

  // One progressive update: the direct pass, then the indirect method's bounces.
  // While texels wait for their first estimate since an edit, an update covers the next batch
  // of them (EngineParams::edit_batch, in priority order) instead of every texel.
  UpdateStats update();

  // After a scene edit: the host changed the world, ray scene, lights and G-buffers in place
  // (the same objects and lightmaps) and told the backend. Rebuilds the texels (validity and
  // positions may change), re-places the probes in affected cells and the probe weights, and
  // restarts every texel's estimate: affected texels first, then the rest; within each, texels
  // a camera sees first (seed 001 section 4.7.1 and 4.7.3). What a texel shows blends from its
  // value before the edit to the new estimate (EngineParams::edit_blend).
  void scene_changed(const SceneChange& change, const std::vector<CameraPose>& cameras);
  // Texels that have no estimate since the last edit (0: caught up).
  std::size_t stale_texels() const { return queue_.size() - queue_pos_; }
  // Where the last scene_changed() spent its time ("texels 3 ms, probes (4) 120 ms, ...").
  const std::string& change_timings() const { return change_timings_; }
  // The smallest number of samples of any texel since its last restart.
  std::uint32_t min_samples() const;

  std::uint32_t updates() const { return updates_; }
  const EngineParams& params() const { return params_; }
  const ProbeGrid& probes() const { return probes_.grid; }
  const ProbeStats& probe_stats() const { return probes_.stats; }
  std::size_t texel_count() const { return texels_.size(); }
  const TraceBackend& backend() const { return *backend_; }
  // The indirect method's state in one line ("" for radiance cells).
  std::string method_summary() const;
  const IndirectMethod* method() const { return method_.get(); }

  // Total irradiance E = E_direct + sum of the bounces, per object, dilated into the gutters.
  std::vector<Lightmap> lightmaps() const;
  // What is published (the server's tiles, the bake's lightmaps): lightmaps(), or with
  // EngineParams::denoise a denoised copy of them (denoise.h); the running means stay as they
  // are. `stats` gets the filter's counts (zero without the denoiser).
  std::vector<Lightmap> published_lightmaps(DenoiseStats* stats = nullptr) const;
  // Irradiance of one component: 0 = direct, k = k-th indirect bounce.
  std::vector<Lightmap> component(int bounce) const;
  // Per texel: samples (updates) so far, and the relative standard error of its total estimate.
  double mean_relative_error() const;
  // Per texel, the standard error of the mean of its total estimate (luminance, in every
  // channel), as lightmaps like lightmaps(); empty before the second update. The tile store
  // uses it to tell a real change of a tile from Monte Carlo noise.
  std::vector<Lightmap> standard_error() const;

 private:
  struct Before;  // what the texels had and showed when an edit came (engine.cpp)

  void build_texels(const std::vector<TexelGBuffer>& gbuffers);
  void build_dispatch();
  std::vector<Lightmap> to_lightmaps(const std::vector<glm::vec3>& values) const;
  void to_lightmaps(const std::vector<glm::vec3>& values, std::vector<Lightmap>& maps) const;
  // Per texel: the standard error of its total's mean (luminance; 0 below two samples).
  std::vector<float> texel_standard_error() const;
  // Per texel: the total it shows (the blend of the new estimate and its value before an edit).
  std::vector<glm::vec3> shown() const;
  // update()'s steps: the next batch of texels waiting since an edit (grouped into units), and
  // after the direct pass of a full update the bounces and the texels' statistics.
  void next_batch(std::vector<std::uint32_t>& texels, std::vector<std::uint32_t>& offsets);
  // `total`: the luminance of the direct pass's estimates, to which each bounce's is added.
  void bounces(PassInput& in, std::vector<float>& total, UpdateStats& stats);
  // scene_changed()'s steps: what every texel had before; its old values carried over to the
  // rebuilt texels (returns each texel's index before, -1 if it was not valid); the priority tier
  // of each texel; the restart of the statistics and the queue of texels waiting.
  Before take_before(bool rebuild);
  std::vector<std::int32_t> carry_over(const Before& before);
  void carry_over_dilated(const Before& before, const std::vector<std::uint32_t>& missing);
  std::vector<std::uint8_t> priorities(const SceneChange& change,
                                       const std::vector<CameraPose>& cameras) const;
  void restart(const Before& before, const std::vector<std::int32_t>& old_of,
               const std::vector<std::uint8_t>& tier, const SceneChange& change);

  const World* world_;
  const Atlas* atlas_;
  const std::vector<TexelGBuffer>* gbuffers_;
  const RayScene* rays_;
  std::unique_ptr<TraceBackend> backend_;
  EngineParams params_;
  std::unique_ptr<IndirectMethod> method_;
  SurfaceTexels texels_;
  Probes probes_;  // the grid of cells; placed and weighed by the method that reads probes
  std::vector<std::uint32_t> unit_texels_, unit_offsets_;
  // Per object: its lightmap's gap fill, from the G-buffer's texel kinds (made with the texels).
  std::vector<DilationPlan> dilation_;
  std::uint32_t updates_ = 0;
  std::uint64_t generation_ = 0;  // PassInput::generation
  // Running means: [0] direct, [k] bounce k. A texel's means count samples_[i] samples; before
  // its first sample since an edit they hold its old values.
  std::vector<std::vector<glm::vec3>> mean_;
  std::vector<std::uint32_t> samples_;         // direct samples since the last restart
  std::vector<std::uint32_t> bounce_samples_;  // indirect samples since the last restart
  std::vector<glm::vec3> before_;              // per texel: what it showed when the last edit came
  std::vector<std::uint8_t> restarted_;        // per texel: restarted by the last edit (blends)
  // Texels waiting for their first sample since the last edit, in priority order.
  std::vector<std::uint32_t> queue_;
  std::size_t queue_pos_ = 0;
  std::string change_timings_;
  // Welford statistics of each texel's total per-update estimate (luminance), worked in double
  // and kept in single precision: a noise estimate, 8 bytes a texel instead of 16.
  std::vector<float> total_mean_, total_m2_;
};

}  // namespace irradcast

// Radiance cells (seed 001 chapter 3), the default indirect method: one probe per cell of the
// engine's grid, relocated out of geometry and read by the texels that see it; each bounce
// gathers every probe's radiance on the trace backend (biased mode) and scatters hemisphere
// rays within the tracing range, the probes standing in for the light beyond it. Unbiased mode
// (an infinite tracing range) reads no probes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indirect_method.h"
#include "irradcast/engine/trace_backend.h"

namespace irradcast {

class CellsMethod final : public IndirectMethod {
 public:
  // `rays` places the probes and tests their visibility; the bounces run on `backend`.
  CellsMethod(const EngineParams& params, const World& world, const RayScene& rays,
              TraceBackend& backend);

  std::string name() const override { return "cells"; }
  void place_probes(const SurfaceTexels& texels, const SceneChange* change, Probes& probes,
                    const Lap& lap) override;
  PassResult prepare(const PassInput& in) override;
  BounceResult bounce(const PassInput& in, const RadianceField& prev,
                      std::vector<glm::vec3>& out) override;
  void scene_changed(const SceneChange& change, const Lap& lap) override;
  std::string summary() const override { return std::string(); }

 private:
  // Places the probes of cells `which` (from their centres, moved out of geometry).
  void place(const std::vector<std::size_t>& which, Probes& probes) const;
  // Per texel: the usable probes around it that it sees (Probes::corners).
  void weigh(const SurfaceTexels& texels, Probes& probes) const;

  const EngineParams params_;
  const World* world_;
  const RayScene* rays_;
  TraceBackend* backend_;
  // Running mean of every probe texel's radiance, per bounce, kept by the backend
  // (TraceBackend::probe_bounce); every full update gathers every probe, so one count serves
  // them all (restarted by every edit).
  ProbeMeans means_;
  std::uint32_t probe_samples_ = 0;
  float probe_weight_ = 1.0f;  // of this update's probe estimate in the running mean
};

}  // namespace irradcast

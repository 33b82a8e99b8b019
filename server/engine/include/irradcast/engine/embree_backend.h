// The CPU backend: the engine's passes on Embree rays, TBB across all cores.
#pragma once

#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/trace_backend.h"

namespace irradcast {

class EmbreeBackend final : public TraceBackend {
 public:
  // `rays` and `lights` must outlive the backend.
  EmbreeBackend(const RayScene& rays, const LightSampler& lights)
      : rays_(&rays), lights_(&lights) {}
  std::string name() const override { return "embree"; }
  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override;
  PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                           std::vector<glm::vec3>& out) override;
  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override;

 private:
  const RayScene* rays_;
  const LightSampler* lights_;
};

}  // namespace irradcast

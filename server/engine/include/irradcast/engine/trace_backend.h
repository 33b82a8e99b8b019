// The one interface the GI engine's passes run behind: an Embree (CPU) backend and a Vulkan
// compute backend (backend_select.h picks one). A backend owns its acceleration structure; the
// engine owns the data (texels, probes, accumulated estimates) and calls one pass at a time,
// except the probes' running means, which stay with the backend (probe_bounce) so that a device
// backend keeps them in device memory between updates.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/engine/pass_data.h"

namespace irradcast {

// The running means of every probe texel's radiance, one per indirect bounce, that
// TraceBackend::probe_bounce updates. Its owner (the radiance cells method) keeps it for the
// engine's life; a backend that computes on the host keeps the means in `host`, a device backend
// in its own memory under `id` (unique per ProbeMeans, so two engines never share means).
struct ProbeMeans {
  ProbeMeans();
  const std::uint64_t id;
  std::vector<std::vector<glm::vec3>> host;  // per bounce (index 0 unused)
};

class TraceBackend {
 public:
  virtual ~TraceBackend() = default;
  virtual std::string name() const = 0;
  // The name and the device it runs on ("vulkan on NVIDIA H100 ..."), for logs and reports.
  virtual std::string describe() const { return name(); }
  // The world, the lights or the materials changed (a scene edit; the objects are the same):
  // a backend that copied scene data (geometry, materials, lights) copies it again.
  virtual void scene_changed() {}

  // Direct irradiance per texel (one update's estimate).
  virtual PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) = 0;
  // One update's estimate of every probe texel's radiance from the previous bounce.
  virtual PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                                   std::vector<glm::vec3>& out) = 0;
  // One indirect bounce: irradiance per texel from hemisphere rays within the tracing range,
  // probes beyond it.
  virtual PassResult scatter(const PassInput& in, const RadianceField& prev,
                             const std::vector<glm::vec3>& probe_radiance,
                             std::vector<glm::vec3>& out) = 0;

  // One bounce of the radiance cells method with probes (biased mode): gather_probes from
  // `prev`, this update's estimates folded into the bounce's running means (mean += (estimate -
  // mean) * weight, from zero the first time; weight 1 restarts them), then scatter reading
  // those means. The default does exactly that with the means in `means.host`; a device backend
  // keeps the means on the device and runs both dispatches in one submission (same arithmetic).
  virtual BounceResult probe_bounce(const PassInput& in, const RadianceField& prev, float weight,
                                    ProbeMeans& means, std::vector<glm::vec3>& out);
};

}  // namespace irradcast

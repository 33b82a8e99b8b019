// The one interface the GI engine's passes run behind: an Embree (CPU) backend and a Vulkan
// compute backend (backend_select.h picks one). A backend owns its acceleration structure; the
// engine owns the data (texels, probes, accumulated estimates) and calls one pass at a time.
#pragma once

#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/engine/pass_data.h"

namespace irradcast {

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
};

}  // namespace irradcast

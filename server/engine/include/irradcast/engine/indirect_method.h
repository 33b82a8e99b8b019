// The indirect bounces of the methods other than radiance cells (docs/METHODS.md): instant
// radiosity (vpl_method.h) and the irradiance cache (irradiance_cache.h). The engine keeps
// everything else (texels, the direct pass on its backend, running means, edits and their
// catch-up), so every method writes the same lightmaps and the service does not change. These
// methods trace on the CPU with the host's Embree scene, whichever backend runs the direct pass.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/trace_backend.h"

namespace irradcast {

struct SceneChange;

class IndirectMethod {
 public:
  virtual ~IndirectMethod() = default;
  virtual std::string name() const = 0;
  // Once per full update, before its bounces (place records, shoot or replace VPLs).
  virtual PassResult prepare(const PassInput& in) = 0;
  // Bounce in.bounce of this update for every texel of `in` (out sized like in.texels);
  // `prev` is the running mean of the bounce before (the direct light for bounce 1).
  virtual PassResult bounce(const PassInput& in, const RadianceField& prev,
                            std::vector<glm::vec3>& out) = 0;
  // The host changed the scene (the world, rays and lights the method was built with).
  virtual void scene_changed(const SceneChange& change) = 0;
  // One line for logs: "412 records", "2048 VPLs (37 replaced)".
  virtual std::string summary() const = 0;
};

// The method of params.method (nullptr for Method::Cells, which the engine runs on its backend).
std::unique_ptr<IndirectMethod> make_indirect_method(const EngineParams& params, const World& world,
                                                     const RayScene& rays,
                                                     const LightSampler& lights);

}  // namespace irradcast

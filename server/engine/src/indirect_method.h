// The indirect bounces of the GI engine, one implementation per method (docs/METHODS.md):
// radiance cells with probes on the trace backend (cells_method.h, the default), instant
// radiosity (vpl_method.h) and the irradiance cache (irradiance_cache.h). The engine keeps
// everything else (texels, the direct pass on its backend, running means, edits and their
// catch-up), so every method writes the same lightmaps and the service does not change. The
// VPL method and the irradiance cache trace on the CPU with the host's Embree scene, whichever
// backend runs the direct pass.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/pass_data.h"

namespace irradcast {

class TraceBackend;

class IndirectMethod {
 public:
  // Ends one timed step of a scene change ("probes (12)"), for Engine::change_timings().
  using Lap = std::function<void(const std::string& step)>;

  virtual ~IndirectMethod() = default;
  virtual std::string name() const = 0;
  // The engine built its texels (and their cells in probes.grid): at the start (`change` null)
  // or again after an edit. A method that reads probes places them and weighs them per texel;
  // the others leave `probes` as it is.
  virtual void place_probes(const SurfaceTexels& /*texels*/, const SceneChange* /*change*/,
                            Probes& /*probes*/, const Lap& /*lap*/) {}
  // Once per full update, before its bounces (place records, shoot or replace VPLs).
  virtual PassResult prepare(const PassInput& in) = 0;
  // Bounce in.bounce of this update for every texel of `in` (out sized like in.texels);
  // `prev` is the running mean of the bounce before (the direct light for bounce 1).
  virtual BounceResult bounce(const PassInput& in, const RadianceField& prev,
                              std::vector<glm::vec3>& out) = 0;
  // The host changed the scene (the world, rays and lights the method was built with), after
  // the engine and its backend took the change; `lap` times the method's work (a step under
  // its name where it has any).
  virtual void scene_changed(const SceneChange& change, const Lap& lap) = 0;
  // One line for logs: "412 records", "2048 VPLs (37 replaced)"; "" when there is nothing to say.
  virtual std::string summary() const = 0;
};

// The method of params.method. Radiance cells run on `backend`; the others need the scene's
// `lights` (throws without them). Everything passed must outlive the method.
std::unique_ptr<IndirectMethod> make_indirect_method(const EngineParams& params, const World& world,
                                                     const RayScene& rays,
                                                     const LightSampler* lights,
                                                     TraceBackend& backend);

}  // namespace irradcast

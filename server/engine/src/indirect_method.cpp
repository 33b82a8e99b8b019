#include "irradcast/engine/indirect_method.h"

#include "irradcast/engine/irradiance_cache.h"
#include "irradcast/engine/vpl_method.h"

namespace irradcast {

std::unique_ptr<IndirectMethod> make_indirect_method(const EngineParams& params, const World& world,
                                                     const RayScene& rays,
                                                     const LightSampler& lights) {
  switch (params.method) {
    case Method::Cells:
      return nullptr;
    case Method::Vpl:
      return std::make_unique<VplMethod>(params, world, rays, lights);
    case Method::IrradianceCache:
      return std::make_unique<IrradianceCache>(params, world, rays);
  }
  return nullptr;
}

}  // namespace irradcast

// The factory of the indirect methods (indirect_method.h).
#include "indirect_method.h"

#include "cells_method.h"
#include "irradcast/common/error.h"
#include "irradiance_cache.h"
#include "vpl_method.h"

namespace irradcast {

std::unique_ptr<IndirectMethod> make_indirect_method(const EngineParams& params, const World& world,
                                                     const RayScene& rays,
                                                     const LightSampler* lights,
                                                     TraceBackend& backend) {
  if (params.method == Method::Cells)
    return std::make_unique<CellsMethod>(params, world, rays, backend);
  if (!lights) throw Error("engine: method " + method_name(params.method) + " needs the lights");
  if (params.method == Method::Vpl)
    return std::make_unique<VplMethod>(params, world, rays, *lights);
  return std::make_unique<IrradianceCache>(params, world, rays);
}

}  // namespace irradcast

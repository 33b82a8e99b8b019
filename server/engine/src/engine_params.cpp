#include "irradcast/engine/engine_params.h"

#include <cmath>

#include "irradcast/common/error.h"

namespace irradcast {

void EngineParams::validate() const {
  if (!(cell_size > 0.0f && cell_size <= 1.0f))
    throw Error("cell_size must be in (0, 1] (a fraction of the scene size)");
  if (!(tracing_range >= 0.0f)) throw Error("tracing_range must be >= 0 or inf");
  if (direct_samples < 1 || direct_samples > 4096) throw Error("direct_samples must be in 1..4096");
  if (indirect_samples < 1 || indirect_samples > 4096)
    throw Error("indirect_samples must be in 1..4096");
  if (indirect_bounces < 0 || indirect_bounces > 16)
    throw Error("indirect_bounces must be in 0..16");
  if (probe_resolution < 2 || probe_resolution > 64)
    throw Error("probe_resolution must be in 2..64");
  if (!(edit_blend >= 0.0f && edit_blend <= 64.0f))
    throw Error("edit_blend must be in [0, 64] (updates; 0 = no blending)");
  if (edit_keep < 0 || edit_keep > 1 << 20) throw Error("edit_keep must be in 0..2^20");
  if (!(edit_batch > 0.0f && edit_batch <= 1.0f))
    throw Error("edit_batch must be in (0, 1] (a fraction of the texels)");
  if (vpl_paths < 1 || vpl_paths > 1 << 20) throw Error("vpl_paths must be in 1..2^20");
  if (vpl_sets < 1 || vpl_sets > 1024) throw Error("vpl_sets must be in 1..1024");
  if (vpl_interleave < 1 || vpl_interleave > 16) throw Error("vpl_interleave must be in 1..16");
  if (static_cast<long>(vpl_sets) * vpl_interleave * vpl_interleave > vpl_paths)
    throw Error(
        "vpl_paths must be at least vpl_sets x vpl_interleave^2 (every texel's subset "
        "needs a path)");
  if (!(vpl_clamp >= 0.0f && vpl_clamp <= 1.0f))
    throw Error("vpl_clamp must be in [0, 1] (a fraction of the scene size; 0 = no clamping)");
  if (vpl_replace < 0) throw Error("vpl_replace must be >= 0 (0 = no cap)");
  if (!(ic_accuracy > 0.0f && ic_accuracy <= 4.0f)) throw Error("ic_accuracy must be in (0, 4]");
  if (ic_rays < 2 || ic_rays > 64) throw Error("ic_rays must be in 2..64");
  if (!(ic_min_radius > 0.0f && ic_min_radius <= ic_max_radius && ic_max_radius <= 1.0f))
    throw Error("ic radii must satisfy 0 < ic_min_radius <= ic_max_radius <= 1");
  if (std::ceil(1.0f / cell_size) > 256.0f)
    throw Error("cell_size is too small (over 256 cells per axis)");
}

Dispatch parse_dispatch(const std::string& name) {
  if (name == "cell") return Dispatch::PerCell;
  if (name == "object") return Dispatch::PerObject;
  throw Error("unknown dispatch '" + name + "' (expected cell or object)");
}

DistantPoint parse_distant_point(const std::string& name) {
  if (name == "project") return DistantPoint::BoundsProjection;
  if (name == "fixed") return DistantPoint::FixedDistance;
  throw Error("unknown distant point mode '" + name + "' (expected project or fixed)");
}

Method parse_method(const std::string& name) {
  if (name == "cells") return Method::Cells;
  if (name == "vpl") return Method::Vpl;
  if (name == "irradiance-cache") return Method::IrradianceCache;
  throw Error("unknown method '" + name + "' (expected cells, vpl or irradiance-cache)");
}

std::string method_name(Method m) {
  switch (m) {
    case Method::Cells:
      return "cells";
    case Method::Vpl:
      return "vpl";
    case Method::IrradianceCache:
      return "irradiance-cache";
  }
  return "?";
}

float parse_tracing_range(const std::string& text) {
  if (text == "inf") return std::numeric_limits<float>::infinity();
  try {
    std::size_t used = 0;
    float v = std::stof(text, &used);
    if (used != text.size() || !(v >= 0.0f)) throw std::invalid_argument(text);
    return v;
  } catch (const std::exception&) {
    throw Error("tracing range '" + text + "' must be a number >= 0 or inf");
  }
}

}  // namespace irradcast

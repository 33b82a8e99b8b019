#include "irradcast/engine_params.h"

#include <cmath>

#include "irradcast/error.h"

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
  if (!(edit_batch > 0.0f && edit_batch <= 1.0f))
    throw Error("edit_batch must be in (0, 1] (a fraction of the texels)");
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

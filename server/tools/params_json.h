// The engine parameters in JSON, for irradcast-bake's report (report.json "engine"); one key per
// parameter of engine_params.inc, so a new parameter appears there by itself.
#pragma once

#include <nlohmann/json.hpp>

#include <limits>
#include <type_traits>

#include "irradcast/engine/engine_params.h"

namespace irradcast::tools {

// Every engine parameter by name, as the bake report (report.json "engine") gives it: numbers,
// flags as booleans, enums by name, an infinite tracing range as "inf", a length in metres as
// "2m" and a fraction capped in metres as "0.25:1m".
inline nlohmann::json params_json(const EngineParams& p) {
  nlohmann::json j = nlohmann::json::object();
  for_each_param(p, [&](const ParamSpec& s, const auto& v) {
    using T = std::remove_cvref_t<decltype(v)>;
    if constexpr (std::is_enum_v<T>)
      j[s.name] = param_text(v);
    else if constexpr (std::is_same_v<T, Length>)
      j[s.name] = v.metres || v.infinite() || v.has_cap() ? nlohmann::json(param_text(v))
                                                          : nlohmann::json(v.value);
    else if constexpr (std::is_same_v<T, float>)
      j[s.name] = s.kind == ParamKind::Distance && !(v < std::numeric_limits<float>::infinity())
                      ? nlohmann::json("inf")
                      : nlohmann::json(v);
    else
      j[s.name] = v;
  });
  return j;
}

}  // namespace irradcast::tools

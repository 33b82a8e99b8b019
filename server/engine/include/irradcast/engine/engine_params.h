// Parameters of the GI engine, with seed 001's names and defaults. They are declared once, in
// engine_params.inc (member, default, range, command-line flag, help); EngineParams' members,
// validate(), the command-line options (server/tools/engine_options.h), the bake report and the
// tile epoch (server/service) all come from that list through for_each_param.
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <string>

namespace irradcast {

enum class Dispatch { PerCell, PerObject };
enum class DistantPoint { BoundsProjection, FixedDistance };
// How the indirect bounces are estimated (docs/METHODS.md). All write the same lightmaps.
enum class Method { Cells, Vpl, IrradianceCache };

// What a parameter is, for its command-line option, its check and its text.
enum class ParamKind {
  Int,       // int in lo..hi
  IntShown,  // the same, and the command line checks it too, showing the range in --help
  Real,      // float in [lo, hi]
  Positive,  // float in (lo, hi]; a Length: a fraction in (lo, hi], metres > 0 ("2m"), or
             // such a fraction capped at metres > 0 ("0.25:1m")
  Distance,  // float >= lo, or inf; on the command line a number or "inf"; a Length: a
             // fraction >= lo, metres >= 0 ("2m"), such a finite fraction capped at metres
             // >= 0 ("0.3:1.2m"), or inf
  Choice,    // an enum, on the command line one of choice_names()
  Off,       // a bool, true by default; its command-line flag turns it off
  On,        // a bool, false by default; its command-line flag turns it on
  Seed,      // any 64-bit value
};

// No upper bound.
inline constexpr double kNoLimit = std::numeric_limits<double>::infinity();

// A length in the scene: a fraction of its largest extent (seed 001's convention: the scene
// normalised to its bounding box), metres (world units) whatever the scene's size, or a fraction
// capped in metres (the defaults: a small scene keeps seed 001's grid, a large one gets cells and
// rays of a room's size). On the command line "0.25" is a fraction, "2m" metres and "0.25:1m" a
// quarter of the scene, at most 1 m (docs/ENGINE.md, "Sizes in metres").
struct Length {
  float value = 0.0f;
  bool metres = false;
  float cap = std::numeric_limits<float>::infinity();  // a fraction's ceiling, metres
  constexpr Length() = default;
  constexpr Length(float fraction) : value(fraction) {}  // NOLINT: a plain number is a fraction
  static constexpr Length in_metres(float m) {
    Length l(m);
    l.metres = true;
    return l;
  }
  static constexpr Length capped(float fraction, float max_metres) {
    Length l(fraction);
    l.cap = max_metres;
    return l;
  }
  // A fraction with a ceiling in metres (any cap but +inf, NaN included, which validate()
  // refuses).
  bool has_cap() const { return !metres && !(cap == std::numeric_limits<float>::infinity()); }
  // In world units, for a scene whose largest extent is `extent`.
  float resolve(float extent) const {
    if (metres) return value;
    const float v = value * extent;
    return cap < v ? cap : v;
  }
  bool infinite() const { return !(value < std::numeric_limits<float>::infinity()); }
  bool operator==(const Length&) const = default;
};

struct EngineParams {
#define IRRADCAST_ENGINE_PARAM(kind, type, name, init, lo, hi, flags, help) type name = init;
#include "irradcast/engine/engine_params.inc"
#undef IRRADCAST_ENGINE_PARAM

  bool unbiased() const {
    return tracing_range.infinite();
  }
  // Radiance cells with a finite tracing range: the only configuration that places probes.
  bool uses_probes() const {
    return method == Method::Cells && !unbiased();
  }
  // Throws irradcast::Error naming the bad parameter.
  void validate() const;
  bool operator==(const EngineParams&) const = default;
};

// One entry of engine_params.inc, less its type and default.
struct ParamSpec {
  const char* name;  // EngineParams' member; its key in the bake report and the tile epoch
  ParamKind kind;
  double lo, hi;      // the range validate() checks (see ParamKind)
  const char* flags;  // command-line names, CLI11 style ("--bounces,--indirect-bounces")
  const char* help;   // --help text
};

inline constexpr ParamSpec kEngineParamSpecs[] = {
#define IRRADCAST_ENGINE_PARAM(kind, type, name, init, lo, hi, flags, help) \
  {#name, ParamKind::kind, lo, hi, flags, help},
#include "irradcast/engine/engine_params.inc"
#undef IRRADCAST_ENGINE_PARAM
};

// Calls f(spec, member) for every parameter, in the list's order, `member` being the
// parameter's field of `p` (a const reference when `p` is const).
template <class Params, class F>
void for_each_param(Params& p, F&& f) {
  const ParamSpec* spec = kEngineParamSpecs;
#define IRRADCAST_ENGINE_PARAM(kind, type, name, init, lo, hi, flags, help) f(*spec++, p.name);
#include "irradcast/engine/engine_params.inc"
#undef IRRADCAST_ENGINE_PARAM
}

// A parameter's value as the command line spells it: numbers in their shortest exact form,
// inf as "inf", enums by name.
std::string param_text(float v);
std::string param_text(Length v);  // "0.25", "2m", "0.25:1m" or "inf"
std::string param_text(int v);
std::string param_text(std::uint64_t v);
std::string param_text(bool v);
std::string param_text(Method v);
std::string param_text(Dispatch v);
std::string param_text(DistantPoint v);
// The names of a Choice parameter's values, in the enum's order.
std::span<const char* const> choice_names(Method);
std::span<const char* const> choice_names(Dispatch);
std::span<const char* const> choice_names(DistantPoint);
// A Choice or Distance parameter from its command-line text; throws irradcast::Error naming
// the parameter and what it accepts.
void parse_param(const ParamSpec& spec, const std::string& text, Method& v);
void parse_param(const ParamSpec& spec, const std::string& text, Dispatch& v);
void parse_param(const ParamSpec& spec, const std::string& text, DistantPoint& v);
void parse_param(const ParamSpec& spec, const std::string& text, float& v);
void parse_param(const ParamSpec& spec, const std::string& text, Length& v);
// Every parameter as "name=text|...": what the tile epoch keys on (server/service), so that
// any change of a parameter gives another epoch.
std::string engine_params_key(const EngineParams& p);

Dispatch parse_dispatch(const std::string& name);           // "cell" | "object"
DistantPoint parse_distant_point(const std::string& name);  // "project" | "fixed"
Length parse_tracing_range(const std::string& text);        // a fraction, "2m", "0.3:1.2m" or "inf"
Method parse_method(const std::string& name);               // "cells" | "vpl" | "irradiance-cache"
std::string method_name(Method m);

}  // namespace irradcast

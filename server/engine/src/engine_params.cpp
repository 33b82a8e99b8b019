// EngineParams' checks and texts, all driven by the list in engine_params.inc.
#include "irradcast/engine/engine_params.h"

#include <charconv>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <type_traits>

#include "irradcast/common/error.h"

namespace irradcast {

namespace {

constexpr const char* kMethodNames[] = {"cells", "vpl", "irradiance-cache"};
constexpr const char* kDispatchNames[] = {"cell", "object"};
constexpr const char* kDistantPointNames[] = {"project", "fixed"};

// The shortest text that reads back as exactly `v` (std::to_chars' guarantee).
template <class T>
std::string shortest(T v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

template <class E>
E parse_choice(const char* what, const std::string& text) {
  const std::span<const char* const> names = choice_names(E{});
  for (std::size_t i = 0; i < names.size(); ++i)
    if (text == names[i]) return static_cast<E>(i);
  std::string expected;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (i > 0) expected += i + 1 == names.size() ? " or " : ", ";
    expected += names[i];
  }
  throw Error("unknown " + std::string(what) + " '" + text + "' (expected " + expected + ")");
}

float parse_distance(const char* what, double lo, const std::string& text) {
  if (text == "inf") return std::numeric_limits<float>::infinity();
  try {
    std::size_t used = 0;
    float v = std::stof(text, &used);
    if (used != text.size() || !(v >= lo)) throw std::invalid_argument(text);
    return v;
  } catch (const std::exception&) {
    throw Error(std::string(what) + " '" + text + "' must be a number >= " + shortest(lo) +
                " or inf");
  }
}

// A number and nothing else, finite (inf only where `inf_ok`); throws std::invalid_argument.
float parse_number(const std::string& text, bool inf_ok) {
  if (inf_ok && text == "inf") return std::numeric_limits<float>::infinity();
  std::size_t used = 0;
  const float v = std::stof(text, &used);
  if (text.empty() || used != text.size() || !std::isfinite(v)) throw std::invalid_argument(text);
  return v;
}

Length parse_length(const ParamSpec& s, const std::string& text) {
  const bool distance = s.kind == ParamKind::Distance;
  const bool metres = !text.empty() && text.back() == 'm';
  const std::size_t colon = text.find(':');
  try {
    if (colon != std::string::npos) {  // "0.25:1m": a fraction, at most that many metres
      if (!metres) throw std::invalid_argument(text);
      const std::string cap = text.substr(colon + 1, text.size() - colon - 2);
      return Length::capped(parse_number(text.substr(0, colon), false), parse_number(cap, false));
    }
    const std::string number = metres ? text.substr(0, text.size() - 1) : text;
    const float v = parse_number(number, distance && !metres);
    return metres ? Length::in_metres(v) : Length(v);
  } catch (const std::exception&) {
    throw Error(std::string(s.name) + " '" + text + "' must be a fraction of the scene (" +
                (distance ? "0.3" : "0.25") + "), metres (2m)" + (distance ? ", " : " or ") +
                "a fraction of at most so many metres (" + (distance ? "0.3:1.2m" : "0.25:1m") +
                ")" + (distance ? " or inf" : ""));
  }
}

bool in_range(const ParamSpec& s, double v) {
  switch (s.kind) {
    case ParamKind::Int:
    case ParamKind::IntShown:
    case ParamKind::Real:
      return v >= s.lo && v <= s.hi;
    case ParamKind::Positive:
      return v > s.lo && v <= s.hi;
    case ParamKind::Distance:
      return v >= s.lo;
    default:  // Seed: any value
      return true;
  }
}

std::string range_text(const ParamSpec& s) {
  const std::string lo = shortest(s.lo), hi = shortest(s.hi);
  switch (s.kind) {
    case ParamKind::Real:
      return "in [" + lo + ", " + hi + "]";
    case ParamKind::Positive:
      return "in (" + lo + ", " + hi + "]";
    case ParamKind::Distance:
      return ">= " + lo + " or inf";
    default:  // Int, IntShown
      return s.hi == kNoLimit ? ">= " + lo : "in " + lo + ".." + hi;
  }
}

// Throws unless `v` is within `s`'s range (ParamKind).
template <class T>
void check_param(const ParamSpec& s, T v) {
  if constexpr (std::is_same_v<T, Length>) {
    // Metres, and a fraction's cap: finite and above zero (a Distance may also be zero, or inf
    // written as a plain fraction).
    auto metres_ok = [&](float m) {
      return (s.kind == ParamKind::Distance ? m >= 0.0f : m > 0.0f) && std::isfinite(m);
    };
    if (v.metres && !(v.cap == std::numeric_limits<float>::infinity()))
      throw Error(std::string(s.name) + " in metres takes no cap");
    if (v.has_cap()) {
      if (v.infinite()) throw Error(std::string(s.name) + " capped in metres must be finite");
      check_param(s, v.value);
    } else if (!v.metres) {
      return check_param(s, v.value);
    }
    if (!metres_ok(v.metres ? v.value : v.cap))
      throw Error(std::string(s.name) + " in metres must be " +
                  (s.kind == ParamKind::Distance ? ">= 0" : "> 0") + " and finite");
  } else if constexpr (std::is_enum_v<T>) {
    if (static_cast<std::size_t>(v) >= choice_names(v).size())
      throw Error(std::string(s.name) + " has no value " + std::to_string(static_cast<int>(v)));
  } else if constexpr (!std::is_same_v<T, bool>) {
    if (!in_range(s, static_cast<double>(v)))
      throw Error(std::string(s.name) + " must be " + range_text(s));
  }
}

}  // namespace

void EngineParams::validate() const {
  for_each_param(*this, [](const ParamSpec& s, const auto& v) { check_param(s, v); });
  // What one parameter's range cannot say.
  if (static_cast<long>(vpl_sets) * vpl_interleave * vpl_interleave > vpl_paths)
    throw Error(
        "vpl_paths must be at least vpl_sets x vpl_interleave^2 (every texel's subset "
        "needs a path)");
  if (!(ic_min_radius <= ic_max_radius))
    throw Error("ic radii must satisfy 0 < ic_min_radius <= ic_max_radius <= 1");
  if (!cell_size.metres && std::ceil(1.0f / cell_size.value) > 256.0f)
    throw Error("cell_size is too small (over 256 cells per axis)");
  // In metres the scene decides: ProbeGrid::cells_of refuses over 256 cells along its extent.
}

std::string param_text(float v) {
  return v == std::numeric_limits<float>::infinity() ? "inf" : shortest(v);
}
std::string param_text(Length v) {
  if (v.metres) return shortest(v.value) + "m";
  return v.has_cap() ? param_text(v.value) + ":" + shortest(v.cap) + "m" : param_text(v.value);
}
std::string param_text(int v) {
  return std::to_string(v);
}
std::string param_text(std::uint64_t v) {
  return std::to_string(v);
}
std::string param_text(bool v) {
  return v ? "true" : "false";
}
std::string param_text(Method v) {
  return method_name(v);
}
std::string param_text(Dispatch v) {
  return choice_names(v)[static_cast<std::size_t>(v)];
}
std::string param_text(DistantPoint v) {
  return choice_names(v)[static_cast<std::size_t>(v)];
}

std::span<const char* const> choice_names(Method) {
  return kMethodNames;
}
std::span<const char* const> choice_names(Dispatch) {
  return kDispatchNames;
}
std::span<const char* const> choice_names(DistantPoint) {
  return kDistantPointNames;
}

void parse_param(const ParamSpec& s, const std::string& text, Method& v) {
  v = parse_choice<Method>(s.name, text);
}
void parse_param(const ParamSpec& s, const std::string& text, Dispatch& v) {
  v = parse_choice<Dispatch>(s.name, text);
}
void parse_param(const ParamSpec& s, const std::string& text, DistantPoint& v) {
  v = parse_choice<DistantPoint>(s.name, text);
}
void parse_param(const ParamSpec& s, const std::string& text, float& v) {
  v = parse_distance(s.name, s.lo, text);
}
void parse_param(const ParamSpec& s, const std::string& text, Length& v) {
  v = parse_length(s, text);
}

std::string engine_params_key(const EngineParams& p) {
  std::string key;
  for_each_param(p, [&](const ParamSpec& s, const auto& v) {
    if (!key.empty()) key += '|';
    key += s.name;
    key += '=';
    key += param_text(v);
  });
  return key;
}

Dispatch parse_dispatch(const std::string& name) {
  return parse_choice<Dispatch>("dispatch", name);
}

DistantPoint parse_distant_point(const std::string& name) {
  return parse_choice<DistantPoint>("distant point mode", name);
}

Method parse_method(const std::string& name) {
  return parse_choice<Method>("method", name);
}

std::string method_name(Method m) {
  const auto names = choice_names(m);
  const auto i = static_cast<std::size_t>(m);
  return i < names.size() ? names[i] : "?";
}

Length parse_tracing_range(const std::string& text) {
  for (const ParamSpec& s : kEngineParamSpecs)
    if (std::strcmp(s.name, "tracing_range") == 0) return parse_length(s, text);
  throw Error("no tracing_range parameter");
}

}  // namespace irradcast

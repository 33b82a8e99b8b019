// The engine's command-line flags, shared by irradcast-bake and irradcast-server so that both
// spell every parameter the same way. The engine parameters' options come from their one list
// (engine_params.inc, through for_each_param); the atlas and backend options are the tools' own.
#pragma once

#include "irradcast/common/cli.h"

#include <cstring>
#include <map>
#include <string>
#include <type_traits>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/backend_select.h"
#include "irradcast/engine/engine_params.h"

namespace irradcast::tools {

struct EngineOptions {
  // Numbers and flags are parsed straight into `values`; Choice, Distance and Length parameters
  // are kept as typed, by name, and parsed by params().
  EngineParams values;
  std::map<std::string, std::string> text;
  float texels_per_scene = 256.0f;
  int max_lightmap_size = 1024;
  std::string backend = "auto";
  int vulkan_device = -1;
  bool vulkan_validation = false;

  EngineOptions() {
    for_each_param(values, [&](const ParamSpec& s, const auto& v) {
      if (s.kind == ParamKind::Choice || s.kind == ParamKind::Distance ||
          std::is_same_v<std::remove_cvref_t<decltype(v)>, Length>)
        text[s.name] = param_text(v);
    });
  }

  // Binds the engine parameters' options alone (no atlas or backend options: a bench that has its
  // own) to this object, which must outlive `app`'s parse.
  void add_params_to(CLI::App& app) {
    for_each_param(values, [&](const ParamSpec& s, auto& v) { add_param(app, s, v); });
  }

  // Binds the options to this object, which must outlive `app`'s parse.
  void add_to(CLI::App& app) {
    for_each_param(values, [&](const ParamSpec& s, auto& v) {
      add_param(app, s, v);
      // The tools' own options, where --help has always listed them.
      if (std::strcmp(s.name, "indirect_bounces") == 0) add_atlas_options(app);
      if (std::strcmp(s.name, "seed") == 0) add_backend_options(app);
    });
  }

  // Throws irradcast::Error naming a bad value.
  EngineParams params() const {
    EngineParams p = values;
    for_each_param(p, [&](const ParamSpec& s, auto& v) {
      if constexpr (std::is_enum_v<std::remove_reference_t<decltype(v)>> ||
                    std::is_same_v<std::remove_reference_t<decltype(v)>, float> ||
                    std::is_same_v<std::remove_reference_t<decltype(v)>, Length>)
        if (auto it = text.find(s.name); it != text.end()) parse_param(s, it->second, v);
    });
    p.validate();
    return p;
  }

  // Throws irradcast::Error naming a bad --backend.
  BackendOptions backend_options() const {
    BackendOptions b;
    b.kind = parse_backend(backend);
    b.vulkan_device = vulkan_device;
    b.vulkan_validation = vulkan_validation;
    return b;
  }

  AtlasOptions atlas() const {
    AtlasOptions a;
    a.texels_per_scene = texels_per_scene;
    a.max_lightmap_size = max_lightmap_size;
    return a;
  }

 private:
  template <class T>
  void add_param(CLI::App& app, const ParamSpec& s, T& v) {
    if constexpr (std::is_same_v<T, bool>) {
      app.add_flag_callback(
          s.flags, [&v, on = s.kind == ParamKind::On] { v = on; }, s.help);  // Off / On
    } else if constexpr (std::is_enum_v<T>) {
      app.add_option(s.flags, text[s.name], s.help);  // ParamKind::Choice
    } else if constexpr (std::is_same_v<T, Length>) {
      app.add_option(s.flags, text[s.name], s.help);  // a fraction, metres ("2m") or inf
    } else if (s.kind == ParamKind::Distance) {
      app.add_option(s.flags, text[s.name], s.help);
    } else {
      CLI::Option* o = app.add_option(s.flags, v, s.help);
      if (s.kind == ParamKind::IntShown)
        o->check(CLI::Range(static_cast<int>(s.lo), static_cast<int>(s.hi)));
    }
  }

  void add_atlas_options(CLI::App& app) {
    app.add_option("--texels-per-scene", texels_per_scene,
                   "lightmap density: texels across the scene's largest extent")
        ->check(CLI::Range(1.0f, 65536.0f));
    app.add_option("--max-lightmap-size", max_lightmap_size, "per-object lightmap size cap")
        ->check(CLI::Range(8, 16384));
  }

  void add_backend_options(CLI::App& app) {
    app.add_option("--backend", backend,
                   "engine: auto (a Vulkan GPU if one opens, else Embree) | vulkan | embree");
    app.add_option("--vulkan-device", vulkan_device,
                   "engine: Vulkan device index from --list-devices (default: the best)")
        ->check(CLI::Range(0, 1024));
    app.add_flag("--vulkan-validation", vulkan_validation,
                 "engine: run Vulkan with the Khronos validation layer (slow; for debugging)");
  }
};

}  // namespace irradcast::tools

// The options that change the loaded scene, shared by irradcast-bake and irradcast-server:
// --sky R,G,B | FILE.exr, --sky-strength S and --sun DX,DY,DZ,W (docs/ENGINE.md "Sky and sun"),
// and --dynamic NAME[,NAME...] (docs/DYNAMIC.md). The sky becomes Scene::sky; the sun a directional
// light on a node of its own, exactly as a glTF directional light loads, so edits and the scene
// package see an ordinary light.
#pragma once

#include "irradcast/common/cli.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/image.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/sky.h"

namespace irradcast::tools {

// Splits "a,b,c" into exactly `count` finite numbers; throws irradcast::Error naming `option`.
inline std::vector<float> parse_numbers(const std::string& option, const std::string& text,
                                        std::size_t count, const std::string& expected) {
  std::vector<float> v;
  std::size_t at = 0;
  while (true) {
    const std::size_t comma = text.find(',', at);
    const std::string part =
        text.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    char* end = nullptr;
    const float x = std::strtof(part.c_str(), &end);
    if (part.empty() || end != part.c_str() + part.size() || !std::isfinite(x))
      throw Error(option + " expects " + expected + ", not '" + text + "'");
    v.push_back(x);
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  if (v.size() != count) throw Error(option + " expects " + expected + ", not '" + text + "'");
  return v;
}

// Whether `s` ends with `suffix`, ignoring ASCII case.
inline bool ends_with_nocase(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (std::size_t i = 0; i < suffix.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) !=
        std::tolower(static_cast<unsigned char>(suffix[i])))
      return false;
  return true;
}

// A directional light of irradiance `w` (W m^-2 on a surface facing it) travelling along
// `direction`, as a Light on a new root node whose local -Z is that direction (glTF's
// convention). Returns the node's index.
inline int add_sun(Scene& scene, glm::vec3 direction, float w) {
  Light light;
  light.name = "sun";
  light.type = Light::Type::Directional;
  light.color = glm::vec3(1.0f);
  light.intensity = w;
  const glm::vec3 z = -glm::normalize(direction);
  const glm::vec3 helper = std::fabs(z.y) < 0.9f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0);
  const glm::vec3 x = glm::normalize(glm::cross(helper, z));
  const glm::vec3 y = glm::cross(z, x);
  Node node;
  node.name = "sun";
  node.local = glm::mat4(glm::vec4(x, 0.0f), glm::vec4(y, 0.0f), glm::vec4(z, 0.0f),
                         glm::vec4(0.0f, 0.0f, 0.0f, 1.0f));
  node.light = static_cast<int>(scene.lights.size());
  scene.lights.push_back(light);
  return scene.add_node(std::move(node));
}

struct SceneOptions {
  std::string sky;  // "" (none), "R,G,B" or FILE.exr
  float sky_strength = 1.0f;
  std::string sun;                   // "" (none) or "DX,DY,DZ,W"
  std::vector<std::string> dynamic;  // node names

  // What apply() did, for the log and the report.
  bool sky_from_file = false;
  glm::vec3 sky_color{0.0f};
  bool has_sun = false;
  glm::vec3 sun_direction{0.0f, -1.0f, 0.0f};  // unit
  float sun_irradiance = 0.0f;

  // Binds the options to this object, which must outlive `app`'s parse.
  void add_to(CLI::App& app) {
    app.add_option("--sky", sky,
                   "light from where rays leave the scene: R,G,B (constant linear radiance, "
                   "W/m^2/sr) or FILE.exr (equirectangular linear radiance: +Y up, the image "
                   "centre faces -Z, right turns toward +X); default none")
        ->default_str("none");
    app.add_option("--sky-strength", sky_strength, "multiplies the --sky colour or map");
    app.add_option("--sun", sun,
                   "add a directional light: DX,DY,DZ is the direction it travels (0,-1,0 shines "
                   "straight down), W its irradiance in W/m^2 on a surface facing it "
                   "(E = W cos theta)")
        ->default_str("none");
    app.add_option("--dynamic", dynamic,
                   "make these nodes (by name, with their subtrees) dynamic: no lightmap, not in "
                   "the static scene, moved by edits at no engine cost and lit in the viewers by "
                   "the probe volume (docs/DYNAMIC.md); repeat or comma-separate")
        ->delimiter(',');
  }

  // Marks the --dynamic nodes. Throws irradcast::Error naming a name no node has.
  void mark_dynamic(Scene& scene) const {
    for (const std::string& name : dynamic) {
      bool found = false;
      for (Node& n : scene.nodes)
        if (n.name == name) n.dynamic = found = true;
      if (!found) throw Error("--dynamic: the scene has no node named '" + name + "'");
    }
  }

  // Puts the sky and the sun into `scene`, and marks the --dynamic nodes. Throws irradcast::Error
  // naming the bad option.
  void apply(Scene& scene) {
    if (sky == "none") sky.clear();  // the defaults --help shows
    if (sun == "none") sun.clear();
    if (!std::isfinite(sky_strength) || sky_strength < 0.0f)
      throw Error("--sky-strength must be a finite number >= 0, not " +
                  std::to_string(sky_strength));
    if (!sky.empty()) {
      Sky s;
      s.strength = sky_strength;
      if (ends_with_nocase(sky, ".exr")) {
        sky_from_file = true;
        try {
          s.map = read_exr(sky, kMaxSkyWidth, kMaxSkyHeight);
        } catch (const Error& e) {
          throw Error("--sky " + sky + ": " + e.what());
        }
        s.source = sky;
      } else {
        const std::vector<float> c = parse_numbers("--sky", sky, 3, "R,G,B or FILE.exr");
        sky_color = glm::vec3(c[0], c[1], c[2]);
        s.color = sky_color;
      }
      validate_sky(s, "--sky " + sky);
      scene.sky = std::move(s);
    } else if (sky_strength != 1.0f) {
      throw Error("--sky-strength needs --sky");
    }
    if (!sun.empty()) {
      const std::vector<float> v = parse_numbers("--sun", sun, 4, "DX,DY,DZ,W");
      const glm::vec3 d(v[0], v[1], v[2]);
      const float len = glm::length(d);
      if (!(len > 0.0f) || !std::isfinite(len))
        throw Error("--sun: the direction " + sun + " has no length");
      if (v[3] < 0.0f) throw Error("--sun: the irradiance W must be >= 0, not '" + sun + "'");
      has_sun = true;
      sun_direction = d / len;
      sun_irradiance = v[3];
      add_sun(scene, sun_direction, sun_irradiance);
    }
    mark_dynamic(scene);
  }

  // One line for the log: what lights `scene` (after apply()): its emitters and lights, the sun
  // and the sky.
  std::string describe(const Scene& scene) const {
    auto num = [](float x) {
      char b[32];
      std::snprintf(b, sizeof b, "%g", static_cast<double>(x));
      return std::string(b);
    };
    auto vec = [&](glm::vec3 v) { return num(v.x) + "," + num(v.y) + "," + num(v.z); };
    std::size_t emissive = 0, lights = 0;
    for (const Material& m : scene.materials) emissive += m.is_emissive() ? 1 : 0;
    for (const Node& n : scene.nodes) lights += n.light >= 0 ? 1 : 0;
    if (has_sun) --lights;
    std::size_t dynamic_nodes = 0;
    for (const bool d : scene.dynamic_nodes()) dynamic_nodes += d ? 1 : 0;
    std::string s = std::to_string(emissive) + " emissive materials, " + std::to_string(lights) +
                    " lights from the scene, ";
    if (has_sun)
      s += "sun travelling " + vec(sun_direction) + " at " + num(sun_irradiance) + " W/m^2, ";
    if (!scene.sky.enabled())
      s += "no sky";
    else if (scene.sky.map.width > 0)
      s += "sky map " + scene.sky.source + " (" + std::to_string(scene.sky.map.width) + "x" +
           std::to_string(scene.sky.map.height) + ") x " + num(scene.sky.strength);
    else
      s += "sky " + vec(scene.sky.color) + " x " + num(scene.sky.strength);
    if (dynamic_nodes > 0) s += "; " + std::to_string(dynamic_nodes) + " dynamic nodes";
    return s;
  }
};

}  // namespace irradcast::tools

#include <cmath>
#include <string>

#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"

namespace irradcast {

namespace {

Scene build_or_load(const std::string& spec, float detail, const std::string& scene_root) {
  if (spec.empty())
    throw Error("empty scene spec (expected cornell, rooms:N, sponza or a glTF file)");
  if (spec == "cornell") return make_cornell_box();
  if (spec == "sponza") return make_sponza(scene_root);
  if (spec.rfind("rooms:", 0) == 0) {
    std::string n = spec.substr(6);
    // rooms:N, rooms:N:lit (every room lit), rooms:N:trim (and emissive trim).
    RoomsOptions o;
    if (const std::size_t colon = n.find(':'); colon != std::string::npos) {
      const std::string variant = n.substr(colon + 1);
      if (variant == "lit")
        o.every_room_lit = true;
      else if (variant == "trim")
        o.trim = true;
      else
        throw Error("scene spec '" + spec + "': after rooms:N comes :lit or :trim, not '" +
                    variant + "'");
      n = n.substr(0, colon);
    }
    int count = 0;
    try {
      std::size_t used = 0;
      count = std::stoi(n, &used);
      if (used != n.size()) throw std::invalid_argument(n);
    } catch (const std::exception&) {
      throw Error("scene spec '" + spec + "': N must be a whole number, as in rooms:4");
    }
    if (count < 1 || count > 64)
      throw Error("scene spec '" + spec + "': N must be between 1 and 64");
    if (!(detail > 0.0f) || !std::isfinite(detail) || detail > 1000.0f)
      throw Error("--detail must be a number in (0, 1000]");
    o.n = count;
    o.detail = detail;
    return make_rooms(o);
  }
  return load_gltf(spec, nullptr, scene_root);
}

}  // namespace

Scene load_scene(const std::string& spec, float detail, const std::string& scene_root) {
  Scene scene = build_or_load(spec, detail, scene_root);
  drop_degenerate_triangles(scene, spec);
  return scene;
}

}  // namespace irradcast

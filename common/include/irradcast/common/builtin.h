// Built-in scenes and the scene spec parser shared by every tool:
//   "cornell"            the Cornell box (published measurements, ceiling light, standard camera)
//   "rooms:N"            a procedural N x N building of rooms (see RoomsOptions)
//   anything else        a glTF 2.0 file (.gltf / .glb)
#pragma once

#include <cstdint>
#include <string>

#include "irradcast/common/scene.h"

namespace irradcast {

Scene make_cornell_box();

struct RoomsOptions {
  int n = 2;               // rooms per side: N x N rooms
  float detail = 1.0f;     // tessellation knob: triangle count grows ~ detail^2 (thousands at 1,
                           // millions at ~30)
  std::uint32_t seed = 1;  // furniture placement and which rooms are lit
};
// A building of N x N rooms on one floor, joined by doorways, with furniture, and an emissive
// ceiling panel in some rooms (never all, never none when N > 1). Room (i, j) is named
// "room_i_j"; lit rooms have a node "light_i_j". Deterministic for given options.
Scene make_rooms(const RoomsOptions& options);

// Parses a scene spec (see above) and loads or builds the scene; `detail` applies to rooms:N.
// A glTF file may read external files under `scene_root` only (default: its own folder; see
// load_gltf). Degenerate and non-finite triangles are dropped (drop_degenerate_triangles).
// Throws irradcast::Error on a bad spec or file.
Scene load_scene(const std::string& spec, float detail = 1.0f, const std::string& scene_root = "");

}  // namespace irradcast

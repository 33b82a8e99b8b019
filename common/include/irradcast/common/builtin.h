// Built-in scenes and the scene spec parser shared by every tool:
//   "cornell"            the Cornell box (published measurements, ceiling light, standard camera)
//   "rooms:N"            a procedural N x N building of rooms (see RoomsOptions); "rooms:N:lit"
//                        lights every room, "rooms:N:trim" adds emissive trim (many lights)
//   "sponza"             the Dabrovic Sponza of the shared sample data, with a sky and a sun
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
  bool every_room_lit = false;  // every room gets its ceiling panel (scene spec rooms:N:lit)
  bool trim = false;  // every room lit, and 8 emissive trim strips along its walls (rooms:N:trim)
};
// A building of N x N rooms on one floor, joined by doorways, with furniture, and an emissive
// ceiling panel in some rooms (never all, never none when N > 1; all with every_room_lit or trim,
// and trim adds 16 emissive triangles per room: rooms:12:trim has 3,456 emissive triangles). Room
// (i, j) is named "room_i_j"; lit rooms have a node "light_i_j". Deterministic for given options.
Scene make_rooms(const RoomsOptions& options);

// The file `relative` (e.g. "dabrovic-sponza/sponza.gltf") in the shared sample data: under
// $IRRADCAST_TESTDATA, else ../shared/testdata or shared/testdata from the current directory.
// Throws irradcast::Error naming the places tried.
std::string find_sample_data(const std::string& relative);
// The Dabrovic Sponza atrium (find_sample_data) lit as an outdoor courtyard: a constant daylight
// sky (radiance (0.25, 0.33, 0.45)), a sun (directional, 6 W/m^2, travelling along
// (0.35, -1, 0.22)) through the open roof, and a camera down the long axis.
Scene make_sponza(const std::string& scene_root = "");

// Parses a scene spec (see above) and loads or builds the scene; `detail` applies to rooms:N.
// A glTF file may read external files under `scene_root` only (default: its own folder; see
// load_gltf). Degenerate and non-finite triangles are dropped (drop_degenerate_triangles).
// Throws irradcast::Error on a bad spec or file.
Scene load_scene(const std::string& spec, float detail = 1.0f, const std::string& scene_root = "");

}  // namespace irradcast

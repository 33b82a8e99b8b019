// The procedural "rooms:N" scene: N x N rooms on one floor joined by doorways.
//
// Layout (metres, y up): room (i, j) occupies the grid cell [4i, 4i + 4] x [4j, 4j + 4] in x and
// z. Walls are 0.2 m thick boxes centred on the grid lines and run from the underside of the floor
// slab (y = -0.2) to the top of the ceiling slab (y = 3.0); the floor (top at y = 0) and the
// ceiling (underside at y = 2.8) are 0.2 m slabs filling the room's interior [0.1, 3.9]^2. Every
// part is a closed box, so the union of all boxes is watertight: light cannot pass through a wall,
// a slab or a corner. Each wall between two adjacent rooms has a 1.0 m x 2.1 m doorway centred on
// the wall (on the line joining the two room centres).
//
// Room (i, j) owns its west (x = 4i) and south (z = 4j) walls, the pillar at their corner, and
// the east / north walls and corner pillars where it is on the building's edge. Its node
// "room_i_j" (translated to the cell's corner) has children "room_i_j_walls", "_floor",
// "_ceiling", one per piece of furniture ("_couch", "_shelf", "_table") and, in lit rooms,
// "light_i_j": a thin box 1 cm below the ceiling whose underside is emissive.
//
// Lit rooms form a checkerboard whose parity is set by the seed ((i + j + seed) even is lit), so
// for N > 1 some rooms are lit and some are not and every unlit room has a lit neighbour; the
// single room of rooms:1 is always lit. Furniture is placed from a per-room random stream
// derived from the seed, outside the zones in front of the doorways and clear of the walls.
//
// Tessellation: every box face is a grid of quads with ceil(length * detail) segments along each
// edge (at least 1), i.e. quads of at most (1 / detail) m; the triangle count grows ~ detail^2.
// The segment count along an edge depends only on its length, so faces sharing a box edge share
// its vertices exactly (no cracks). Normals are flat per face, pointing out of each box.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <glm/gtc/matrix_transform.hpp>

#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"

namespace irradcast {
namespace {

constexpr float kPitch = 4.0f;      // grid line to grid line
constexpr float kHalfWall = 0.1f;   // half the wall thickness
constexpr float kInLo = kHalfWall;  // interior of a room, room-local x and z
constexpr float kInHi = kPitch - kHalfWall;
constexpr float kCentre = 0.5f * kPitch;  // room centre, room-local x and z
constexpr float kHeight = 2.8f;           // floor top to ceiling underside
constexpr float kSlab = 0.2f;             // floor and ceiling slab thickness
constexpr float kDoorHalfWidth = 0.5f;
constexpr float kDoorHeight = 2.1f;
constexpr float kDoorZoneDepth = 0.9f;  // kept free of furniture in front of a doorway
constexpr float kDoorZoneMargin = 0.1f;
constexpr float kLightHalfSize = 0.6f;
constexpr float kLightThickness = 0.03f;
constexpr float kLightGap = 0.01f;  // between the panel and the ceiling
constexpr float kLightStrength = 10.0f;
constexpr float kTrimStrength = 4.0f;
constexpr float kTrimHalfLength = 0.4f;    // emissive trim: strips along the walls, clear of the
constexpr float kTrimHalfHeight = 0.025f;  // doorways, facing into the room
constexpr float kTrimY = 0.3f;
constexpr float kTrimGap = 0.01f;        // off the wall
constexpr float kWallGap = 0.02f;        // furniture against a wall
constexpr float kTableWallGap = 0.25f;   // free-standing furniture to the walls
constexpr float kFurnitureClear = 0.1f;  // between pieces of furniture
constexpr int kPlacementAttempts = 256;

enum MaterialId : std::uint32_t {
  kWallMat,
  kFloorMat,
  kCeilingMat,
  kWoodMat,
  kFabricBlueMat,
  kFabricRedMat,
  kHousingMat,
  kLightMat,
  kTrimMat,
};

std::vector<Material> make_materials() {
  auto lambert = [](const char* name, glm::vec3 albedo) {
    Material m;
    m.name = name;
    m.base_color = albedo;
    return m;
  };
  std::vector<Material> mats;
  mats.push_back(lambert("wall", {0.72f, 0.70f, 0.66f}));
  mats.push_back(lambert("floor", {0.50f, 0.36f, 0.22f}));
  mats.push_back(lambert("ceiling", {0.78f, 0.78f, 0.76f}));
  mats.push_back(lambert("wood", {0.35f, 0.22f, 0.12f}));
  mats.push_back(lambert("fabric_blue", {0.20f, 0.30f, 0.55f}));
  mats.push_back(lambert("fabric_red", {0.60f, 0.18f, 0.15f}));
  mats.push_back(lambert("light_housing", {0.80f, 0.80f, 0.80f}));
  Material light = lambert("light", {0.80f, 0.80f, 0.80f});
  light.emissive = glm::vec3(1.0f);
  light.emissive_strength = kLightStrength;
  mats.push_back(light);
  Material trim = lambert("trim", {0.80f, 0.80f, 0.80f});
  trim.emissive = glm::vec3(1.0f, 0.85f, 0.6f);
  trim.emissive_strength = kTrimStrength;
  mats.push_back(trim);
  return mats;
}

// splitmix64: a small, portable, well-mixed generator (the standard distributions are not
// guaranteed to give the same numbers on every library, this is).
std::uint64_t mix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

class Rng {
 public:
  Rng(std::uint32_t seed, int i, int j)
      : state_(mix64(mix64(mix64(seed) ^ static_cast<std::uint64_t>(i)) ^
                     static_cast<std::uint64_t>(j))) {}
  std::uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ull;
    return mix64(state_);
  }
  float uniform() { return static_cast<float>(next() >> 40) * (1.0f / 16777216.0f); }  // [0,1)
  float range(float lo, float hi) { return lo + (hi - lo) * uniform(); }
  int below(int n) { return static_cast<int>(next() % static_cast<std::uint64_t>(n)); }

 private:
  std::uint64_t state_;
};

// Appends tessellated closed boxes to a mesh.
class BoxBuilder {
 public:
  BoxBuilder(Mesh& mesh, float detail) : mesh_(mesh), detail_(detail) {}

  // Face order: -x, +x, -y, +y, -z, +z.
  void box(glm::vec3 lo, glm::vec3 hi, const std::array<std::uint32_t, 6>& materials) {
    for (int axis = 0; axis < 3; ++axis)
      if (!(hi[axis] > lo[axis])) throw Error("rooms: internal error, an empty box was built");
    for (int axis = 0; axis < 3; ++axis)
      for (int positive = 0; positive < 2; ++positive)
        face(lo, hi, axis, positive != 0, materials[2 * axis + positive]);
  }
  void box(glm::vec3 lo, glm::vec3 hi, std::uint32_t material) {
    box(lo, hi, {material, material, material, material, material, material});
  }

 private:
  int segments(float length) const {
    double n = std::ceil(static_cast<double>(length) * detail_ - 1e-3);
    if (n > 1e6) throw Error("rooms: detail " + std::to_string(detail_) + " is too large");
    return std::max(1, static_cast<int>(n));
  }
  // Coordinate of grid line k of n along an axis; the ends are exact so that faces sharing an
  // edge share its vertices bit for bit.
  static float coord(float lo, float hi, int k, int n) {
    if (k == 0) return lo;
    if (k == n) return hi;
    return lo + (hi - lo) * (static_cast<float>(k) / static_cast<float>(n));
  }

  void face(glm::vec3 lo, glm::vec3 hi, int axis, bool positive, std::uint32_t material) {
    // (a, b) spans the face with e_a x e_b along the outward normal: counter-clockwise seen
    // from outside.
    int a = (axis + 1) % 3, b = (axis + 2) % 3;
    if (!positive) std::swap(a, b);
    glm::vec3 normal(0.0f);
    normal[axis] = positive ? 1.0f : -1.0f;
    int na = segments(hi[a] - lo[a]), nb = segments(hi[b] - lo[b]);
    std::size_t base = mesh_.positions.size();
    std::size_t count = static_cast<std::size_t>(na + 1) * static_cast<std::size_t>(nb + 1);
    if (base + count > std::numeric_limits<std::uint32_t>::max())
      throw Error("rooms: detail " + std::to_string(detail_) + " gives a mesh over 2^32 vertices");
    for (int u = 0; u <= na; ++u) {
      for (int v = 0; v <= nb; ++v) {
        glm::vec3 p(0.0f);
        p[axis] = positive ? hi[axis] : lo[axis];
        p[a] = coord(lo[a], hi[a], u, na);
        p[b] = coord(lo[b], hi[b], v, nb);
        mesh_.positions.push_back(p);
        mesh_.normals.push_back(normal);
      }
    }
    auto index = [&](int u, int v) {
      return static_cast<std::uint32_t>(base + static_cast<std::size_t>(u) * (nb + 1) + v);
    };
    for (int u = 0; u < na; ++u) {
      for (int v = 0; v < nb; ++v) {
        std::uint32_t i00 = index(u, v), i10 = index(u + 1, v);
        std::uint32_t i11 = index(u + 1, v + 1), i01 = index(u, v + 1);
        mesh_.triangles.emplace_back(i00, i10, i11);
        mesh_.triangles.emplace_back(i00, i11, i01);
        mesh_.triangle_material.push_back(material);
        mesh_.triangle_material.push_back(material);
      }
    }
  }

  Mesh& mesh_;
  double detail_;
};

// An axis-aligned footprint in a room's local x-z plane.
struct Rect {
  float x0, z0, x1, z1;
  bool overlaps(const Rect& o, float clearance) const {
    return x0 < o.x1 + clearance && o.x0 < x1 + clearance && z0 < o.z1 + clearance &&
           o.z0 < z1 + clearance;
  }
};

enum Side { kWest, kEast, kSouth, kNorth };  // -x, +x, -z, +z

struct RoomInfo {
  int i = 0, j = 0;
  std::array<bool, 4> door{};  // doorway on each side
};

Rect door_zone(Side side) {
  const float h = kDoorHalfWidth + kDoorZoneMargin;
  switch (side) {
    case kWest:
      return {kInLo, kCentre - h, kInLo + kDoorZoneDepth, kCentre + h};
    case kEast:
      return {kInHi - kDoorZoneDepth, kCentre - h, kInHi, kCentre + h};
    case kSouth:
      return {kCentre - h, kInLo, kCentre + h, kInLo + kDoorZoneDepth};
    case kNorth:
      return {kCentre - h, kInHi - kDoorZoneDepth, kCentre + h, kInHi};
  }
  return {};
}

// Rotation about +y by a multiple of 90 degrees (exact) followed by a translation.
glm::mat4 placement(float cos_a, float sin_a, glm::vec3 t) {
  glm::mat4 m(1.0f);
  m[0] = glm::vec4(cos_a, 0.0f, -sin_a, 0.0f);
  m[2] = glm::vec4(sin_a, 0.0f, cos_a, 0.0f);
  m[3] = glm::vec4(t, 1.0f);
  return m;
}

// A piece built with its back on local z = 0, facing +z, spanning x in [0, width], placed
// against the wall on `side` starting at `t` along that wall.
std::pair<Rect, glm::mat4> against_wall(Side side, float t, float width, float depth) {
  const float lo = kInLo + kWallGap, hi = kInHi - kWallGap;
  switch (side) {
    case kSouth:
      return {{t, lo, t + width, lo + depth}, placement(1.0f, 0.0f, {t, 0.0f, lo})};
    case kNorth:
      return {{t, hi - depth, t + width, hi}, placement(-1.0f, 0.0f, {t + width, 0.0f, hi})};
    case kWest:
      return {{lo, t, lo + depth, t + width}, placement(0.0f, 1.0f, {lo, 0.0f, t + width})};
    case kEast:
      return {{hi - depth, t, hi, t + width}, placement(0.0f, -1.0f, {hi, 0.0f, t})};
  }
  return {};
}

bool is_free(const Rect& r, const std::vector<Rect>& doors, const std::vector<Rect>& furniture) {
  for (const Rect& d : doors)
    if (r.overlaps(d, 0.0f)) return false;
  for (const Rect& f : furniture)
    if (r.overlaps(f, kFurnitureClear)) return false;
  return true;
}

struct Piece {
  std::string name;
  glm::mat4 local{1.0f};
  Mesh mesh;
};

void build_couch(BoxBuilder& b, float length, std::uint32_t fabric) {
  const float arm = 0.15f, back = 0.2f, depth = 0.85f;
  b.box({0.0f, 0.0f, 0.0f}, {length, 0.85f, back}, fabric);          // backrest
  b.box({0.0f, 0.0f, back}, {arm, 0.6f, depth}, fabric);             // arms
  b.box({length - arm, 0.0f, back}, {length, 0.6f, depth}, fabric);  //
  b.box({arm, 0.0f, back}, {length - arm, 0.42f, depth}, fabric);    // seat
}

void build_shelf(BoxBuilder& b, float width, float height, float depth, int boards) {
  const float panel = 0.03f, back = 0.02f;
  b.box({0.0f, 0.0f, 0.0f}, {width, height, back}, kWoodMat);
  b.box({0.0f, 0.0f, back}, {panel, height, depth}, kWoodMat);
  b.box({width - panel, 0.0f, back}, {width, height, depth}, kWoodMat);
  for (int k = 0; k < boards; ++k) {
    float y = (height - panel) * static_cast<float>(k) / static_cast<float>(boards - 1);
    b.box({panel, y, back}, {width - panel, y + panel, depth}, kWoodMat);
  }
}

void build_table(BoxBuilder& b, float wx, float wz) {
  const float height = 0.75f, top = 0.04f, leg = 0.06f, inset = 0.05f;
  b.box({0.0f, height - top, 0.0f}, {wx, height, wz}, kWoodMat);
  for (int cx = 0; cx < 2; ++cx) {
    for (int cz = 0; cz < 2; ++cz) {
      float x0 = cx == 0 ? inset : wx - inset - leg;
      float z0 = cz == 0 ? inset : wz - inset - leg;
      b.box({x0, 0.0f, z0}, {x0 + leg, height - top, z0 + leg}, kWoodMat);
    }
  }
}

std::vector<Piece> furnish(const RoomInfo& room, std::uint32_t seed, float detail) {
  Rng rng(seed, room.i, room.j);
  std::vector<Rect> doors;
  for (int s = 0; s < 4; ++s)
    if (room.door[s]) doors.push_back(door_zone(static_cast<Side>(s)));
  std::vector<Rect> placed;
  std::vector<Piece> pieces;
  const std::string prefix = "room_" + std::to_string(room.i) + "_" + std::to_string(room.j);
  // The size range narrows to its minimum over the attempts so that crowded rooms still get one.
  auto shrink = [](int attempt, float lo, float hi) {
    float f = std::min(1.0f, static_cast<float>(attempt) / (0.5f * kPlacementAttempts));
    return hi - (hi - lo) * f;
  };

  // A piece `length` along a wall drawn now and `depth` deep, made by build(b), at a random
  // spot along it; false (nothing placed) when the spot is not free.
  auto place_against_wall = [&](const char* name, float length, float depth, auto build) {
    Side side = static_cast<Side>(rng.below(4));
    float t = rng.range(kInLo + kWallGap, kInHi - kWallGap - length);
    auto [rect, local] = against_wall(side, t, length, depth);
    if (!is_free(rect, doors, placed)) return false;
    placed.push_back(rect);
    Piece p{prefix + name, local, {}};
    BoxBuilder b(p.mesh, detail);
    build(b);
    pieces.push_back(std::move(p));
    return true;
  };
  // Couch against a wall.
  std::uint32_t fabric = rng.below(2) == 0 ? kFabricBlueMat : kFabricRedMat;
  for (int attempt = 0; attempt < kPlacementAttempts; ++attempt) {
    float length = rng.range(1.2f, shrink(attempt, 1.2f, 1.9f));
    if (place_against_wall("_couch", length, 0.85f,
                           [&](BoxBuilder& b) { build_couch(b, length, fabric); }))
      break;
  }
  // Shelf against a wall.
  for (int attempt = 0; attempt < kPlacementAttempts; ++attempt) {
    float width = rng.range(0.7f, shrink(attempt, 0.7f, 1.2f));
    float height = rng.range(1.5f, 2.0f);
    int boards = 3 + rng.below(3);
    if (place_against_wall("_shelf", width, 0.35f,
                           [&](BoxBuilder& b) { build_shelf(b, width, height, 0.35f, boards); }))
      break;
  }
  // Free-standing table, axis aligned either way round.
  for (int attempt = 0; attempt < kPlacementAttempts; ++attempt) {
    float wx = rng.range(0.8f, shrink(attempt, 0.8f, 1.4f));
    float wz = rng.range(0.6f, 0.9f);
    if (rng.below(2) == 1) std::swap(wx, wz);
    float x0 = rng.range(kInLo + kTableWallGap, kInHi - kTableWallGap - wx);
    float z0 = rng.range(kInLo + kTableWallGap, kInHi - kTableWallGap - wz);
    Rect rect{x0, z0, x0 + wx, z0 + wz};
    if (!is_free(rect, doors, placed)) continue;
    placed.push_back(rect);
    Piece p{prefix + "_table", placement(1.0f, 0.0f, {x0, 0.0f, z0}), {}};
    BoxBuilder b(p.mesh, detail);
    build_table(b, wx, wz);
    pieces.push_back(std::move(p));
    break;
  }
  return pieces;
}

// The walls a room owns (see the file comment), in room-local coordinates.
Mesh build_walls(int i, int j, int n, float detail) {
  Mesh mesh;
  BoxBuilder b(mesh, detail);
  const float y0 = -kSlab, y1 = kHeight + kSlab;
  // A wall along z (x across) or along x (z across), optionally with a centred doorway.
  auto wall = [&](bool along_z, float across, bool door) {
    auto add = [&](float lo, float hi, float ylo, float yhi) {
      if (along_z)
        b.box({across - kHalfWall, ylo, lo}, {across + kHalfWall, yhi, hi}, kWallMat);
      else
        b.box({lo, ylo, across - kHalfWall}, {hi, yhi, across + kHalfWall}, kWallMat);
    };
    if (!door) {
      add(kInLo, kInHi, y0, y1);
      return;
    }
    const float d0 = kCentre - kDoorHalfWidth, d1 = kCentre + kDoorHalfWidth;
    add(kInLo, d0, y0, y1);
    add(d1, kInHi, y0, y1);
    add(d0, d1, y0, 0.0f);         // sill, flush with the floor
    add(d0, d1, kDoorHeight, y1);  // lintel
  };
  auto pillar = [&](float x, float z) {
    b.box({x - kHalfWall, y0, z - kHalfWall}, {x + kHalfWall, y1, z + kHalfWall}, kWallMat);
  };
  wall(true, 0.0f, i > 0);
  wall(false, 0.0f, j > 0);
  pillar(0.0f, 0.0f);
  if (i == n - 1) {
    wall(true, kPitch, false);
    pillar(kPitch, 0.0f);
  }
  if (j == n - 1) {
    wall(false, kPitch, false);
    pillar(0.0f, kPitch);
  }
  if (i == n - 1 && j == n - 1) pillar(kPitch, kPitch);
  return mesh;
}

Mesh slab(float y0, float y1, std::uint32_t material, float detail) {
  Mesh mesh;
  BoxBuilder b(mesh, detail);
  b.box({kInLo, y0, kInLo}, {kInHi, y1, kInHi}, material);
  return mesh;
}

Mesh light_panel(float detail) {
  Mesh mesh;
  BoxBuilder b(mesh, detail);
  // Only the underside emits; the rest is the panel's housing.
  std::array<std::uint32_t, 6> mats{kHousingMat, kHousingMat, kLightMat,
                                    kHousingMat, kHousingMat, kHousingMat};
  b.box({-kLightHalfSize, -kLightThickness, -kLightHalfSize},
        {kLightHalfSize, 0.0f, kLightHalfSize}, mats);
  return mesh;
}

// The emissive trim of a room: on each wall two strips (one quad each, emitting into the room),
// centred 0.8 m from the corners, clear of the doorway in the wall's middle.
Mesh trim_strips() {
  Mesh mesh;
  const glm::vec3 up(0.0f, 1.0f, 0.0f);
  auto strip = [&](glm::vec3 c, glm::vec3 n) {
    const glm::vec3 t = glm::cross(up, n);  // t x up = n: counter-clockwise seen from n
    const glm::vec3 a = t * kTrimHalfLength, b = up * kTrimHalfHeight;
    const auto first = static_cast<std::uint32_t>(mesh.positions.size());
    mesh.positions.insert(mesh.positions.end(), {c - a - b, c + a - b, c + a + b, c - a + b});
    mesh.normals.insert(mesh.normals.end(), {n, n, n, n});
    mesh.uv0.insert(mesh.uv0.end(), {{0, 0}, {1, 0}, {1, 1}, {0, 1}});
    mesh.triangles.push_back({first, first + 1, first + 2});
    mesh.triangles.push_back({first, first + 2, first + 3});
    mesh.triangle_material.insert(mesh.triangle_material.end(), {kTrimMat, kTrimMat});
  };
  const float lo = kInLo + kTrimGap, hi = kInHi - kTrimGap;
  for (float along : {kInLo + 0.8f, kInHi - 0.8f}) {
    strip({lo, kTrimY, along}, {1.0f, 0.0f, 0.0f});
    strip({hi, kTrimY, along}, {-1.0f, 0.0f, 0.0f});
    strip({along, kTrimY, lo}, {0.0f, 0.0f, 1.0f});
    strip({along, kTrimY, hi}, {0.0f, 0.0f, -1.0f});
  }
  return mesh;
}

glm::mat4 translation(glm::vec3 t) {
  return glm::translate(glm::mat4(1.0f), t);
}

int add_mesh_node(Scene& scene, std::string name, int parent, glm::mat4 local, Mesh mesh) {
  mesh.name = name;
  Node node;
  node.name = std::move(name);
  node.parent = parent;
  node.local = local;
  node.mesh = static_cast<int>(scene.meshes.size());
  scene.meshes.push_back(std::move(mesh));
  return scene.add_node(std::move(node));
}

}  // namespace

Scene make_rooms(const RoomsOptions& options) {
  const int n = options.n;
  const float detail = options.detail;
  if (n < 1 || n > 1000)
    throw Error("rooms: the number of rooms per side must be in 1..1000, not " + std::to_string(n));
  if (!std::isfinite(detail) || !(detail > 0.0f))
    throw Error("rooms: detail must be a positive number, not " + std::to_string(detail));

  Scene scene;
  scene.name = "rooms:" + std::to_string(n);
  scene.materials = make_materials();
  auto lit = [&](int i, int j) {
    return n == 1 || options.every_room_lit || options.trim ||
           (static_cast<std::uint32_t>(i + j) + options.seed % 2u) % 2u == 0u;
  };

  Node building;
  building.name = "building";
  const int root = scene.add_node(std::move(building));
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const std::string id = std::to_string(i) + "_" + std::to_string(j);
      const std::string name = "room_" + id;
      Node room;
      room.name = name;
      room.parent = root;
      room.local =
          translation({kPitch * static_cast<float>(i), 0.0f, kPitch * static_cast<float>(j)});
      const int node = scene.add_node(std::move(room));

      add_mesh_node(scene, name + "_walls", node, glm::mat4(1.0f), build_walls(i, j, n, detail));
      add_mesh_node(scene, name + "_floor", node, glm::mat4(1.0f),
                    slab(-kSlab, 0.0f, kFloorMat, detail));
      add_mesh_node(scene, name + "_ceiling", node, glm::mat4(1.0f),
                    slab(kHeight, kHeight + kSlab, kCeilingMat, detail));
      RoomInfo info;
      info.i = i;
      info.j = j;
      info.door = {i > 0, i<n - 1, j> 0, j < n - 1};
      for (Piece& p : furnish(info, options.seed, detail))
        add_mesh_node(scene, p.name, node, p.local, std::move(p.mesh));
      if (lit(i, j))
        add_mesh_node(scene, "light_" + id, node,
                      translation({kCentre, kHeight - kLightGap, kCentre}), light_panel(detail));
      if (options.trim) add_mesh_node(scene, "trim_" + id, node, glm::mat4(1.0f), trim_strips());
    }
  }

  // Default camera: in the first lit room that has a neighbour in +x, near its west wall at eye
  // height, looking through the east doorway at the neighbour's centre. rooms:1 gets a view from
  // one corner to the opposite one.
  glm::vec3 eye, target;
  if (n == 1) {
    eye = {kInLo + 0.6f, 1.6f, kInLo + 0.6f};
    target = {kInHi - 0.5f, 0.6f, kInHi - 0.5f};
  } else {
    int ci = 0, cj = 0;
    for (int j = 0; j < n; ++j) {
      if (lit(0, j)) {
        cj = j;
        break;
      }
    }
    glm::vec3 origin(kPitch * static_cast<float>(ci), 0.0f, kPitch * static_cast<float>(cj));
    eye = origin + glm::vec3(kInLo + 0.6f, 1.6f, kCentre - 0.7f);
    target = origin + glm::vec3(kPitch + kCentre, 1.0f, kCentre);
  }
  Camera camera;
  camera.name = "camera";
  camera.yfov = 1.0f;
  camera.znear = 0.05f;
  scene.cameras.push_back(camera);
  Node cam;
  cam.name = "camera";
  cam.camera = 0;
  cam.local = glm::inverse(glm::lookAt(eye, target, glm::vec3(0.0f, 1.0f, 0.0f)));
  scene.add_node(std::move(cam));
  return scene;
}

}  // namespace irradcast

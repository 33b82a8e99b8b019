// Tests of the procedural rooms:N scene: structure, tessellation, mesh validity, lighting, and
// the geometry that matters for light transport (doorways open, walls and the shell closed),
// checked with a brute-force segment-triangle intersection independent of the ray tracers.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/world.h"

namespace irradcast::test_builtin_rooms {

namespace {

constexpr float kPitch = 4.0f;  // room grid spacing the tests rely on (room centre at 4i + 2)

Scene rooms(int n, float detail = 1.0f, std::uint32_t seed = 1) {
  RoomsOptions o;
  o.n = n;
  o.detail = detail;
  o.seed = seed;
  return make_rooms(o);
}

glm::vec3 room_centre(int i, int j, float y) {
  return {kPitch * static_cast<float>(i) + 0.5f * kPitch, y,
          kPitch * static_cast<float>(j) + 0.5f * kPitch};
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

struct Hit {
  float t = 0.0f;  // fraction of the segment
  int object = -1;
};

// First intersection of segment p -> q with any triangle of the objects accepted by `keep`.
// Slightly inclusive at triangle edges so that a segment grazing a shared edge counts as a hit
// (conservative for the "passes through nothing" checks).
template <class Keep>
std::optional<Hit> first_hit(const World& world, glm::vec3 p, glm::vec3 q, Keep keep) {
  const glm::dvec3 o(p), d = glm::dvec3(q) - glm::dvec3(p);
  std::optional<Hit> best;
  for (const WorldObject& obj : world.objects) {
    if (!keep(obj)) continue;
    for (const glm::uvec3& tri : obj.triangles()) {
      glm::dvec3 v0(obj.positions[tri.x]), v1(obj.positions[tri.y]), v2(obj.positions[tri.z]);
      glm::dvec3 e1 = v1 - v0, e2 = v2 - v0;
      glm::dvec3 pv = glm::cross(d, e2);
      double det = glm::dot(e1, pv);
      if (std::abs(det) < 1e-14) continue;
      double inv = 1.0 / det;
      glm::dvec3 tv = o - v0;
      double u = glm::dot(tv, pv) * inv;
      if (u < -1e-7 || u > 1.0 + 1e-7) continue;
      glm::dvec3 qv = glm::cross(tv, e1);
      double v = glm::dot(d, qv) * inv;
      if (v < -1e-7 || u + v > 1.0 + 1e-7) continue;
      double t = glm::dot(e2, qv) * inv;
      if (t < 0.0 || t > 1.0) continue;
      if (!best || t < best->t) best = Hit{static_cast<float>(t), obj.object};
    }
  }
  return best;
}

std::optional<Hit> first_hit(const World& world, glm::vec3 p, glm::vec3 q) {
  return first_hit(world, p, q, [](const WorldObject&) { return true; });
}

const std::string& object_name(const World& world, int object) {
  return world.scene->nodes[world.objects[object].node].name;
}

int find_node(const Scene& s, const std::string& name) {
  for (int i = 0; i < static_cast<int>(s.nodes.size()); ++i)
    if (s.nodes[i].name == name) return i;
  return -1;
}

int count_prefix(const Scene& s, const std::string& prefix) {
  int c = 0;
  for (const Node& n : s.nodes)
    if (n.name.rfind(prefix, 0) == 0) ++c;
  return c;
}

}  // namespace

TEST(Rooms, NamesRoomsAndCamera) {
  for (int n : {1, 3}) {
    Scene s = rooms(n);
    EXPECT_EQ(s.name, "rooms:" + std::to_string(n));
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        std::string name = "room_" + std::to_string(i) + "_" + std::to_string(j);
        int node = find_node(s, name);
        ASSERT_GE(node, 0) << name;
        // The room's node is placed at its grid cell and carries its geometry as children.
        glm::vec3 t(s.nodes[node].local[3]);
        EXPECT_FLOAT_EQ(t.x, kPitch * i);
        EXPECT_FLOAT_EQ(t.z, kPitch * j);
        EXPECT_GE(s.nodes[node].children.size(), 3u) << name;
        for (const char* part : {"_walls", "_floor", "_ceiling"})
          EXPECT_GE(find_node(s, name + part), 0) << name << part;
      }
    }
    EXPECT_GT(count_prefix(s, "light_"), 0);
    std::set<std::string> names;
    for (const Node& node : s.nodes)
      if (node.mesh >= 0) {
        EXPECT_TRUE(names.insert(node.name).second) << node.name;
      }
    // Objects per room stay a handful: no giant all-building object.
    EXPECT_LE(s.objects().size(), static_cast<std::size_t>(n * n * 8));
    EXPECT_GE(s.objects().size(), static_cast<std::size_t>(n * n * 3));
    ASSERT_GE(s.first_camera_node(), 0);
  }
}

TEST(Rooms, RejectsBadOptions) {
  EXPECT_THROW(rooms(0), Error);
  EXPECT_THROW(rooms(-2), Error);
  EXPECT_THROW(rooms(2, 0.0f), Error);
  EXPECT_THROW(rooms(2, -1.0f), Error);
  EXPECT_THROW(rooms(2, std::nanf("")), Error);
}

TEST(Rooms, TriangleCountGrowsWithN) {
  std::size_t prev = 0;
  std::vector<std::size_t> counts;
  for (int n = 1; n <= 5; ++n) {
    std::size_t c = rooms(n).triangle_count();
    EXPECT_GT(c, prev) << "n=" << n;
    prev = c;
    counts.push_back(c);
  }
  // About proportional to the number of rooms.
  double ratio = static_cast<double>(counts[3]) / static_cast<double>(counts[1]);  // 16 vs 4
  EXPECT_GT(ratio, 3.0);
  EXPECT_LT(ratio, 5.0);
  // rooms:2 at detail 1 is a scene of a few thousand triangles.
  EXPECT_GT(counts[1], 1000u);
  EXPECT_LT(counts[1], 10000u);
}

TEST(Rooms, TriangleCountGrowsWithDetailSquared) {
  std::size_t c1 = rooms(2, 1.0f).triangle_count();
  std::size_t c2 = rooms(2, 2.0f).triangle_count();
  std::size_t c4 = rooms(2, 4.0f).triangle_count();
  std::size_t c8 = rooms(2, 8.0f).triangle_count();
  EXPECT_GT(c2, c1);
  EXPECT_GT(c4, c2);
  double r84 = static_cast<double>(c8) / static_cast<double>(c4);
  double r42 = static_cast<double>(c4) / static_cast<double>(c2);
  EXPECT_GT(r42, 2.5);
  EXPECT_LT(r42, 5.0);
  EXPECT_GT(r84, 3.0);
  EXPECT_LT(r84, 5.0);
  // Fractional detail works and sits in between.
  std::size_t c15 = rooms(2, 1.5f).triangle_count();
  EXPECT_GT(c15, c1);
  EXPECT_LT(c15, c2);
}

TEST(Rooms, TrianglesAreValidAndNonDegenerate) {
  for (float detail : {0.3f, 1.0f, 2.5f}) {
    Scene s = rooms(3, detail, 7);
    World w = World::build(s);
    for (const WorldObject& o : w.objects) {
      const Mesh& m = *o.source;
      ASSERT_FALSE(m.triangles.empty()) << m.name;
      ASSERT_EQ(m.triangle_material.size(), m.triangles.size()) << m.name;
      ASSERT_EQ(m.normals.size(), m.positions.size()) << m.name;
      for (const glm::vec3& p : o.positions)
        ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) << m.name;
      for (std::uint32_t t = 0; t < m.triangles.size(); ++t) {
        const glm::uvec3& tri = m.triangles[t];
        ASSERT_LT(tri.x, m.positions.size());
        ASSERT_LT(tri.y, m.positions.size());
        ASSERT_LT(tri.z, m.positions.size());
        ASSERT_LT(m.triangle_material[t], s.materials.size());
        // Area above a small floor and no sliver: the smallest quads are ~1 cm panels.
        glm::vec3 a = o.positions[tri.x], b = o.positions[tri.y], c = o.positions[tri.z];
        float area = o.area(t);
        float longest = std::max({glm::length(b - a), glm::length(c - b), glm::length(a - c)});
        ASSERT_GT(area, 1e-6f) << m.name << " triangle " << t;
        ASSERT_GT(2.0f * area / (longest * longest), 1e-3f) << m.name << " triangle " << t;
      }
    }
  }
}

TEST(Rooms, NormalsAreUnitAndMatchWinding) {
  Scene s = rooms(2, 2.0f, 3);
  World w = World::build(s);
  for (const WorldObject& o : w.objects) {
    const Mesh& m = *o.source;
    for (const glm::vec3& n : m.normals) ASSERT_NEAR(glm::length(n), 1.0f, 1e-5f) << m.name;
    for (std::uint32_t t = 0; t < m.triangles.size(); ++t) {
      glm::vec3 ng = o.geometric_normal(t);
      const glm::uvec3& tri = m.triangles[t];
      for (std::uint32_t v : {tri.x, tri.y, tri.z})
        ASSERT_GT(glm::dot(o.normals[v], ng), 0.9999f) << m.name << " triangle " << t;
    }
  }
}

// Every mesh is a union of closed, outward-oriented boxes: each directed edge is matched by its
// reverse (watertight and consistently wound) and the enclosed signed volume is positive.
TEST(Rooms, MeshesAreClosedAndOutwardFacing) {
  Scene s = rooms(2, 1.7f, 5);
  for (const Mesh& m : s.meshes) {
    std::map<std::array<float, 6>, int> edges;
    double volume = 0.0;
    for (const glm::uvec3& tri : m.triangles) {
      std::array<glm::vec3, 3> p{m.positions[tri.x], m.positions[tri.y], m.positions[tri.z]};
      for (int k = 0; k < 3; ++k) {
        glm::vec3 a = p[k], b = p[(k + 1) % 3];
        edges[{a.x, a.y, a.z, b.x, b.y, b.z}] += 1;
        edges[{b.x, b.y, b.z, a.x, a.y, a.z}] -= 1;
      }
      volume += glm::dot(glm::dvec3(p[0]), glm::cross(glm::dvec3(p[1]), glm::dvec3(p[2]))) / 6.0;
    }
    for (const auto& [edge, balance] : edges)
      ASSERT_EQ(balance, 0) << m.name << " has an open or inconsistently wound edge";
    EXPECT_GT(volume, 0.0) << m.name;
  }
  // The floor slab: 3.8 m x 3.8 m x 0.2 m, its visible top at y = 0 facing up.
  const Mesh& floor = s.meshes[s.nodes[find_node(s, "room_0_0_floor")].mesh];
  double volume = 0.0;
  int up = 0;
  for (const glm::uvec3& tri : floor.triangles) {
    glm::dvec3 a(floor.positions[tri.x]), b(floor.positions[tri.y]), c(floor.positions[tri.z]);
    volume += glm::dot(a, glm::cross(b, c)) / 6.0;
    if (a.y == 0.0 && b.y == 0.0 && c.y == 0.0) {
      EXPECT_GT(glm::normalize(glm::cross(b - a, c - a)).y, 0.999);
      ++up;
    }
  }
  EXPECT_NEAR(volume, 3.8 * 3.8 * 0.2, 1e-3);
  EXPECT_GT(up, 0);
}

TEST(Rooms, SomeButNotAllRoomsAreLit) {
  for (int n = 1; n <= 5; ++n) {
    for (std::uint32_t seed : {1u, 2u, 3u, 10u}) {
      Scene s = rooms(n, 1.0f, seed);
      World w = World::build(s);
      int lights = 0;
      std::set<int> lit_rooms;  // room nodes holding emissive triangles
      for (const WorldObject& o : w.objects) {
        const std::string& name = object_name(w, o.object);
        bool is_light = name.rfind("light_", 0) == 0;
        int emissive = 0;
        for (std::uint32_t t = 0; t < o.source->triangles.size(); ++t) {
          const Material& mat = w.material(o.object, t);
          if (!mat.is_emissive()) continue;
          ++emissive;
          // Emitters face down, into the room, with a radiance that lights a room well.
          EXPECT_LT(o.geometric_normal(t).y, -0.999f) << name;
          EXPECT_GE(mat.emission().x, 5.0f);
          EXPECT_LE(mat.emission().x, 100.0f);
        }
        EXPECT_EQ(emissive > 0, is_light) << name;
        if (!is_light) continue;
        ++lights;
        // light_i_j hangs under room_i_j, just below its ceiling.
        int parent = s.nodes[o.node].parent;
        ASSERT_GE(parent, 0);
        EXPECT_EQ("room_" + name.substr(6), s.nodes[parent].name);
        lit_rooms.insert(parent);
        glm::vec3 centre(s.world_matrices()[o.node][3]);
        EXPECT_NEAR(centre.y, 2.8f, 0.05f);
      }
      EXPECT_EQ(static_cast<int>(lit_rooms.size()), lights);
      if (n == 1) {
        EXPECT_EQ(lights, 1) << "seed " << seed;
      } else {
        EXPECT_GE(lights, 1) << "n=" << n << " seed " << seed;
        EXPECT_LE(lights, n * n - 1) << "n=" << n << " seed " << seed;
      }
    }
  }
}

TEST(Rooms, DoorwaysConnectAdjacentRooms) {
  const int n = 3;
  for (std::uint32_t seed : {1u, 2u, 9u}) {
    Scene s = rooms(n, 1.3f, seed);
    World w = World::build(s);
    auto walls = [&](const WorldObject& o) {
      return ends_with(object_name(w, o.object), "_walls");
    };
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        for (int axis = 0; axis < 2; ++axis) {
          int i2 = i + (axis == 0), j2 = j + (axis == 1);
          if (i2 >= n || j2 >= n) continue;
          SCOPED_TRACE("rooms " + std::to_string(i) + "," + std::to_string(j) + " -> " +
                       std::to_string(i2) + "," + std::to_string(j2) + " seed " +
                       std::to_string(seed));
          glm::vec3 side = axis == 0 ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0);
          glm::vec3 a = room_centre(i, j, 1.0f), b = room_centre(i2, j2, 1.0f);
          // Through the doorway at 1 m: nothing at all in the way (no wall, no furniture).
          EXPECT_FALSE(first_hit(w, a, b).has_value());
          // Also 0.4 m to either side of the centre line, and just above the floor.
          for (float off : {-0.4f, 0.4f})
            EXPECT_FALSE(first_hit(w, a + off * side, b + off * side, walls).has_value());
          glm::vec3 low(0.0f, -0.95f, 0.0f);
          EXPECT_FALSE(first_hit(w, a + low, b + low, walls).has_value());
          // Above the doorway (2.5 m) the wall blocks, at the wall between the rooms.
          glm::vec3 high(0.0f, 1.5f, 0.0f);
          auto hit = first_hit(w, a + high, b + high);
          ASSERT_TRUE(hit.has_value());
          EXPECT_TRUE(ends_with(object_name(w, hit->object), "_walls"));
          EXPECT_NEAR(hit->t, 0.5f, 0.1f / kPitch + 1e-4f);  // the near face of the wall
        }
      }
    }
  }
}

TEST(Rooms, WallsBlockOutsideDoorways) {
  const int n = 2;
  Scene s = rooms(n, 1.0f, 4);
  World w = World::build(s);
  auto walls = [&](const WorldObject& o) { return ends_with(object_name(w, o.object), "_walls"); };
  for (int axis = 0; axis < 2; ++axis) {
    glm::vec3 side = axis == 0 ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0);
    glm::vec3 a = room_centre(0, 0, 1.0f);
    glm::vec3 b = axis == 0 ? room_centre(1, 0, 1.0f) : room_centre(0, 1, 1.0f);
    // Beside the doorway (0.6 m and more off the centre line, door 1 m wide) the wall blocks,
    // at every height from the floor to the ceiling.
    for (float off : {-1.5f, -0.6f, 0.6f, 1.2f}) {
      for (float y : {0.05f, 1.0f, 2.0f, 2.75f}) {
        glm::vec3 lift(0.0f, y - 1.0f, 0.0f);
        auto hit = first_hit(w, a + off * side + lift, b + off * side + lift, walls);
        ASSERT_TRUE(hit.has_value()) << "axis " << axis << " offset " << off << " y " << y;
        EXPECT_NEAR(hit->t, 0.5f, 0.1f / kPitch + 1e-4f);
      }
    }
  }
}

TEST(Rooms, BuildingIsClosed) {
  for (int n : {1, 2, 3}) {
    Scene s = rooms(n, 1.0f, static_cast<std::uint32_t>(n));
    World w = World::build(s);
    const float far = 1000.0f;
    // From inside every room, in every direction (including through doorways and up / down),
    // a long segment ends on geometry: no gap lets light in or out of the building.
    const int kDirections = 96;
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        for (float y : {0.3f, 1.4f, 2.6f}) {
          glm::vec3 c = room_centre(i, j, y) + glm::vec3(0.31f, 0.0f, -0.17f);
          for (int k = 0; k < kDirections; ++k) {
            // Fibonacci sphere plus the six axis directions (grazing the slabs and walls).
            glm::vec3 d;
            if (k < 6) {
              d = glm::vec3(0.0f);
              d[k / 2] = k % 2 ? 1.0f : -1.0f;
            } else {
              float z = 1.0f - 2.0f * (static_cast<float>(k) + 0.5f) / kDirections;
              float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
              float phi = 2.39996323f * static_cast<float>(k);
              d = glm::vec3(r * std::cos(phi), z, r * std::sin(phi));
            }
            ASSERT_TRUE(first_hit(w, c, c + far * d).has_value())
                << "rooms:" << n << " room " << i << "," << j << " direction " << k;
          }
        }
      }
    }
    // The shell is the scene: its bounds are the grid plus half a wall, floor to ceiling slab.
    EXPECT_NEAR(w.bounds.lo.x, -0.1f, 1e-4f);
    EXPECT_NEAR(w.bounds.hi.x, kPitch * n + 0.1f, 1e-4f);
    EXPECT_NEAR(w.bounds.lo.y, -0.2f, 1e-4f);
    EXPECT_NEAR(w.bounds.hi.y, 3.0f, 1e-4f);
  }
}

TEST(Rooms, FurnitureStaysInsideItsRoomAndOutOfDoorways) {
  const int n = 4;
  int pieces = 0, rooms_with_furniture = 0;
  for (std::uint32_t seed : {1u, 2u, 3u, 4u, 5u}) {
    Scene s = rooms(n, 1.0f, seed);
    World w = World::build(s);
    std::set<std::string> furnished;
    for (const WorldObject& o : w.objects) {
      const std::string& name = object_name(w, o.object);
      if (!(ends_with(name, "_table") || ends_with(name, "_shelf") || ends_with(name, "_couch")))
        continue;
      ++pieces;
      int i = -1, j = -1;
      ASSERT_EQ(std::sscanf(name.c_str(), "room_%d_%d_", &i, &j), 2) << name;
      furnished.insert(name.substr(0, name.rfind('_')));
      Bounds b;
      for (const glm::vec3& p : o.positions) b.extend(p);
      glm::vec3 lo = glm::vec3(kPitch * i, 0.0f, kPitch * j);
      // Inside the room's interior (walls are 0.1 m either side of the grid line).
      EXPECT_GE(b.lo.x, lo.x + 0.1f) << name;
      EXPECT_GE(b.lo.z, lo.z + 0.1f) << name;
      EXPECT_LE(b.hi.x, lo.x + kPitch - 0.1f) << name;
      EXPECT_LE(b.hi.z, lo.z + kPitch - 0.1f) << name;
      EXPECT_GE(b.lo.y, -1e-5f) << name;
      EXPECT_LE(b.hi.y, 2.1f) << name;
      // Not in front of a doorway: 0.5 m deep, door width, on each side with a neighbour.
      float c = 0.5f * kPitch;
      std::vector<Bounds> zones;
      auto zone = [&](float x0, float z0, float x1, float z1) {
        Bounds z;
        z.extend(lo + glm::vec3(x0, 0.0f, z0));
        z.extend(lo + glm::vec3(x1, 2.1f, z1));
        zones.push_back(z);
      };
      if (i > 0) zone(0.1f, c - 0.5f, 0.6f, c + 0.5f);
      if (i < n - 1) zone(kPitch - 0.6f, c - 0.5f, kPitch - 0.1f, c + 0.5f);
      if (j > 0) zone(c - 0.5f, 0.1f, c + 0.5f, 0.6f);
      if (j < n - 1) zone(c - 0.5f, kPitch - 0.6f, c + 0.5f, kPitch - 0.1f);
      for (const Bounds& z : zones) {
        bool overlap = b.lo.x < z.hi.x && z.lo.x < b.hi.x && b.lo.z < z.hi.z && z.lo.z < b.hi.z;
        EXPECT_FALSE(overlap) << name << " blocks a doorway";
      }
    }
    rooms_with_furniture += static_cast<int>(furnished.size());
  }
  // Furniture is the norm: nearly every room has all three pieces.
  EXPECT_EQ(rooms_with_furniture, 5 * n * n);
  EXPECT_GE(pieces, 5 * n * n * 3 * 9 / 10);
}

TEST(Rooms, DeterministicForTheSameSeed) {
  auto same = [](const Scene& a, const Scene& b) {
    if (a.nodes.size() != b.nodes.size() || a.meshes.size() != b.meshes.size()) return false;
    for (std::size_t k = 0; k < a.nodes.size(); ++k)
      if (a.nodes[k].name != b.nodes[k].name || a.nodes[k].local != b.nodes[k].local ||
          a.nodes[k].mesh != b.nodes[k].mesh)
        return false;
    for (std::size_t k = 0; k < a.meshes.size(); ++k)
      if (a.meshes[k].positions != b.meshes[k].positions ||
          a.meshes[k].triangles != b.meshes[k].triangles ||
          a.meshes[k].triangle_material != b.meshes[k].triangle_material)
        return false;
    return true;
  };
  EXPECT_TRUE(same(rooms(3, 1.0f, 42), rooms(3, 1.0f, 42)));
  EXPECT_FALSE(same(rooms(3, 1.0f, 42), rooms(3, 1.0f, 43)));
  EXPECT_FALSE(same(rooms(3, 1.0f, 42), rooms(3, 1.0f, 44)));  // same parity: furniture differs
}

TEST(Rooms, DefaultCameraLooksFromALitRoomThroughADoorway) {
  for (int n : {1, 2, 4}) {
    for (std::uint32_t seed : {1u, 2u}) {
      Scene s = rooms(n, 1.0f, seed);
      World w = World::build(s);
      int cam = s.first_camera_node();
      ASSERT_GE(cam, 0);
      CameraPose pose = camera_pose(s, cam);
      int i = static_cast<int>(std::floor(pose.eye.x / kPitch));
      int j = static_cast<int>(std::floor(pose.eye.z / kPitch));
      ASSERT_TRUE(i >= 0 && i < n && j >= 0 && j < n);
      EXPECT_GE(find_node(s, "light_" + std::to_string(i) + "_" + std::to_string(j)), 0)
          << "camera is not in a lit room";
      EXPECT_GT(pose.eye.y, 0.5f);
      EXPECT_LT(pose.eye.y, 2.5f);
      EXPECT_NEAR(glm::length(pose.forward), 1.0f, 1e-4f);
      auto hit = first_hit(w, pose.eye, pose.eye + 50.0f * pose.forward);
      ASSERT_TRUE(hit.has_value());
      if (n > 1) {
        // The view axis goes through the doorway: the first thing it meets is beyond the room.
        glm::vec3 p = pose.eye + 50.0f * hit->t * pose.forward;
        int hi = static_cast<int>(std::floor(p.x / kPitch));
        int hj = static_cast<int>(std::floor(p.z / kPitch));
        EXPECT_TRUE(hi != i || hj != j) << "view axis stops inside the camera's room";
      }
    }
  }
}

// Seen from outside, the shell is solid all round: segments from far away aimed at points 5 cm
// inside its outer faces (walls, corners, roof, underside) all meet geometry before their end.
TEST(Rooms, ShellIsSolidFromOutside) {
  const int n = 2;
  Scene s = rooms(n, 1.0f, 1);
  World w = World::build(s);
  const float lo = -0.1f, hi = kPitch * n + 0.1f, in = 0.05f;
  int checked = 0;
  for (float t = lo + in; t <= hi - in + 1e-4f; t += 0.1f) {
    for (float y = -0.15f; y <= 2.95f + 1e-4f; y += 0.35f) {
      // Points just inside the four outer walls (including the corner pillars at the ends),
      // with the outward normal and a direction along the face.
      const std::array<std::array<glm::vec3, 3>, 4> sides{{
          {{{lo + in, y, t}, {-1, 0, 0}, {0, 0, 1}}},
          {{{hi - in, y, t}, {1, 0, 0}, {0, 0, 1}}},
          {{{t, y, lo + in}, {0, 0, -1}, {1, 0, 0}}},
          {{{t, y, hi - in}, {0, 0, 1}, {1, 0, 0}}},
      }};
      for (const auto& [p, out, along] : sides) {
        // Approach along the normal and obliquely; the start is far out beyond the face's plane,
        // so only the shell near p can be met.
        const glm::vec3 up(0.0f, 1.0f, 0.0f);
        for (glm::vec3 d : {out, glm::normalize(out + 0.4f * along + 0.2f * up),
                            glm::normalize(out - 0.4f * along - 0.2f * up)}) {
          ASSERT_TRUE(first_hit(w, p + 50.0f * d, p).has_value())
              << "hole at " << p.x << "," << p.y << "," << p.z;
          ++checked;
        }
      }
    }
    for (float u = lo + in; u <= hi - in + 1e-4f; u += 0.1f) {
      for (glm::vec3 p : {glm::vec3(t, 3.0f - in, u), glm::vec3(t, -0.2f + in, u)}) {
        glm::vec3 d(0.0f, p.y > 1.0f ? 1.0f : -1.0f, 0.0f);
        ASSERT_TRUE(first_hit(w, p + 50.0f * d, p).has_value())
            << "hole at " << p.x << "," << p.y << "," << p.z;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 1000);
}

// rooms:N:lit lights every room; rooms:N:trim also gives each room 16 emissive triangles of
// trim along its walls, emitting into the room, off the doorways: a building of many lights
// (rooms:12:trim: 3,456 emissive triangles at detail 1). Other variants are refused by name.
TEST(Rooms, EveryRoomLitAndTrimGiveManyLights) {
  auto count = [](const Scene& s, const std::string& prefix) {
    int n = 0;
    for (const Node& node : s.nodes) n += node.name.rfind(prefix, 0) == 0;
    return n;
  };
  const Scene lit = load_scene("rooms:3:lit");
  EXPECT_EQ(count(lit, "light_"), 9);
  EXPECT_EQ(count(lit, "trim_"), 0);
  const Scene trim = load_scene("rooms:3:trim");
  EXPECT_EQ(count(trim, "light_"), 9);
  ASSERT_EQ(count(trim, "trim_"), 9);
  const World w = World::build(trim);
  int trim_triangles = 0;
  for (const WorldObject& o : w.objects) {
    const std::string& name = object_name(w, o.object);
    if (name.rfind("trim_", 0) != 0) continue;
    const int parent = trim.nodes[o.node].parent;
    const glm::vec3 room(trim.world_matrices()[parent][3]);
    for (std::uint32_t t = 0; t < o.source->triangles.size(); ++t) {
      ASSERT_TRUE(w.material(o.object, t).is_emissive()) << name;
      ++trim_triangles;
      const glm::uvec3 tri = o.source->triangles[t];
      const glm::vec3 c =
          (o.positions[tri.x] + o.positions[tri.y] + o.positions[tri.z]) / 3.0f - room;
      // Inside the room, low on a wall, facing its middle, away from the doorway there.
      EXPECT_GT(std::min(c.x, c.z), 0.1f) << name;
      EXPECT_LT(std::max(c.x, c.z), 3.9f) << name;
      EXPECT_NEAR(c.y, 0.3f, 0.03f) << name;
      const glm::vec3 ng = o.geometric_normal(t);
      EXPECT_NEAR(ng.y, 0.0f, 1e-5f);
      EXPECT_GT(glm::dot(ng, glm::vec3(2.0f, c.y, 2.0f) - c), 1.0f) << name;
      const float along = std::fabs(ng.x) > 0.5f ? c.z : c.x;
      EXPECT_GT(std::fabs(along - 2.0f), 0.5f) << name << " in front of a doorway";
    }
  }
  EXPECT_EQ(trim_triangles, 9 * 16);
  for (const char* bad : {"rooms:3:dark", "rooms:3:", "rooms::lit", "rooms:3:lit:trim"}) {
    SCOPED_TRACE(bad);
    EXPECT_THROW(load_scene(bad), Error);
  }
}

}  // namespace irradcast::test_builtin_rooms

// Embree acceleration structure over a World: one triangle geometry per object (geomID equals
// the object index). Single rays for the estimators, 8-wide packets for primary rays.
//
// An editable scene (scene edits, docs/EDITS.md) is Embree's two-level structure: every object
// has its own BVH and a top-level BVH sits over them. update() after an object moves refits that
// object's BVH and rebuilds only the top level; hidden objects are disabled, not removed.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/world.h"

struct RTCSceneTy;  // Embree's scene handle is RTCSceneTy* (RTCScene)

namespace irradcast {

struct Hit {
  int object = -1;  // -1: miss
  std::uint32_t triangle = 0;
  float u = 0.0f, v = 0.0f;  // barycentrics: p = (1-u-v) p0 + u p1 + v p2
  float t = 0.0f;
  bool valid() const { return object >= 0; }
};

struct Ray {
  glm::vec3 origin{0.0f};
  glm::vec3 direction{0.0f, 0.0f, 1.0f};
  float tmin = 0.0f;
  float tmax = 3.4e38f;
};

// Up to kSize rays that share one tmax (tmin 0), held as arrays so that the loops that draw them
// vectorize, and their hits: RayScene::intersect(RayBatch&) traces them in one call.
struct RayBatch {
  static constexpr int kSize = 32;
  int count = 0;
  float tmax = 3.4e38f;
  alignas(16) float ox[kSize], oy[kSize], oz[kSize];  // origins
  alignas(16) float dx[kSize], dy[kSize], dz[kSize];  // directions
  Hit hit[kSize];
};

// Which of a world's objects a RayScene holds.
enum class RaySceneContent {
  Static,   // the static scene: what the engine lights and traces (dynamic objects are not in it)
  Dynamic,  // the dynamic objects only: what a viewer draws over the static scene (always
            // editable, so that a move refits one object's BVH)
};

class RayScene {
 public:
  // The world's static scene (dynamic objects are not in it; hidden ones are, disabled), or with
  // RaySceneContent::Dynamic its dynamic objects (hidden ones disabled). Geometry IDs are object
  // indices either way. `editable`: build the two-level structure that update() changes
  // incrementally (traversal is somewhat slower than the single-level BVH a static scene gets).
  explicit RayScene(const World& world, bool editable = false,
                    RaySceneContent content = RaySceneContent::Static);
  ~RayScene();
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;

  Hit intersect(const Ray& ray) const;
  bool occluded(const Ray& ray) const;
  // Up to 8 rays at once (count <= 8), one Embree packet.
  void intersect8(const Ray* rays, int count, Hit* hits) const;
  // intersect() of each of the batch's rays, into b.hit: the same hits, in Embree packets of 16
  // where the CPU has AVX-512 (Embree's 16-wide kernels), else one ray at a time.
  void intersect(RayBatch& b) const;
  // occluded() for up to 8 rays at once (count <= 8), one Embree packet: blocked[i] for ray i.
  void occluded8(const Ray* rays, int count, bool* blocked) const;

  // Offset used to leave a surface: scales with the scene so that it works in millimetres and
  // in kilometres alike.
  float epsilon() const { return epsilon_; }
  // Origin moved off the surface at p (geometric normal ng) to the side of direction d.
  glm::vec3 offset(glm::vec3 p, glm::vec3 ng, glm::vec3 d) const {
    return p + (glm::dot(ng, d) >= 0.0f ? epsilon_ : -epsilon_) * ng;
  }

  // After World::update: the objects whose positions or visibility changed (objects this scene
  // does not hold are skipped). Refits their BVHs
  // (rigid motion keeps every triangle, so a refit is always valid) and rebuilds the top level.
  // Not thread-safe against concurrent intersect() calls.
  void update(const std::vector<int>& objects);
  bool editable() const;

  const World& world() const { return *world_; }
  // The Embree scene behind intersect() / occluded(), for benchmarks that time raw Embree calls
  // on the same BVH. Owned by this RayScene; do not modify or release it.
  RTCSceneTy* embree_scene() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const World* world_;
  float epsilon_;
};

}  // namespace irradcast

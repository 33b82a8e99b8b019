// A BVH over a World's triangles in the layout the Vulkan backend's shaders traverse
// (shaders/common.glsl): built by Embree's generic builder (rtcBuildBVH, binned SAH), then
// flattened into two arrays for storage buffers. `intersect` walks the same layout on the host
// in the same order as the shader, so tests can check the layout against Embree's own rays.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

// Two children per node, each with its box. count 0: the child is the inner node `child`;
// kEmptyChild: no child; otherwise a leaf of `count` triangles starting at `child`.
struct GpuBvhNode {
  glm::vec3 lo0;
  std::uint32_t child0;
  glm::vec3 hi0;
  std::uint32_t child1;
  glm::vec3 lo1;
  std::uint32_t count0;
  glm::vec3 hi1;
  std::uint32_t count1;
};
static_assert(sizeof(GpuBvhNode) == 64);

// A triangle in BVH order, its corners as the world has them (the watertight test needs the
// shared vertices of neighbours bit for bit), with its object and its index there, and whether
// its material is Mask (Material::cut_out): the shaders test the alpha of those hits only.
struct GpuTriangle {
  glm::vec3 v0;
  std::uint32_t object;
  glm::vec3 v1;
  std::uint32_t triangle;
  glm::vec3 v2;
  std::uint32_t cut_out = 0;  // 1: a Mask material's triangle
};
static_assert(sizeof(GpuTriangle) == 48);

inline constexpr std::uint32_t kEmptyChild = 0xFFFFFFFFu;

struct GpuBvh {
  std::vector<GpuBvhNode> nodes;  // nodes[0] is the root
  std::vector<GpuTriangle> triangles;
  int depth = 0;  // longest root-to-leaf path, in nodes

  // Closest hit in (tmin, tmax), as the shader computes it for opaque triangles (it does not
  // evaluate alpha: a cut-out triangle counts as hit here).
  Hit intersect(const Ray& ray) const;
};

// Throws irradcast::Error if Embree's builder fails.
GpuBvh build_gpu_bvh(const World& world);

}  // namespace irradcast

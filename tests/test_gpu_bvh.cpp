// The BVH the Vulkan shaders traverse (Embree's builder, our node layout), walked on the host in
// the shader's order, against Embree's own intersector on the same scenes.
#include <gtest/gtest.h>

#include <cmath>

#include "gpu_bvh.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/world.h"
#include "scene_builders.h"
#include "testdata.h"

namespace irradcast::test_gpu_bvh {

namespace {

// Rays from random points in the scene bounds in random directions, some with a short tmax.
// Returns the fraction that agree with Embree on what they hit (object and triangle, or a miss)
// and checks t and the barycentrics of every agreeing hit.
double agreement(const World& world, int rays_to_cast) {
  RayScene rays(world);
  GpuBvh bvh = build_gpu_bvh(world);
  EXPECT_LE(bvh.depth, 40);
  std::size_t triangles = 0;
  for (const WorldObject& o : world.objects) triangles += o.triangles().size();
  EXPECT_EQ(bvh.triangles.size(), triangles) << "every triangle in exactly one leaf";
  Rng rng(7, 1);
  const Bounds& b = world.bounds;
  const float extent = b.max_extent();
  int agree = 0, hits = 0;
  for (int i = 0; i < rays_to_cast; ++i) {
    Ray r;
    r.origin = b.lo + glm::vec3(rng.next_float(), rng.next_float(), rng.next_float()) * b.extent();
    glm::vec2 u = rng.next_2d();
    float z = 1.0f - 2.0f * u.x, s = std::sqrt(std::max(0.0f, 1.0f - z * z));
    r.direction = glm::vec3(s * std::cos(2.0f * kPi * u.y), s * std::sin(2.0f * kPi * u.y), z);
    if (i % 4 == 0) r.tmax = 0.2f * extent;
    const Hit e = rays.intersect(r), g = bvh.intersect(r);
    hits += e.valid() ? 1 : 0;
    const bool same = e.object == g.object && (!e.valid() || e.triangle == g.triangle);
    // Coincident faces (boxes that touch, as the rooms' walls and slabs do) tie at the same t;
    // either answer is right.
    const bool tie = e.valid() && g.valid() && std::fabs(e.t - g.t) <= 1e-5f * extent;
    if (!same && !tie) continue;
    ++agree;
    if (!same || !e.valid()) continue;
    EXPECT_NEAR(g.t, e.t, 1e-4f * extent);
    EXPECT_NEAR(g.u, e.u, 1e-3f);
    EXPECT_NEAR(g.v, e.v, 1e-3f);
  }
  EXPECT_GT(hits, rays_to_cast / 4) << "the test must cast rays that hit";
  return static_cast<double>(agree) / rays_to_cast;
}

}  // namespace

// Rays that graze an edge shared by two triangles may report either one, so a few in 10^4 may
// differ; anything more is a traversal or layout bug. Random origins include points inside
// geometry, which reach internal faces too.
TEST(GpuBvh, AgreesWithEmbreeOnTheCornellBox) {
  Scene scene = make_cornell_box();
  EXPECT_GT(agreement(World::build(scene), 20000), 0.999);
}

TEST(GpuBvh, AgreesWithEmbreeOnRooms) {
  RoomsOptions ro;
  ro.n = 3;
  Scene scene = make_rooms(ro);
  EXPECT_GT(agreement(World::build(scene), 20000), 0.999);
}

TEST(GpuBvh, AgreesWithEmbreeOnTheLargeGltfSample) {
  IRRADCAST_NEED_TESTDATA();
  Scene scene = load_scene(test::testdata("gltf-samples/2CylinderEngine/2CylinderEngine.gltf"));
  EXPECT_GT(agreement(World::build(scene), 20000), 0.999);
}

TEST(GpuBvh, OneTriangleAndNoTriangles) {
  Scene one;
  test::add_quad_object(one, "q", {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                        test::add_material(one, glm::vec3(0.5f)));
  World w = World::build(one);
  GpuBvh bvh = build_gpu_bvh(w);
  Ray r;
  r.origin = glm::vec3(0.25f, 0.5f, 1.0f);
  r.direction = glm::vec3(0, 0, -1);
  Hit h = bvh.intersect(r);
  ASSERT_TRUE(h.valid());
  EXPECT_NEAR(h.t, 1.0f, 1e-6f);
  r.direction = glm::vec3(0, 0, 1);
  EXPECT_FALSE(bvh.intersect(r).valid());

  Scene none;
  GpuBvh empty = build_gpu_bvh(World::build(none));
  ASSERT_EQ(empty.nodes.size(), 1u);
  EXPECT_FALSE(empty.intersect(r).valid());
}

}  // namespace irradcast::test_gpu_bvh

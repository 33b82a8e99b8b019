#include <gtest/gtest.h>

#include "irradcast/common/atlas.h"
#include "irradcast/common/error.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/texel_validity.h"
#include "scene_builders.h"

namespace irradcast::test_texel_validity {

namespace {

// A closed room [-1,1]^3 with a block standing on its floor over [-0.5,0.5] x [-0.5,0.5]: a
// quarter of the floor's area lies under the block, inside solid matter.
struct BlockOnFloor {
  explicit BlockOnFloor(bool double_sided) {
    Progress::set_enabled(false);
    scene = test::closed_box(glm::vec3(0.5f), glm::vec3(0.0f));
    std::uint32_t m = test::add_material(scene, glm::vec3(0.5f));
    scene.materials[m].double_sided = double_sided;
    test::add_block(scene, "block", {-0.5f, -1.0f, -0.5f}, {0.5f, 0.0f, 0.5f}, m);
    world = World::build(scene);
    rays = std::make_unique<RayScene>(world);
    AtlasOptions ao;
    ao.texels_per_scene = 64.0f;
    atlas = build_atlas(world, ao);
    gbuffers = rasterize_gbuffer(world, atlas);
  }
  int object(const std::string& name) const {
    for (std::size_t o = 0; o < world.objects.size(); ++o)
      if (scene.objects()[world.objects[o].object].name == name) return static_cast<int>(o);
    return -1;
  }
  Scene scene;
  World world;
  std::unique_ptr<RayScene> rays;
  Atlas atlas;
  std::vector<TexelGBuffer> gbuffers;
};

}  // namespace

TEST(TexelValidity, TexelsUnderABlockAreHiddenAndTheRestStayValid) {
  BlockOnFloor s(false);
  const int floor = s.object("y-");
  ASSERT_GE(floor, 0);
  const std::size_t floor_before = s.gbuffers[floor].valid_count();
  std::vector<std::size_t> before;
  for (const auto& g : s.gbuffers) before.push_back(g.valid_count());
  const std::size_t hidden = mark_hidden_texels(*s.rays, s.gbuffers);
  const std::size_t floor_hidden = floor_before - s.gbuffers[floor].valid_count();
  EXPECT_EQ(hidden, floor_hidden) << "only the floor has texels inside the block";
  // A quarter of the floor, up to the texels straddling the block's outline.
  const double fraction = static_cast<double>(floor_hidden) / static_cast<double>(floor_before);
  EXPECT_NEAR(fraction, 0.25, 0.04);
  const TexelGBuffer& g = s.gbuffers[floor];
  for (std::size_t i = 0; i < g.size(); ++i) {
    if (g.kind[i] != TexelKind::Hidden) continue;
    const glm::vec3 q = g.position(s.world.objects[floor], i);
    EXPECT_LE(std::max(std::abs(q.x), std::abs(q.z)), 0.5f + 0.05f) << "hidden outside the block";
  }
  for (std::size_t o = 0; o < s.gbuffers.size(); ++o)
    if (static_cast<int>(o) != floor) {
      EXPECT_EQ(s.gbuffers[o].valid_count(), before[o]) << o;
    }
  // Hidden texels are filled from their visible neighbours like empty ones.
  std::vector<glm::vec3> values(g.size(), glm::vec3(0.0f));
  for (std::size_t i = 0; i < g.size(); ++i)
    if (g.valid(i)) values[i] = glm::vec3(2.0f);
  dilate(values, g.width, g.height, g.kind);
  for (std::size_t i = 0; i < g.size(); ++i)
    if (g.kind[i] == TexelKind::Hidden) {
      EXPECT_EQ(values[i], glm::vec3(2.0f));
    }
}

TEST(TexelValidity, BackFacesOfDoubleSidedSurfacesDoNotHide) {
  BlockOnFloor s(true);
  EXPECT_EQ(mark_hidden_texels(*s.rays, s.gbuffers), 0u);
}

TEST(TexelValidity, RejectsBadOptions) {
  BlockOnFloor s(false);
  TexelValidityOptions o;
  o.rays = 0;
  EXPECT_THROW(mark_hidden_texels(*s.rays, s.gbuffers, o), Error);
  std::vector<TexelGBuffer> wrong(1);
  EXPECT_THROW(mark_hidden_texels(*s.rays, wrong), Error);
}

}  // namespace irradcast::test_texel_validity

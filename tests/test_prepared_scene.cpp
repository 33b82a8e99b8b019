// PreparedScene: built the same way twice it has the same bits; its parts keep their addresses
// when it is moved and when it applies edits; after an edit its world and G-buffers are those of
// a fresh build of the edited scene, and the SceneChange names what changed; an edit that fails
// changes nothing.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/prepared_scene.h"

namespace irradcast::test_prepared_scene {

namespace {

PreparedSceneOptions options(bool editable) {
  Progress::set_enabled(false);
  PreparedSceneOptions o;
  o.atlas.texels_per_scene = 32.0f;
  o.editable = editable;
  o.name = "cornell";
  return o;
}

SceneEdit one(EditOp::Kind kind, const std::string& target, glm::vec3 v) {
  EditOp o;
  o.kind = kind;
  o.target = target;
  o.vector = v;
  return SceneEdit{{o}};
}

std::size_t object_index(const PreparedScene& p, const std::string& name) {
  const std::vector<Object> objects = p.scene().objects();
  for (std::size_t o = 0; o < p.world().objects.size(); ++o)
    if (objects[p.world().objects[o].object].name == name) return o;
  ADD_FAILURE() << "no object " << name;
  return 0;
}

Bounds box_of(const PreparedScene& p, std::size_t o) {
  Bounds b;
  for (const glm::vec3& q : p.world().objects[o].positions) b.extend(q);
  return b;
}

bool has_region(const SceneChange& c, const Bounds& b) {
  for (const Bounds& r : c.regions)
    if (r.lo == b.lo && r.hi == b.hi) return true;
  return false;
}

// The same G-buffers; positions within `tolerance` (0: the same bits).
void expect_same_gbuffers(const PreparedScene& a, const PreparedScene& b, float tolerance = 0.0f) {
  ASSERT_EQ(a.gbuffers().size(), b.gbuffers().size());
  for (std::size_t o = 0; o < a.gbuffers().size(); ++o) {
    const TexelGBuffer &x = a.gbuffers()[o], &y = b.gbuffers()[o];
    ASSERT_EQ(x.size(), y.size());
    const WorldObject &xo = a.world().objects[o], &yo = b.world().objects[o];
    float d = 0.0f;
    std::size_t normals = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      const TexelPoint p = x.point(xo, i), q = y.point(yo, i);
      d = std::max(d, glm::length(p.position - q.position));
      normals += p.normal != q.normal;
    }
    EXPECT_LE(d, tolerance) << "object " << o;
    EXPECT_EQ(normals, 0u) << "object " << o;
    if (tolerance == 0.0f) {
      EXPECT_EQ(x.bary, y.bary) << "object " << o;
    }
    EXPECT_EQ(x.triangle, y.triangle) << "object " << o;
    EXPECT_EQ(x.kind, y.kind) << "object " << o;
  }
}

}  // namespace

TEST(PreparedScene, BuildsTheSameBitsTwice) {
  const PreparedScene a = PreparedScene::build(make_cornell_box(), options(false));
  const PreparedScene b = PreparedScene::build(make_cornell_box(), options(false));
  EXPECT_EQ(a.gbuffers().size(), a.atlas().objects.size());
  EXPECT_GT(a.valid_texels(), 0u);
  EXPECT_LT(a.valid_texels(), a.atlas().texel_count());
  EXPECT_EQ(a.valid_texels(), b.valid_texels());
  EXPECT_EQ(a.hidden_texels(), b.hidden_texels());
  expect_same_gbuffers(a, b);
}

TEST(PreparedScene, PartsKeepTheirAddressesWhenMoved) {
  PreparedScene a = PreparedScene::build(make_cornell_box(), options(true));
  const World* world = &a.world();
  const RayScene* rays = &a.rays();
  const LightSampler* lights = &a.lights();
  const Atlas* atlas = &a.atlas();
  const std::vector<TexelGBuffer>* gbuffers = &a.gbuffers();
  PreparedScene b = std::move(a);
  EXPECT_EQ(&b.world(), world);
  EXPECT_EQ(&b.rays(), rays);
  EXPECT_EQ(&b.lights(), lights);
  EXPECT_EQ(&b.atlas(), atlas);
  EXPECT_EQ(&b.gbuffers(), gbuffers);
  const std::vector<SceneEdit> edits{one(EditOp::Kind::Move, "tall_block", {0.05f, 0, 0})};
  b.apply(edits);
  EXPECT_EQ(&b.world(), world);
  EXPECT_EQ(&b.rays(), rays);
  EXPECT_EQ(&b.lights(), lights);
  EXPECT_EQ(&b.gbuffers(), gbuffers);
}

TEST(PreparedScene, AMoveGivesTheWorldAndGBuffersOfAFreshBuild) {
  PreparedScene p = PreparedScene::build(make_cornell_box(), options(true));
  const std::size_t tall = object_index(p, "tall_block");
  const Bounds before = box_of(p, tall);
  const SceneEdit move = one(EditOp::Kind::Move, "tall_block", {0.05f, 0, 0});
  EditReport report;
  const SceneChange change = p.apply(std::vector<SceneEdit>{move}, &report);
  ASSERT_EQ(report.edits.size(), 1u);
  EXPECT_TRUE(report.edits[0].applied);
  EXPECT_EQ(report.applied, 1u);
  EXPECT_EQ(report.moved, 1u);
  EXPECT_TRUE(change.geometry);
  EXPECT_FALSE(change.surfaces);
  EXPECT_TRUE(has_region(change, before));
  EXPECT_TRUE(has_region(change, box_of(p, tall)));
  EXPECT_NE(before.lo, box_of(p, tall).lo);
  EXPECT_FALSE(change.other_lights.empty());  // the ceiling light did not change

  Scene edited = make_cornell_box();
  apply_edit(edited, move);
  const PreparedScene fresh = PreparedScene::build(std::move(edited), options(true));
  ASSERT_EQ(p.world().objects.size(), fresh.world().objects.size());
  for (std::size_t o = 0; o < p.world().objects.size(); ++o) {
    const WorldObject& moved = p.world().objects[o];
    EXPECT_EQ(moved.positions, fresh.world().objects[o].positions);
    // The per-triangle normals follow the move (every texel's geometric normal reads them).
    EXPECT_EQ(moved.face_normals, fresh.world().objects[o].face_normals);
    ASSERT_EQ(moved.face_normals.size(), moved.triangles().size());
    for (std::uint32_t t = 0; t < moved.face_normals.size(); ++t)
      EXPECT_EQ(moved.face_normals[t], moved.face_normal(t)) << "object " << o << " triangle " << t;
  }
  // The same texels, at the same points up to rounding (the edited G-buffers interpolate over
  // the atlas charts of the scene as loaded).
  expect_same_gbuffers(p, fresh, 1e-5f);
}

TEST(PreparedScene, AnAlbedoEditChangesSurfacesNotGeometry) {
  PreparedScene p = PreparedScene::build(make_cornell_box(), options(true));
  const std::size_t red = object_index(p, "left_wall_red");
  const SceneChange change =
      p.apply(std::vector<SceneEdit>{one(EditOp::Kind::MaterialAlbedo, "red", {0.2f, 0.6f, 0.2f})});
  EXPECT_FALSE(change.geometry);
  EXPECT_TRUE(change.surfaces);
  EXPECT_TRUE(has_region(change, box_of(p, red)));
  // The world the hits read their albedo from has the new one.
  const TexelGBuffer& g = p.gbuffers()[red];
  for (std::size_t i = 0; i < g.size(); ++i)
    if (g.valid(i)) {
      const auto t = static_cast<std::uint32_t>(g.triangle[i]);
      EXPECT_NEAR(p.world().albedo(static_cast<int>(red), t, 1.0f / 3.0f, 1.0f / 3.0f).y, 0.6f,
                  1e-6f);
      break;
    }
}

TEST(PreparedScene, AnEditThatFailsChangesNothing) {
  PreparedScene p = PreparedScene::build(make_cornell_box(), options(true));
  const std::vector<glm::vec3> positions = p.world().objects[0].positions;
  EditReport report;
  const SceneChange change =
      p.apply(std::vector<SceneEdit>{one(EditOp::Kind::Move, "no_such_node", {1, 0, 0})}, &report);
  ASSERT_EQ(report.edits.size(), 1u);
  EXPECT_FALSE(report.edits[0].applied);
  EXPECT_NE(report.edits[0].error.find("no_such_node"), std::string::npos) << report.edits[0].error;
  EXPECT_EQ(report.applied, 0u);
  EXPECT_FALSE(change.geometry || change.surfaces);
  EXPECT_TRUE(change.regions.empty() && change.light_points.empty() && change.other_lights.empty());
  EXPECT_EQ(p.world().objects[0].positions, positions);

  // Next to a good edit, only the good one is applied.
  p.apply(std::vector<SceneEdit>{one(EditOp::Kind::Move, "no_such_node", {1, 0, 0}),
                                 one(EditOp::Kind::Hide, "short_block", {})},
          &report);
  EXPECT_FALSE(report.edits[0].applied);
  EXPECT_TRUE(report.edits[1].applied);
  EXPECT_EQ(report.applied, 1u);
  EXPECT_FALSE(p.world().objects[object_index(p, "short_block")].visible);
}

TEST(PreparedScene, AnEmptySceneIsRefusedByName) {
  try {
    PreparedScene::build(Scene{}, options(false));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cornell: the scene has no triangles"), std::string::npos)
        << e.what();
  }
}

}  // namespace irradcast::test_prepared_scene

// The "sponza" scene spec (common/src/builtin_sponza.cpp): it finds the shared sample data and
// lights the open atrium with a sky and a sun.
#include <gtest/gtest.h>

#include <cstdlib>

#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/world.h"
#include "testdata.h"

namespace irradcast::test_builtin_sponza {
namespace {

TEST(SponzaScene, LoadsTheSampleDataWithSkySunAndCamera) {
  IRRADCAST_NEED_TESTDATA();
  ::setenv("IRRADCAST_TESTDATA", test::testdata_dir().c_str(), 1);
  Scene s = load_scene("sponza");
  // 66 450 in the file; one of the doors has zero area and is dropped.
  EXPECT_EQ(s.triangle_count(), 66449u);
  EXPECT_TRUE(s.sky.enabled());
  ASSERT_EQ(s.lights.size(), 1u);
  EXPECT_EQ(s.lights[0].type, Light::Type::Directional);
  World w = World::build(s);
  ASSERT_EQ(w.lights.size(), 1u);
  // The sun shines down into the courtyard.
  EXPECT_LT(w.lights[0].direction.y, -0.8f);
  ASSERT_GE(s.first_camera_node(), 0);
  CameraPose pose = camera_pose(s, s.first_camera_node());
  EXPECT_NEAR(glm::distance(pose.eye, glm::vec3(-14, 2, 0)), 0.0f, 1e-4f);
  EXPECT_GT(pose.forward.x, 0.9f);
}

TEST(SponzaScene, MissingSampleDataIsAClearError) {
  const char* old = std::getenv("IRRADCAST_TESTDATA");
  const std::string saved = old ? old : "";
  ::setenv("IRRADCAST_TESTDATA", "/nonexistent-irradcast-data", 1);
  try {
    find_sample_data("no-such-folder/scene.gltf");
    ADD_FAILURE() << "no error for a missing file";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no-such-folder/scene.gltf"), std::string::npos) << what;
    EXPECT_NE(what.find("/nonexistent-irradcast-data"), std::string::npos) << what;
    EXPECT_NE(what.find("IRRADCAST_TESTDATA"), std::string::npos) << what;
  }
  if (old)
    ::setenv("IRRADCAST_TESTDATA", saved.c_str(), 1);
  else
    ::unsetenv("IRRADCAST_TESTDATA");
}

}  // namespace
}  // namespace irradcast::test_builtin_sponza

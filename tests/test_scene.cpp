#include <gtest/gtest.h>

#include <glm/gtc/matrix_transform.hpp>

#include "irradcast/common/scene.h"
#include "irradcast/common/world.h"

namespace irradcast::test_scene {

TEST(Scene, WorldMatricesComposeDownTheHierarchy) {
  Scene s;
  Node a;
  a.local = glm::translate(glm::mat4(1.0f), glm::vec3(1, 0, 0));
  int ia = s.add_node(a);
  Node b;
  b.parent = ia;
  b.local = glm::scale(glm::mat4(1.0f), glm::vec3(2.0f));
  int ib = s.add_node(b);
  auto w = s.world_matrices();
  glm::vec4 p = w[ib] * glm::vec4(1, 1, 1, 1);
  EXPECT_FLOAT_EQ(p.x, 3.0f);
  EXPECT_FLOAT_EQ(p.y, 2.0f);
  EXPECT_EQ(s.roots.size(), 1u);
}

}  // namespace irradcast::test_scene

// The octahedral map's decoding.
#include "irradcast/common/octahedral.h"

namespace irradcast {

glm::vec3 octahedral_decode(glm::vec2 uv) {
  glm::vec2 e = 2.0f * uv - 1.0f;
  glm::vec3 d(e.x, e.y, 1.0f - std::fabs(e.x) - std::fabs(e.y));
  if (d.z < 0.0f) {
    glm::vec2 xy = (1.0f - glm::abs(glm::vec2(d.y, d.x))) *
                   glm::vec2(d.x >= 0.0f ? 1.0f : -1.0f, d.y >= 0.0f ? 1.0f : -1.0f);
    d.x = xy.x;
    d.y = xy.y;
  }
  return glm::normalize(d);
}

}  // namespace irradcast

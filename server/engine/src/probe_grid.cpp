#include <cmath>

#include "irradcast/engine/trace_backend.h"

namespace irradcast {

int ProbeGrid::cell_index(glm::vec3 p) const {
  glm::ivec3 c = glm::clamp(glm::ivec3(glm::floor((p - origin) / cell)), glm::ivec3(0), dims - 1);
  return (c.z * dims.y + c.y) * dims.x + c.x;
}

glm::vec2 octahedral_encode(glm::vec3 d) {
  d /= (std::fabs(d.x) + std::fabs(d.y) + std::fabs(d.z));
  glm::vec2 e(d.x, d.y);
  if (d.z < 0.0f) {
    e = (1.0f - glm::abs(glm::vec2(d.y, d.x))) *
        glm::vec2(d.x >= 0.0f ? 1.0f : -1.0f, d.y >= 0.0f ? 1.0f : -1.0f);
  }
  return 0.5f * e + 0.5f;
}

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

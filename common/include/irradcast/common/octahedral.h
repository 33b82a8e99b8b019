// Octahedral mapping of unit directions to [0, 1]^2 and back: the engine's probe maps and the
// irradiance volume's distance maps (encode inline: every scatter miss reads a probe through it).
#pragma once

#include <cmath>

#include <glm/glm.hpp>

namespace irradcast {

inline glm::vec2 octahedral_encode(glm::vec3 d) {
  d /= (std::fabs(d.x) + std::fabs(d.y) + std::fabs(d.z));
  glm::vec2 e(d.x, d.y);
  if (d.z < 0.0f) {
    e = (1.0f - glm::abs(glm::vec2(d.y, d.x))) *
        glm::vec2(d.x >= 0.0f ? 1.0f : -1.0f, d.y >= 0.0f ? 1.0f : -1.0f);
  }
  return 0.5f * e + 0.5f;
}
glm::vec3 octahedral_decode(glm::vec2 uv);

}  // namespace irradcast

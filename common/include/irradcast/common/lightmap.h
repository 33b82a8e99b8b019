// An irradiance lightmap: one RGB value (irradiance E, W/m^2) per texel of an object's atlas
// layout, looked up bilinearly in texel units (texel centres at i + 0.5).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include <glm/glm.hpp>

namespace irradcast {

struct Lightmap {
  int width = 0;
  int height = 0;
  std::vector<glm::vec3> texels;

  Lightmap() = default;
  Lightmap(int w, int h, glm::vec3 fill = glm::vec3(0.0f))
      : width(w), height(h), texels(static_cast<std::size_t>(w) * h, fill) {}

  glm::vec3 bilinear(glm::vec2 uv) const {
    float x = uv.x - 0.5f, y = uv.y - 0.5f;
    float fx = std::floor(x), fy = std::floor(y);
    float ax = x - fx, ay = y - fy;
    int x0 = std::clamp(static_cast<int>(fx), 0, width - 1);
    int y0 = std::clamp(static_cast<int>(fy), 0, height - 1);
    int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
    if (fx < 0.0f) x1 = x0;
    if (fy < 0.0f) y1 = y0;
    auto at = [&](int i, int j) { return texels[static_cast<std::size_t>(j) * width + i]; };
    return glm::mix(glm::mix(at(x0, y0), at(x1, y0), ax), glm::mix(at(x0, y1), at(x1, y1), ax), ay);
  }
};

}  // namespace irradcast

#include "irradcast/common/shapes.h"

#include <cmath>

#include "irradcast/common/error.h"

namespace irradcast {

Mesh uv_sphere(const std::string& name, float radius, int rings, int segments,
               std::uint32_t material) {
  if (rings < 2 || segments < 3 || rings > 4096 || segments > 4096)
    throw Error("sphere '" + name + "': " + std::to_string(rings) + " rings and " +
                std::to_string(segments) + " segments (need 2..4096 and 3..4096)");
  if (!(radius > 0.0f) || !std::isfinite(radius))
    throw Error("sphere '" + name + "': the radius must be finite and positive");
  constexpr float kPi = 3.14159265358979f;
  Mesh m;
  m.name = name;
  // A vertex row per ring boundary and a seam column duplicated (u = 0 and 1).
  const int cols = segments + 1;
  for (int r = 0; r <= rings; ++r) {
    const float v = static_cast<float>(r) / static_cast<float>(rings);
    const float theta = v * kPi;
    for (int c = 0; c < cols; ++c) {
      const float u = static_cast<float>(c) / static_cast<float>(segments);
      const float phi = u * 2.0f * kPi;
      // Around +Y, from +X towards -Z, so that the triangles below wind outward.
      const glm::vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta),
                        -std::sin(theta) * std::sin(phi));
      m.positions.push_back(radius * n);
      m.normals.push_back(n);
      m.uv0.emplace_back(u, v);
    }
  }
  const auto at = [cols](int r, int c) { return static_cast<std::uint32_t>(r * cols + c); };
  for (int r = 0; r < rings; ++r)
    for (int c = 0; c < segments; ++c) {
      const std::uint32_t a = at(r, c), b = at(r + 1, c), d = at(r, c + 1), e = at(r + 1, c + 1);
      if (r > 0) m.triangles.emplace_back(a, b, d);          // none at the north pole
      if (r < rings - 1) m.triangles.emplace_back(d, b, e);  // none at the south pole
    }
  m.triangle_material.assign(m.triangles.size(), material);
  return m;
}

}  // namespace irradcast

#include "irradcast/common/shapes.h"

#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

namespace {

void check_counts(const char* what, const std::string& name, float radius, int rings,
                  int segments) {
  if (rings < 2 || segments < 3 || rings > 4096 || segments > 4096)
    throw Error(std::string(what) + " '" + name + "': " + std::to_string(rings) + " rings and " +
                std::to_string(segments) + " segments (need 2..4096 and 3..4096)");
  if (!(radius > 0.0f) || !std::isfinite(radius))
    throw Error(std::string(what) + " '" + name + "': the radius must be finite and positive");
}

// A surface of revolution about +Y: per ring boundary r (0 at the north pole), its polar angle
// and the height its row is lifted by; vertex rows with a duplicated seam column (u = 0 and 1).
template <typename Row>
Mesh revolve(const std::string& name, float radius, int rows, int segments, std::uint32_t material,
             Row row) {
  Mesh m;
  m.name = name;
  const int cols = segments + 1;
  for (int r = 0; r < rows; ++r) {
    const auto [theta, lift, v] = row(r);
    for (int c = 0; c < cols; ++c) {
      const float u = static_cast<float>(c) / static_cast<float>(segments);
      const float phi = u * 2.0f * kPi;
      // Around +Y, from +X towards -Z, so that the triangles below wind outward.
      const glm::vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta),
                        -std::sin(theta) * std::sin(phi));
      m.positions.push_back(radius * n + glm::vec3(0.0f, lift, 0.0f));
      m.normals.push_back(n);
      m.uv0.emplace_back(u, v);
    }
  }
  const auto at = [cols](int r, int c) { return static_cast<std::uint32_t>(r * cols + c); };
  for (int r = 0; r + 1 < rows; ++r)
    for (int c = 0; c < segments; ++c) {
      const std::uint32_t a = at(r, c), b = at(r + 1, c), d = at(r, c + 1), e = at(r + 1, c + 1);
      if (r > 0) m.triangles.emplace_back(a, b, d);         // none at the north pole
      if (r + 2 < rows) m.triangles.emplace_back(d, b, e);  // none at the south pole
    }
  m.triangle_material.assign(m.triangles.size(), material);
  return m;
}

struct RingRow {
  float theta, lift, v;
};

}  // namespace

Mesh uv_sphere(const std::string& name, float radius, int rings, int segments,
               std::uint32_t material) {
  check_counts("sphere", name, radius, rings, segments);
  return revolve(name, radius, rings + 1, segments, material, [rings](int r) {
    const float v = static_cast<float>(r) / static_cast<float>(rings);
    return RingRow{v * kPi, 0.0f, v};
  });
}

Mesh capsule(const std::string& name, float radius, float length, int rings, int segments,
             std::uint32_t material) {
  check_counts("capsule", name, radius, rings, segments);
  if (rings % 2 != 0) throw Error("capsule '" + name + "': the rings must be even");
  if (!(length >= 0.0f) || !std::isfinite(length))
    throw Error("capsule '" + name + "': the length must be finite and not negative");
  // The equator's row twice: once lifted with the upper hemisphere, once lowered with the lower.
  const int half = rings / 2;
  const float profile = kPi * radius + length;
  return revolve(name, radius, rings + 2, segments, material, [=](int r) {
    const bool upper = r <= half;
    const int k = upper ? r : r - 1;
    const float theta = static_cast<float>(k) / static_cast<float>(rings) * kPi;
    const float arc = theta * radius + (upper ? 0.0f : length);
    return RingRow{theta, upper ? 0.5f * length : -0.5f * length, arc / profile};
  });
}

}  // namespace irradcast

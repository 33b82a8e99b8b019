// Spherical harmonics, the octahedral map and the irradiance volume's look-up.
#include "irradcast/common/irradiance_volume.h"

#include <algorithm>
#include <cmath>

namespace irradcast {

std::array<float, kShCoefficients> sh_basis(glm::vec3 d) {
  return {0.282095f,
          0.488603f * d.y,
          0.488603f * d.z,
          0.488603f * d.x,
          1.092548f * d.x * d.y,
          1.092548f * d.y * d.z,
          0.315392f * (3.0f * d.z * d.z - 1.0f),
          1.092548f * d.x * d.z,
          0.546274f * (d.x * d.x - d.y * d.y)};
}

glm::vec3 sh_irradiance(const ShIrradiance& e, glm::vec3 n) {
  const std::array<float, kShCoefficients> y = sh_basis(n);
  glm::vec3 sum(0.0f);
  for (int i = 0; i < kShCoefficients; ++i)
    sum += e[static_cast<std::size_t>(i)] * y[static_cast<std::size_t>(i)];
  return glm::max(sum, glm::vec3(0.0f));
}

glm::ivec3 VolumeGrid::cell_of(std::size_t index) const {
  const auto nx = static_cast<std::size_t>(counts.x), ny = static_cast<std::size_t>(counts.y);
  return {static_cast<int>(index % nx), static_cast<int>((index / nx) % ny),
          static_cast<int>(index / (nx * ny))};
}

void IrradianceVolume::reset(const VolumeGrid& g) {
  grid = g;
  const std::size_t n = g.probe_count();
  offsets.assign(n, glm::vec3(0.0f));
  active.assign(n, 1);
  sh.assign(n, ShIrradiance{});
  emitted.assign(n, ShIrradiance{});
  const float far = g.max_distance();
  depth.assign(n * kDepthTexels, glm::vec2(far, far * far));
}

glm::vec2 IrradianceVolume::moments(std::size_t probe, glm::vec3 d) const {
  const glm::vec2 uv = octahedral_encode(d) * float(kDepthSize) - 0.5f;
  const glm::vec2 f = glm::clamp(uv, glm::vec2(0.0f), glm::vec2(float(kDepthSize - 1)));
  const glm::ivec2 a(static_cast<int>(f.x), static_cast<int>(f.y));
  const glm::ivec2 b = glm::min(a + 1, glm::ivec2(kDepthSize - 1));
  const glm::vec2 t = f - glm::vec2(a);
  const glm::vec2* m = depth.data() + probe * kDepthTexels;
  const auto at = [&](int x, int y) { return m[static_cast<std::size_t>(y * kDepthSize + x)]; };
  return glm::mix(glm::mix(at(a.x, a.y), at(b.x, a.y), t.x),
                  glm::mix(at(a.x, b.y), at(b.x, b.y), t.x), t.y);
}

glm::vec3 IrradianceVolume::irradiance(glm::vec3 p, glm::vec3 n, bool with_emitted) const {
  if (grid.probe_count() == 0) return glm::vec3(0.0f);
  // A little off the surface, so that the visibility test does not see the surface itself.
  const glm::vec3 q = p + n * (0.05f * grid.spacing);
  const glm::vec3 g = (q - grid.origin) / grid.spacing;
  glm::ivec3 base;
  glm::vec3 f;
  for (int a = 0; a < 3; ++a) {
    const int last = std::max(grid.counts[a] - 2, 0);
    base[a] = static_cast<int>(std::clamp(std::floor(g[a]), 0.0f, float(last)));  // NaN: 0
    f[a] = grid.counts[a] > 1 ? std::clamp(g[a] - float(base[a]), 0.0f, 1.0f) : 0.0f;
  }
  glm::vec3 sum(0.0f);
  float weights = 0.0f;
  for (int corner = 0; corner < 8; ++corner) {
    const glm::ivec3 o(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
    const glm::ivec3 c = glm::min(base + o, grid.counts - 1);
    const std::size_t i = grid.index(c);
    if (!active[i]) continue;
    const glm::vec3 tri = glm::mix(1.0f - f, f, glm::vec3(o));
    const float trilinear = tri.x * tri.y * tri.z;
    if (trilinear <= 0.0f) continue;
    const glm::vec3 to_probe = probe_position(i) - q;
    const float dist = glm::length(to_probe);
    const glm::vec3 dir = dist > 0.0f ? to_probe / dist : n;
    // Probes behind the surface count less (DDGI's smooth backface term), with the square root
    // of DDGI's (1 + cos) / 2 rather than its square: the square leans on the probes in front of
    // the surface so much that a point reads the light half a spacing out along its normal
    // (spheres near walls and openings 5-10 % off against the path tracer; docs/DYNAMIC.md).
    const float facing = 0.5f * (glm::dot(dir, n) + 1.0f);
    float w = std::sqrt(std::max(facing, 0.0f)) + 0.2f;  // a dot a hair under -1: no NaN
    // Chebyshev: how likely the probe sees q, from its distance moments towards q.
    const glm::vec2 m = moments(i, -dir);
    if (dist > m.x) {
      const float variance = std::fabs(m.y - m.x * m.x) + 1e-6f * grid.spacing * grid.spacing;
      const float d = dist - m.x;
      const float chebyshev = variance / (variance + d * d);
      w *= std::max(chebyshev * chebyshev * chebyshev, 0.0f);
    }
    // Weights crushed near zero, so that a wall's far side contributes next to nothing.
    if (w < 0.2f) w *= w * w / (0.2f * 0.2f);
    w = std::max(w, 1e-6f) * trilinear;
    if (with_emitted) {
      ShIrradiance all = sh[i];
      for (int k = 0; k < kShCoefficients; ++k)
        all[static_cast<std::size_t>(k)] += emitted[i][static_cast<std::size_t>(k)];
      sum += w * sh_irradiance(all, n);
    } else {
      sum += w * sh_irradiance(sh[i], n);
    }
    weights += w;
  }
  return weights > 0.0f ? sum / weights : glm::vec3(0.0f);
}

}  // namespace irradcast

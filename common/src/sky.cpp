#include "irradcast/common/sky.h"

#include <algorithm>
#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

bool finite_non_negative(glm::vec3 c) {
  return std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z) && c.x >= 0.0f &&
         c.y >= 0.0f && c.z >= 0.0f;
}

// The texel of map coordinates uv (clamped to the map).
glm::ivec2 texel_of(glm::vec2 uv, int width, int height) {
  int x = static_cast<int>(uv.x * static_cast<float>(width));
  int y = static_cast<int>(uv.y * static_cast<float>(height));
  return {std::clamp(x, 0, width - 1), std::clamp(y, 0, height - 1)};
}

// The index of the interval of `cdf` (ascending, cdf[0] = 0, cdf[n] = 1) that holds u, skipping
// empty intervals, and where u lies in it (0 .. 1).
int find_interval(const float* cdf, int n, float u, float& within) {
  int i = static_cast<int>(std::upper_bound(cdf, cdf + n + 1, u) - cdf) - 1;
  i = std::clamp(i, 0, n - 1);
  while (i > 0 && !(cdf[i + 1] > cdf[i])) --i;  // u at 1 (or rounding) lands past the mass
  const float width = cdf[i + 1] - cdf[i];
  within = width > 0.0f ? std::clamp((u - cdf[i]) / width, 0.0f, 0.99999994f) : 0.5f;
  return i;
}

}  // namespace

glm::vec2 sky_uv(glm::vec3 dir) {
  float u = 0.5f + std::atan2(dir.x, -dir.z) * (0.5f * kInvPi);
  float v = std::acos(std::clamp(dir.y, -1.0f, 1.0f)) * kInvPi;
  return {std::clamp(u, 0.0f, 1.0f), std::clamp(v, 0.0f, 1.0f)};
}

glm::vec3 sky_direction(glm::vec2 uv) {
  const float theta = uv.y * kPi;
  const float phi = (uv.x - 0.5f) * 2.0f * kPi;
  const float s = std::sin(theta);
  return {s * std::sin(phi), std::cos(theta), -s * std::cos(phi)};
}

bool Sky::enabled() const {
  if (!(strength > 0.0f)) return false;
  if (map.width > 0 && map.height > 0) return true;
  return color.x > 0.0f || color.y > 0.0f || color.z > 0.0f;
}

glm::vec3 Sky::radiance(glm::vec3 dir) const {
  if (map.width <= 0 || map.height <= 0) return color * strength;
  glm::ivec2 t = texel_of(sky_uv(dir), map.width, map.height);
  return map.at(t.x, t.y) * strength;
}

void validate_sky(const Sky& sky, const std::string& label) {
  if (!std::isfinite(sky.strength) || sky.strength < 0.0f)
    throw Error(label + ": sky strength must be finite and >= 0");
  if (!finite_non_negative(sky.color))
    throw Error(label + ": sky colour must be finite and >= 0 in every channel");
  if (sky.map.pixels.empty() && sky.map.width == 0 && sky.map.height == 0) return;
  if (sky.map.width <= 0 || sky.map.height <= 0 ||
      sky.map.pixels.size() != static_cast<std::size_t>(sky.map.width) * sky.map.height)
    throw Error(label + ": sky map has no pixels");
  if (sky.map.width > kMaxSkyWidth || sky.map.height > kMaxSkyHeight)
    throw Error(label + ": sky map is " + std::to_string(sky.map.width) + "x" +
                std::to_string(sky.map.height) + ", larger than " + std::to_string(kMaxSkyWidth) +
                "x" + std::to_string(kMaxSkyHeight));
  for (std::size_t i = 0; i < sky.map.pixels.size(); ++i)
    if (!finite_non_negative(sky.map.pixels[i]))
      throw Error(label + ": sky map pixel (" + std::to_string(i % sky.map.width) + ", " +
                  std::to_string(i / sky.map.width) + ") is negative or not finite");
}

SkyDistribution::SkyDistribution(const Sky& sky) {
  if (!sky.enabled() || sky.map.width <= 0 || sky.map.height <= 0) return;
  const int w = sky.map.width, h = sky.map.height;
  std::vector<double> weight(static_cast<std::size_t>(w) * h);
  std::vector<double> row_sum(h, 0.0);
  double total = 0.0;
  for (int y = 0; y < h; ++y) {
    const double sin_theta = std::sin((static_cast<double>(y) + 0.5) / h * kPi);
    for (int x = 0; x < w; ++x) {
      double l = std::max(0.0f, luminance(sky.map.at(x, y))) * sin_theta;
      weight[static_cast<std::size_t>(y) * w + x] = l;
      row_sum[y] += l;
    }
    total += row_sum[y];
  }
  if (!(total > 0.0) || !std::isfinite(total)) return;  // black map: cosine rays only
  width_ = w;
  height_ = h;
  marginal_.assign(h + 1, 0.0f);
  conditional_.assign(static_cast<std::size_t>(h) * (w + 1), 0.0f);
  density_.assign(static_cast<std::size_t>(w) * h, 0.0f);
  const double texels = static_cast<double>(w) * h;
  double run = 0.0;
  for (int y = 0; y < h; ++y) {
    run += row_sum[y];
    marginal_[y + 1] = static_cast<float>(run / total);
    float* row = &conditional_[static_cast<std::size_t>(y) * (w + 1)];
    double r = 0.0;
    for (int x = 0; x < w; ++x) {
      const double wt = weight[static_cast<std::size_t>(y) * w + x];
      r += wt;
      row[x + 1] = row_sum[y] > 0.0 ? static_cast<float>(r / row_sum[y]) : 0.0f;
      density_[static_cast<std::size_t>(y) * w + x] = static_cast<float>(wt / total * texels);
    }
    if (row_sum[y] > 0.0) row[w] = 1.0f;
  }
  marginal_[h] = 1.0f;
}

SkyDistribution::Sample SkyDistribution::sample(glm::vec2 u) const {
  Sample s;
  if (!valid()) return s;
  float fy = 0.0f, fx = 0.0f;
  const int y = find_interval(marginal_.data(), height_, u.y, fy);
  const int x =
      find_interval(&conditional_[static_cast<std::size_t>(y) * (width_ + 1)], width_, u.x, fx);
  const glm::vec2 uv((static_cast<float>(x) + fx) / static_cast<float>(width_),
                     (static_cast<float>(y) + fy) / static_cast<float>(height_));
  const float sin_theta = std::sin(uv.y * kPi);
  const float d = density_[static_cast<std::size_t>(y) * width_ + x];
  if (!(sin_theta > 0.0f) || !(d > 0.0f)) return s;
  s.direction = sky_direction(uv);
  s.pdf = d / (2.0f * kPi * kPi * sin_theta);
  return s;
}

float SkyDistribution::pdf(glm::vec3 dir) const {
  if (!valid()) return 0.0f;
  const glm::vec2 uv = sky_uv(dir);
  const float sin_theta = std::sin(uv.y * kPi);
  if (!(sin_theta > 0.0f)) return 0.0f;
  const glm::ivec2 t = texel_of(uv, width_, height_);
  return density_[static_cast<std::size_t>(t.y) * width_ + t.x] / (2.0f * kPi * kPi * sin_theta);
}

}  // namespace irradcast

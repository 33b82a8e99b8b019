#include "irradcast/common/tonemap.h"

#include <algorithm>
#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

float srgb_encode(float c) {
  c = std::clamp(c, 0.0f, 1.0f);
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

glm::vec3 aces(glm::vec3 x) {  // Narkowicz 2015
  const float a = 2.51f, b = 0.03f, c = 2.43f, d = 0.59f, e = 0.14f;
  return glm::clamp((x * (a * x + b)) / (x * (c * x + d) + e), 0.0f, 1.0f);
}

}  // namespace

ToneOperator parse_tone_operator(const std::string& name) {
  if (name == "reinhard") return ToneOperator::Reinhard;
  if (name == "aces") return ToneOperator::Aces;
  if (name == "clamp") return ToneOperator::Clamp;
  throw Error("unknown tone map '" + name + "' (expected reinhard, aces or clamp)");
}

float exposure_scale(const ImageRGB& image, const ToneMapOptions& o) {
  if (!o.auto_exposure) return std::exp2(o.exposure_ev);
  double sum = 0.0;
  std::size_t n = 0;
  for (const glm::vec3& p : image.pixels) {
    float l = luminance(p);
    if (!(l > 0.0f) || !std::isfinite(l)) continue;  // background does not darken the key
    sum += std::log(1e-4 + l);
    ++n;
  }
  if (n == 0) return 1.0f;
  double log_avg = std::exp(sum / static_cast<double>(n));
  return static_cast<float>(o.key / log_avg);
}

std::vector<std::uint8_t> tonemap_srgb8(const ImageRGB& image, const ToneMapOptions& o) {
  float scale = exposure_scale(image, o);
  std::vector<std::uint8_t> out(image.pixels.size() * 3);
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    glm::vec3 c = image.pixels[i] * scale;
    if (!std::isfinite(c.x + c.y + c.z)) c = glm::vec3(0.0f);
    c = glm::max(c, glm::vec3(0.0f));
    switch (o.op) {
      case ToneOperator::Reinhard: {
        float l = luminance(c);
        if (l > 0.0f) c *= (1.0f / (1.0f + l));
        break;
      }
      case ToneOperator::Aces:
        c = aces(c);
        break;
      case ToneOperator::Clamp:
        break;
    }
    for (int k = 0; k < 3; ++k)
      out[3 * i + k] = static_cast<std::uint8_t>(std::lround(255.0f * srgb_encode(c[k])));
  }
  return out;
}

}  // namespace irradcast

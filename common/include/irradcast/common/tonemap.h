// Exposure and tone mapping of linear radiance to displayable sRGB.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "irradcast/common/image.h"

namespace irradcast {

enum class ToneOperator { Reinhard, Aces, Clamp };

struct ToneMapOptions {
  ToneOperator op = ToneOperator::Reinhard;
  bool auto_exposure = true;  // Reinhard's key: scale = key / log-average luminance
  float key = 0.18f;
  float exposure_ev = 0.0f;  // used when auto_exposure is false: scale = 2^ev
};

// Parses "reinhard|aces|clamp"; throws irradcast::Error otherwise.
ToneOperator parse_tone_operator(const std::string& name);

float exposure_scale(const ImageRGB& image, const ToneMapOptions& options);
// Reinhard works on luminance, L_d = L / (1 + L) (seed 001, eq. 3.1), keeping the hue; ACES is
// Narkowicz's fit of the ACES filmic curve per channel; then the sRGB transfer function.
std::vector<std::uint8_t> tonemap_srgb8(const ImageRGB& image, const ToneMapOptions& options);

}  // namespace irradcast

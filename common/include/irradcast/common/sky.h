// The sky: radiance arriving from every direction in which a ray leaves the scene (an environment
// light at infinity). A constant colour or an equirectangular map of linear radiance, times a
// strength. The scene carries it (Scene::sky), so the engine, the path tracer and every viewer
// (as the background of rays that miss) see the same sky.
//
// Orientation of a map (docs/ENGINE.md "Sky"): +Y is up. Row 0 of the image is straight up
// (+Y), the last row straight down (-Y), the middle row the horizon. The image centre faces -Z,
// where a glTF camera with no rotation looks; moving right in the image turns toward +X (to that
// camera's right), and both side edges face +Z. So a panorama shot from inside the scene looks
// the same in the image and from a default camera.
#pragma once

#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/image.h"

namespace irradcast {

// The largest map the sky takes (larger ones are refused: the sampling tables of a map cost
// about 24 bytes per texel, and every viewer downloads it).
inline constexpr int kMaxSkyWidth = 4096;
inline constexpr int kMaxSkyHeight = 2048;

// Direction <-> map coordinates in [0, 1]^2 (u to the right, v down), as described above.
glm::vec2 sky_uv(glm::vec3 dir);
glm::vec3 sky_direction(glm::vec2 uv);

struct Sky {
  glm::vec3 color{0.0f};  // constant radiance (linear RGB, W m^-2 sr^-1) when `map` is empty
  ImageRGB map;           // equirectangular linear radiance; empty = the constant colour
  std::string source;     // where the map came from (a file name), for logs; "" for a colour
  float strength = 1.0f;  // multiplies the colour or the map

  // Whether any light comes from the sky.
  bool enabled() const;
  // Radiance arriving from direction `dir` (unit, pointing away from the scene, toward the sky).
  // A map is looked up at the nearest texel (piecewise constant, like its sampling density).
  glm::vec3 radiance(glm::vec3 dir) const;
};

// Throws irradcast::Error naming `label` if the sky is unusable: a strength or colour that is
// negative or not finite, a map larger than kMaxSkyWidth x kMaxSkyHeight, with a zero side, or
// with a pixel that is negative or not finite.
void validate_sky(const Sky& sky, const std::string& label);

// Importance sampling of a sky map by luminance x sin(theta) (piecewise constant over the map's
// texels, PBRT's Distribution2D). A constant sky needs none: cosine-weighted hemisphere rays
// sample it exactly up to visibility.
class SkyDistribution {
 public:
  SkyDistribution() = default;
  explicit SkyDistribution(const Sky& sky);

  // False for a constant or disabled sky, or a map that is black everywhere.
  bool valid() const { return width_ > 0; }

  struct Sample {
    glm::vec3 direction{0.0f, 1.0f, 0.0f};
    float pdf = 0.0f;  // per unit solid angle; 0: no sample
  };
  // A direction drawn with probability proportional to the map's luminance (u in [0, 1)^2).
  Sample sample(glm::vec2 u) const;
  // The density sample() draws `dir` with, per unit solid angle.
  float pdf(glm::vec3 dir) const;

  // The tables, for a backend that samples on its own (Vulkan): per row the cumulative
  // probability of the rows above (height + 1 entries, 0 ... 1); per row its columns' cumulative
  // probabilities (height x (width + 1)); per texel its density over the unit square [0, 1]^2
  // (width x height, row-major).
  int width() const { return width_; }
  int height() const { return height_; }
  const std::vector<float>& marginal_cdf() const { return marginal_; }
  const std::vector<float>& conditional_cdf() const { return conditional_; }
  const std::vector<float>& density() const { return density_; }

 private:
  int width_ = 0, height_ = 0;
  std::vector<float> marginal_;
  std::vector<float> conditional_;
  std::vector<float> density_;
};

}  // namespace irradcast

// The sampling warps of common/sampling.h: the trigonometry-free azimuth (cos_sin_2pi) against
// the C library in double precision, and the scatter's cosine_hemisphere_fast against
// cosine_hemisphere (the same map of the random numbers, so the same distribution).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "irradcast/common/sampling.h"

namespace irradcast::test_sampling {
namespace {

TEST(Sampling, CosSin2PiMatchesTheLibraryOnTheWholeTurn) {
  double worst = 0.0;
  float worst_u = 0.0f;
  // Every 2^-20 of the turn, the quarter-turn boundaries and their float neighbours, the ends.
  std::vector<float> us;
  for (int k = 0; k <= (1 << 20); ++k) us.push_back(static_cast<float>(k) * 0x1p-20f);
  for (float q : {0.125f, 0.25f, 0.375f, 0.5f, 0.625f, 0.75f, 0.875f, 1.0f}) {
    us.push_back(std::nextafter(q, 0.0f));
    us.push_back(std::nextafter(q, 2.0f));
  }
  us.push_back(std::nextafter(1.0f, 0.0f));  // the largest Rng::next_float()
  for (float u : us) {
    const glm::vec2 cs = cos_sin_2pi(u);
    const double phi = 2.0 * 3.14159265358979323846 * static_cast<double>(u);
    const double err = std::max(std::fabs(cs.x - std::cos(phi)), std::fabs(cs.y - std::sin(phi)));
    if (err > worst) worst = err, worst_u = u;
  }
  RecordProperty("max_abs_error", std::to_string(worst));
  EXPECT_LT(worst, 1e-6) << "at u = " << worst_u;
}

TEST(Sampling, FastCosineHemisphereIsTheSameMapAsCosineHemisphere) {
  Rng rng(7, 3);
  double worst = 0.0, worst_norm = 0.0;
  for (int k = 0; k < 200000; ++k) {
    const glm::vec2 u = rng.next_2d();
    const glm::vec3 a = cosine_hemisphere(u), b = cosine_hemisphere_fast(u);
    for (int c = 0; c < 3; ++c)
      worst = std::max(worst, static_cast<double>(std::fabs(a[c] - b[c])));
    worst_norm = std::max(worst_norm, static_cast<double>(std::fabs(glm::length(b) - 1.0f)));
    ASSERT_GE(b.z, 0.0f);
  }
  EXPECT_LT(worst, 2e-6);
  EXPECT_LT(worst_norm, 2e-6);
}

}  // namespace
}  // namespace irradcast::test_sampling

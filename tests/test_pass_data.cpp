// pass_data.h: a texel's probes and weights worked out from the corners it reads
// (probe_weights).
#include <gtest/gtest.h>

#include <glm/glm.hpp>

#include "irradcast/engine/pass_data.h"

namespace irradcast::test_pass_data {
namespace {

ProbeGrid grid_4x4x4() {
  ProbeGrid g;
  g.dims = glm::ivec3(4);
  g.origin = glm::vec3(0.0f);
  g.cell = 1.0f;
  g.position.resize(64);
  g.usable.assign(64, 1);
  for (std::size_t i = 0; i < g.position.size(); ++i) g.position[i] = g.centre(i);
  return g;
}

// The trilinear weight of corner c of the cell block around p, from the probe centres.
float trilinear(const ProbeGrid& g, glm::vec3 p, int c) {
  const glm::vec3 f = (p - g.origin) / g.cell - 0.5f;
  const glm::vec3 t = f - glm::floor(f);
  const glm::vec3 w((c & 1) ? t.x : 1.0f - t.x, (c & 2) ? t.y : 1.0f - t.y,
                    (c & 4) ? t.z : 1.0f - t.z);
  return w.x * w.y * w.z;
}

TEST(ProbeWeights, AllEightCornersGiveTheTrilinearWeightsOfTheirProbes) {
  const ProbeGrid g = grid_4x4x4();
  const glm::vec3 p(1.3f, 1.7f, 2.2f);  // between the centres 0.5 .. 3.5 on every axis
  const ProbeWeights w = probe_weights(g, p, 0xff);
  ASSERT_EQ(w.count(), 8);
  float sum = 0.0f;
  for (int k = 0; k < 8; ++k) {
    // In corner order: probe k is corner k, the cell (0 or 1 above the block's base per axis).
    const glm::ivec3 base(0, 1, 1);  // floor((p - 0.5) / 1)
    const glm::ivec3 cell = base + glm::ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
    EXPECT_EQ(w.probe(k, g.dims), static_cast<std::uint32_t>((cell.z * 4 + cell.y) * 4 + cell.x));
    EXPECT_NEAR(w.weight[k], trilinear(g, p, k), 1e-6f) << "corner " << k;
    sum += w.weight[k];
  }
  EXPECT_NEAR(sum, 1.0f, 1e-6f);
}

TEST(ProbeWeights, ACornerLeftOutSharesItsWeightWithTheOthers) {
  const ProbeGrid g = grid_4x4x4();
  const glm::vec3 p(1.3f, 1.7f, 2.2f);
  const std::uint8_t mask = (1u << 0) | (1u << 5) | (1u << 6);
  const ProbeWeights w = probe_weights(g, p, mask);
  ASSERT_EQ(w.count(), 3);
  const int corners[3] = {0, 5, 6};
  float total = 0.0f;
  for (int c : corners) total += trilinear(g, p, c);
  for (int k = 0; k < 3; ++k) {
    const ProbeWeights all = probe_weights(g, p, 0xff);
    EXPECT_EQ(w.probe(k, g.dims), all.probe(corners[k], g.dims));
    EXPECT_NEAR(w.weight[k], trilinear(g, p, corners[k]) / total, 1e-6f) << "probe " << k;
  }
  EXPECT_EQ(probe_weights(g, p, 0).count(), 0);  // a texel that sees none reads none
}

TEST(ProbeWeights, AreAPureFunctionOfPositionGridAndMask) {
  // The scatter, a miss on the reference path and the Vulkan upload each work them out again:
  // the same bits every time.
  const ProbeGrid g = grid_4x4x4();
  for (std::uint32_t mask = 1; mask < 256; mask += 7) {
    const glm::vec3 p(0.2f + 0.013f * static_cast<float>(mask), 2.9f, 0.6f);
    const ProbeWeights a = probe_weights(g, p, static_cast<std::uint8_t>(mask));
    const ProbeWeights b = probe_weights(g, p, static_cast<std::uint8_t>(mask));
    ASSERT_EQ(a.count(), b.count());
    EXPECT_EQ(a.base, b.base);
    EXPECT_EQ(a.corners, b.corners);
    for (int k = 0; k < a.count(); ++k) EXPECT_EQ(a.weight[k], b.weight[k]);
    // At least 1e-4 each before the division: a corner read is never weightless.
    for (int k = 0; k < a.count(); ++k) EXPECT_GT(a.weight[k], 0.0f);
  }
}

}  // namespace
}  // namespace irradcast::test_pass_data

// The lightmap denoiser (server/engine/denoise.h): on synthetic texels (planes with known
// irradiance and noise) it brings a noisy constant field closer to the truth, keeps a step in
// irradiance and a crease between charts sharp, uses neighbours across a chart seam, never moves
// a texel beyond its confidence interval and keeps the energy of a uniform patch; in the engine
// it filters a copy (the means stay), and a host with it publishes the denoised lightmaps with
// tile versions that settle as without it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "engine_setup.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/denoise.h"
#include "irradcast/service/engine_host.h"
#include "service_fixture.h"

namespace irradcast::test_denoise {
namespace {

// An n x n grid of texels (texel size 1) on a plane through `origin` spanned by `u` and `v`,
// appended to `t` with chart `chart(i, j)`.
struct Texels {
  SurfaceTexels t;
  DenoiseGuide guide{{}, {1.0f}, {1}};
  std::vector<glm::vec3> value, truth;
  std::vector<float> se;

  template <class Chart, class Truth>
  void plane(int n, glm::vec3 origin, glm::vec3 u, glm::vec3 v, Chart chart, Truth level,
             float sigma, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> noise(0.0f, sigma);
    const glm::vec3 normal = glm::normalize(glm::cross(u, v));
    guide.width[0] = n;  // the planes' texels follow each other in one lightmap, n per row
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        t.position.push_back(origin + (i + 0.5f) * u + (j + 0.5f) * v);
        t.normal.push_back(normal);
        t.object.push_back(0);
        t.texel.push_back(static_cast<std::uint32_t>(t.texel.size()));
        t.triangle.push_back(0);
        guide.chart.push_back(chart(i, j));
        const float e = level(i, j);
        truth.push_back(glm::vec3(e));
        value.push_back(glm::vec3(e + noise(rng)));
        se.push_back(sigma);
      }
  }
  std::vector<glm::vec3> run(DenoiseStats* stats = nullptr) const {
    return denoise(t, guide, value, se, {}, stats);
  }
};

double rmse(const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b) {
  double s = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) s += glm::dot(a[i] - b[i], a[i] - b[i]) / 3.0;
  return std::sqrt(s / static_cast<double>(a.size()));
}

// Mean luminance of column i of the first n x n plane (or of the plane starting at `first`).
double column_mean(const std::vector<glm::vec3>& v, int n, int i, std::size_t first = 0) {
  double s = 0.0;
  for (int j = 0; j < n; ++j) s += luminance(v[first + static_cast<std::size_t>(j) * n + i]);
  return s / n;
}

const auto one_chart = [](int, int) { return 0u; };

TEST(Denoise, BringsANoisyConstantFieldCloserToTheTruth) {
  Texels x;
  x.plane(
      48, glm::vec3(0), {1, 0, 0}, {0, 1, 0}, one_chart, [](int, int) { return 1.0f; }, 0.1f, 1);
  DenoiseStats st;
  const std::vector<glm::vec3> out = x.run(&st);
  const double before = rmse(x.value, x.truth), after = rmse(out, x.truth);
  EXPECT_NEAR(before, 0.1, 0.01);
  EXPECT_LT(after, 0.5 * before) << "before " << before << " after " << after;
  EXPECT_GT(st.filtered, 48u * 48u * 95 / 100);
  EXPECT_EQ(st.unknown, 0u);
}

TEST(Denoise, KeepsAStepInIrradianceSharp) {
  Texels x;
  const int n = 48;
  x.plane(
      n, glm::vec3(0), {1, 0, 0}, {0, 1, 0}, one_chart,
      [&](int i, int) { return i < n / 2 ? 1.0f : 3.0f; }, 0.05f, 2);
  const std::vector<glm::vec3> out = x.run();
  // The columns on either side of the step keep their level (a blur would move them by ~0.5).
  EXPECT_NEAR(column_mean(out, n, n / 2 - 1), 1.0, 0.03);
  EXPECT_NEAR(column_mean(out, n, n / 2), 3.0, 0.03);
  EXPECT_LT(rmse(out, x.truth), 0.6 * rmse(x.value, x.truth));
}

TEST(Denoise, DoesNotAverageAcrossACreaseButUsesNeighboursAcrossASeam) {
  // A floor (chart 0) meeting a wall (chart 1) at x = 0, with light levels 1 and 1.3 that differ
  // by no more than the noise: only the geometry keeps them apart.
  const int n = 32;
  Texels crease;
  crease.plane(
      n, glm::vec3(-n, 0, 0), {1, 0, 0}, {0, 0, 1}, one_chart, [](int, int) { return 1.0f; }, 0.3f,
      3);
  crease.plane(
      n, glm::vec3(0, 0, 0), {0, 1, 0}, {0, 0, 1}, [](int, int) { return 1u; },
      [](int, int) { return 1.3f; }, 0.3f, 4);
  DenoiseStats st;
  std::vector<glm::vec3> out = crease.run(&st);
  const std::size_t wall = static_cast<std::size_t>(n) * n;
  EXPECT_NEAR(column_mean(out, n, n - 1), 1.0, 0.05) << "floor texels at the crease";
  EXPECT_NEAR(column_mean(out, n, 0, wall), 1.3, 0.05) << "wall texels at the crease";
  EXPECT_EQ(st.seams, 0u);
  // The same floor cut into two charts at x = n/2 (a seam in one plane): the texels at the seam
  // use the other chart's texels and come out as smooth as those inside.
  Texels seam;
  seam.plane(
      n, glm::vec3(0), {1, 0, 0}, {0, 1, 0}, [&](int i, int) { return i < n / 2 ? 0u : 1u; },
      [](int, int) { return 1.0f; }, 0.3f, 5);
  out = seam.run(&st);
  EXPECT_GE(st.seams, static_cast<std::size_t>(2 * n)) << "the two columns at the seam at least";
  double at_seam = 0.0, inside = 0.0;
  for (int j = 0; j < n; ++j) {
    const auto k = [&](int i) { return static_cast<std::size_t>(j) * n + i; };
    at_seam += std::pow(luminance(out[k(n / 2)]) - 1.0, 2) +
               std::pow(luminance(out[k(n / 2 - 1)]) - 1.0, 2);
    inside += std::pow(luminance(out[k(n / 4)]) - 1.0, 2) +
              std::pow(luminance(out[k(3 * n / 4)]) - 1.0, 2);
  }
  EXPECT_LT(at_seam, 2.0 * inside) << "the seam's texels are as smooth as the chart's inside";
  EXPECT_LT(std::sqrt(at_seam / (2 * n)), 0.5 * 0.3);
}

TEST(Denoise, NeverMovesATexelOutsideItsConfidenceAndKeepsTheEnergyOfAUniformPatch) {
  Texels x;
  const int n = 40;
  // A uniform patch with heavy noise and a few fireflies.
  x.plane(
      n, glm::vec3(0), {1, 0, 0}, {0, 1, 0}, one_chart, [](int, int) { return 2.0f; }, 0.4f, 6);
  for (std::size_t i = 0; i < x.value.size(); i += 97) x.value[i] *= 6.0f;
  x.se[5] = 0.0f;  // a texel without a noise estimate
  DenoiseStats st;
  const std::vector<glm::vec3> out = x.run(&st);
  const float z = DenoiseOptions{}.confidence;
  double sum_in = 0.0, sum_out = 0.0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    ASSERT_LE(std::abs(luminance(out[i]) - luminance(x.value[i])), z * 0.4f + 1e-5f) << i;
    sum_in += luminance(x.value[i]);
    sum_out += luminance(out[i]);
  }
  EXPECT_EQ(out[5], x.value[5]) << "no noise estimate: kept";
  EXPECT_EQ(st.unknown, 1u);
  for (std::size_t i = 97; i < out.size(); i += 97)
    EXPECT_GT(luminance(out[i]), 0.95f * luminance(x.value[i])) << "a firefly keeps its light";
  EXPECT_NEAR(sum_out / sum_in, 1.0, 0.01) << "no light removed";
  // A filter that would average everything (no range test) with a narrow confidence interval:
  // the texels whose average lands outside it keep their own value, the others move at most
  // that far.
  DenoiseOptions wide;
  wide.range_sigmas = 1e3f;
  wide.confidence = 0.5f;
  const std::vector<glm::vec3> narrow = denoise(x.t, x.guide, x.value, x.se, wide, &st);
  EXPECT_GT(st.kept, out.size() / 4);
  EXPECT_GT(st.filtered, out.size() / 4);
  for (std::size_t i = 0; i < out.size(); ++i)
    ASSERT_LE(std::abs(luminance(narrow[i]) - luminance(x.value[i])), 0.5f * 0.4f + 1e-5f) << i;
}

TEST(Denoise, RefusesMismatchedInput) {
  Texels x;
  x.plane(
      4, glm::vec3(0), {1, 0, 0}, {0, 1, 0}, one_chart, [](int, int) { return 1.0f; }, 0.1f, 7);
  x.se.pop_back();
  EXPECT_THROW(x.run(), Error);
}

// The engine filters a copy: its means (lightmaps()) stay, and 4 denoised updates of the
// cornell box are closer to a longer plain run (another seed) than 4 plain ones.
TEST(Denoise, EnginePublishesADenoisedCopyCloserToTheConvergedImage) {
  test::EngineSetup s(make_cornell_box(), 32.0f);
  EngineParams p;
  p.denoise = true;
  auto engine = s.engine(p);
  for (int u = 0; u < 4; ++u) engine->update();
  const std::vector<Lightmap> plain = engine->lightmaps();
  DenoiseStats st;
  const std::vector<Lightmap> denoised = engine->published_lightmaps(&st);
  EXPECT_GT(st.filtered, 0u);
  const std::vector<Lightmap> again = engine->lightmaps();
  for (std::size_t o = 0; o < plain.size(); ++o) ASSERT_EQ(plain[o].texels, again[o].texels);
  EngineParams q = p;
  q.seed = 77;
  q.denoise = false;
  auto converged = s.engine(q);
  for (int u = 0; u < 24; ++u) converged->update();
  const std::vector<Lightmap> truth = converged->lightmaps();
  double e_plain = 0.0, e_denoised = 0.0;
  for (std::size_t o = 0; o < truth.size(); ++o)
    for (std::size_t k = 0; k < truth[o].texels.size(); ++k) {
      if (!s.gbuffers[o].valid(k)) continue;
      e_plain += std::pow(luminance(plain[o].texels[k] - truth[o].texels[k]), 2);
      e_denoised += std::pow(luminance(denoised[o].texels[k] - truth[o].texels[k]), 2);
    }
  RecordProperty("squared_error_ratio", std::to_string(e_denoised / e_plain));
  EXPECT_LT(e_denoised, 0.7 * e_plain) << e_denoised << " vs " << e_plain;
}

// A host with --denoise publishes the denoised lightmaps (those of an engine with the same
// parameters, within the tile store's change threshold), and once converged its tiles get new
// versions no more often than a plain host's.
TEST(Denoise, AHostWithItPublishesDenoisedTilesAndVersionsSettle) {
  struct Run {
    std::vector<Lightmap> published;
    std::uint64_t late_versions = 0;  // tiles published in updates 9..16
  };
  const auto run = [](bool denoise, std::uint32_t updates, std::uint32_t max_updates) {
    EngineHostOptions o = test::host_options(32.0f, max_updates);
    o.backend.kind = BackendKind::Embree;
    o.engine.denoise = denoise;
    EngineHost host(make_cornell_box(), "cornell", o);
    Run r;
    for (std::uint32_t u = 0; u < updates; ++u) {
      if (u == 8) r.late_versions = host.stats().tiles_published;
      host.step();
    }
    r.late_versions = host.stats().tiles_published - r.late_versions;
    r.published = host.tiles().published();
    return r;
  };
  // Final after 6 updates: every tile that changed beyond the threshold is published.
  const Run host = run(true, 6, 6);
  test::EngineSetup s(make_cornell_box(), 32.0f);
  EngineParams p;
  p.denoise = true;
  auto engine = s.engine(p);
  for (int u = 0; u < 6; ++u) engine->update();
  const std::vector<Lightmap> denoised = engine->published_lightmaps(), plain = engine->lightmaps();
  double to_denoised = 0.0, to_plain = 0.0, level = 0.0;
  std::size_t count = 0;
  for (std::size_t o = 0; o < denoised.size(); ++o)
    for (std::size_t k = 0; k < denoised[o].texels.size(); ++k) {
      if (!s.gbuffers[o].valid(k)) continue;
      const float h = luminance(host.published[o].texels[k]);
      to_denoised += std::pow(h - luminance(denoised[o].texels[k]), 2);
      to_plain += std::pow(h - luminance(plain[o].texels[k]), 2);
      level += luminance(plain[o].texels[k]);
      ++count;
    }
  level /= static_cast<double>(count);
  const double rel_denoised = std::sqrt(to_denoised / count) / level;
  const double rel_plain = std::sqrt(to_plain / count) / level;
  RecordProperty("host_to_denoised", std::to_string(rel_denoised));
  RecordProperty("host_to_plain", std::to_string(rel_plain));
  EXPECT_LT(rel_denoised, 0.02);
  EXPECT_GT(rel_plain, 2.0 * rel_denoised) << rel_plain << " vs " << rel_denoised;
  // Versions settle as without the denoiser (noise-aware tile versions).
  const Run plain_run = run(false, 16, 0), denoised_run = run(true, 16, 0);
  RecordProperty("late_versions_plain", std::to_string(plain_run.late_versions));
  RecordProperty("late_versions_denoised", std::to_string(denoised_run.late_versions));
  EXPECT_LE(denoised_run.late_versions, plain_run.late_versions + plain_run.late_versions / 4 + 2)
      << denoised_run.late_versions << " vs " << plain_run.late_versions;
}

}  // namespace
}  // namespace irradcast::test_denoise

// irradcast-bench-lights: three ways to pick an area light, side by side on the same texels in
// one run: by power alone (LightSampler::pick_triangle), by the light hierarchy
// (LightSampler::pick: the path tracer past kMaxFront emissive triangles) and by the hierarchy
// mixed with the tables the engine's direct pass learns (LightCache: the engine's direct pass
// past kMaxFront), the tables learned first in --learn-updates passes over every texel. Each way
// draws `--samples` one-sample estimates of the direct irradiance at every `--step`-th texel (a
// light picked, a point on it, a shadow ray), interleaved texel by texel so that all see the
// same machine state. Reports per scene and way: time per sample, the share of shadow rays that
// end occluded, its mean over power's (all unbiased: near 1) and the speed-up at equal error
// over power (time x variance), per texel and over the scene, as a table and JSON
// (docs/bench/engine.md, "Many lights").
//   irradcast-bench-lights --scenes rooms:6,rooms:6:trim,rooms:12:trim --out out/lights
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "irradcast/common/builtin.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/prepared_scene.h"

using namespace irradcast;

namespace {

using Clock = std::chrono::steady_clock;

// The three ways to pick an area light.
enum Way { kPower, kTree, kLearned, kWays };
const char* const kWayName[kWays] = {"power", "tree", "learned"};

struct Estimator {
  double seconds = 0.0;
  std::uint64_t samples = 0, rays = 0, occluded = 0;
  double variance_sum = 0.0;  // over texels: the variance of the texel's mean, relative
  double raw_variance = 0.0;  // over texels: the variance of the texel's mean
  double mean_sum = 0.0;
};

// One sample of the direct irradiance at p with the light picked by `way` (0 unless its
// shadow ray came back unoccluded, and then the light in *light).
glm::vec3 sample(const LightSampler& l, const RayScene& rays, const LightCache& cache, glm::vec3 p,
                 glm::vec3 n, Way way, glm::vec3 u, Estimator& e, std::size_t* light = nullptr) {
  std::size_t i;
  float pdf;
  bool ok = true;
  if (way == kPower) {
    i = l.pick_triangle(u.x);
    pdf = l.pick_pdf()[i];
  } else {
    const LightCache::Table* table =
        way == kLearned && cache.valid() ? cache.find(cache.region(p, n)) : nullptr;
    ok = l.pick(p, n, u.x, i, pdf, table);
  }
  LightSampler::ShadowSample s;
  if (!ok || !l.triangle_sample(rays, i, p, n, n, glm::vec2(u.y, u.z), s)) return glm::vec3(0.0f);
  if (s.shadow.tmax > 0.0f) {
    const bool blocked = rays.occluded(s.shadow);
    ++e.rays;
    e.occluded += blocked;
    if (blocked) return glm::vec3(0.0f);
  }
  if (light) *light = i;
  return l.triangle_emitted(s) / pdf;
}

// One texel's `samples` estimates (stratified in the pick); its mean and the variance of that.
void run_texel(const LightSampler& l, const RayScene& rays, const LightCache& cache, glm::vec3 p,
               glm::vec3 n, Way way, int samples, Rng& rng, Estimator& e, double& mean,
               double& var) {
  const auto start = Clock::now();
  double sum = 0.0, sq = 0.0;
  for (int k = 0; k < samples; ++k) {
    const float u = (static_cast<float>(k) + rng.next_float()) / static_cast<float>(samples);
    const glm::vec2 pos = rng.next_2d();
    const glm::vec3 c = sample(l, rays, cache, p, n, way, glm::vec3(u, pos), e);
    const double v = static_cast<double>(c.x) + c.y + c.z;
    sum += v;
    sq += v * v;
  }
  e.seconds += std::chrono::duration<double>(Clock::now() - start).count();
  e.samples += static_cast<std::uint64_t>(samples);
  mean = sum / samples;
  var = std::max(sq / samples - mean * mean, 0.0) / samples;  // of the mean
}

// What the engine's direct pass learns in `updates` updates: 8 samples at every texel, picked
// with what was learned so far (EmbreeBackend::area_direct's records).
LightCache learn(const PreparedScene& s, int updates) {
  const LightSampler& l = s.lights();
  if (l.tree().empty()) return LightCache();
  float unit = 0.0f;
  for (const EmissiveTriangle& t : l.emissive_triangles())
    if (t.uniform_emission) unit = std::max(unit, luminance(t.emission));
  LightCache cache(s.world().bounds, l.emissive_triangles().size(), unit > 0.0f ? unit : 1.0f);
  Rng rng(7);
  Estimator ignored;
  constexpr int kSamples = 8;
  for (int update = 0; update < updates; ++update) {
    LightCache::Record record(cache.unit());
    for (const TexelGBuffer& g : s.gbuffers())
      for (std::size_t i = 0; i < g.size(); ++i) {
        if (!g.valid(i)) continue;
        const std::uint64_t region = cache.region(g.position[i], g.normal[i]);
        for (int k = 0; k < kSamples; ++k) {
          const glm::vec3 u((static_cast<float>(k) + rng.next_float()) / kSamples, rng.next_2d());
          std::size_t light = 0;
          const glm::vec3 c =
              sample(l, s.rays(), cache, g.position[i], g.normal[i], kLearned, u, ignored, &light);
          record.add(region, static_cast<std::uint32_t>(light), luminance(c));
        }
      }
    cache.learn({&record});
  }
  return cache;
}

// One scene: the three estimators on every step-th texel, a row printed; its JSON.
nlohmann::json measure_scene(const std::string& spec, int samples, int step, int updates) {
  Scene scene = load_scene(spec);
  PreparedSceneOptions o;
  o.name = spec;
  PreparedScene s = PreparedScene::build(std::move(scene), o);
  const LightSampler& l = s.lights();
  const auto learn_start = Clock::now();
  const LightCache cache = learn(s, updates);
  const double learn_s = std::chrono::duration<double>(Clock::now() - learn_start).count();
  Estimator est[kWays];
  Rng rng(1);
  std::size_t k = 0, texels = 0;
  double truth_sq = 0.0;
  for (const TexelGBuffer& g : s.gbuffers())
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i) || k++ % static_cast<std::size_t>(step) != 0) continue;
      double m[kWays], v[kWays], truth = 0.0;
      for (int w = 0; w < kWays; ++w) {
        run_texel(l, s.rays(), cache, g.position[i], g.normal[i], static_cast<Way>(w), samples, rng,
                  est[w], m[w], v[w]);
        truth += m[w] / static_cast<double>(kWays);
      }
      // The variance of each texel's mean relative to its squared mean (the estimators' means
      // averaged: the same truth), so bright and dim texels count alike.
      for (int w = 0; w < kWays; ++w) {
        if (truth > 0.0) est[w].variance_sum += v[w] / (truth * truth);
        est[w].raw_variance += v[w];
        est[w].mean_sum += m[w];
      }
      truth_sq += truth * truth;
      ++texels;
    }
  auto ns = [](const Estimator& e) { return 1e9 * e.seconds / static_cast<double>(e.samples); };
  auto occl = [](const Estimator& e) {
    return e.rays ? static_cast<double>(e.occluded) / static_cast<double>(e.rays) : 0.0;
  };
  // Per texel: the relative variances averaged; over the scene: the variances summed over the
  // squared means summed (bright texels weigh more, as in a lightmap's RMSE). Speed-up: power's
  // time x variance over the way's (time to the same error).
  auto rv = [&](const Estimator& e) { return e.variance_sum / static_cast<double>(texels); };
  auto sv = [&](const Estimator& e) { return e.raw_variance / truth_sq; };
  std::printf("%-16s %9zu %7zu |", spec.c_str(), l.emissive_triangles().size(), texels);
  nlohmann::json row{{"scene", spec},
                     {"emissive_triangles", l.emissive_triangles().size()},
                     {"tree_used", !l.tree().empty()},
                     {"texels", texels},
                     {"samples_per_texel", samples},
                     {"learned_regions", cache.regions()},
                     {"learning_updates", updates},
                     {"learning_seconds", learn_s}};
  for (int w = 0; w < kWays; ++w) {
    const Estimator& e = est[w];
    const double speedup = (est[kPower].seconds * rv(est[kPower])) / (e.seconds * rv(e));
    const double scene_speedup = (est[kPower].seconds * sv(est[kPower])) / (e.seconds * sv(e));
    const double means = e.mean_sum / est[kPower].mean_sum;
    if (w > 0)
      std::printf(" %6.0f %5.1f%% %6.3f %6.1fx %6.1fx |", ns(e), 100.0 * occl(e), means, speedup,
                  scene_speedup);
    else
      std::printf(" %6.0f %5.1f%% |", ns(e), 100.0 * occl(e));
    row[kWayName[w]] = {{"ns_per_sample", ns(e)},
                        {"occluded", occl(e)},
                        {"relative_variance", rv(e)},
                        {"scene_variance", sv(e)},
                        {"mean_ratio_to_power", means},
                        {"speedup_at_equal_error", speedup},
                        {"scene_speedup_at_equal_error", scene_speedup}};
  }
  std::printf("\n");
  std::fflush(stdout);
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-lights: area lights picked by the light hierarchy vs by power"};
  std::string scenes = "rooms:6,rooms:6:trim,rooms:12:trim", out = "out/lights";
  int samples = 64, step = 40, updates = 4;
  app.add_option("--scenes", scenes, "scene specs, comma separated");
  app.add_option("--samples", samples, "samples per texel per estimator")
      ->check(CLI::Range(1, 1 << 16));
  app.add_option("--step", step, "every step-th texel")->check(CLI::Range(1, 1 << 20));
  app.add_option("--learn-updates", updates,
                 "direct passes the learned way learns from before it is measured")
      ->check(CLI::Range(1, 64));
  app.add_option("--out", out, "directory for bench_lights.json");
  CLI11_PARSE(app, argc, argv);
  Progress::set_enabled(false);
  nlohmann::json report = nlohmann::json::array();
  std::printf("%-16s %9s %7s | %6s %6s | %6s %6s %6s %7s %7s | %6s %6s %6s %7s %7s |\n", "scene",
              "emissive", "texels", "power", "occl", "tree", "occl", "means", "texel", "scene",
              "learnd", "occl", "means", "texel", "scene");
  std::size_t from = 0;
  while (from <= scenes.size()) {
    const std::size_t comma = std::min(scenes.find(',', from), scenes.size());
    const std::string spec = scenes.substr(from, comma - from);
    from = comma + 1;
    if (spec.empty()) continue;
    report.push_back(measure_scene(spec, samples, step, updates));
  }
  std::printf(
      "ns per sample and occluded share of shadow rays per way; means: its mean over power's "
      "(all unbiased: near 1); texel / scene: the speed-up at equal error over power (time x "
      "variance), per texel (relative variances averaged) and over the scene (variances summed "
      "over squared means summed, as a lightmap's RMSE weighs them). learned: the hierarchy "
      "mixed with the tables learned in --learn-updates direct passes over every texel.\n");
  std::filesystem::create_directories(out);
  std::ofstream(out + "/bench_lights.json") << report.dump(2) << "\n";
  std::printf("wrote %s/bench_lights.json\n", out.c_str());
  return 0;
}

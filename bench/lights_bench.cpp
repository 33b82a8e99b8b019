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
// (docs/bench/engine.md, "Many lights"). With --oracle, also the floor of the occluded share:
// each texel's own pick in proportion to what each light brings it.
//   irradcast-bench-lights --scenes rooms:6,rooms:6:trim,rooms:12:trim --out out/lights
#include "irradcast/common/cli.h"

#include <algorithm>
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

// What a sample traced: its light, and the luminance of the light's emitted irradiance (0
// when its shadow ray was occluded); light -1 when it traced no ray.
struct Traced {
  std::int64_t light = -1;
  float luminance = 0.0f;
};

// One sample of the direct irradiance at p with the light picked by `way` (0 unless its
// shadow ray came back unoccluded); what it traced to *traced.
// The hierarchy and learned ways pick as the engine's direct pass does (LightSampler::
// direct_sample): among `front`, the lights in front of p, where the scene has at most kMaxFront
// (by power; learned: mixed with the region's table), else by the hierarchy (learned: mixed).
glm::vec3 sample(const LightSampler& l, const RayScene& rays, const LightCache& cache,
                 const LightSampler::FrontLights* front, glm::vec3 p, glm::vec3 n,
                 std::uint32_t object, Way way, glm::vec3 u, Estimator& e,
                 Traced* traced = nullptr) {
  LightSampler::ShadowSample s;
  glm::vec3 weight(0.0f);
  if (way == kPower) {
    const std::size_t i = l.pick_triangle(u.x);
    if (!l.triangle_sample(rays, i, p, n, n, glm::vec2(u.y, u.z), s)) return glm::vec3(0.0f);
    weight = l.triangle_emitted(s) / l.pick_pdf()[i];
  } else {
    const LightCache::Table* table =
        way == kLearned && cache.valid()
            ? cache.table_for(cache.region(p, n, object), front != nullptr)
            : nullptr;
    if (!l.direct_sample(rays, front, p, n, n, u, s, weight, table)) return glm::vec3(0.0f);
  }
  const std::size_t i = s.triangle;
  bool blocked = false;
  if (s.shadow.tmax > 0.0f) {
    blocked = rays.occluded(s.shadow);
    ++e.rays;
    e.occluded += blocked;
    if (traced) traced->light = static_cast<std::int64_t>(i);
  }
  if (blocked) return glm::vec3(0.0f);
  if (traced) traced->luminance = luminance(l.triangle_emitted(s));
  return weight;
}

// One texel's `samples` estimates (stratified in the pick; learned: an eighth of them where the
// patch is dark, as the engine's pass takes); its mean and the variance of that.
void run_texel(const LightSampler& l, const RayScene& rays, const LightCache& cache, glm::vec3 p,
               glm::vec3 n, std::uint32_t object, Way way, int samples, Rng& rng, Estimator& e,
               double& mean, double& var) {
  const auto start = Clock::now();
  if (way == kLearned && cache.valid())
    samples = cache.samples_in(cache.patch(p, n, object), samples);
  LightSampler::FrontLights front;
  const bool culled = l.front_lights(p, n, front);
  double sum = 0.0, sq = 0.0;
  for (int k = 0; k < samples; ++k) {
    const float u = (static_cast<float>(k) + rng.next_float()) / static_cast<float>(samples);
    const glm::vec2 pos = rng.next_2d();
    const glm::vec3 c =
        sample(l, rays, cache, culled ? &front : nullptr, p, n, object, way, glm::vec3(u, pos), e);
    const double v = static_cast<double>(c.x) + c.y + c.z;
    sum += v;
    sq += v * v;
  }
  e.seconds += std::chrono::duration<double>(Clock::now() - start).count();
  e.samples += static_cast<std::uint64_t>(samples);
  mean = sum / samples;
  var = std::max(sq / samples - mean * mean, 0.0) / samples;  // of the mean
}

// The oracle: the texel's own light choice, in proportion to what each light brings it (each
// light's irradiance at p from 4 x 4 stratified points with their shadow rays), then `samples`
// samples picked that way; returns how many of their shadow rays ended occluded, -1 when no
// light brings p anything (where every ray of any pick ends occluded: the caller counts the
// hierarchy's). No picking of a light can waste fewer rays, so this is the floor of the occluded
// share for a light pick followed by a uniform point on the light, at a fixed number of samples
// per texel (only a choice of the point, or fewer samples where no light reaches, could go
// lower).
double oracle_occluded(const LightSampler& l, const RayScene& rays, glm::vec3 p, glm::vec3 n,
                       int samples, Rng& rng, std::uint64_t& traced) {
  const std::size_t lights = l.emissive_triangles().size();
  std::vector<double> cdf(lights);
  double total = 0.0;
  for (std::size_t i = 0; i < lights; ++i) {
    for (int q = 0; q < 16; ++q) {
      const glm::vec2 u((static_cast<float>(q % 4) + 0.5f) / 4.0f,
                        (static_cast<float>(q / 4) + 0.5f) / 4.0f);
      total += luminance(l.triangle_irradiance(rays, i, p, n, n, u)) / 16.0;
    }
    cdf[i] = total;
  }
  if (!(total > 0.0)) return -1.0;
  std::uint64_t rays_traced = 0, occluded = 0;
  for (int k = 0; k < samples; ++k) {
    const double u = (static_cast<double>(k) + rng.next_float()) / samples * total;
    const std::size_t i = std::min<std::size_t>(
        static_cast<std::size_t>(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin()),
        lights - 1);
    LightSampler::ShadowSample sm;
    if (!l.triangle_sample(rays, i, p, n, n, rng.next_2d(), sm) || !(sm.shadow.tmax > 0.0f))
      continue;
    ++rays_traced;
    occluded += rays.occluded(sm.shadow);
  }
  traced += rays_traced;
  return static_cast<double>(occluded);
}

// What the engine's direct pass learns in `updates` updates: 8 samples at every texel, picked
// with what was learned so far, each traced ray recorded (EmbreeBackend::area_direct's records).
LightCache learn(const PreparedScene& s, int updates) {
  const LightSampler& l = s.lights();
  if (l.emissive_triangles().size() < LightCache::kLearnFrom) return LightCache();
  float unit = 0.0f;
  for (const EmissiveTriangle& t : l.emissive_triangles())
    if (t.uniform_emission) unit = std::max(unit, luminance(t.emission));
  LightCache cache(s.world().bounds, l.emissive_triangles().size(), unit > 0.0f ? unit : 1.0f);
  Rng rng(7);
  Estimator ignored;
  constexpr int kSamples = 8;
  for (int update = 0; update < updates; ++update) {
    LightCache::Record record(cache.unit());
    for (std::uint32_t o = 0; o < s.gbuffers().size(); ++o) {
      const TexelGBuffer& g = s.gbuffers()[o];
      for (std::size_t i = 0; i < g.size(); ++i) {
        if (!g.valid(i)) continue;
        const TexelPoint p = g.point(s.world().objects[o], i);
        const std::uint64_t region = cache.region(p.position, p.normal, o);
        const std::uint64_t patch = cache.patch(p.position, p.normal, o);
        const int count = cache.samples_in(patch, kSamples);
        std::uint32_t rays = 0, lit = 0;
        LightSampler::FrontLights front;
        const bool culled = l.front_lights(p.position, p.normal, front);
        for (int k = 0; k < count; ++k) {
          const glm::vec3 u((static_cast<float>(k) + rng.next_float()) / static_cast<float>(count),
                            rng.next_2d());
          Traced t;
          sample(l, s.rays(), cache, culled ? &front : nullptr, p.position, p.normal, o, kLearned,
                 u, ignored, &t);
          if (t.light < 0) continue;
          record.add(region, static_cast<std::uint32_t>(t.light), t.luminance);
          ++rays;
          lit += t.luminance > 0.0f ? 1u : 0u;
        }
        record.add_patch(patch, rays, lit);
      }
    }
    cache.learn({&record});
  }
  return cache;
}

// One scene: the three estimators on every step-th texel, a row printed; its JSON.
// Every step-th visible texel of the scene, sampled `samples` times by each way (and by the
// oracle, where asked).
struct Tally {
  Estimator est[kWays];
  std::size_t texels = 0;
  double truth_sq = 0.0;
  std::uint64_t oracle_rays = 0, oracle_occluded_rays = 0;
  std::size_t dark_texels = 0;
};

Tally sample_scene(const PreparedScene& s, const LightCache& cache, int samples, int step,
                   bool oracle) {
  const LightSampler& l = s.lights();
  Tally t;
  Estimator* est = t.est;
  Rng rng(1);
  std::size_t k = 0;
  for (std::uint32_t o = 0; o < s.gbuffers().size(); ++o) {
    const TexelGBuffer& g = s.gbuffers()[o];
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i) || k++ % static_cast<std::size_t>(step) != 0) continue;
      const TexelPoint p = g.point(s.world().objects[o], i);
      double m[kWays], v[kWays], truth = 0.0;
      const std::uint64_t tree_rays_before = est[kTree].rays;
      for (int w = 0; w < kWays; ++w) {
        run_texel(l, s.rays(), cache, p.position, p.normal, o, static_cast<Way>(w), samples, rng,
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
      t.truth_sq += truth * truth;
      ++t.texels;
      if (oracle) {
        const double blocked =
            oracle_occluded(l, s.rays(), p.position, p.normal, samples, rng, t.oracle_rays);
        if (blocked >= 0.0) {
          t.oracle_occluded_rays += static_cast<std::uint64_t>(blocked);
        } else {  // no light reaches the texel: any pick's rays end occluded (the hierarchy's)
          t.oracle_rays += est[kTree].rays - tree_rays_before;
          t.oracle_occluded_rays += est[kTree].rays - tree_rays_before;
          ++t.dark_texels;
        }
      }
    }
  }
  return t;
}

nlohmann::json measure_scene(const std::string& spec, int samples, int step, int updates,
                             bool oracle) {
  Scene scene = load_scene(spec);
  PreparedSceneOptions o;
  o.name = spec;
  PreparedScene s = PreparedScene::build(std::move(scene), o);
  const LightSampler& l = s.lights();
  const auto learn_start = Clock::now();
  const LightCache cache = learn(s, updates);
  const double learn_s = std::chrono::duration<double>(Clock::now() - learn_start).count();
  Tally t = sample_scene(s, cache, samples, step, oracle);
  const Estimator* est = t.est;
  const std::size_t texels = t.texels;
  const double truth_sq = t.truth_sq;
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
  if (oracle) {
    const double share = t.oracle_rays ? static_cast<double>(t.oracle_occluded_rays) /
                                             static_cast<double>(t.oracle_rays)
                                       : 0.0;
    std::printf(" %5.1f%% %5.1f%% |", 100.0 * share,
                100.0 * static_cast<double>(t.dark_texels) / static_cast<double>(texels));
    row["oracle"] = {{"occluded", share}, {"dark_texels", t.dark_texels}};
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
  bool oracle = false;
  app.add_option("--scenes", scenes, "scene specs, comma separated");
  app.add_option("--samples", samples, "samples per texel per estimator")
      ->check(CLI::Range(1, 1 << 16));
  app.add_option("--step", step, "every step-th texel")->check(CLI::Range(1, 1 << 20));
  app.add_option("--learn-updates", updates,
                 "direct passes the learned way learns from before it is measured")
      ->check(CLI::Range(1, 64));
  app.add_flag("--oracle", oracle,
               "also the occluded share of the oracle's picks (each light in proportion to what it "
               "brings the texel, from 16 shadow rays per light and texel: slow with many lights)");
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
    report.push_back(measure_scene(spec, samples, step, updates, oracle));
  }
  std::printf(
      "ns per sample and occluded share of shadow rays per way; means: its mean over power's "
      "(all unbiased: near 1); texel / scene: the speed-up at equal error over power (time x "
      "variance), per texel (relative variances averaged) and over the scene (variances summed "
      "over squared means summed, as a lightmap's RMSE weighs them). learned: the hierarchy "
      "mixed with the tables learned in --learn-updates direct passes over every texel. oracle: "
      "each light in proportion to what it brings the texel (the floor of a light pick's "
      "occluded share).\n");
  std::filesystem::create_directories(out);
  std::ofstream(out + "/bench_lights.json") << report.dump(2) << "\n";
  std::printf("wrote %s/bench_lights.json\n", out.c_str());
  return 0;
}

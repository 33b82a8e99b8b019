// irradcast-bench-lights: picking area lights by the light hierarchy (LightSampler::pick, the
// engine's direct pass and the path tracer past kMaxFront emissive triangles) against picking
// them by power alone (LightSampler::pick_triangle), side by side on the same texels in one run.
// Each estimator draws `--samples` one-sample estimates of the direct irradiance at every
// `--step`-th texel (a light picked, a point on it, a shadow ray), the two interleaved texel by
// texel so that both see the same machine state. Reports per scene: time per sample, the share
// of shadow rays that end occluded, the variance of the mean over the texels (relative to the
// mean squared), the two means' ratio (both unbiased: near 1), and the speed-up at equal error
// (power's time x variance over the hierarchy's), as a table and JSON (docs/BENCHMARKS.md,
// "Many lights").
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

struct Estimator {
  double seconds = 0.0;
  std::uint64_t samples = 0, rays = 0, occluded = 0;
  double variance_sum = 0.0;  // over texels: the variance of the texel's mean, relative
  double raw_variance = 0.0;  // over texels: the variance of the texel's mean
};

// One texel's samples of the direct irradiance's luminance-ish sum (r + g + b); `tree` picks
// by the hierarchy, else by power.
void run_texel(const LightSampler& l, const RayScene& rays, glm::vec3 p, glm::vec3 n, bool tree,
               int samples, Rng& rng, Estimator& e, double& mean, double& var) {
  const auto start = Clock::now();
  double sum = 0.0, sq = 0.0;
  for (int k = 0; k < samples; ++k) {
    const float u = (static_cast<float>(k) + rng.next_float()) / static_cast<float>(samples);
    const glm::vec2 pos = rng.next_2d();
    std::size_t i;
    float pdf;
    bool ok;
    if (tree) {
      ok = l.pick(p, n, u, i, pdf);
    } else {
      i = l.pick_triangle(u);
      pdf = l.pick_pdf()[i];
      ok = true;
    }
    double v = 0.0;
    LightSampler::ShadowSample s;
    if (ok && l.triangle_sample(rays, i, p, n, n, pos, s)) {
      bool blocked = false;
      if (s.shadow.tmax > 0.0f) {
        blocked = rays.occluded(s.shadow);
        ++e.rays;
        e.occluded += blocked;
      }
      if (!blocked) {
        const glm::vec3 c = l.triangle_emitted(s) / pdf;
        v = static_cast<double>(c.x) + c.y + c.z;
      }
    }
    sum += v;
    sq += v * v;
  }
  e.seconds += std::chrono::duration<double>(Clock::now() - start).count();
  e.samples += static_cast<std::uint64_t>(samples);
  mean = sum / samples;
  var = std::max(sq / samples - mean * mean, 0.0) / samples;  // of the mean
}

// One scene: the power and hierarchy estimators on every step-th texel, a row printed; its
// JSON.
nlohmann::json measure_scene(const std::string& spec, int samples, int step) {
  Scene scene = load_scene(spec);
  PreparedSceneOptions o;
  o.name = spec;
  PreparedScene s = PreparedScene::build(std::move(scene), o);
  const LightSampler& l = s.lights();
  Estimator power, tree;
  Rng rng(1);
  std::size_t k = 0, texels = 0;
  double mean_power = 0.0, mean_tree = 0.0, truth_sq = 0.0;
  for (const TexelGBuffer& g : s.gbuffers())
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i) || k++ % static_cast<std::size_t>(step) != 0) continue;
      double m[2], v[2];
      run_texel(l, s.rays(), g.position[i], g.normal[i], false, samples, rng, power, m[0], v[0]);
      run_texel(l, s.rays(), g.position[i], g.normal[i], true, samples, rng, tree, m[1], v[1]);
      // The variance of each texel's mean relative to its squared mean (both estimators'
      // means averaged: the same truth), so bright and dim texels count alike.
      const double truth = 0.5 * (m[0] + m[1]);
      if (truth > 0.0) {
        power.variance_sum += v[0] / (truth * truth);
        tree.variance_sum += v[1] / (truth * truth);
      }
      power.raw_variance += v[0];
      tree.raw_variance += v[1];
      truth_sq += truth * truth;
      mean_power += m[0];
      mean_tree += m[1];
      ++texels;
    }
  auto ns = [](const Estimator& e) { return 1e9 * e.seconds / static_cast<double>(e.samples); };
  auto occl = [](const Estimator& e) {
    return e.rays ? static_cast<double>(e.occluded) / static_cast<double>(e.rays) : 0.0;
  };
  const double rv_power = power.variance_sum / texels, rv_tree = tree.variance_sum / texels;
  const double speedup = (power.seconds * rv_power) / (tree.seconds * rv_tree);
  // The same over the whole scene: summed variance over summed squared means (bright texels
  // weigh more, as in a lightmap's RMSE).
  const double sv_power = power.raw_variance / truth_sq, sv_tree = tree.raw_variance / truth_sq;
  const double scene_speedup = (power.seconds * sv_power) / (tree.seconds * sv_tree);
  std::printf(
      "%-16s %9zu %7zu %9d | %10.1f %7.1f%% %10.4f | %10.1f %7.1f%% %10.4f | %7.3f %8.1fx "
      "%8.1fx\n",
      spec.c_str(), l.emissive_triangles().size(), texels, samples, ns(power), 100.0 * occl(power),
      rv_power, ns(tree), 100.0 * occl(tree), rv_tree, mean_tree / mean_power, speedup,
      scene_speedup);
  return nlohmann::json{
      {"scene", spec},
      {"emissive_triangles", l.emissive_triangles().size()},
      {"tree_used", !l.tree().empty()},
      {"texels", texels},
      {"samples_per_texel", samples},
      {"power",
       {{"ns_per_sample", ns(power)}, {"occluded", occl(power)}, {"relative_variance", rv_power}}},
      {"tree",
       {{"ns_per_sample", ns(tree)}, {"occluded", occl(tree)}, {"relative_variance", rv_tree}}},
      {"mean_ratio_tree_power", mean_tree / mean_power},
      {"speedup_at_equal_error", speedup}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-lights: area lights picked by the light hierarchy vs by power"};
  std::string scenes = "rooms:6,rooms:6:trim,rooms:12:trim", out = "out/lights";
  int samples = 64, step = 40;
  app.add_option("--scenes", scenes, "scene specs, comma separated");
  app.add_option("--samples", samples, "samples per texel per estimator")
      ->check(CLI::Range(1, 1 << 16));
  app.add_option("--step", step, "every step-th texel")->check(CLI::Range(1, 1 << 20));
  app.add_option("--out", out, "directory for bench_lights.json");
  CLI11_PARSE(app, argc, argv);
  Progress::set_enabled(false);
  nlohmann::json report = nlohmann::json::array();
  std::printf("%-16s %9s %7s %9s | %10s %8s %10s | %10s %8s %10s | %7s %9s %9s\n", "scene",
              "emissive", "texels", "samples", "power ns", "occl", "rel var", "tree ns", "occl",
              "rel var", "means", "speed-up", "scene");
  std::size_t from = 0;
  while (from <= scenes.size()) {
    const std::size_t comma = std::min(scenes.find(',', from), scenes.size());
    const std::string spec = scenes.substr(from, comma - from);
    from = comma + 1;
    if (spec.empty()) continue;
    report.push_back(measure_scene(spec, samples, step));
  }
  std::printf(
      "rel var: variance of a texel's mean over its squared mean, averaged over texels; "
      "speed-up: power's time x rel var over the hierarchy's (time to the same error); scene: "
      "the same with the variance summed over texels over their squared means summed (bright "
      "texels weigh more, as in a lightmap's RMSE).\n");
  std::filesystem::create_directories(out);
  std::ofstream(out + "/bench_lights.json") << report.dump(2) << "\n";
  std::printf("wrote %s/bench_lights.json\n", out.c_str());
  return 0;
}

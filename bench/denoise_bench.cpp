// irradcast-bench-denoise: what the lightmap denoiser (--denoise, docs/DENOISER.md) buys. One
// engine (default parameters, Embree backend) runs on a scene (default the Sponza with its sky
// and sun); after each update its plain lightmaps and their denoised copy are composed into the
// scene camera's view and compared per pixel with the reference: the reference path tracer per
// texel (reference_lightmaps) at --ref-spp samples, as two independent halves composed the same
// way, so that the comparison measures noise and filter bias, not the lightmaps' resolution;
// (A - B) / 2 gives the reference's own noise. Prints and writes (JSON, two PNGs):
//   - the relative RMSE (RMSE / mean of the reference) of plain and denoised after each update,
//     and the goal: denoised after --few updates below plain after --many;
//   - after --converged updates, the relative RMS difference denoised - plain, against the
//     reference's own relative noise (the goal: below it);
//   - OUT/denoise_error.png (error vs updates) and OUT/denoise_crops.png (the view's centre:
//     plain and denoised after --few updates, plain after --many, the reference).
//   irradcast-bench-denoise --out docs/images --json docs/images/denoise_bench.json
// The reference halves are cached in --cache (keyed by scene, density, samples and seeds).
#include "irradcast/common/cli.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "bench_options.h"
#include "bench_scene.h"
#include "bench_util.h"
#include "embree_backend.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/engine/denoise.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "plot.h"

using namespace irradcast;
using namespace irradcast::bench;
namespace fs = std::filesystem;

namespace {

struct Options {
  std::string scene = "sponza", out = "docs/images", json, cache = "out/denoise-cache";
  float texels = 64.0f;
  std::string tracing_range;  // the engine's --tracing-range ("" = its default)
  int ref_spp = 1024, few = 4, many = 16, converged = 64, width = 320, height = 240, threads = 0;
};

// One half of the reference lightmaps, read from the cache or traced (and cached).
std::vector<Lightmap> reference_half(const Options& o, const PreparedScene& p, int half) {
  const std::uint64_t seed = 0xDE05E000ull + static_cast<std::uint64_t>(half);
  const std::string name = o.scene + "_" + std::to_string(static_cast<int>(o.texels)) + "_" +
                           std::to_string(p.world().objects.size()) + "_" +
                           std::to_string(o.ref_spp / 2) + "_" + std::to_string(seed) + ".bin";
  const fs::path file = fs::path(o.cache) / name;
  std::vector<Lightmap> maps;
  if (std::ifstream in{file, std::ios::binary}) {
    for (const TexelGBuffer& g : p.gbuffers()) {
      Lightmap m(g.width, g.height);
      in.read(reinterpret_cast<char*>(m.texels.data()),
              static_cast<std::streamsize>(m.texels.size() * sizeof(glm::vec3)));
      maps.push_back(std::move(m));
    }
    if (in && in.peek() == std::char_traits<char>::eof()) return maps;
    maps.clear();
  }
  std::fprintf(stderr, "reference half %d: %d spp per texel ...\n", half + 1, o.ref_spp / 2);
  PathTracerOptions pto;
  pto.seed = seed;
  const PathTracer tracer(p.world(), p.rays(), p.lights(), pto);
  const Stopwatch t;
  maps = reference_lightmaps(p.world(), tracer, p.gbuffers(), std::max(1, o.ref_spp / 2));
  std::fprintf(stderr, "  %.1f s\n", t.seconds());
  fs::create_directories(o.cache);
  std::ofstream out(file, std::ios::binary);
  for (const Lightmap& m : maps)
    out.write(reinterpret_cast<const char*>(m.texels.data()),
              static_cast<std::streamsize>(m.texels.size() * sizeof(glm::vec3)));
  return maps;
}

double mean_of(const ImageRGB& img) {
  double s = 0.0;
  for (const glm::vec3& c : img.pixels) s += c.x + c.y + c.z;
  return s / (3.0 * static_cast<double>(img.pixels.size()));
}

// sqrt(mean over pixels and channels of (a - b)^2) / level.
double rel_rms(const ImageRGB& a, const ImageRGB& b, double level) {
  return compare(a, b).rmse / level;
}

// The centre half of `img`, twice enlarged, pasted into `canvas` at column `slot`.
void paste_crop(std::vector<std::uint8_t>& canvas, int canvas_w, const ImageRGB& img, float scale,
                int slot) {
  ToneMapOptions t;
  t.auto_exposure = false;
  t.exposure_ev = std::log2(scale);
  const std::vector<std::uint8_t> rgb = tonemap_srgb8(img, t);
  const int w = img.width / 2, h = img.height / 2, x0 = img.width / 4, y0 = img.height / 4;
  for (int y = 0; y < 2 * h; ++y)
    for (int x = 0; x < 2 * w; ++x) {
      const std::size_t src = 3 * (static_cast<std::size_t>(y0 + y / 2) * img.width + x0 + x / 2);
      const std::size_t dst = 3 * (static_cast<std::size_t>(y) * canvas_w + slot * 2 * w + x);
      for (int c = 0; c < 3; ++c) canvas[dst + c] = rgb[src + c];
    }
}

// OUT/denoise_error.png: e = plain, denoised, and both with the reference's noise taken out.
void write_error_plot(const Options& o, const std::vector<double>& xs,
                      const std::vector<std::vector<double>>& e, double ref_noise) {
  plot::XYPlot xy;
  xy.title = "Denoiser on " + o.scene + ": per-pixel error vs updates";
  xy.note = "relative RMSE vs a " + std::to_string(o.ref_spp) +
            " spp per-texel reference (grey: its own noise)";
  xy.x_label = "updates";
  xy.y_label = "relative RMSE";
  xy.x_log = xy.y_log = true;
  xy.legend = plot::XYPlot::Legend::BottomLeft;
  const auto series = [&](const char* label, std::vector<double> x, std::vector<double> y,
                          plot::Color c, bool points) {
    plot::Series se;
    se.label = label;
    se.x = std::move(x);
    se.y = std::move(y);
    se.color = c;
    se.points = points;
    se.lines = true;
    xy.series.push_back(std::move(se));
  };
  series("plain", xs, e[0], plot::kBlue, true);
  series("denoised", xs, e[1], plot::kOrange, true);
  series("plain, reference noise taken out", xs, e[2], plot::kGreen, false);
  series("denoised, reference noise taken out", xs, e[3], plot::kRed, false);
  series("reference noise", {1.0, xs.back()}, {ref_noise, ref_noise}, plot::kDarkGrey, false);
  write_xy_plot((fs::path(o.out) / "denoise_error.png").string(), xy);
}

// OUT/denoise_crops.png: the centre crops of `images` side by side, at the last one's exposure.
void write_crops(const Options& o, const std::vector<const ImageRGB*>& images) {
  const float scale = exposure_scale(*images.back(), ToneMapOptions{});
  const int cw = static_cast<int>(images.size()) * (o.width / 2) * 2, ch = (o.height / 2) * 2;
  std::vector<std::uint8_t> crops(static_cast<std::size_t>(cw) * ch * 3, 255);
  int slot = 0;
  for (const ImageRGB* img : images) paste_crop(crops, cw, *img, scale, slot++);
  write_png((fs::path(o.out) / "denoise_crops.png").string(), cw, ch, crops);
}

// The engine's error against the reference, plain and denoised, update by update.
struct Series {
  std::vector<double> xs, plain_err, denoised_err;
  ImageRGB few_plain, few_denoised, many_plain;
  double diff = 0.0, denoise_s = 0.0, update_s = 0.0;
  DenoiseStats ds;
  std::size_t texels = 0;
};

template <class View>
Series measure(const Options& o, const PreparedScene& p, const View& view, const ImageRGB& ref,
               double level, double ref_noise) {
  EngineParams ep;
  ep.denoise = true;
  if (!o.tracing_range.empty()) ep.tracing_range = parse_tracing_range(o.tracing_range);
  Engine engine(p.world(), p.atlas(), p.gbuffers(), p.rays(),
                std::make_unique<EmbreeBackend>(p.rays(), p.lights()), ep, &p.lights());
  // The error with the reference's own noise taken out (E[(x - ref)^2] = E[(x - truth)^2] +
  // E[(ref - truth)^2] for independent x and reference).
  const auto corrected = [&](double e) {
    return std::sqrt(std::max(0.0, e * e - ref_noise * ref_noise));
  };
  Series r;
  auto& [xs, plain_err, denoised_err, few_plain, few_denoised, many_plain, diff, denoise_s,
         update_s, ds, texels] = r;
  texels = engine.texel_count();
  const int last = std::max(o.converged, o.many);
  for (int u = 1; u <= last; ++u) {
    update_s += engine.update().total_seconds;
    if (u > o.many && u != o.converged) continue;
    const ImageRGB plain = view(engine.lightmaps());
    const Stopwatch t;
    const std::vector<Lightmap> dmaps = engine.published_lightmaps(&ds);
    denoise_s = t.seconds();
    const ImageRGB denoised = view(dmaps);
    if (u == o.converged) diff = rel_rms(denoised, plain, level);
    if (u > o.many) continue;
    xs.push_back(u);
    plain_err.push_back(rel_rms(plain, ref, level));
    denoised_err.push_back(rel_rms(denoised, ref, level));
    std::printf("update %3d: plain %.4f (corrected %.4f)  denoised %.4f (corrected %.4f)\n", u,
                plain_err.back(), corrected(plain_err.back()), denoised_err.back(),
                corrected(denoised_err.back()));
    if (u == o.few) few_plain = plain, few_denoised = denoised;
    if (u == o.many) many_plain = plain;
  }
  return r;
}

int run(Options o) {
  auto limit = start_run(o.threads, o.out, o.json, "denoise_bench.json");
  const PreparedScene p = prepare(load_scene(o.scene), density(o.texels));
  const CameraPose cam = default_camera(p.scene(), p.world());
  const auto view = [&](const std::vector<Lightmap>& maps) {
    return compose(p.world(), p.rays(), p.atlas(), maps, cam, o.width, o.height);
  };
  const ImageRGB ref_a = view(reference_half(o, p, 0)), ref_b = view(reference_half(o, p, 1));
  ImageRGB ref = ref_a;
  for (std::size_t i = 0; i < ref.pixels.size(); ++i)
    ref.pixels[i] = 0.5f * (ref_a.pixels[i] + ref_b.pixels[i]);
  const double level = mean_of(ref);
  // (A - B) / 2 has the variance of the mean's noise.
  const double ref_noise = 0.5 * rel_rms(ref_a, ref_b, level);

  Series r = measure(o, p, view, ref, level, ref_noise);
  const auto& [xs, plain_err, denoised_err, few_plain, few_denoised, many_plain, diff, denoise_s,
               update_s, ds, texels] = r;
  const int last = std::max(o.converged, o.many);
  const auto corrected = [&](double e) {
    return std::sqrt(std::max(0.0, e * e - ref_noise * ref_noise));
  };
  const double few_d = denoised_err[o.few - 1], many_p = plain_err[o.many - 1];
  std::printf("\n%s, %zu texels, %dx%d view, reference %d spp per texel (own noise %.4f)\n",
              o.scene.c_str(), texels, o.width, o.height, o.ref_spp, ref_noise);
  std::printf(
      "denoised after %d updates: %.4f (corrected %.4f)  vs plain after %d: %.4f "
      "(corrected %.4f)  -> %s\n",
      o.few, few_d, corrected(few_d), o.many, many_p, corrected(many_p),
      few_d < many_p ? "goal met" : "goal NOT met");
  // The noise of a 1024-spp reference, from this one's by the Monte Carlo law.
  const double noise_1024 = ref_noise * std::sqrt(o.ref_spp / 1024.0);
  std::printf(
      "after %d updates: |denoised - plain| %.4f  vs reference noise %.4f (at 1024 spp "
      "%.4f)  -> %s\n",
      o.converged, diff, ref_noise, noise_1024,
      diff < std::min(ref_noise, noise_1024) ? "goal met" : "goal NOT met");
  std::printf("denoiser %.3f s per publish (%zu filtered, %zu kept, %zu seams), update %.3f s\n",
              denoise_s, ds.filtered, ds.kept, ds.seams, update_s / last);

  std::vector<double> plain_c, denoised_c;
  for (double e : plain_err) plain_c.push_back(corrected(e));
  for (double e : denoised_err) denoised_c.push_back(corrected(e));
  write_error_plot(o, xs, {plain_err, denoised_err, plain_c, denoised_c}, ref_noise);
  write_crops(o, {&few_plain, &few_denoised, &many_plain, &ref});

  nlohmann::json j = {{"bench", "irradcast-bench-denoise"},
                      {"scene", o.scene},
                      {"texels", texels},
                      {"view", {o.width, o.height}},
                      {"ref_spp", o.ref_spp},
                      {"ref_noise", ref_noise},
                      {"ref_noise_at_1024_spp", noise_1024},
                      {"updates", xs},
                      {"plain", plain_err},
                      {"denoised", denoised_err},
                      {"few", o.few},
                      {"plain_corrected", plain_c},
                      {"denoised_corrected", denoised_c},
                      {"many", o.many},
                      {"converged", o.converged},
                      {"converged_difference", diff},
                      {"denoise_seconds", denoise_s},
                      {"update_seconds", update_s / last},
                      {"machine", machine_json(tbb_threads())}};
  write_json(o.json, j);
  std::printf("wrote %s, %s/denoise_error.png, %s/denoise_crops.png\n", o.json.c_str(),
              o.out.c_str(), o.out.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-denoise: per-pixel error of plain and denoised lightmaps"};
  Options o;
  app.add_option("--scene", o.scene, "scene spec (cornell, rooms:N, sponza, FILE)");
  add_texels_per_scene(app, o.texels)->check(CLI::Range(8.0f, 4096.0f));
  app.add_option("--ref-spp", o.ref_spp, "reference samples per texel (two halves)")
      ->check(CLI::Range(2, 1 << 20));
  app.add_option("--few", o.few, "denoised updates of the goal")->check(CLI::Range(2, 1000));
  app.add_option("--many", o.many, "plain updates of the goal")->check(CLI::Range(2, 1000));
  app.add_option("--converged", o.converged, "updates of the converged comparison")
      ->check(CLI::Range(2, 100000));
  app.add_option("--width", o.width, "view width")->check(CLI::Range(16, 4096));
  app.add_option("--height", o.height, "view height")->check(CLI::Range(16, 4096));
  app.add_option("--tracing-range", o.tracing_range,
                 "the engine's tracing range (a fraction of the scene, metres: 2.4m, a capped "
                 "fraction: 0.3:1.2m, or inf: no probes; its default when not given)");
  app.add_option("--threads", o.threads, "TBB threads (0 = all cores)");
  app.add_option("--out", o.out, "output directory (PNGs)");
  app.add_option("--json", o.json, "JSON report (default OUT/denoise_bench.json)");
  app.add_option("--cache", o.cache, "reference cache directory");
  CLI11_PARSE(app, argc, argv);
  if (o.few > o.many) o.many = o.few;
  return run_guarded("irradcast-bench-denoise: error: ", [&] { return run(o); });
}

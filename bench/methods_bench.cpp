// irradcast-bench-methods: the indirect methods side by side (docs/METHODS.md). For each scene,
// every method at a few settings runs in an EngineHost as the server would (tile store and its
// noise-aware publishing included); after every update its published lightmaps are compared
// with reference lightmaps from the reference path tracer (texel by texel, RMSE and relative
// MSE as irradcast::compare defines them), and the bytes of the tiles it published are summed
// (what a client that keeps up receives). Writes a table, a convergence plot and an image grid
// (composed views next to a path-traced reference).
//   irradcast-bench-methods --scenes cornell,rooms:2 --updates 24 --out out/methods
#include <tbb/global_control.h>
#include "irradcast/common/cli.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bench_options.h"
#include "bench_util.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "irradcast/engine/texel_validity.h"
#include "irradcast/service/engine_host.h"
#include "plot.h"

using namespace irradcast;
using namespace irradcast::bench;
using json = nlohmann::json;
namespace fs = std::filesystem;

namespace {

struct Config {
  std::string label;
  EngineParams params;
};

// The engine's defaults for each method, and variants: one of them with a tweak applied.
std::vector<Config> configs() {
  using P = EngineParams&;
  const EngineParams cells;
  EngineParams vpl, cache;
  vpl.method = Method::Vpl;
  cache.method = Method::IrradianceCache;
  auto tweak = [](EngineParams p, auto change) {
    change(p);
    return p;
  };
  return {
      {"cells", cells},
      {"cells range inf",
       tweak(cells, [](P p) { p.tracing_range = std::numeric_limits<float>::infinity(); })},
      {"vpl", vpl},
      {"vpl 4096 paths", tweak(vpl, [](P p) { p.vpl_paths = 4096; })},
      {"vpl clamp 0.01", tweak(vpl,
                               [](P p) {
                                 p.vpl_paths = 1024;
                                 p.vpl_clamp = 0.01f;
                               })},
      {"cache", cache},
      {"cache a 0.4", tweak(cache, [](P p) { p.ic_accuracy = 0.4f; })},
      {"cache a 0.15", tweak(cache, [](P p) { p.ic_accuracy = 0.15f; })},
  };
}

struct Curve {
  std::string label;
  std::vector<double> seconds, bytes, rmse, rel_mse;
  ImageRGB view;
  std::string summary;
};

// The valid texels of a set of lightmaps, as a one-row image (for irradcast::compare).
ImageRGB texel_row(const std::vector<Lightmap>& maps, const std::vector<TexelGBuffer>& g) {
  ImageRGB row;
  for (std::size_t o = 0; o < maps.size(); ++o)
    for (std::size_t i = 0; i < maps[o].texels.size(); ++i)
      if (g[o].valid(i)) row.pixels.push_back(maps[o].texels[i]);
  row.width = static_cast<int>(row.pixels.size());
  row.height = 1;
  return row;
}

// First update whose relative MSE is at most `target`; -1 if none.
int first_at(const Curve& c, double target) {
  for (std::size_t i = 0; i < c.rel_mse.size(); ++i)
    if (c.rel_mse[i] <= target) return static_cast<int>(i);
  return -1;
}

void paste(plot::Canvas& canvas, const ImageRGB& image, float scale, int x0, int y0) {
  ToneMapOptions tm;
  tm.auto_exposure = false;
  tm.exposure_ev = std::log2(scale);
  const std::vector<std::uint8_t> rgb = tonemap_srgb8(image, tm);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const std::size_t i = (static_cast<std::size_t>(y) * image.width + x) * 3;
      canvas.blend(x0 + x, y0 + y, plot::Color{rgb[i], rgb[i + 1], rgb[i + 2]}, 1.0);
    }
}

// The reference of a scene: the path tracer per texel on the host's own world and atlas (two
// independent halves: their mean is the reference, their difference its noise), and an image.
struct Reference {
  std::vector<Lightmap> lightmaps;
  std::vector<TexelGBuffer> gbuffers;
  ImageRGB image;
  double floor = 0.0;  // its own relative MSE
};

struct Settings {
  int updates = 24, ref_spp = 4096, image_spp = 256, size = 128;
};

Reference make_reference(const std::string& spec, const EngineHost& host, const Config& cfg,
                         const Settings& st) {
  const int ref_spp = st.ref_spp;
  Reference ref;
  std::vector<Lightmap>& reference = ref.lightmaps;
  std::vector<TexelGBuffer>& gbuffers = ref.gbuffers;
  double& floor = ref.floor;
  const Stopwatch t0;
  RayScene rays(host.world());
  LightSampler lights(host.world());
  gbuffers = rasterize_gbuffer(host.world(), host.atlas());
  mark_hidden_texels(rays, gbuffers);
  // Two independent halves: their mean is the reference, their difference its noise.
  PathTracer tracer(host.world(), rays, lights,
                    PathTracerOptions{cfg.params.indirect_bounces, true, 4242});
  PathTracer other(host.world(), rays, lights,
                   PathTracerOptions{cfg.params.indirect_bounces, true, 4343});
  reference = reference_lightmaps(host.world(), tracer, gbuffers, (ref_spp + 1) / 2);
  const std::vector<Lightmap> half =
      reference_lightmaps(host.world(), other, gbuffers, (ref_spp + 1) / 2);
  // rel MSE of the mean against the truth ~ rel MSE(a, b) / 4.
  floor = compare(texel_row(half, gbuffers), texel_row(reference, gbuffers)).rel_mse / 4.0;
  for (std::size_t m = 0; m < reference.size(); ++m)
    for (std::size_t i = 0; i < reference[m].texels.size(); ++i)
      reference[m].texels[i] = 0.5f * (reference[m].texels[i] + half[m].texels[i]);
  const CameraPose cam = default_camera(host.scene(), host.world());
  ref.image = tracer.render(cam, st.size, st.size, st.image_spp);
  std::fprintf(stderr, "%s: reference (%d paths per texel, its own rel MSE ~%.5f) in %.1f s\n",
               spec.c_str(), ref_spp, floor, t0.seconds());
  return ref;
}

// Runs one configuration for st.updates updates: its error curve against the reference.
Curve run_config(EngineHost& host, const Config& cfg, const Reference& ref, const Settings& st) {
  const std::vector<TexelGBuffer>& gbuffers = ref.gbuffers;
  const ImageRGB ref_row = texel_row(ref.lightmaps, gbuffers);
  Curve c;
  c.label = cfg.label;
  double bytes = 0.0;
  host.set_listener([&](const std::vector<std::uint32_t>& changed) {
    for (std::uint32_t i : changed)
      bytes +=
          static_cast<double>(host.tiles().snapshot(i, wire::TILE_RGB9E5_ZSTD).payload->size());
  });
  for (int u = 0; u < st.updates; ++u) {
    host.step();
    const ImageError e = compare(texel_row(host.tiles().published(), gbuffers), ref_row);
    c.seconds.push_back(host.stats().seconds_total);
    c.bytes.push_back(bytes);
    c.rmse.push_back(e.rmse);
    c.rel_mse.push_back(e.rel_mse);
  }
  RayScene rays(host.world());
  c.view = compose(host.world(), rays, host.atlas(), host.tiles().published(),
                   default_camera(host.scene(), host.world()), st.size, st.size);
  c.summary = host.method_summary();
  std::fprintf(stderr, "  %s: %s\n", cfg.label.c_str(), c.summary.c_str());
  return c;
}

// Prints the rows of one scene and adds them to the report. Converged: within 10 % of the run's
// own best error. Target: the worst final error of all configurations (every one reaches it),
// so time and bytes compare at equal quality.
void report_scene(const std::string& spec, const std::vector<Curve>& curves, double floor,
                  json& report) {
  double target = 0.0;
  for (const Curve& c : curves) target = std::max(target, c.rel_mse.back());
  for (const Curve& c : curves) {
    const double best = *std::min_element(c.rel_mse.begin(), c.rel_mse.end());
    const int conv = first_at(c, 1.1 * best), hit = first_at(c, target);
    const double per_update = c.seconds.back() / static_cast<double>(c.seconds.size());
    std::printf("%-9s %-16s %9.3f %9.4f %9.5f | %9.2f %10.0f | %9.2f %10.0f | %s\n", spec.c_str(),
                c.label.c_str(), per_update, c.rmse.back(), c.rel_mse.back(),
                c.seconds[static_cast<std::size_t>(conv)],
                c.bytes[static_cast<std::size_t>(conv)] / 1024.0,
                c.seconds[static_cast<std::size_t>(hit)],
                c.bytes[static_cast<std::size_t>(hit)] / 1024.0, c.summary.c_str());
    report.push_back({{"scene", spec},
                      {"method", c.label},
                      {"seconds_per_update", per_update},
                      {"rmse", c.rmse},
                      {"rel_mse", c.rel_mse},
                      {"seconds", c.seconds},
                      {"bytes", c.bytes},
                      {"target_rel_mse", target},
                      {"reference_rel_mse", floor},
                      {"state", c.summary},
                      {"converged_update", conv + 1},
                      {"target_update", hit + 1}});
  }
}

// The convergence plot of one scene: OUT/methods_SCENE.png.
void plot_scene(const std::string& spec, const std::vector<Curve>& curves, double floor,
                int ref_spp, const std::string& out_dir) {
  plot::XYPlot xy;
  xy.title = spec + ": error against the reference path tracer";
  xy.x_label = "server seconds (2-core VM, Embree)";
  xy.y_label = "relative MSE of the lightmaps";
  xy.y_log = true;
  xy.legend = plot::XYPlot::Legend::TopRight;
  char note[128];
  std::snprintf(note, sizeof note, "reference: %d paths per texel, its own rel MSE ~%.5f", ref_spp,
                floor);
  xy.note = note;
  const plot::Color colors[] = {plot::kBlue,
                                plot::Color{120, 170, 220},
                                plot::kOrange,
                                plot::kRed,
                                plot::Color{250, 190, 120},
                                plot::kGreen,
                                plot::Color{140, 200, 140},
                                plot::kDarkGrey};
  for (std::size_t i = 0; i < curves.size(); ++i) {
    plot::Series s;
    s.label = curves[i].label;
    s.x = curves[i].seconds;
    s.y = curves[i].rel_mse;
    s.color = colors[i % 8];
    s.lines = true;
    s.points = false;
    xy.series.push_back(s);
  }
  std::string stem = spec;
  std::replace(stem.begin(), stem.end(), ':', '_');
  plot::write_xy_plot(out_dir + "/methods_" + stem + ".png", xy);
}

// The image grid: a row per scene, the reference first, every configuration after it, all at
// the reference's exposure.
void write_grid(const std::vector<std::string>& scenes, const std::vector<ImageRGB>& references,
                const std::vector<std::vector<Curve>>& all, std::size_t configs, int size,
                const std::string& out_dir) {
  const int pad = 6, label_h = 18;
  const int cols = static_cast<int>(configs) + 1;
  plot::Canvas grid(cols * (size + pad) + pad,
                    static_cast<int>(all.size()) * (size + label_h + pad) + pad);
  for (std::size_t r = 0; r < all.size(); ++r) {
    const float scale = exposure_scale(references[r], ToneMapOptions{});
    const int y0 = pad + static_cast<int>(r) * (size + label_h + pad);
    for (int c = 0; c < cols; ++c) {
      const int x0 = pad + c * (size + pad);
      const ImageRGB& img = c == 0 ? references[r] : all[r][static_cast<std::size_t>(c - 1)].view;
      paste(grid, img, scale, x0, y0 + label_h);
      grid.text(x0, y0 + 4,
                c == 0 ? scenes[r] + " ref" : all[r][static_cast<std::size_t>(c - 1)].label, 1.0,
                plot::kBlack);
    }
  }
  grid.write_png(out_dir + "/methods_grid.png");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-methods: cells, VPL and irradiance cache against the reference"};
  std::string scenes_arg = "cornell,rooms:2", out_dir = "out/methods", only;
  Settings st;
  int threads = 0;
  float density = 64.0f;
  app.add_option("--scenes", scenes_arg, "comma-separated scene specs");
  app.add_option("--updates", st.updates, "updates per configuration")->check(CLI::Range(2, 1000));
  add_texels_per_scene(app, density);
  app.add_option("--ref-spp", st.ref_spp, "reference paths per texel")
      ->check(CLI::Range(1, 1 << 16));
  app.add_option("--image-spp", st.image_spp, "reference image samples per pixel");
  app.add_option("--size", st.size, "side of each image in the grid")->check(CLI::Range(16, 1024));
  app.add_option("--only", only, "run only the configurations whose label contains this");
  app.add_option("--threads", threads, "worker threads (0 = all)");
  app.add_option("--out", out_dir, "output directory");
  std::vector<std::string> cell_sizes, tracing_ranges;
  app.add_option("--cell-size", cell_sizes,
                 "adds a configuration 'sized ...': the default cells with this cell size (a "
                 "fraction, metres: 2m, or capped: 0.25:1m); repeat with --tracing-range for "
                 "more");
  app.add_option("--tracing-range", tracing_ranges,
                 "... and this tracing range (a fraction, metres, capped or inf); the n-th goes "
                 "with the n-th --cell-size");
  CLI11_PARSE(app, argc, argv);
  try {
    quiet_run();
    const auto limit = limit_threads(threads);
    const std::vector<std::string> scenes = split_list(scenes_arg);
    fs::create_directories(out_dir);
    std::vector<Config> cfgs;
    std::vector<Config> all_configs = configs();
    if (cell_sizes.size() != tracing_ranges.size())
      throw Error("--cell-size and --tracing-range come in pairs");
    for (std::size_t i = 0; i < cell_sizes.size(); ++i) {
      Config sized{"sized cell " + cell_sizes[i] + " range " + tracing_ranges[i], EngineParams{}};
      sized.params.cell_size = parse_tracing_range(cell_sizes[i]);
      sized.params.tracing_range = parse_tracing_range(tracing_ranges[i]);
      sized.params.validate();
      all_configs.push_back(sized);
    }
    for (const Config& c : all_configs)
      if (only.empty() || c.label.find(only) != std::string::npos) cfgs.push_back(c);
    json report = json::array();
    std::vector<std::vector<Curve>> all;
    std::vector<ImageRGB> references;
    std::printf("%-9s %-16s %9s %9s %9s | %9s %10s | %9s %10s | %s\n", "scene", "method",
                "s/update", "RMSE", "rel MSE", "conv. s", "conv. KiB", "target s", "target KiB",
                "state");
    for (const std::string& spec : scenes) {
      const Scene scene = load_scene(spec, 1.0f);
      std::vector<Curve> curves;
      Reference ref;
      for (const Config& cfg : cfgs) {
        EngineHostOptions o;
        o.engine = cfg.params;
        o.atlas.texels_per_scene = density;
        o.max_updates = static_cast<std::uint32_t>(st.updates);
        o.engine_nice = 0;
        o.backend.kind = BackendKind::Embree;
        EngineHost host(scene, spec, o);
        if (ref.lightmaps.empty()) ref = make_reference(spec, host, cfg, st);
        curves.push_back(run_config(host, cfg, ref, st));
      }
      report_scene(spec, curves, ref.floor, report);
      plot_scene(spec, curves, ref.floor, st.ref_spp, out_dir);
      references.push_back(ref.image);
      all.push_back(std::move(curves));
    }
    write_grid(scenes, references, all, cfgs.size(), st.size, out_dir);
    write_json(out_dir + "/methods.json", report, 1);
    std::printf("wrote %s/methods.json, methods_grid.png and one plot per scene\n",
                out_dir.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-methods: %s\n", e.what());
    return 1;
  }
}

// irradcast-bench-client: the cost of the client passes of seed 002 along a camera path, side
// by side in one run. Lightmaps from the engine (default parameters, --updates updates); then,
// frame by frame along the path, the same camera through three compositors, interleaved so
// that load from other processes hits them alike:
//   plain       irradcast::compose (no passes; irradcast-view without flags)
//   ssao        SSAO on every pixel every frame (--ssao)
//   ssao+reproj SSAO through the reverse-reprojection cache (--ssao --reproject)
// Prints per-configuration frame times (trace, SSAO, reprojection, resolve), the ratios, the
// fraction of pixels whose SSAO was reused, and the RMS relative difference between the
// reprojected and the from-scratch SSAO frames; writes JSON, a PNG plot of frame time along the
// path and (--images) the image pair with and without SSAO (docs/CLIENT_PASSES.md).
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "bench_scene.h"
#include "bench_util.h"
#include "client_pass_scenes.h"
#include "irradcast/client/camera_path.h"
#include "irradcast/client/client_passes.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/embree_backend.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/texel_validity.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;
using irradcast::bench::upper_median;
using irradcast::test::rms_relative;

namespace {

struct Options {
  std::string scene = "cornell";
  std::string scene_root;
  int width = 512, height = 512;
  int frames = 120;
  int repeat = 3;
  std::string path = "orbit";
  double path_dt = 1.0 / 30.0;
  double path_period = 20.0;
  int updates = 16;
  int threads = 0;
  std::string json_out = "client_bench.json";
  std::string plot_out = "client_bench.png";
  std::string images;
  float ssao_radius = SsaoParams{}.radius;
  int reproject_frames = ReprojectionParams{}.converge_frames;
  float reproject_refresh = ReprojectionParams{}.refresh;
};

constexpr int kConfigs = 3;
const char* const kNames[kConfigs] = {"plain", "ssao", "ssao+reproject"};

struct Totals {
  double total = 0, trace = 0, ssao = 0, reproject = 0, resolve = 0;
  double reused = 0, ssao_pixels = 0, disoccluded = 0;
  std::vector<double> per_frame_ms;
};

// The scene and the lightmaps the client passes read: o.updates engine updates.
struct ClientScene {
  PreparedScene prepared;
  std::vector<Lightmap> lightmaps;

  explicit ClientScene(const Options& o)
      : prepared(irradcast::bench::prepare(load_scene(o.scene, 1.0f, o.scene_root))) {
    std::fprintf(stderr, "[client] %s: %d engine updates for the lightmaps ...\n", o.scene.c_str(),
                 o.updates);
    const RayScene& rays = prepared.rays();
    Engine engine(prepared.world(), prepared.atlas(), prepared.gbuffers(), rays,
                  std::make_unique<EmbreeBackend>(rays, prepared.lights()), EngineParams{});
    for (int u = 0; u < o.updates; ++u) engine.update();
    lightmaps = engine.lightmaps();
  }
};

using Runs = std::vector<std::vector<Totals>>;  // per repeat, per configuration

// Every repeat along the path, every configuration per frame; rms_per_frame: the reprojected
// vs the from-scratch SSAO frame of the first repeat.
Runs measure(const Options& o, const ClientScene& cs, const CameraPath& path,
             const ClientPassOptions (&opts)[kConfigs], std::vector<double>& rms_per_frame) {
  const World& world = cs.prepared.world();
  const RayScene& rays = cs.prepared.rays();
  const Atlas& atlas = cs.prepared.atlas();
  const std::vector<Lightmap>& lightmaps = cs.lightmaps;
  Runs runs(static_cast<std::size_t>(o.repeat), std::vector<Totals>(kConfigs));
  rms_per_frame.assign(static_cast<std::size_t>(o.frames), 0.0);
  for (int r = 0; r < o.repeat; ++r) {
    std::vector<std::unique_ptr<ClientPasses>> passes;
    for (const ClientPassOptions& c : opts) passes.push_back(std::make_unique<ClientPasses>(c));
    for (int f = 0; f < o.frames; ++f) {
      const CameraPose cam = path.at(static_cast<double>(f) * o.path_dt);
      ImageRGB images[kConfigs];
      for (int c = 0; c < kConfigs; ++c) {
        ClientFrameStats st;
        images[c] = passes[static_cast<std::size_t>(c)]->compose(world, rays, atlas, lightmaps, cam,
                                                                 o.width, o.height, &st);
        Totals& t = runs[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)];
        t.total += st.total_s;
        t.trace += st.trace_s;
        t.ssao += st.ssao_s;
        t.reproject += st.reproject_s;
        t.resolve += st.resolve_s;
        t.per_frame_ms.push_back(st.total_s * 1e3);
        t.ssao_pixels += static_cast<double>(st.ssao_pixels) / (o.width * o.height);
        if (c == 2) {
          t.reused += st.reprojection.reused_fraction();
          t.disoccluded += st.reprojection.pixels
                               ? static_cast<double>(st.reprojection.disoccluded) /
                                     static_cast<double>(st.reprojection.pixels)
                               : 0.0;
        }
      }
      if (r == 0) rms_per_frame[static_cast<std::size_t>(f)] = rms_relative(images[2], images[1]);
    }
  }
  return runs;
}

// Prints the table and ratios; returns the JSON report.
json report(const Options& o, const Totals (&best)[kConfigs],
            const std::vector<double>& rms_per_frame, int threads) {
  const double nf = o.frames;
  auto ms = [&](double s) { return 1e3 * s / nf; };
  double rms_mean = 0.0, rms_max = 0.0;
  for (double e : rms_per_frame) {
    rms_mean += e * e;
    rms_max = std::max(rms_max, e);
  }
  rms_mean = std::sqrt(rms_mean / nf);
  std::printf(
      "irradcast-bench-client: %s, %dx%d, %d frames along '%s' (dt %.4f s), %d thread(s), "
      "median of %d runs\n",
      o.scene.c_str(), o.width, o.height, o.frames, o.path.c_str(), o.path_dt, threads, o.repeat);
  std::printf("%-16s %9s %9s %9s %9s %9s %10s %9s\n", "config", "ms/frame", "trace", "ssao",
              "reproj", "resolve", "ssao px", "reused");
  json jc = json::array();
  for (int c = 0; c < kConfigs; ++c) {
    const Totals& t = best[c];
    std::printf("%-16s %9.2f %9.2f %9.2f %9.2f %9.2f %9.1f%% %8.1f%%\n", kNames[c], ms(t.total),
                ms(t.trace), ms(t.ssao), ms(t.reproject), ms(t.resolve), 100.0 * t.ssao_pixels / nf,
                100.0 * t.reused / nf);
    jc.push_back({{"config", kNames[c]},
                  {"ms_per_frame", ms(t.total)},
                  {"trace_ms", ms(t.trace)},
                  {"ssao_ms", ms(t.ssao)},
                  {"reproject_ms", ms(t.reproject)},
                  {"resolve_ms", ms(t.resolve)},
                  {"ssao_pixel_fraction", t.ssao_pixels / nf},
                  {"reused_fraction", t.reused / nf},
                  {"disoccluded_fraction", t.disoccluded / nf}});
  }
  const double a = best[0].total, b = best[1].total, c = best[2].total;
  const double ssao_ratio = best[2].ssao / std::max(best[1].ssao, 1e-12);
  std::printf(
      "ratios: ssao / plain %.2f, ssao+reproject / plain %.2f, ssao+reproject / ssao "
      "%.2f (speed-up %.2fx); SSAO pass alone: %.2f (speed-up %.2fx)\n",
      b / a, c / a, c / b, b / c, ssao_ratio, 1.0 / ssao_ratio);
  std::printf(
      "SSAO reused on %.1f%% of the pixels per frame, disoccluded %.2f%%; reprojected vs "
      "from-scratch SSAO frames: RMS relative %.4f (worst frame %.4f)\n",
      100.0 * best[2].reused / nf, 100.0 * best[2].disoccluded / nf, rms_mean, rms_max);
  json j = {{"scene", o.scene},
            {"width", o.width},
            {"height", o.height},
            {"frames", o.frames},
            {"path", o.path},
            {"path_dt", o.path_dt},
            {"threads", threads},
            {"repeat", o.repeat},
            {"engine_updates", o.updates},
            {"configs", jc},
            {"ratio_ssao_over_plain", b / a},
            {"ratio_reproject_over_plain", c / a},
            {"ratio_reproject_over_ssao", c / b},
            {"ratio_ssao_pass_reproject_over_full", ssao_ratio},
            {"rms_relative_reproject_vs_scratch", rms_mean},
            {"rms_relative_worst_frame", rms_max}};
  return j;
}

// The frame time along the path per configuration (o.plot_out).
void plot_frames(const Options& o, const Totals (&best)[kConfigs], int threads) {
  plot::XYPlot p;
  p.title = "Client frame time, " + o.path + " path (" + o.scene + ", " + std::to_string(o.width) +
            "x" + std::to_string(o.height) + ")";
  p.x_label = "frame";
  p.y_label = "ms per frame";
  p.note = std::to_string(threads) + " thread(s); median run of " + std::to_string(o.repeat);
  const plot::Color colors[kConfigs] = {plot::kBlue, plot::kOrange, plot::kGreen};
  for (int k = 0; k < kConfigs; ++k) {
    plot::Series s;
    s.label = kNames[k];
    s.color = colors[k];
    s.points = false;
    s.lines = true;
    for (int f = 0; f < o.frames; ++f) {
      s.x.push_back(f);
      s.y.push_back(best[k].per_frame_ms[static_cast<std::size_t>(f)]);
    }
    p.series.push_back(s);
  }
  p.legend = plot::XYPlot::Legend::TopRight;
  p.y_headroom = 0.3;
  plot::write_xy_plot(o.plot_out, p);
}

// The pair at the scene's own camera, one exposure for both (the plain frame's), and the SSAO
// visibility (o.images).
void write_images(const Options& o, const ClientScene& cs, const ClientPassOptions& ssao) {
  const World& world = cs.prepared.world();
  const RayScene& rays = cs.prepared.rays();
  const Atlas& atlas = cs.prepared.atlas();
  const std::vector<Lightmap>& lightmaps = cs.lightmaps;

  fs::create_directories(o.images);
  const CameraPose cam = default_camera(cs.prepared.scene(), world);
  ImageRGB plain = compose(world, rays, atlas, lightmaps, cam, o.width, o.height);
  ClientPasses ssao_passes(ssao);
  ImageRGB with = ssao_passes.compose(world, rays, atlas, lightmaps, cam, o.width, o.height);
  ToneMapOptions tm;
  tm.auto_exposure = false;
  tm.exposure_ev = std::log2(exposure_scale(plain, ToneMapOptions{}));
  const std::string stem = o.images + "/client_" + fs::path(o.scene).stem().string();
  write_png(stem + "_plain.png", plain.width, plain.height, tonemap_srgb8(plain, tm));
  write_png(stem + "_ssao.png", with.width, with.height, tonemap_srgb8(with, tm));
  // The visibility itself, white = unoccluded.
  ImageRGB vis(o.width, o.height);
  for (std::size_t i = 0; i < vis.pixels.size(); ++i)
    vis.pixels[i] = glm::vec3(ssao_passes.visibility()[i]);
  ToneMapOptions lin;
  lin.op = ToneOperator::Clamp;
  lin.auto_exposure = false;
  write_png(stem + "_ssao_visibility.png", vis.width, vis.height, tonemap_srgb8(vis, lin));
  std::printf("images: %s_{plain,ssao,ssao_visibility}.png\n", stem.c_str());
}

int run(const Options& o) {
  Progress::set_enabled(false);
  std::optional<tbb::global_control> limit;
  if (o.threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, o.threads);
  const int threads =
      o.threads > 0 ? o.threads : static_cast<int>(std::thread::hardware_concurrency());
  const ClientScene cs(o);
  const World& world = cs.prepared.world();
  CameraPath path = o.path == "orbit" ? CameraPath::orbit(world.bounds, o.path_period, 0.0)
                    : o.path == "random-walk"
                        ? CameraPath::random_walk(world.bounds, 1)
                        : CameraPath::keyframes(load_camera_keyframes(o.path), 0.0);
  ClientPassOptions opts[kConfigs];
  opts[1].ssao = opts[2].ssao = true;
  opts[2].reproject = true;
  for (ClientPassOptions& c : opts) {
    c.ssao_params.radius = o.ssao_radius;
    c.reprojection.converge_frames = o.reproject_frames;
    c.reprojection.refresh = o.reproject_refresh;
    c.validate();
  }
  std::vector<double> rms_per_frame;
  const Runs runs = measure(o, cs, path, opts, rms_per_frame);
  // The repeat with the median total time of each configuration.
  Totals best[kConfigs];
  for (int c = 0; c < kConfigs; ++c) {
    std::vector<double> totals;
    for (const auto& rr : runs) totals.push_back(rr[static_cast<std::size_t>(c)].total);
    const double m = upper_median(totals);
    for (const auto& rr : runs)
      if (rr[static_cast<std::size_t>(c)].total == m) best[c] = rr[static_cast<std::size_t>(c)];
  }
  const json j = report(o, best, rms_per_frame, threads);
  if (!o.json_out.empty()) {
    std::ofstream f(o.json_out);
    f << j.dump(2) << "\n";
    if (!f) throw Error(o.json_out + ": cannot write");
  }
  if (!o.plot_out.empty()) plot_frames(o, best, threads);
  if (!o.images.empty()) write_images(o, cs, opts[1]);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-bench-client: frame time of irradcast-view's client passes (--ssao, "
      "--reproject) along a camera path, side by side in one run",
      "irradcast-bench-client"};
  app.option_defaults()->always_capture_default();
  app.add_option("--scene", o.scene, "cornell | rooms:N | FILE.gltf");
  app.add_option(
      "--scene-root", o.scene_root,
      "folder a glTF scene may read buffers and images from (default: the scene file's folder)");
  app.add_option("--width", o.width)->check(CLI::Range(8, 8192));
  app.add_option("--height", o.height)->check(CLI::Range(8, 8192));
  app.add_option("--frames", o.frames, "frames along the path")->check(CLI::Range(2, 100000));
  app.add_option("--repeat", o.repeat, "runs; the median is reported")->check(CLI::Range(1, 100));
  app.add_option("--path", o.path, "orbit | random-walk | FILE (camera_path.h)");
  app.add_option("--path-dt", o.path_dt, "seconds along the path per frame")
      ->check(CLI::PositiveNumber);
  app.add_option("--path-period", o.path_period, "seconds per orbit")->check(CLI::PositiveNumber);
  app.add_option("--updates", o.updates, "engine updates for the lightmaps")
      ->check(CLI::Range(1, 10000));
  app.add_option("--threads", o.threads, "worker threads (0 = all)")->check(CLI::Range(0, 1024));
  app.add_option("--ssao-radius", o.ssao_radius, "as irradcast-view --ssao-radius");
  app.add_option("--reproject-frames", o.reproject_frames, "as irradcast-view");
  app.add_option("--reproject-refresh", o.reproject_refresh, "as irradcast-view");
  app.add_option("--json", o.json_out, "JSON report ('' = none)");
  app.add_option("--plot", o.plot_out, "PNG plot of frame time along the path ('' = none)");
  app.add_option("--images", o.images, "also write the with/without SSAO pair into this folder");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return irradcast::bench::run_guarded("irradcast-bench-client: error: ", [&] { return run(o); });
}

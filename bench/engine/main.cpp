// irradcast-bench-engine: how fast the GI engine's passes trace rays compared with raw Embree on
// the very same rays, and how the cost of a full update grows with the number of texels.
//
// 1. Pass throughput. The engine runs on a BenchBackend, a TraceBackend that forwards every pass
//    to the real EmbreeBackend. In the measured update it also regenerates, from the PassInput it
//    is handed, the exact rays that pass traces (the backend's own sampling code, copied below),
//    and then times, side by side and interleaved, repetitions of
//      - the engine pass itself (EmbreeBackend, as the engine calls it),
//      - the same rays through RayScene::intersect / occluded (the wrapper alone),
//      - the same rays through rtcIntersect1 / rtcOccluded1 in a tight TBB loop (raw Embree),
//    all on the same BVH (RayScene::embree_scene()) and the same TBB thread pool. Regenerated rays
//    are checked against the engine: shading them with the engine's formulas must reproduce the
//    pass's output.
// 2. Scaling. Full updates (1 direct + K indirect bounces, default parameters) on rooms:N for
//    growing N at a constant number of texels per metre, and on one rooms:M at growing density,
//    all measured in interleaved rounds (fastest kept); a least-squares line through update time
//    against texel count gives the cost per texel and R^2.
//
// Prints a table, writes JSON and two PNG plots (see docs/BENCHMARKS.md). This file: the options,
// the pass report and main; passes.cpp and scaling.cpp run the two parts (engine_bench.h).
#include <embree3/rtcore.h>
#include "irradcast/common/cli.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "bench_options.h"
#include "bench_util.h"
#include "embree_backend.h"
#include "engine_bench.h"
#include "engine_options.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "params_json.h"
#include "plot.h"

using namespace irradcast;
using namespace irradcast::bench;

namespace {

struct Options {
  std::string out_dir = "docs/images", json_path;
  std::string scenes_text = "cornell,rooms:2";
  float texels_per_scene = AtlasOptions{}.texels_per_scene;
  int threads = 0;
  MeasureOptions mo;
  ScalingOptions scaling;
  tools::EngineOptions engine;  // the scaling benchmark's engine parameters
  bool skip_passes = false, skip_scaling = false;
};

// Prints the pass table and adds it to the JSON.
void report_passes(const std::vector<PassRow>& rows, json& result) {
  std::printf(
      "\nEngine passes vs raw Embree on the same rays (one update, bounces summed, fastest of "
      "the interleaved repetitions)\n");
  std::printf("%-8s %-8s %9s %11s %11s %6s %10s %10s %10s %10s %8s %8s %9s\n", "scene", "pass",
              "texels", "rays(eng)", "rays(trc)", "hit", "engine ms", "eng Mr/s", "RS Mr/s",
              "raw Mr/s", "eng/raw", "RS/raw", "verify");
  json table = json::array();
  for (const PassRow& r : rows) {
    double ratio = r.pipeline_s > 0 ? r.raw_s / r.pipeline_s : 0;
    double rs_ratio = r.rayscene_s > 0 ? r.raw_s / r.rayscene_s : 0;
    std::printf(
        "%-8s %-8s %9zu %11llu %11llu %5.1f%% %10.2f %10.2f %10.2f %10.2f %7.1f%% %7.1f%% "
        "%9.1e\n",
        r.scene.c_str(), r.pass.c_str(), r.texels, static_cast<unsigned long long>(r.engine_rays),
        static_cast<unsigned long long>(r.traced_rays),
        r.traced_rays ? 100.0 * r.hits / r.traced_rays : 0.0, r.pipeline_s * 1e3,
        r.mrays(r.pipeline_s), r.mrays(r.rayscene_s), r.mrays(r.raw_s), 100 * ratio, 100 * rs_ratio,
        r.max_rel_diff);
    table.push_back({{"scene", r.scene},
                     {"pass", r.pass},
                     {"texels", r.texels},
                     {"engine_rays", r.engine_rays},
                     {"traced_rays", r.traced_rays},
                     {"hits", r.hits},
                     {"engine_s", r.pipeline_s},
                     {"rayscene_s", r.rayscene_s},
                     {"raw_s", r.raw_s},
                     {"engine_mrays_per_s", r.mrays(r.pipeline_s)},
                     {"engine_reported_mrays_per_s",
                      r.pipeline_s > 0 ? r.engine_rays / r.pipeline_s * 1e-6 : 0.0},
                     {"rayscene_mrays_per_s", r.mrays(r.rayscene_s)},
                     {"raw_mrays_per_s", r.mrays(r.raw_s)},
                     {"engine_over_raw", ratio},
                     {"rayscene_over_raw", rs_ratio},
                     {"verify_max_rel_diff", r.max_rel_diff}});
  }
  result["pass_table"] = table;
  std::printf(
      "rays(eng): what the pass reports; rays(trc): rays actually traced (the direct pass "
      "counts every punctual light's ray, traced or not).\nMr/s: traced rays per second; eng/raw = "
      "engine throughput / raw Embree throughput on the same rays; RS = through RayScene.\n"
      "hit: rays occluded (direct) or hitting within their tmax (probes, scatter); a scatter "
      "miss reads one probe, picked by weight.\nverify: max |regenerated-ray shading - pass "
      "output| / "
      "max |pass output|.\n");
}

// Prints the direct pass with its shadow rays measured (the default), in packets and one by one,
// and adds it to the JSON.
void report_shadow_rays(const std::vector<PassRow>& rows, json& result) {
  std::printf(
      "\nThe direct pass's shadow rays: the default (auto: packets toward at most %d light "
      "objects in front, else single rays) against packets of 8 and single rays, side by side "
      "(fastest repetition); in packets: the share of the default's shadow rays it traced in "
      "packets; disagree: rays raw packets and single rays answer apart\n",
      EmbreeBackend::kPacketLights);
  std::printf("%-10s %9s %12s %12s %12s %12s %14s %9s\n", "scene", "texels", "default ms",
              "packets ms", "single ms", "in packets", "default/best", "disagree");
  json table = json::array();
  for (const PassRow& r : rows) {
    if (r.pass != "direct" || r.packets_s <= 0.0) continue;
    const double best = std::min(r.packets_s, r.single_s);
    std::printf("%-10s %9zu %12.2f %12.2f %12.2f %11.1f%% %13.1f%% %9llu\n", r.scene.c_str(),
                r.texels, r.pipeline_s * 1e3, r.packets_s * 1e3, r.single_s * 1e3,
                100.0 * r.auto_packet_share, 100.0 * r.pipeline_s / best,
                static_cast<unsigned long long>(r.packet_disagreements));
    table.push_back({{"scene", r.scene},
                     {"texels", r.texels},
                     {"default_s", r.pipeline_s},
                     {"packets_s", r.packets_s},
                     {"single_s", r.single_s},
                     {"auto_packet_share", r.auto_packet_share},
                     {"default_over_best", r.pipeline_s / best},
                     {"packet_disagreements", r.packet_disagreements}});
  }
  result["shadow_rays_table"] = table;
}

// The bar chart OUT_DIR/bench_shadow_rays.png: each way's direct pass over the faster forced way.
void plot_shadow_rays(const std::vector<PassRow>& rows, int used_threads,
                      const std::string& out_dir) {
  plot::BarChart chart;
  chart.title = "Direct pass: shadow rays in packets or single";
  chart.note = std::to_string(used_threads) +
               " thread(s), default engine params, the same update; under each scene: the share "
               "of auto's rays in packets";
  chart.y_label = "% of the faster way's time";
  chart.series_labels = {"auto (default)", "packets of 8", "single rays"};
  chart.colors = {plot::kBlue, plot::kOrange, plot::kGreen};
  chart.mark_label = "the faster way";
  chart.values.assign(3, {});
  chart.width = 1400;
  chart.value_decimals = 0;
  for (const PassRow& r : rows) {
    if (r.pass != "direct" || r.packets_s <= 0.0) continue;
    const double best = std::min(r.packets_s, r.single_s);
    chart.categories.push_back(r.scene + "\n" + fmt("%.0f%%", 100.0 * r.auto_packet_share));
    chart.values[0].push_back(100.0 * r.pipeline_s / best);
    chart.values[1].push_back(100.0 * r.packets_s / best);
    chart.values[2].push_back(100.0 * r.single_s / best);
    chart.marks.push_back(100.0);
  }
  if (chart.categories.empty()) return;
  const std::string png = (fs::path(out_dir) / "bench_shadow_rays.png").string();
  plot::write_bar_chart(png, chart);
  std::printf("wrote %s\n", png.c_str());
}

// The bar chart OUT_DIR/bench_pass_vs_embree.png.
void plot_passes(const std::vector<PassRow>& rows, int used_threads, const std::string& out_dir) {
  plot::BarChart chart;
  chart.title = "Engine passes vs raw Embree, same rays";
  chart.note =
      std::to_string(used_threads) +
      " threads, default engine params, the same rays on the same BVH; % = engine / raw Embree";
  chart.y_label = "Mrays/s";
  chart.series_labels = {"engine pass", "via RayScene", "raw Embree"};
  chart.colors = {plot::kBlue, plot::kGreen, plot::kOrange};
  chart.mark_label = "70% of raw (goal)";
  chart.values.assign(3, {});
  for (const PassRow& r : rows) {
    double ratio = r.pipeline_s > 0 ? r.raw_s / r.pipeline_s : 0;
    chart.categories.push_back(r.scene + "\n" + r.pass + "\n" + fmt("%.0f%%", 100 * ratio));
    chart.values[0].push_back(r.mrays(r.pipeline_s));
    chart.values[1].push_back(r.mrays(r.rayscene_s));
    chart.values[2].push_back(r.mrays(r.raw_s));
    chart.marks.push_back(0.7 * r.mrays(r.raw_s));
  }
  chart.height = 640;
  std::string png = (fs::path(out_dir) / "bench_pass_vs_embree.png").string();
  plot::write_bar_chart(png, chart);
  std::printf("wrote %s\n", png.c_str());
}

// 1. Pass throughput against raw Embree, every scene.
void run_passes(const Options& o, int used_threads, json& result) {
  std::vector<PassRow> rows;
  json scenes = json::array();
  for (const std::string& spec : split_list(o.scenes_text)) {
    std::fprintf(stderr, "passes: %s ...\n", spec.c_str());
    for (auto& r : bench_passes(spec, o.texels_per_scene, o.mo, scenes)) rows.push_back(r);
  }
  result["passes"] = scenes;
  report_passes(rows, result);
  report_shadow_rays(rows, result);
  plot_passes(rows, used_threads, o.out_dir);
  plot_shadow_rays(rows, used_threads, o.out_dir);
}

json params_json(const Options& o) {
  return {{"engine", "pass benchmark: EngineParams defaults"},
          {"scaling_engine", tools::params_json(o.scaling.params)},
          {"pass_texels_per_scene", o.texels_per_scene},
          {"scaling_texels_per_metre", o.scaling.density},
          {"density_sweep_scene", "rooms:" + std::to_string(o.scaling.sweep_size)},
          {"density_sweep_texels_per_metre", o.scaling.sweep_text},
          {"scaling_updates", o.scaling.updates},
          {"min_reps", o.mo.min_reps},
          {"min_seconds", o.mo.min_seconds},
          {"cpu_time", o.mo.cpu_time}};
}

int run(Options o) {
  const auto limit = start_run(o.threads, o.out_dir, o.json_path, "bench_engine.json");
  const int used_threads = tbb_threads();
  if (o.mo.cpu_time && used_threads != 1)
    throw Error("--cpu-time needs --threads 1 (the other threads' CPU time would not count)");
  o.scaling.params = o.engine.params();  // throws irradcast::Error naming a bad value
  const Stopwatch total;
  json result;
  result["machine"] = machine_json(used_threads);
  result["machine"]["embree"] = RTC_VERSION_STRING;
  result["params"] = params_json(o);
  std::printf(
      "irradcast-bench-engine: %s, %u hardware threads, %d TBB threads, Embree %s, load "
      "average %s\n",
      cpu_model().c_str(), std::thread::hardware_concurrency(), used_threads, RTC_VERSION_STRING,
      load_average().c_str());
  if (!o.skip_passes) run_passes(o, used_threads, result);
  if (!o.skip_scaling) run_scaling(o.scaling, used_threads, o.out_dir, result);
  result["machine"]["load_average_at_end"] = load_average();
  result["total_wall_s"] = total.seconds();
  write_json(o.json_path, result);
  std::printf("wrote %s (total %.1f s, load average at the end %s)\n", o.json_path.c_str(),
              total.seconds(), load_average().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-engine: engine passes vs raw Embree, update time vs texels"};
  Options o;
  app.add_option("--out", o.out_dir, "directory for the PNG plots (and the JSON by default)");
  app.add_option("--json", o.json_path, "JSON results file (default OUT/bench_engine.json)");
  app.add_option("--scenes", o.scenes_text, "scenes for the pass benchmark, comma separated");
  add_texels_per_scene(app, o.texels_per_scene, "for the pass benchmark");
  app.add_option("--sizes", o.scaling.sizes_text, "N of rooms:N for the scaling benchmark");
  add_texels_per_metre(app, o.scaling.density, "for the scaling benchmark");
  app.add_option("--sweep-size", o.scaling.sweep_size, "M of rooms:M for the density sweep");
  app.add_option("--sweep-densities", o.scaling.sweep_text,
                 "texels per metre for the density sweep, comma separated (empty: none)");
  o.engine.add_params_to(app);  // the scaling benchmark's engine, as irradcast-server's
  app.add_option("--many-lights", o.scaling.many_text,
                 "many-light buildings for the scaling benchmark, as N:lit or N:trim (rooms:N:lit, "
                 "rooms:N:trim), comma separated (empty: none)");
  app.add_option("--updates", o.scaling.updates,
                 "timed updates (rounds) per configuration; fastest kept");
  app.add_option("--reps", o.mo.min_reps, "minimum repetitions per pass");
  app.add_option("--min-time", o.mo.min_seconds, "minimum engine seconds per pass measurement");
  app.add_option("--threads", o.threads, "TBB threads (0: all cores)");
  app.add_flag("--cpu-time", o.mo.cpu_time,
               "time with the thread's CPU time, not the wall clock (needs --threads 1)");
  app.add_flag("--skip-passes", o.skip_passes, "skip the pass-vs-Embree benchmark");
  app.add_flag("--skip-scaling", o.skip_scaling, "skip the update-vs-texels benchmark");
  CLI11_PARSE(app, argc, argv);
  return irradcast::bench::run_guarded("error: ", [&] { return run(o); });
}

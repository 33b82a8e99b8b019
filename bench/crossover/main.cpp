// irradcast-bench-crossover: the number of users from which the shared GI server (one engine
// for everybody, each client composing its own view from the lightmaps) costs less CPU time than
// one reference path tracer per user, *at equal measured error* against a converged reference.
//
// Per scene and K fixed viewpoints:
//  - Reference: PathTracer::render at high spp (two independent halves, cached as EXR), the same
//    bounce count as the engine. The halves also measure the reference's own noise, which is
//    subtracted from every measured MSE (see error_of()).
//  - Shared engine: the real server's code path, EngineHost::step() (Engine::update, lightmaps,
//    TileStore::publish with RGB9E5 + zstd encoding), the server's options; a client decodes the
//    tiles that changed (wire::decode_tile) and composes its view (irradcast::compose) after
//    every update, on one thread. Process CPU time for the server, thread CPU time for the
//    client.
//  - Per-user path tracer: progressive PathTracer::render passes with seeds of their own,
//    process CPU time and error at checkpoints.
// The cross-over for a target error e is K* = server(e) / (pt(e) - client(e)). Prints a table,
// writes JSON and PNG plots (see docs/BENCHMARKS.md, "Cross-over at equal error"). The engine
// takes every option irradcast-server takes (server/tools/engine_options.h). With --join, the
// time a new viewer takes to get a converged first image instead (join.cpp).
// This file: the options and main; scene_run.cpp measures, report.cpp prints and plots
// (crossover.h).
#include "irradcast/common/cli.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "crossover.h"
#include "engine_options.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/engine_params.h"
#include "params_json.h"

using namespace irradcast;
using namespace irradcast::bench;

namespace {

struct Cli {
  Options o;
  tools::EngineOptions engine;  // every engine parameter, as irradcast-server takes it
  std::string scenes_text = "cornell,rooms:2", targets_text, json_path, metric = "corrected";
  int threads = 0;
  bool quick = false, join = false;
};

json run_params_json(const Options& o, const std::string& metric) {
  return {{"width", o.width},
          {"height", o.height},
          {"views", o.views},
          {"reference_spp", o.ref_spp},
          {"engine_updates", o.updates},
          {"pt_max_spp", o.pt_max_spp},
          {"metric", metric},
          {"engine", tools::params_json(o.engine.engine)},
          {"texels_per_scene", o.engine.atlas.texels_per_scene},
          {"max_lightmap_size", o.engine.atlas.max_lightmap_size},
          {"indirect_bounces", o.engine.engine.indirect_bounces}};
}

int run(Cli& cli) {
  Options& o = cli.o;
  const auto limit = start_run(cli.threads, o.out, cli.json_path,
                               cli.join ? "crossover_join.json" : "crossover.json");
  const int used_threads = tbb_threads();
  const Stopwatch wall;
  const double cpu_start = process_cpu_seconds();
  json result;
  result["machine"] = machine_json(used_threads);
  const std::string load_start = result["machine"]["load_average_at_start"];
  std::printf(
      "irradcast-bench-crossover: %s, %u hardware threads, %d TBB threads, load average %s\n"
      "%dx%d pixels, %d views, reference %d spp, %d engine updates, error metric: %s relative "
      "RMSE\n",
      cpu_model().c_str(), std::thread::hardware_concurrency(), used_threads, load_start.c_str(),
      o.width, o.height, o.views, o.ref_spp, o.updates, cli.metric.c_str());
  result["params"] = run_params_json(o, cli.metric);
  if (cli.join) {
    result["join"] = run_join(split_list(cli.scenes_text), o);
  } else {
    std::vector<SceneResult> results;
    for (const std::string& spec : split_list(cli.scenes_text))
      results.push_back(run_scene(spec, o));
    result["scenes"] = report_scenes(results, o);
    for (const SceneResult& r : results) plot_scene(r, o, cli.metric, used_threads);
  }
  result["machine"]["load_average_at_end"] = load_average();
  result["total_wall_s"] = wall.seconds();
  result["total_cpu_s"] = process_cpu_seconds() - cpu_start;
  write_json(cli.json_path, result);
  std::printf("wrote %s (total %.1f s wall, %.1f s CPU; load average at start %s, at end %s)\n",
              cli.json_path.c_str(), wall.seconds(), process_cpu_seconds() - cpu_start,
              load_start.c_str(), load_average().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Cli cli;
  Options& o = cli.o;
  CLI::App app{
      "irradcast-bench-crossover: users from which the shared engine (server + K clients) costs "
      "less CPU time than K path tracers, at equal error against a converged reference"};
  o.out = "out/crossover";
  const char* home = std::getenv("HOME");
  o.cache = (fs::path(home != nullptr && *home != '\0' ? home : "/tmp") / ".cache" / "irradcast" /
             "crossover")
                .string();
  app.add_option("--out", o.out, "directory for the JSON and the PNG plots");
  app.add_option("--cache", o.cache,
                 "directory for the cached reference images (EXR; keep it out of the repo)");
  app.add_option("--json", cli.json_path, "JSON results file (default OUT/crossover.json)");
  app.add_option("--scenes", cli.scenes_text, "scenes, comma separated");
  app.add_option("--size,--width", o.width, "image width")->check(CLI::Range(8, 4096));
  app.add_option("--height", o.height, "image height (default: 3/4 of the width)")
      ->check(CLI::Range(6, 4096));
  app.add_option("--views", o.views, "viewpoints per scene (at most 8 for the built-in scenes)")
      ->check(CLI::Range(1, 8));
  app.add_option("--ref-spp", o.ref_spp, "reference samples per pixel (two halves)")
      ->check(CLI::Range(2, 1 << 20));
  app.add_option("--updates", o.updates, "engine updates")->check(CLI::Range(1, 10000));
  app.add_option("--pt-max-spp", o.pt_max_spp, "per-user path tracer: most samples per pixel")
      ->check(CLI::Range(1, 1 << 20));
  app.add_option("--targets", cli.targets_text,
                 "target errors, comma separated (default: automatic, from the engine's first "
                 "update to its floor, plus one below the floor)");
  app.add_option("--levels", o.levels, "automatic target levels above the floor")
      ->check(CLI::Range(2, 20));
  app.add_option("--metric", cli.metric,
                 "corrected (the reference's own noise subtracted from the MSE) | raw")
      ->check(CLI::IsMember({"corrected", "raw"}));
  app.add_option("--threads", cli.threads, "TBB threads (0: all cores)");
  app.add_flag(
      "--quick", cli.quick,
      "smoke run: 64x48, 4 views, 64 reference spp, 4 updates, path tracer to 64 spp (unless "
      "given)");
  // The server's own options (engine parameters, atlas, backend): a parameter added to
  // engine_params.inc reaches this bench by itself.
  cli.engine.add_to(app);
  app.add_flag("--join", cli.join,
               "instead: a new viewer's first converged image, on a converged server and on a "
               "fresh one (scene camera, --updates updates; JSON default OUT/crossover_join.json)");
  CLI11_PARSE(app, argc, argv);
  if (cli.quick) {  // smaller defaults; options given explicitly keep their values
    auto unless_given = [&](const char* name, int& value, int quick_value) {
      if (app.count(name) == 0) value = quick_value;
    };
    unless_given("--size", o.width, 64);
    unless_given("--views", o.views, 4);
    unless_given("--ref-spp", o.ref_spp, 64);
    unless_given("--updates", o.updates, 4);
    unless_given("--pt-max-spp", o.pt_max_spp, 64);
  }
  if (app.count("--height") == 0) o.height = std::max(1, o.width * 3 / 4);
  o.corrected = cli.metric == "corrected";
  for (const std::string& item : split_list(cli.targets_text)) o.targets.push_back(std::stod(item));
  return irradcast::bench::run_guarded("irradcast-bench-crossover: error: ", [&] {
    o.engine.engine = cli.engine.params();  // throws irradcast::Error naming a bad value
    o.engine.backend = cli.engine.backend_options();
    o.engine.atlas = cli.engine.atlas();
    return run(cli);
  });
}

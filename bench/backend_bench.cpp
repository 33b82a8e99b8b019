// irradcast-bench-backend: the engine's passes on each TraceBackend (Embree on the CPU, Vulkan
// compute on whatever device the machine has: lavapipe in CI, a GPU where one is lent), side by
// side in one run: the same scene, atlas, probes and parameters, updates interleaved (one
// update on each backend in turn) so that machine load drifts hit both alike. Reports per pass
// time and rays/s per backend and their ratio, the backend set-up time (BVH, upload, shader
// compilation) apart, and the reference path tracer's lightmaps on each backend; writes JSON
// and a PNG bar chart (docs/BENCHMARKS.md, "Backends").
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/backend_select.h"
#include "irradcast/common/builtin.h"
#include "irradcast/engine/engine.h"
#include "irradcast/common/error.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "irradcast/engine/texel_validity.h"
#include "irradcast/engine/vulkan_backend.h"
#include "irradcast/common/world.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

struct PassTotals {
  std::string pass;  // direct, probes_k, scatter_k
  double seconds = 0.0;
  std::uint64_t rays = 0;
};

struct BackendRun {
  std::string name;      // embree | vulkan
  std::string describe;  // with the device
  double setup_seconds = 0.0;
  std::vector<PassTotals> passes;
  double update_seconds = 0.0;  // timed updates, total
};

void add(std::vector<PassTotals>& totals, const std::string& pass, const PassTiming& t) {
  for (PassTotals& p : totals)
    if (p.pass == pass) {
      p.seconds += t.seconds;
      p.rays += t.rays;
      return;
    }
  totals.push_back({pass, t.seconds, t.rays});
}

void add(BackendRun& run, const UpdateStats& st) {
  add(run.passes, "direct", st.direct);
  for (std::size_t b = 0; b < st.scatter.size(); ++b) {
    if (b < st.probes.size() && st.probes[b].rays > 0)
      add(run.passes, "probes_" + std::to_string(b + 1), st.probes[b]);
    add(run.passes, "scatter_" + std::to_string(b + 1), st.scatter[b]);
  }
  run.update_seconds += st.total_seconds;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-backend: engine passes per backend (Embree vs Vulkan), one run"};
  std::string scenes_text = "cornell,rooms:2,rooms:4";
  std::string backends_text = "embree,vulkan";
  std::string out = "out/backend";
  std::string json_path;
  float texels_per_scene = 256.0f;
  float range = 0.3f;
  int updates = 4, warmup = 1, threads = 0, vulkan_device = -1, reference_spp = 16;
  app.add_option("--scenes", scenes_text, "scenes, comma separated");
  app.add_option("--backends", backends_text, "backends, comma separated: embree, vulkan");
  app.add_option("--vulkan-device", vulkan_device, "Vulkan device index (--list-devices)");
  app.add_option("--texels-per-scene", texels_per_scene, "lightmap density")
      ->check(CLI::Range(4.0f, 8192.0f));
  app.add_option("--tracing-range", range, "tracing range (fraction of the scene)");
  app.add_option("--updates", updates, "timed updates per backend")->check(CLI::Range(1, 1000));
  app.add_option("--warmup", warmup, "untimed updates first (uploads, shader compilation)")
      ->check(CLI::Range(0, 100));
  app.add_option("--reference-spp", reference_spp,
                 "reference lightmaps per backend, paths per texel (0: skip)")
      ->check(CLI::Range(0, 100000));
  app.add_option("--threads", threads, "TBB threads for Embree and the host (0: all cores)");
  app.add_option("--out", out, "directory for the JSON and the PNG chart");
  app.add_option("--json", json_path, "JSON results file (default OUT/backend.json)");
  CLI11_PARSE(app, argc, argv);
  try {
    Progress::set_enabled(false);
    log::set_level(log::Level::Warn);
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0)
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(threads));
    fs::create_directories(out);
    if (json_path.empty()) json_path = (fs::path(out) / "backend.json").string();
    const std::vector<std::string> backends = split(backends_text);
    json results = json::array();
    plot::BarChart chart;
    chart.title = "Engine passes: rays/s per backend (higher is better)";
    chart.y_label = "Mrays/s";
    chart.series_labels = backends;
    chart.colors = {plot::kBlue, plot::kOrange, plot::kGreen};
    chart.values.assign(backends.size(), {});

    std::printf("%-10s %8s %-10s", "scene", "texels", "pass");
    for (const std::string& b : backends) std::printf(" %10s %12s", (b + " ms").c_str(), "Mrays/s");
    if (backends.size() == 2) std::printf(" %12s", "time ratio");
    std::printf("\n");

    for (const std::string& spec : split(scenes_text)) {
      Scene scene = load_scene(spec);
      World world = World::build(scene);
      RayScene rays(world);
      LightSampler lights(world);
      AtlasOptions ao;
      ao.texels_per_scene = texels_per_scene;
      Atlas atlas = build_atlas(world, ao);
      std::vector<TexelGBuffer> gbuffers = rasterize_gbuffer(world, atlas);
      mark_hidden_texels(rays, gbuffers);
      EngineParams params;
      params.tracing_range = range;

      std::vector<BackendRun> runs;
      std::vector<std::unique_ptr<Engine>> engines;
      for (const std::string& b : backends) {
        BackendOptions bo;
        bo.kind = parse_backend(b);
        bo.vulkan_device = vulkan_device;
        const auto start = Clock::now();
        BackendChoice choice = make_backend(bo, world, rays, lights);
        BackendRun run;
        run.name = choice.backend->name();
        run.describe = choice.backend->describe();
        engines.push_back(std::make_unique<Engine>(world, atlas, gbuffers, rays,
                                                   std::move(choice.backend), params));
        for (int u = 0; u < warmup; ++u) engines.back()->update();
        run.setup_seconds = seconds_since(start);
        runs.push_back(run);
      }
      for (int u = 0; u < updates; ++u)
        for (std::size_t k = 0; k < engines.size(); ++k) add(runs[k], engines[k]->update());

      json scene_json;
      scene_json["scene"] = spec;
      scene_json["texels"] = engines.front()->texel_count();
      scene_json["updates"] = updates;
      for (const BackendRun& r : runs) {
        json j;
        j["backend"] = r.name;
        j["device"] = r.describe;
        j["setup_seconds"] = r.setup_seconds;
        j["seconds_per_update"] = r.update_seconds / updates;
        for (const PassTotals& p : r.passes)
          j["passes"].push_back({{"pass", p.pass},
                                 {"seconds_per_update", p.seconds / updates},
                                 {"rays_per_update", p.rays / static_cast<std::uint64_t>(updates)},
                                 {"rays_per_second", p.rays / p.seconds}});
        scene_json["backends"].push_back(j);
      }
      auto row = [&](const std::string& pass, auto&& pick) {
        std::printf("%-10s %8zu %-10s", spec.c_str(), engines.front()->texel_count(), pass.c_str());
        std::vector<double> secs;
        for (std::size_t k = 0; k < runs.size(); ++k) {
          auto [s, rays] = pick(runs[k]);
          secs.push_back(s);
          std::printf(" %10.2f %12.2f", 1e3 * s / updates, rays > 0 ? rays / s / 1e6 : 0.0);
        }
        if (secs.size() == 2) std::printf(" %12.2f", secs[1] / secs[0]);
        std::printf("\n");
      };
      for (const PassTotals& p : runs.front().passes)
        row(p.pass, [&](const BackendRun& r) {
          for (const PassTotals& q : r.passes)
            if (q.pass == p.pass) return std::pair<double, double>(q.seconds, q.rays);
          return std::pair<double, double>(0.0, 0.0);
        });
      // The chart: per pass kind (bounces summed) and the whole update.
      for (const char* kind : {"direct", "probes", "scatter", "update"}) {
        chart.categories.push_back(spec + "\n" + kind);
        for (std::size_t k = 0; k < runs.size(); ++k) {
          double secs = 0.0, rays = 0.0;
          for (const PassTotals& q : runs[k].passes)
            if (std::string(kind) == "update" || q.pass.rfind(kind, 0) == 0) {
              secs += q.seconds;
              rays += static_cast<double>(q.rays);
            }
          chart.values[k].push_back(secs > 0.0 ? rays / secs / 1e6 : 0.0);
        }
      }
      row("update", [&](const BackendRun& r) {
        std::uint64_t rays = 0;
        for (const PassTotals& q : r.passes) rays += q.rays;
        return std::pair<double, double>(r.update_seconds, static_cast<double>(rays));
      });
      for (const BackendRun& r : runs)
        std::printf("%-10s set-up + %d warm-up update(s) %-8s %.2f s (%s)\n", spec.c_str(), warmup,
                    r.name.c_str(), r.setup_seconds, r.describe.c_str());
      // The reference path tracer's lightmaps on each backend (set-up not timed).
      if (reference_spp > 0) {
        const int bounces = params.indirect_bounces;
        for (const std::string& b : backends) {
          ReferenceLightmapStats st;
          std::string device = "embree";
          if (parse_backend(b) == BackendKind::Vulkan) {
            VulkanContextOptions vo;
            vo.device = vulkan_device;
            VulkanBackend v(world, rays, lights, vo);
            device = v.describe();
            v.reference_lightmaps(gbuffers, 1, bounces, 2);  // warm-up: shader compilation
            v.reference_lightmaps(gbuffers, reference_spp, bounces, 1, &st);
          } else {
            PathTracer tracer(world, rays, lights, PathTracerOptions{bounces, true, 1});
            reference_lightmaps(world, tracer, gbuffers, reference_spp, &st);
          }
          std::printf("%-10s reference lightmaps %-8s %d spp: %.2f s, %.2f Mrays/s\n", spec.c_str(),
                      b.c_str(), reference_spp, st.seconds, st.rays / st.seconds / 1e6);
          scene_json["reference"].push_back({{"backend", b},
                                             {"device", device},
                                             {"samples_per_texel", reference_spp},
                                             {"seconds", st.seconds},
                                             {"rays", st.rays}});
        }
      }
      std::fflush(stdout);
      results.push_back(scene_json);
    }
    std::ofstream(json_path) << results.dump(2) << "\n";
    chart.note = "the same engine, scene and parameters on each backend; updates interleaved";
    chart.value_decimals = 1;
    chart.width = std::max(900, 100 * static_cast<int>(chart.categories.size()) + 200);
    const std::string png = (fs::path(out) / "backend_rays.png").string();
    plot::write_bar_chart(png, chart);
    std::printf("wrote %s and %s\n", json_path.c_str(), png.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-backend: %s\n", e.what());
    return 1;
  }
}

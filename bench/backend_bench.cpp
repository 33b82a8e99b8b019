// irradcast-bench-backend: the engine's passes on each TraceBackend (Embree on the CPU, Vulkan
// compute on whatever device the machine has: lavapipe in CI, a GPU where one is lent), side by
// side in one run: the same scene, atlas, probes and parameters, updates interleaved (one
// update on each backend in turn) so that machine load drifts hit both alike. Reports per pass
// time and rays/s per backend and their ratio, the backend set-up time (BVH, upload, shader
// compilation) apart, and the reference path tracer's lightmaps on each backend; writes JSON
// and a PNG bar chart (docs/BENCHMARKS.md, "Backends").
#include <tbb/global_control.h>
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "bench_options.h"
#include "bench_scene.h"
#include "bench_util.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/backend_select.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "irradcast/engine/texel_validity.h"
#include "plot.h"
#include "vulkan_backend.h"

using namespace irradcast;
using namespace irradcast::bench;

namespace {

struct PassTotals {
  std::string pass;  // direct, probes_k, scatter_k
  double seconds = 0.0;
  std::uint64_t rays = 0;
  PassTiming sum;  // everything the backend reported, summed over the timed updates
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
      p.sum += t;
      return;
    }
  totals.push_back({pass, t.seconds, t.rays, t});
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

struct Options {
  std::string scenes_text = "cornell,rooms:2,rooms:4";
  std::string backends_text = "embree,vulkan";
  std::string out = "out/backend";
  std::string json_path;
  float texels_per_scene = 256.0f;
  std::string range;  // --tracing-range as the engine reads it ("": its default)
  int updates = 4, warmup = 1, threads = 0, vulkan_device = -1, reference_spp = 16;
};

// One engine per backend, set up and warmed up, then o.updates updates interleaved.
std::vector<BackendRun> run_backends(const Options& o, const PreparedScene& s,
                                     const std::vector<std::string>& backends,
                                     const EngineParams& params, std::size_t& texels) {
  std::vector<BackendRun> runs;
  std::vector<std::unique_ptr<Engine>> engines;
  for (const std::string& b : backends) {
    // vulkan-host: Vulkan with the probes' running means on the host (two submissions per
    // bounce, as before they stayed on the device), for a before/after comparison in one run.
    const bool host_means = b == "vulkan-host";
    BackendOptions bo;
    bo.kind = parse_backend(host_means ? "vulkan" : b);
    bo.vulkan_device = o.vulkan_device;
    const auto start = Clock::now();
    BackendChoice choice = make_backend(bo, s.world(), s.rays(), s.lights());
    if (host_means) dynamic_cast<VulkanBackend&>(*choice.backend).set_resident_probes(false);
    BackendRun run;
    run.name = host_means ? b : choice.backend->name();
    run.describe = choice.backend->describe();
    engines.push_back(std::make_unique<Engine>(s.world(), s.atlas(), s.gbuffers(), s.rays(),
                                               std::move(choice.backend), params));
    for (int u = 0; u < o.warmup; ++u) engines.back()->update();
    run.setup_seconds = seconds_since(start);
    runs.push_back(run);
  }
  for (int u = 0; u < o.updates; ++u)
    for (std::size_t k = 0; k < engines.size(); ++k) add(runs[k], engines[k]->update());
  texels = engines.front()->texel_count();
  return runs;
}

json scene_json(const std::string& spec, std::size_t texels, int updates,
                const std::vector<BackendRun>& runs) {
  json scene_json;
  scene_json["scene"] = spec;
  scene_json["texels"] = texels;
  scene_json["updates"] = updates;
  for (const BackendRun& r : runs) {
    json j;
    j["backend"] = r.name;
    j["device"] = r.describe;
    j["setup_seconds"] = r.setup_seconds;
    j["seconds_per_update"] = r.update_seconds / updates;
    for (const PassTotals& p : r.passes)
      j["passes"].push_back(
          {{"pass", p.pass},
           {"seconds_per_update", p.seconds / updates},
           {"device_seconds_per_update", p.sum.device_seconds / updates},
           {"bytes_up_per_update", p.sum.bytes_up / static_cast<std::uint64_t>(updates)},
           {"bytes_down_per_update", p.sum.bytes_down / static_cast<std::uint64_t>(updates)},
           {"submissions_per_update", static_cast<double>(p.sum.submissions) / updates},
           {"rays_per_update", p.rays / static_cast<std::uint64_t>(updates)},
           {"rays_per_second", p.rays / p.seconds}});
    scene_json["backends"].push_back(j);
  }
  return scene_json;
}

// Per backend and pass, per update: wall time against the device's own time (timestamps), the
// bytes each way and the submissions (each one a fence wait); the CPU backend reports no
// device numbers.
void print_transfers(const std::string& spec, int updates, const std::vector<BackendRun>& runs) {
  for (const BackendRun& r : runs) {
    if (r.name == "embree") continue;
    PassTiming total;
    auto line = [&](const std::string& pass, const PassTiming& t) {
      std::printf(
          "%-10s %-8s %-10s wall %8.2f ms  device %8.2f ms  up %9.1f KiB  down %9.1f KiB"
          "  submissions %5.2f  %8.2f Mrays/s\n",
          spec.c_str(), r.name.c_str(), pass.c_str(), 1e3 * t.seconds / updates,
          1e3 * t.device_seconds / updates, t.bytes_up / 1024.0 / updates,
          t.bytes_down / 1024.0 / updates, static_cast<double>(t.submissions) / updates,
          t.seconds > 0.0 ? t.rays / t.seconds / 1e6 : 0.0);
    };
    for (const PassTotals& p : r.passes) {
      line(p.pass, p.sum);
      total += p.sum;
    }
    total.seconds = r.update_seconds;
    line("update", total);
  }
}

// The table rows of one scene: per pass, then the whole update, then the set-up times.
void print_rows(const std::string& spec, std::size_t texels, const Options& o,
                const std::vector<BackendRun>& runs) {
  const int updates = o.updates;
  auto row = [&](const std::string& pass, auto&& pick) {
    std::printf("%-10s %8zu %-10s", spec.c_str(), texels, pass.c_str());
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
  row("update", [&](const BackendRun& r) {
    std::uint64_t rays = 0;
    for (const PassTotals& q : r.passes) rays += q.rays;
    return std::pair<double, double>(r.update_seconds, static_cast<double>(rays));
  });
  for (const BackendRun& r : runs)
    std::printf("%-10s set-up + %d warm-up update(s) %-8s %.2f s (%s)\n", spec.c_str(), o.warmup,
                r.name.c_str(), r.setup_seconds, r.describe.c_str());
  print_transfers(spec, updates, runs);
}

// The chart's bars of one scene: per pass kind (bounces summed) and the whole update.
void add_to_chart(const std::string& spec, const std::vector<BackendRun>& runs,
                  plot::BarChart& chart) {
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
}

// The reference path tracer's lightmaps on each backend (set-up not timed).
json run_references(const std::string& spec, const Options& o, const PreparedScene& s,
                    const std::vector<std::string>& backends, int bounces) {
  json out;
  const int reference_spp = o.reference_spp;
  for (const std::string& b : backends) {
    if (b == "vulkan-host") continue;  // the same reference as vulkan
    ReferenceLightmapStats st;
    std::string device = "embree";
    if (parse_backend(b) == BackendKind::Vulkan) {
      VulkanContextOptions vo;
      vo.device = o.vulkan_device;
      VulkanBackend v(s.world(), s.rays(), s.lights(), vo);
      device = v.describe();
      v.reference_lightmaps(s.gbuffers(), 1, bounces, 2);  // warm-up: shader compilation
      v.reference_lightmaps(s.gbuffers(), reference_spp, bounces, 1, &st);
    } else {
      PathTracer tracer(s.world(), s.rays(), s.lights(), PathTracerOptions{bounces, true, 1});
      reference_lightmaps(s.world(), tracer, s.gbuffers(), reference_spp, &st);
    }
    std::printf("%-10s reference lightmaps %-8s %d spp: %.2f s, %.2f Mrays/s\n", spec.c_str(),
                b.c_str(), reference_spp, st.seconds, st.rays / st.seconds / 1e6);
    out.push_back({{"backend", b},
                   {"device", device},
                   {"samples_per_texel", reference_spp},
                   {"seconds", st.seconds},
                   {"rays", st.rays}});
  }
  return out;
}

int run(Options o) {
  const auto limit = start_run(o.threads, o.out, o.json_path, "backend.json");
  const std::vector<std::string> backends = split_list(o.backends_text);
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

  for (const std::string& spec : split_list(o.scenes_text)) {
    const PreparedScene s = prepare(load_scene(spec), density(o.texels_per_scene));
    EngineParams params;
    if (!o.range.empty()) params.tracing_range = parse_tracing_range(o.range);
    std::size_t texels = 0;
    const std::vector<BackendRun> runs = run_backends(o, s, backends, params, texels);
    json sj = scene_json(spec, texels, o.updates, runs);
    print_rows(spec, texels, o, runs);
    add_to_chart(spec, runs, chart);
    if (o.reference_spp > 0)
      sj["reference"] = run_references(spec, o, s, backends, params.indirect_bounces);
    std::fflush(stdout);
    results.push_back(sj);
  }
  write_json(o.json_path, results);
  chart.note = "the same engine, scene and parameters on each backend; updates interleaved";
  chart.value_decimals = 1;
  chart.width = std::max(900, 100 * static_cast<int>(chart.categories.size()) + 200);
  const std::string png = (fs::path(o.out) / "backend_rays.png").string();
  plot::write_bar_chart(png, chart);
  std::printf("wrote %s and %s\n", o.json_path.c_str(), png.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-backend: engine passes per backend (Embree vs Vulkan), one run"};
  Options o;
  app.add_option("--scenes", o.scenes_text, "scenes, comma separated");
  app.add_option("--backends", o.backends_text,
                 "backends, comma separated: embree, vulkan, vulkan-host (the probes' means on "
                 "the host)");
  app.add_option("--vulkan-device", o.vulkan_device, "Vulkan device index (--list-devices)");
  add_texels_per_scene(app, o.texels_per_scene)->check(CLI::Range(4.0f, 8192.0f));
  app.add_option("--tracing-range", o.range,
                 "tracing range: a fraction of the scene (0.3), metres (2.4m), a capped fraction "
                 "(0.3:1.2m) or inf; the engine's default when not given");
  app.add_option("--updates", o.updates, "timed updates per backend")->check(CLI::Range(1, 1000));
  app.add_option("--warmup", o.warmup, "untimed updates first (uploads, shader compilation)")
      ->check(CLI::Range(0, 100));
  app.add_option("--reference-spp", o.reference_spp,
                 "reference lightmaps per backend, paths per texel (0: skip)")
      ->check(CLI::Range(0, 100000));
  app.add_option("--threads", o.threads, "TBB threads for Embree and the host (0: all cores)");
  app.add_option("--out", o.out, "directory for the JSON and the PNG chart");
  app.add_option("--json", o.json_path, "JSON results file (default OUT/backend.json)");
  CLI11_PARSE(app, argc, argv);
  return irradcast::bench::run_guarded("irradcast-bench-backend: ", [&] { return run(o); });
}

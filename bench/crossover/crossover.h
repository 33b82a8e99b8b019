// irradcast-bench-crossover's parts, shared by its files: the viewpoints, the reference and
// the error metric, the measurements of one scene (scene_run.cpp) and the report: table, JSON
// and plots (report.cpp). main.cpp holds the options; what the bench measures is described there.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "irradcast/common/camera.h"
#include "irradcast/common/image.h"
#include "irradcast/common/world.h"
#include "irradcast/service/engine_host.h"
#include "plot.h"

namespace irradcast::bench {

constexpr double kInf = std::numeric_limits<double>::infinity();

struct Options {
  int width = 160, height = 120, views = 8, ref_spp = 1024, updates = 32, pt_max_spp = 1024;
  std::string cache, out;
  // The server's options, as irradcast-server parses them (server/tools/engine_options.h: every
  // parameter of engine_params.inc, the atlas and the backend); the path tracer takes its
  // bounce count from them.
  EngineHostOptions engine;
  bool corrected = true;
  std::vector<double> targets;  // empty: automatic
  int levels = 5;
};

// ---------------------------------------------------------------------------------------------
// Viewpoints.

struct View {
  std::string name;
  CameraPose pose;
};

// Eight fixed, varied viewpoints per built-in scene, all looking at lit surfaces (the first is
// the scene's own camera). Other scenes get the default camera and views around the bounds.
std::vector<View> make_views(const std::string& spec, const Scene& scene, const World& world);
nlohmann::json pose_json(const CameraPose& p);

// ---------------------------------------------------------------------------------------------
// The reference and the error metric.

struct Reference {
  ImageRGB image;             // (A + B) / 2
  double noise_mse = 0.0;     // mean over pixels and channels of ((A - B) / 2)^2
  double noise_mse_se = 0.0;  // noise_mse's standard error (pixels independent)
  double mean = 0.0;          // mean over pixels and channels of the image
  double cpu_s = 0.0;         // 0 when read from the cache
  bool cached = false;
  double rel_noise() const { return mean > 0 ? std::sqrt(noise_mse) / mean : 0.0; }
  // The standard error that noise_mse's own uncertainty gives a corrected error e (relative):
  // d(sqrt(mse - N) / mean) = dN / (2 e mean^2).
  double corrected_se(double e) const {
    return e > 0 && mean > 0 ? noise_mse_se / (2.0 * e * mean * mean) : 0.0;
  }
};

// Relative RMSE of linear radiance: sqrt(mean over pixels and channels of (img - ref)^2) /
// mean(ref). `raw` against the reference as it is; `corrected` with the reference's own noise
// subtracted from the MSE (E[(x - ref)^2] = E[(x - truth)^2] + E[(ref - truth)^2] when x and the
// reference are independent, and mean(((A - B) / 2)^2) estimates the second term without bias).
struct Err {
  double raw = 0.0, corrected = 0.0;
  double get(bool use_corrected) const { return use_corrected ? corrected : raw; }
};

Err error_of(const ImageRGB& img, const Reference& ref);

// ---------------------------------------------------------------------------------------------
// Per scene state and measurements.

struct EngineStep {
  double server_cpu_s = 0, server_wall_s = 0;  // update + lightmaps + publish (RGB9E5 encode)
  double decode_cpu_s = 0;                     // the client: decode the changed tiles
  std::vector<double> compose_cpu_s;           // the client: one frame, per view
  std::size_t tiles_changed = 0;
  std::uint64_t bytes = 0;  // encoded payload of the changed tiles (what each client receives)
  double convergence = 0;
  std::vector<Err> err;  // per view
  double mean_err(bool c) const {
    double s = 0;
    for (const Err& e : err) s += e.get(c);
    return s / static_cast<double>(err.size());
  }
  double max_err(bool c) const {
    double m = 0;
    for (const Err& e : err) m = std::max(m, e.get(c));
    return m;
  }
  double mean_compose() const {
    double s = 0;
    for (double t : compose_cpu_s) s += t;
    return s / static_cast<double>(compose_cpu_s.size());
  }
};

struct PtPoint {
  int spp = 0;
  double cpu_s = 0, wall_s = 0;  // cumulative
  Err err;
};

struct Row {
  double target = 0;
  // Mean-error criterion: the first update whose error averaged over the views is <= target.
  int updates = -1;  // -1: never (below the engine's floor)
  double server_s = kInf, client_s = kInf, kstar = kInf;
  double client_compose_s = kInf;  // the compose part of client_s
  // Every-view criterion: the first update at which every view's error is <= target.
  int updates_all = -1;
  double server_all_s = kInf, client_all_s = kInf, kstar_all = kInf;
  double pt_s = kInf;       // mean over the views of the per-user path tracer's CPU time to target
  int pt_extrapolated = 0;  // views whose time comes from the 1/sqrt(t) law past the last point
  double mean_spp = 0;      // per-user samples per pixel at the target (mean over views)
};

struct SceneResult {
  std::string spec;
  std::size_t texels = 0, tiles = 0, lightmaps = 0, triangles = 0;
  double setup_cpu_s = 0, client_setup_cpu_s = 0;
  std::vector<View> views;
  std::vector<Reference> refs;
  std::vector<EngineStep> engine;
  std::vector<std::vector<PtPoint>> pt;  // per view
  std::vector<double> targets;
  std::vector<Row> rows;
  double floor_mean = kInf, floor_all = kInf;      // the engine's lowest errors over the run
  std::vector<ImageRGB> engine_at_mid, pt_at_mid;  // per view, for the picture
  int mid_update = -1;
  double mid_target = 0;
  std::vector<int> mid_spp;
};

// K* = server / (pt - client); infinite where the path tracer is not slower than the client.
double kstar_of(double server, double client, double pt);
// Per-user path tracer CPU time to reach error e on one view: the first checkpoint at or below
// e, interpolated in log-log with the checkpoint before it; above the first checkpoint, the
// first checkpoint's time (nobody renders less than one pass); below the last checkpoint's error,
// extrapolated with the Monte Carlo law t ~ e^-2 fitted on the last three checkpoints.
double pt_time_to(const std::vector<PtPoint>& c, double e, bool corrected, bool* extrapolated,
                  double* spp);
// The scene spec as a file name part (alphanumerics kept, the rest '_').
std::string file_key(const std::string& spec);

// Measures one scene: references, engine updates, per-user path tracers, cross-over rows
// (scene_run.cpp).
SceneResult run_scene(const std::string& spec, const Options& o);
// The reference of views[v] in `world` (run_scene's, from the same cache; scene_run.cpp).
Reference view_reference(const std::string& spec, const Options& o, const World& world,
                         const std::vector<View>& views, std::size_t v);

// ---------------------------------------------------------------------------------------------
// --join (join.cpp): a new viewer's first converged image, on a converged and on a fresh server.

// Runs both cases for each scene, prints them, writes crossover_join_<scene>.png and returns
// their JSON.
nlohmann::json run_join(const std::vector<std::string>& scenes, const Options& o);

// ---------------------------------------------------------------------------------------------
// The report (report.cpp).

// Prints the cross-over table of every scene and returns their JSON.
nlohmann::json report_scenes(const std::vector<SceneResult>& results, const Options& o);
// Writes the three PNGs of one scene (error vs CPU time, CPU time vs users, the views).
void plot_scene(const SceneResult& r, const Options& o, const std::string& metric,
                int used_threads);

}  // namespace irradcast::bench

// irradcast-bench-engine's parts, shared by its files: the pass benchmark
// (passes.cpp: engine passes vs RayScene vs raw Embree on the same rays) and the scaling
// benchmark (scaling.cpp: full-update time against texel count). main.cpp holds the options and
// the pass report; what the bench measures is described there.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_scene.h"

namespace irradcast::bench {

// ---------------------------------------------------------------------------------------------
// 1. Pass throughput (passes.cpp).

struct MeasureOptions {
  int min_reps = 5;
  int max_reps = 200;
  double min_seconds = 0.25;  // of pipeline time per pass
  // Time every side with the calling thread's CPU time instead of the wall clock (only with one
  // TBB thread, which runs the passes on the calling thread): a loaded machine's other work does
  // not count.
  bool cpu_time = false;
};

// One pass of one scene, bounces summed.
struct PassRow {
  std::string scene, pass;
  std::size_t texels = 0;
  std::uint64_t engine_rays = 0, traced_rays = 0, hits = 0;
  double pipeline_s = 0, rayscene_s = 0, raw_s = 0;  // sums over bounces of the fastest reps
  // The direct pass: the engine's pass with its shadow rays forced into packets of 8 and one by
  // one, and the share of the default's (ShadowRays::Auto) shadow rays it traced in packets.
  double packets_s = 0, single_s = 0;
  double auto_packet_share = 0;
  std::uint64_t packet_disagreements = 0;  // shadow rays raw packets and single rays answer apart
  double max_rel_diff = 0;
  int reps = 0;
  double mrays(double s) const { return s > 0 ? traced_rays / s * 1e-6 : 0.0; }
};

// Measures one update of the scene `spec`: a row per pass, and the scene's JSON (with every
// pass and bounce) appended to `out`.
std::vector<PassRow> bench_passes(const std::string& spec, float texels_per_scene,
                                  const MeasureOptions& mo, nlohmann::json& out);

// ---------------------------------------------------------------------------------------------
// 2. Update time against texel count (scaling.cpp).

struct ScalingOptions {
  std::string sizes_text = "1,2,3,4,6";   // N of rooms:N at `density`
  float density = 16.0f;                  // texels per metre
  int sweep_size = 2;                     // M of rooms:M for the density sweep
  std::string sweep_text = "8,16,24,32";  // its densities
  // Many-light buildings at `density` (N:lit, N:trim; rooms:N:lit, rooms:N:trim), a series of
  // their own.
  std::string many_text = "";
  int updates = 5;      // rounds; the fastest is kept
  EngineParams params;  // the engine's (--cell-size 2m ...: irradcast-server's options)
};

// Runs both series, prints their table and fits, adds their JSON to `result` and writes the
// plot OUT_DIR/bench_update_vs_texels.png.
void run_scaling(const ScalingOptions& o, int used_threads, const std::string& out_dir,
                 nlohmann::json& result);

}  // namespace irradcast::bench

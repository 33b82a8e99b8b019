// Filling a {rays, seconds} statistics record (PathTracer::RenderStats, ReferenceLightmapStats)
// at the end of a CPU reference run.
#pragma once

#include <chrono>
#include <cstdint>

namespace irradcast {

// When `stats` is given: the rays traced and the seconds since `start`.
template <class Stats>
void record_run(Stats* stats, std::uint64_t rays, std::chrono::steady_clock::time_point start) {
  if (!stats) return;
  stats->rays = rays;
  stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace irradcast

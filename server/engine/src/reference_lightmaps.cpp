#include "irradcast/engine/reference_lightmaps.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>

#include "irradcast/common/error.h"
#include "irradcast/common/progress.h"
#include "run_stats.h"

namespace irradcast {

std::vector<Lightmap> reference_lightmaps(const World& world, const PathTracer& tracer,
                                          const std::vector<TexelGBuffer>& gbuffers,
                                          int samples_per_texel, ReferenceLightmapStats* stats) {
  if (samples_per_texel <= 0) throw Error("samples per texel must be positive");
  if (gbuffers.size() != world.objects.size())
    throw Error("reference lightmaps: G-buffers do not match the scene's objects");
  auto start = std::chrono::steady_clock::now();
  std::uint64_t valid = 0;
  for (const TexelGBuffer& g : gbuffers) valid += g.valid_count();
  Progress progress("reference lightmaps", valid, "texels");
  std::atomic<std::uint64_t> rays{0};
  std::vector<Lightmap> maps(gbuffers.size());
  const int bounces = tracer.options().indirect_bounces;
  for (std::size_t o = 0; o < gbuffers.size(); ++o) {
    const TexelGBuffer& g = gbuffers[o];
    const WorldObject& obj = world.objects[o];
    Lightmap& map = maps[o];
    map = Lightmap(g.width, g.height);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, g.size(), 64),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        std::uint64_t local = 0, texels = 0;
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          if (!g.valid(i)) continue;
                          const TexelPoint p = g.point(obj, i);
                          glm::dvec3 sum(0.0);
                          Rng rng(mix64(tracer.options().seed + o) ^ i, 0x11c0ffee);
                          for (int s = 0; s < samples_per_texel; ++s)
                            sum += glm::dvec3(tracer.irradiance(p.position, p.normal, p.geo_normal,
                                                                bounces, rng, &local));
                          map.texels[i] = glm::vec3(sum / static_cast<double>(samples_per_texel));
                          ++texels;
                        }
                        rays += local;
                        progress.advance(texels);
                      });
    dilate(map.texels, map.width, map.height, g.kind);
  }
  progress.finish();
  record_run(stats, rays.load(), start);
  return maps;
}

}  // namespace irradcast

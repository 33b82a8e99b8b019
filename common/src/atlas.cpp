// Lightmap atlas: one lightmap per object, from the file's TEXCOORD_1 when it is usable
// (atlas_file_uv1.cpp) or from generated charts (atlas_charts.cpp) packed with gutters
// (atlas_pack.cpp); objects in parallel.
#include "irradcast/common/atlas.h"

#include <cmath>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "atlas_internal.h"

namespace irradcast {

std::size_t Atlas::texel_count() const {
  std::size_t n = 0;
  for (const ObjectLightmap& o : objects)
    n += static_cast<std::size_t>(o.width) * static_cast<std::size_t>(o.height);
  return n;
}

float atlas_base_density(const World& world, const AtlasOptions& options) {
  float extent = world.bounds.max_extent();
  float d = extent > 0.0f && std::isfinite(extent) ? options.texels_per_scene / extent
                                                   : options.texels_per_scene;
  return d > 0.0f && std::isfinite(d) ? d : 1.0f;
}

Atlas build_atlas(const World& world, const AtlasOptions& options) {
  Atlas atlas;
  atlas.objects.resize(world.objects.size());
  const float density = atlas_base_density(world, options);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, world.objects.size(), 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t oi = r.begin(); oi < r.end(); ++oi) {
                        const WorldObject& wo = world.objects[oi];
                        ObjectLightmap& lm = atlas.objects[oi];
                        if (wo.triangles().empty() || wo.dynamic) continue;
                        if (options.use_file_uv1 && !wo.source->uv1.empty() &&
                            atlas_detail::build_from_file_uv1(world, oi, options, density, lm))
                          continue;
                        atlas_detail::build_generated(world, oi, options, density, lm);
                      }
                    });
  return atlas;
}

}  // namespace irradcast

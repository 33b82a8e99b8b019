// Computes the irradiance volume (common/irradiance_volume.h) of the static scene on the server:
// places the probes (a grid over the scene's bounds; probes inside geometry moved out or switched
// off; their distance moments), then refines their irradiance from the engine's lightmaps: rays
// from each probe read the radiance of the surfaces they hit (albedo / pi x the lightmap's
// irradiance, plus emission) or the sky, projected onto SH L2 and blended into a running mean.
// The punctual lights' direct light is not in it: a sun's or a lamp's shadow edge is far sharper
// than a probe grid, so the viewers add it themselves with a shadow ray (dynamic_view.h). Embree on
// the CPU, probes in parallel.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/irradiance_volume.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct IrradianceVolumeOptions {
  // Distance between probes in scene units (metres); 0: `spacing_fraction` of the static scene's
  // largest extent, at most `max_default_spacing` metres (a fraction alone grows with the world:
  // 4.35 m in the Sponza, where a sphere in the shaded gallery read 37 % bright; 13 % at 1 m,
  // docs/DYNAMIC.md).
  float spacing = 0.0f;
  float spacing_fraction = 0.125f;
  float max_default_spacing = 1.0f;
  // Fewer probes than this: the spacing grows until the grid fits.
  std::size_t max_probes = std::size_t{1} << 16;
  int rays_per_probe = 192;  // per refine()
  int placement_rays = 256;  // per probe, to place it and measure its distances
  int max_history = 32;      // the running mean's window (refines), then exponential
};

// The grid a volume over `bounds` gets: probes every `spacing` (or the fraction), covering the
// bounds with half a spacing to spare on each side, at most max_probes. Throws irradcast::Error
// on a spacing that is not finite and positive.
VolumeGrid probe_grid_for(const Bounds& bounds, const IrradianceVolumeOptions& options);

class IrradianceVolumeBuilder {
 public:
  // The world, its ray scene and atlas must outlive the builder. Places the probes.
  IrradianceVolumeBuilder(const World& world, const RayScene& rays, const Atlas& atlas,
                          IrradianceVolumeOptions options = {});

  // Places every probe again (after the static geometry changed): moved out of geometry or
  // switched off, distance moments measured; the irradiance restarts.
  void place();
  // One refinement from the lightmaps (indexed like world.objects): every active probe takes
  // rays_per_probe new rays (a new rotation of a spherical Fibonacci set each round).
  void refine(const std::vector<Lightmap>& lightmaps);
  // Restarts the running means (after a light changed): the next refine replaces them.
  void restart() { rounds_ = 0; }

  const IrradianceVolume& volume() const { return volume_; }
  std::uint64_t rounds() const { return rounds_; }
  // Probes switched off, and moved, by the last place().
  std::size_t switched_off() const { return switched_off_; }
  std::size_t moved() const { return moved_; }

 private:
  const World& world_;
  const RayScene& rays_;
  const Atlas& atlas_;
  IrradianceVolumeOptions options_;
  IrradianceVolume volume_;
  std::uint64_t rounds_ = 0;
  std::size_t switched_off_ = 0, moved_ = 0;
};

}  // namespace irradcast

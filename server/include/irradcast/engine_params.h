// Parameters of the GI engine, with seed 001's names and defaults. Distances are fractions of
// the scene's largest extent (the scene normalised to its bounding box).
#pragma once

#include <cstdint>
#include <limits>
#include <string>

namespace irradcast {

enum class Dispatch { PerCell, PerObject };
enum class DistantPoint { BoundsProjection, FixedDistance };

struct EngineParams {
  float cell_size = 0.25f;     // radiance cells: ceil(1 / cell_size) per axis
  float tracing_range = 0.3f;  // hemisphere rays end here; +inf = unbiased mode, no probes
  int direct_samples = 8;      // light samples per texel per update (stratified)
  int indirect_samples = 10;   // hemisphere rays per texel per bounce per update
  int indirect_bounces = 2;    // 1 direct + K indirect
  int probe_resolution = 8;    // octahedral radiance map side, in texels
  Dispatch dispatch = Dispatch::PerCell;
  DistantPoint distant_point = DistantPoint::BoundsProjection;  // seed 001 section 4.3.3
  bool relocate_probes = true;   // move probes out of geometry (seed 001 section 4.3.2 leaks)
  bool probe_visibility = true;  // texels only use probes they can see
  std::uint64_t seed = 1;
  // Scene edits (docs/EDITS.md). After an edit every texel starts a new estimate, the affected
  // and visible ones first, `edit_batch` of the texels per update until all have one; what a
  // texel shows blends from its value before the edit to the new estimate with weight
  // exp(-k / edit_blend) on the old value after k new samples (0 = no blending), and drops the
  // old value entirely once that weight is below 1 %.
  float edit_blend = 0.5f;
  float edit_batch = 0.25f;
  // Texels an edit does not affect keep their estimate, weighted as at most this many samples
  // (0: every texel restarts).
  int edit_keep = 2;

  bool unbiased() const { return !(tracing_range < std::numeric_limits<float>::infinity()); }
  // Throws irradcast::Error naming the bad parameter.
  void validate() const;
};

Dispatch parse_dispatch(const std::string& name);           // "cell" | "object"
DistantPoint parse_distant_point(const std::string& name);  // "project" | "fixed"
float parse_tracing_range(const std::string& text);         // a number or "inf"

}  // namespace irradcast

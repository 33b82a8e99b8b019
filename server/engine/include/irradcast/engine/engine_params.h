// Parameters of the GI engine, with seed 001's names and defaults. Distances are fractions of
// the scene's largest extent (the scene normalised to its bounding box).
#pragma once

#include <cstdint>
#include <limits>
#include <string>

namespace irradcast {

enum class Dispatch { PerCell, PerObject };
enum class DistantPoint { BoundsProjection, FixedDistance };
// How the indirect bounces are estimated (docs/METHODS.md). All write the same lightmaps.
//   Cells            radiance cells, probes and a tracing range (seed 001)
//   Vpl              instant radiosity: virtual point lights from the lights (seeds 003, 000)
//   IrradianceCache  sparse irradiance records with gradients, splatted into the texels (seed 004)
enum class Method { Cells, Vpl, IrradianceCache };

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

  Method method = Method::Cells;
  // VPL (instant radiosity, docs/METHODS.md): a pool of `vpl_paths` light paths (each up to
  // `indirect_bounces` VPLs) from a scrambled Halton sequence, split into `vpl_sets` strided
  // temporal sets, one gathered per update (seed 000); within a set each texel gathers one of
  // vpl_interleave^2 subsets, chosen by its lightmap position, and a geometry-aware filter over
  // that neighbourhood rebuilds the whole set (seed 003). Once every set has been gathered the
  // pool is shot again with the next Halton points, so the estimate keeps converging. The
  // geometry term is clamped at a distance of `vpl_clamp` (fraction of the scene). After a
  // scene edit, invalid VPLs (on or from a changed region, or occluded from their parent) are
  // shot again from their parent, at most `vpl_replace` per update (0: all at once).
  int vpl_paths = 1024;
  int vpl_sets = 4;
  int vpl_interleave = 4;
  float vpl_clamp = 0.05f;
  int vpl_replace = 0;
  // Irradiance cache (docs/METHODS.md, seed 004): records where no existing record has Ward
  // weight above 1 / ic_accuracy; each update every record traces ic_rays x (4 ic_rays)
  // stratified hemisphere rays (theta x phi) and gets its irradiance and its rotational and
  // translational gradients; a record's radius is the harmonic mean distance of its rays,
  // clamped to [ic_min_radius, ic_max_radius] (fractions of the scene).
  float ic_accuracy = 0.25f;
  int ic_rays = 4;
  float ic_min_radius = 0.01f;
  float ic_max_radius = 0.25f;

  bool unbiased() const { return !(tracing_range < std::numeric_limits<float>::infinity()); }
  // Radiance cells with a finite tracing range: the only configuration that places probes.
  bool uses_probes() const { return method == Method::Cells && !unbiased(); }
  // Throws irradcast::Error naming the bad parameter.
  void validate() const;
};

Dispatch parse_dispatch(const std::string& name);           // "cell" | "object"
DistantPoint parse_distant_point(const std::string& name);  // "project" | "fixed"
float parse_tracing_range(const std::string& text);         // a number or "inf"
Method parse_method(const std::string& name);               // "cells" | "vpl" | "irradiance-cache"
std::string method_name(Method m);

}  // namespace irradcast

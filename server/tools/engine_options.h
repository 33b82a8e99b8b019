// The engine's command-line flags, shared by irradcast-bake and irradcast-server so that both
// spell every parameter the same way.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "irradcast/common/atlas.h"
#include "irradcast/engine/backend_select.h"
#include "irradcast/engine/engine_params.h"

namespace irradcast::tools {

struct EngineOptions {
  float cell_size = 0.25f;
  std::string tracing_range = "0.3";
  int direct_samples = 8;
  int indirect_samples = 10;
  int bounces = 2;
  int probe_resolution = 8;
  std::string dispatch = "cell";
  std::string distant_point = "project";
  bool no_probe_relocation = false;
  bool no_probe_visibility = false;
  float texels_per_scene = 256.0f;
  int max_lightmap_size = 1024;
  std::uint64_t seed = 1;
  std::string backend = "auto";
  int vulkan_device = -1;
  bool vulkan_validation = false;
  float edit_blend = 0.5f;
  float edit_batch = 0.25f;
  int edit_keep = 2;
  std::string method = "cells";
  // The methods' defaults are EngineParams' (docs/METHODS.md).
  int vpl_paths = EngineParams{}.vpl_paths;
  int vpl_sets = EngineParams{}.vpl_sets;
  int vpl_interleave = EngineParams{}.vpl_interleave;
  float vpl_clamp = EngineParams{}.vpl_clamp;
  int vpl_replace = EngineParams{}.vpl_replace;
  float ic_accuracy = EngineParams{}.ic_accuracy;
  int ic_rays = EngineParams{}.ic_rays;
  float ic_min_radius = EngineParams{}.ic_min_radius;
  float ic_max_radius = EngineParams{}.ic_max_radius;

  void add_to(CLI::App& app) {
    app.add_option("--method", method,
                   "engine: indirect light by cells (radiance cells, seed 001) | vpl (instant "
                   "radiosity, seeds 003/000) | irradiance-cache (seed 004); docs/METHODS.md. "
                   "irradcast-bake also takes reference (the path tracer per texel)")
        ->capture_default_str();
    app.add_option("--vpl-paths", vpl_paths, "vpl: light paths in the pool")->capture_default_str();
    app.add_option("--vpl-sets", vpl_sets, "vpl: temporal sets, one gathered per update")
        ->capture_default_str();
    app.add_option("--vpl-interleave", vpl_interleave,
                   "vpl: interleaved sampling pattern side n (n x n subsets)")
        ->capture_default_str();
    app.add_option("--vpl-clamp", vpl_clamp,
                   "vpl: clamp 1/d^2 below this distance (fraction of the scene; 0 = none)")
        ->capture_default_str();
    app.add_option("--vpl-replace", vpl_replace,
                   "vpl: VPLs shot again per update after an edit (0 = all at once)")
        ->capture_default_str();
    app.add_option("--ic-accuracy", ic_accuracy,
                   "irradiance-cache: a; records where no record has weight above 1/a")
        ->capture_default_str();
    app.add_option("--ic-rays", ic_rays,
                   "irradiance-cache: theta strata per record per update (x 4 in phi)")
        ->capture_default_str();
    app.add_option("--ic-min-radius", ic_min_radius,
                   "irradiance-cache: smallest record radius (fraction of the scene)")
        ->capture_default_str();
    app.add_option("--ic-max-radius", ic_max_radius,
                   "irradiance-cache: largest record radius (fraction of the scene)")
        ->capture_default_str();
    app.add_option("--cell-size", cell_size, "engine: radiance cell size (fraction of the scene)");
    app.add_option("--tracing-range", tracing_range,
                   "engine: hemisphere ray length (fraction of the scene), or inf (unbiased)");
    app.add_option("--direct-samples", direct_samples,
                   "engine: light samples per texel per update");
    app.add_option("--indirect-samples", indirect_samples,
                   "engine: hemisphere rays per texel per bounce per update");
    app.add_option("--probe-resolution", probe_resolution, "engine: octahedral probe map side");
    app.add_option("--dispatch", dispatch, "engine: work units, cell | object");
    app.add_option("--distant-point", distant_point,
                   "engine: probe direction for rays beyond the range: project (onto the scene "
                   "bounds) | fixed (fixed distance 1, seed 001 section 4.3.3)");
    app.add_flag("--no-probe-relocation", no_probe_relocation,
                 "engine: keep probes at cell centres even inside geometry (seed 001 behaviour)");
    app.add_flag("--no-probe-visibility", no_probe_visibility,
                 "engine: texels use their neighbour probes without a visibility test");
    app.add_option("--bounces,--indirect-bounces", bounces,
                   "indirect bounces K (1 direct + K indirect)")
        ->check(CLI::Range(0, 64));
    app.add_option("--texels-per-scene", texels_per_scene,
                   "lightmap density: texels across the scene's largest extent")
        ->check(CLI::Range(1.0f, 65536.0f));
    app.add_option("--max-lightmap-size", max_lightmap_size, "per-object lightmap size cap")
        ->check(CLI::Range(8, 16384));
    app.add_option("--seed", seed, "random seed (same seed, same images)");
    app.add_option("--backend", backend,
                   "engine: auto (a Vulkan GPU if one opens, else Embree) | vulkan | embree");
    app.add_option("--vulkan-device", vulkan_device,
                   "engine: Vulkan device index from --list-devices (default: the best)")
        ->check(CLI::Range(0, 1024));
    app.add_flag("--vulkan-validation", vulkan_validation,
                 "engine: run Vulkan with the Khronos validation layer (slow; for debugging)");
    app.add_option("--edit-blend", edit_blend,
                   "edits: time constant, in updates, of the blend from a texel's old value to "
                   "its new estimate (0 = none; docs/EDITS.md)")
        ->capture_default_str();
    app.add_option("--edit-batch", edit_batch,
                   "edits: fraction of the texels refreshed per update until all have a new "
                   "estimate")
        ->capture_default_str();
    app.add_option("--edit-keep", edit_keep,
                   "edits: samples' worth of its old estimate a texel the edit does not affect "
                   "keeps (0 = every texel restarts)")
        ->capture_default_str();
  }

  // Throws irradcast::Error naming a bad value.
  EngineParams params() const {
    EngineParams p;
    p.cell_size = cell_size;
    p.tracing_range = parse_tracing_range(tracing_range);
    p.direct_samples = direct_samples;
    p.indirect_samples = indirect_samples;
    p.indirect_bounces = bounces;
    p.probe_resolution = probe_resolution;
    p.dispatch = parse_dispatch(dispatch);
    p.distant_point = parse_distant_point(distant_point);
    p.relocate_probes = !no_probe_relocation;
    p.probe_visibility = !no_probe_visibility;
    p.seed = seed;
    p.edit_blend = edit_blend;
    p.edit_batch = edit_batch;
    p.edit_keep = edit_keep;
    p.method = parse_method(method);
    p.vpl_paths = vpl_paths;
    p.vpl_sets = vpl_sets;
    p.vpl_interleave = vpl_interleave;
    p.vpl_clamp = vpl_clamp;
    p.vpl_replace = vpl_replace;
    p.ic_accuracy = ic_accuracy;
    p.ic_rays = ic_rays;
    p.ic_min_radius = ic_min_radius;
    p.ic_max_radius = ic_max_radius;
    p.validate();
    return p;
  }

  // Throws irradcast::Error naming a bad --backend.
  BackendOptions backend_options() const {
    BackendOptions b;
    b.kind = parse_backend(backend);
    b.vulkan_device = vulkan_device;
    b.vulkan_validation = vulkan_validation;
    return b;
  }

  AtlasOptions atlas() const {
    AtlasOptions a;
    a.texels_per_scene = texels_per_scene;
    a.max_lightmap_size = max_lightmap_size;
    return a;
  }
};

}  // namespace irradcast::tools

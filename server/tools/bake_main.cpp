// irradcast-bake: loads a scene, builds its lightmap atlas, fills the lightmaps with irradiance,
// composes a view from them and, with --reference, renders the same view with the reference path
// tracer and reports the error between the two.
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include "engine_options.h"
#include "params_json.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/engine/engine.h"
#include "irradcast/common/error.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "irradcast/engine/texel_validity.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/engine/vulkan_backend.h"
#include "irradcast/common/world.h"

namespace fs = std::filesystem;
using irradcast::Error;
using json = nlohmann::json;

namespace {

struct Options {
  std::string scene = "cornell";
  std::string scene_root;
  std::string out;
  float detail = 1.0f;
  int reference_spp = 0;
  int width = 512;
  int height = 512;
  std::string camera;
  std::string export_gltf;
  std::string method = "cells";
  int updates = 8;
  int lightmap_spp = 64;
  irradcast::tools::EngineOptions engine;
  std::string tonemap = "reinhard";
  std::string exposure = "auto";
  int threads = 0;
  std::string log_level = "info";
  bool quiet = false;
};

class Stopwatch {
 public:
  double lap() {
    auto now = std::chrono::steady_clock::now();
    double s = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    return s;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

std::string file_safe(const std::string& name) {
  std::string s;
  for (char c : name) s += (std::isalnum(static_cast<unsigned char>(c)) || c == '-') ? c : '_';
  return s.empty() ? "object" : s;
}

void write_png_tonemapped(const std::string& path, const irradcast::ImageRGB& image,
                          const irradcast::ToneMapOptions& tm) {
  irradcast::write_png(path, image.width, image.height, irradcast::tonemap_srgb8(image, tm));
}

// --method is the engine's (cells | vpl | irradiance-cache), plus bake's own "reference" (the
// path tracer per texel); "engine" is the old name of the default.
void normalize_method(Options& o) {
  std::string& method = o.engine.text.at("method");
  if (method == "engine") method = "cells";
  o.method = method;
  if (o.method == "reference") method = "cells";
  if (o.method != "reference" && o.method != "cells" && o.method != "vpl" &&
      o.method != "irradiance-cache")
    throw Error("unknown --method '" + o.method +
                "' (expected cells, vpl, irradiance-cache or reference)");
}

int run(const Options& o) {
  using namespace irradcast;
  log::set_level(log::parse_level(o.log_level));
  Progress::set_enabled(!o.quiet);
  ToneMapOptions tm;
  tm.op = parse_tone_operator(o.tonemap);
  if (o.exposure != "auto") {
    tm.auto_exposure = false;
    try {
      std::size_t used = 0;
      tm.exposure_ev = std::stof(o.exposure, &used);
      if (used != o.exposure.size()) throw std::invalid_argument(o.exposure);
    } catch (const std::exception&) {
      throw Error("--exposure must be 'auto' or a number of stops, not '" + o.exposure + "'");
    }
  }
  const EngineParams ep = o.engine.params();
  const BackendOptions bo = o.engine.backend_options();
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(o.threads));

  json report;
  json timings;
  Stopwatch total, sw;

  Scene scene = load_scene(o.scene, o.detail, o.scene_root);
  timings["load"] = sw.lap();
  const std::vector<Object> objects = scene.objects();
  log::info("bake", "scene '" + o.scene + "': " + std::to_string(objects.size()) + " objects, " +
                        std::to_string(scene.triangle_count()) + " triangles");
  if (!o.export_gltf.empty()) {
    save_gltf(scene, o.export_gltf);
    log::info("bake", "exported the scene to " + o.export_gltf);
    timings["export"] = sw.lap();
  }
  if (o.out.empty()) {
    if (!o.export_gltf.empty()) return 0;  // export only
    throw Error("--out DIR is required (or --export-gltf FILE alone)");
  }
  std::error_code ec;
  fs::create_directories(fs::path(o.out) / "lightmaps", ec);
  if (ec) throw Error(o.out + ": cannot create the output directory: " + ec.message());

  World world = World::build(scene);
  if (world.objects.empty()) throw Error(o.scene + ": the scene has no triangles to light");
  CameraPose camera = default_camera(scene, world);
  if (!o.camera.empty()) camera = parse_camera(o.camera, camera);
  RayScene rays(world);
  LightSampler lights(world);
  timings["bvh"] = sw.lap();
  if (lights.empty()) log::warn("bake", "the scene has no lights: every image will be black");

  const AtlasOptions ao = o.engine.atlas();
  Atlas atlas = build_atlas(world, ao);
  timings["atlas"] = sw.lap();
  std::vector<TexelGBuffer> gbuffers = rasterize_gbuffer(world, atlas);
  const std::size_t hidden = mark_hidden_texels(rays, gbuffers);
  timings["gbuffer"] = sw.lap();
  std::uint64_t valid = 0;
  for (const auto& g : gbuffers) valid += g.valid_count();
  log::info("bake", std::to_string(atlas.objects.size()) + " lightmaps, " +
                        std::to_string(atlas.texel_count()) + " texels (" + std::to_string(valid) +
                        " on visible surfaces, " + std::to_string(hidden) + " inside geometry)");

  PathTracerOptions pto;
  pto.indirect_bounces = ep.indirect_bounces;
  pto.seed = ep.seed;
  PathTracer tracer(world, rays, lights, pto);
  std::vector<Lightmap> maps;
  std::uint64_t lightmap_rays = 0;
  double lightmap_seconds = 0.0;
  if (o.method == "reference") {
    ReferenceLightmapStats lm_stats;
    // The per-texel path tracer on the chosen backend: the device's reference.comp, or Embree.
    BackendChoice choice = make_backend(bo, world, rays, lights);
    report["reference_backend"] = choice.backend->describe();
    if (auto* vulkan = dynamic_cast<VulkanBackend*>(choice.backend.get()))
      maps = vulkan->reference_lightmaps(gbuffers, o.lightmap_spp, ep.indirect_bounces, ep.seed,
                                         &lm_stats);
    else
      maps = reference_lightmaps(world, tracer, gbuffers, o.lightmap_spp, &lm_stats);
    lightmap_rays = lm_stats.rays;
    lightmap_seconds = lm_stats.seconds;
    timings["lightmaps"] = sw.lap();
  } else {
    Engine engine(world, atlas, gbuffers, rays, make_backend(bo, world, rays, lights).backend, ep,
                  &lights);
    timings["engine_setup"] = sw.lap();
    const ProbeStats& ps = engine.probe_stats();
    if (ep.uses_probes())
      log::info("bake", std::to_string(ps.probes) + " probes (" + std::to_string(ps.relocated) +
                            " moved out of geometry, " + std::to_string(ps.unusable) +
                            " unusable)");
    Progress progress("engine", static_cast<std::uint64_t>(o.updates), "updates");
    PassTiming direct;
    std::vector<PassTiming> probes(ep.indirect_bounces), scatter(ep.indirect_bounces);
    for (int u = 0; u < o.updates; ++u) {
      UpdateStats us = engine.update();
      direct.seconds += us.direct.seconds;
      direct.rays += us.direct.rays;
      for (int b = 0; b < ep.indirect_bounces; ++b) {
        probes[b].seconds += us.probes[b].seconds;
        probes[b].rays += us.probes[b].rays;
        scatter[b].seconds += us.scatter[b].seconds;
        scatter[b].rays += us.scatter[b].rays;
      }
      lightmap_rays += us.total_rays();
      lightmap_seconds += us.total_seconds;
      progress.advance(1);
    }
    progress.finish();
    if (!engine.method_summary().empty())
      log::info("bake", method_name(ep.method) + ": " + engine.method_summary());
    maps = engine.lightmaps();
    timings["lightmaps"] = sw.lap();
    auto pass = [](const std::string& name, const PassTiming& t) {
      return json{{"pass", name},
                  {"seconds", t.seconds},
                  {"rays", t.rays},
                  {"rays_per_s", t.rays / std::max(1e-9, t.seconds)}};
    };
    json passes = json::array({pass("direct", direct)});
    for (int b = 0; b < ep.indirect_bounces; ++b) {
      if (!ep.unbiased()) passes.push_back(pass("probes_" + std::to_string(b + 1), probes[b]));
      passes.push_back(pass("scatter_" + std::to_string(b + 1), scatter[b]));
    }
    report["engine"] = tools::params_json(ep);  // every parameter, by name
    report["engine"].update(
        {{"backend", engine.backend().describe()},
         {"updates", engine.updates()},
         {"texels", engine.texel_count()},
         {"probes", {{"count", ps.probes}, {"relocated", ps.relocated}, {"unusable", ps.unusable}}},
         {"mean_relative_error", engine.mean_relative_error()},
         {"passes", passes}});
  }

  json lightmaps = json::array();
  for (std::size_t i = 0; i < maps.size(); ++i) {
    const std::string& object_name = objects[i].name;
    std::string name = std::to_string(i) + "_" + file_safe(object_name) + ".exr";
    ImageRGB img;
    img.width = maps[i].width;
    img.height = maps[i].height;
    img.pixels = maps[i].texels;
    write_exr((fs::path(o.out) / "lightmaps" / name).string(), img);
    lightmaps.push_back({{"file", "lightmaps/" + name},
                         {"object", object_name},
                         {"width", maps[i].width},
                         {"height", maps[i].height},
                         {"charts", atlas.objects[i].chart_count},
                         {"from_texcoord1", atlas.objects[i].from_file_uv1},
                         {"valid_texels", gbuffers[i].valid_count()}});
  }
  timings["write_lightmaps"] = sw.lap();

  ComposeStats cs;
  ImageRGB view = compose(world, rays, atlas, maps, camera, o.width, o.height, &cs);
  timings["compose"] = sw.lap();
  write_exr((fs::path(o.out) / "view.exr").string(), view);
  write_png_tonemapped((fs::path(o.out) / "view.png").string(), view, tm);
  log::info("bake", "wrote " + (fs::path(o.out) / "view.exr").string() + " and view.png");

  json rays_json = {{"lightmaps", lightmap_rays}, {"compose", cs.rays}};
  json rate = {{"lightmaps", lightmap_rays / std::max(1e-9, lightmap_seconds)},
               {"compose", cs.rays / std::max(1e-9, cs.seconds)}};
  if (o.reference_spp > 0) {
    PathTracer::RenderStats rs;
    ImageRGB ref;
    BackendChoice choice = make_backend(bo, world, rays, lights);
    report["reference_view_backend"] = choice.backend->describe();
    if (auto* vulkan = dynamic_cast<VulkanBackend*>(choice.backend.get())) {
      ReferenceLightmapStats vs;
      ref = vulkan->render_reference(camera, o.width, o.height, o.reference_spp,
                                     ep.indirect_bounces, ep.seed, &vs);
      rs.rays = vs.rays;
      rs.seconds = vs.seconds;
    } else {
      Progress progress("reference", static_cast<std::uint64_t>(o.reference_spp), "spp");
      ref = tracer.render(
          camera, o.width, o.height, o.reference_spp, [&](int, int) { progress.advance(1); }, &rs);
      progress.finish();
    }
    timings["reference"] = sw.lap();
    write_exr((fs::path(o.out) / "reference.exr").string(), ref);
    // The reference uses the view's exposure so the two PNGs compare by eye.
    ToneMapOptions ref_tm = tm;
    ref_tm.auto_exposure = false;
    ref_tm.exposure_ev = std::log2(exposure_scale(view, tm));
    write_png_tonemapped((fs::path(o.out) / "reference.png").string(), ref, ref_tm);
    // view | reference side by side, both at the view's exposure.
    ImageRGB pair(2 * o.width, o.height);
    for (int y = 0; y < o.height; ++y)
      for (int x = 0; x < o.width; ++x) {
        pair.at(x, y) = view.at(x, y);
        pair.at(o.width + x, y) = ref.at(x, y);
      }
    write_png_tonemapped((fs::path(o.out) / "view_vs_reference.png").string(), pair, ref_tm);
    ImageError err = compare(view, ref);
    report["error"] = {
        {"rmse", err.rmse}, {"rel_mse", err.rel_mse}, {"reference_spp", o.reference_spp}};
    rays_json["reference"] = rs.rays;
    rate["reference"] = rs.rays / std::max(1e-9, rs.seconds);
    log::info("bake", "view vs reference: RMSE " + std::to_string(err.rmse) + ", relative MSE " +
                          std::to_string(err.rel_mse));
  }
  timings["total"] = total.lap();

  report["scene"] = {{"spec", o.scene},
                     {"name", scene.name},
                     {"objects", world.objects.size()},
                     {"triangles", scene.triangle_count()},
                     {"emissive_triangles", lights.emissive_triangles().size()},
                     {"punctual_lights", world.lights.size()}};
  report["settings"] = {
      {"exposure_ev", std::log2(exposure_scale(view, tm))},
      {"width", o.width},
      {"height", o.height},
      {"bounces", {{"direct", 1}, {"indirect", ep.indirect_bounces}}},
      {"lightmap_spp", o.lightmap_spp},
      {"texels_per_scene", o.engine.texels_per_scene},
      {"max_lightmap_size", o.engine.max_lightmap_size},
      {"seed", ep.seed},
      {"threads",
       o.threads > 0 ? o.threads : static_cast<int>(std::thread::hardware_concurrency())},
      {"method", o.method}};
  report["atlas"] = {{"texels", atlas.texel_count()},
                     {"valid_texels", valid},
                     {"hidden_texels", hidden},
                     {"lightmaps", lightmaps}};
  report["timings_s"] = timings;
  report["rays"] = rays_json;
  report["rays_per_s"] = rate;
  std::string report_path = (fs::path(o.out) / "report.json").string();
  std::ofstream f(report_path);
  f << report.dump(2) << "\n";
  if (!f) throw Error(report_path + ": cannot write the report");
  log::info("bake", "wrote " + report_path + " (total " +
                        std::to_string(timings["total"].get<double>()) + " s)");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-bake: computes a scene's diffuse irradiance lightmaps, composes a view from them "
      "and optionally renders the same view with the reference path tracer.\n"
      "Writes DIR/lightmaps/*.exr, DIR/view.exr, DIR/view.png, DIR/report.json and, with "
      "--reference, DIR/reference.exr and DIR/reference.png.",
      "irradcast-bake"};
  app.option_defaults()->always_capture_default();
  app.add_option("--scene", o.scene, "cornell | rooms:N | FILE.gltf | FILE.glb");
  app.add_option(
      "--scene-root", o.scene_root,
      "folder a glTF scene may read buffers and images from (default: the scene file's folder)");
  app.add_option("--out", o.out, "output directory");
  app.add_option("--detail", o.detail, "tessellation of rooms:N (triangles grow ~detail^2)")
      ->check(CLI::PositiveNumber);
  app.add_option("--reference", o.reference_spp,
                 "also render the view with the reference path tracer at SPP samples per pixel")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--width", o.width, "image width")->check(CLI::Range(1, 16384));
  app.add_option("--height", o.height, "image height")->check(CLI::Range(1, 16384));
  app.add_option("--camera", o.camera,
                 "override the camera: eye=x,y,z:target=x,y,z:fov=deg[:up=x,y,z]");
  app.add_option("--export-gltf", o.export_gltf, "write the loaded scene as glTF (.gltf or .glb)");
  app.add_option("--updates", o.updates, "engine: progressive updates to run")
      ->check(CLI::Range(1, 1 << 20));
  app.add_option("--lightmap-spp", o.lightmap_spp, "reference method: samples per texel")
      ->check(CLI::Range(1, 1 << 20));
  o.engine.add_to(app);
  app.add_option("--tonemap", o.tonemap, "reinhard | aces | clamp");
  app.add_option("--exposure", o.exposure, "auto (key 0.18) or exposure in stops");
  app.add_option("--threads", o.threads, "worker threads (0 = all cores)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--log-level", o.log_level, "debug | info | warn | error | off");
  app.add_flag("--quiet", o.quiet, "no progress lines");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    normalize_method(o);
    return run(o);
  } catch (const Error& e) {
    std::fprintf(stderr, "irradcast-bake: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bake: internal error: %s\n", e.what());
    return 2;
  }
}

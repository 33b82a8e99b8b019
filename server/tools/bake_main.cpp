// irradcast-bake: loads a scene, builds its lightmap atlas, fills the lightmaps with irradiance,
// composes a view from them and, with --reference, renders the same view with the reference path
// tracer and reports the error between the two.
#include <tbb/global_control.h>
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include "engine_options.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/common/world.h"
#include "irradcast/engine/backend_select.h"
#include "irradcast/engine/denoise.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/irradiance_volume_builder.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/prepared_scene.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "params_json.h"
#include "scene_options.h"

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

using namespace irradcast;

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
  tools::EngineOptions engine;
  tools::SceneOptions lighting;
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

void write_png_tonemapped(const std::string& path, const ImageRGB& image,
                          const ToneMapOptions& tm) {
  write_png(path, image.width, image.height, tonemap_srgb8(image, tm));
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

ToneMapOptions tone_map_options(const Options& o) {
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
  return tm;
}

// One bake: the options, the engine's parameters from them, and what the steps add to the
// report (steps time themselves with `sw`).
struct Bake {
  explicit Bake(const Options& options)
      : o(options),
        lighting(options.lighting),
        ep(options.engine.params()),
        bo(options.engine.backend_options()) {}
  const Options& o;
  tools::SceneOptions lighting;  // --sky, --sun: applied to the scene by load()
  const EngineParams ep;
  const BackendOptions bo;
  json report;
  json timings;
  json rays = json::object();        // rays traced per step
  json rays_per_s = json::object();  // and their rate
  Stopwatch total, sw;

  void add_rays(const std::string& step, std::uint64_t n, double seconds) {
    rays[step] = n;
    rays_per_s[step] = n / std::max(1e-9, seconds);
  }
};

// Loads the scene and, with --export-gltf, exports it. Returns false when there is nothing
// more to do (export only).
bool load(Bake& b, Scene& scene) {
  const Options& o = b.o;
  scene = load_scene(o.scene, o.detail, o.scene_root);
  b.lighting.apply(scene);
  b.timings["load"] = b.sw.lap();
  log::info("bake", "scene '" + o.scene + "': " + std::to_string(scene.objects().size()) +
                        " objects, " + std::to_string(scene.triangle_count()) + " triangles");
  log::info("bake", "lit by " + b.lighting.describe(scene));
  if (!o.export_gltf.empty()) {
    save_gltf(scene, o.export_gltf);
    log::info("bake", "exported the scene to " + o.export_gltf);
    b.timings["export"] = b.sw.lap();
  }
  if (o.out.empty()) {
    if (!o.export_gltf.empty()) return false;  // export only
    throw Error("--out DIR is required (or --export-gltf FILE alone)");
  }
  std::error_code ec;
  fs::create_directories(fs::path(o.out) / "lightmaps", ec);
  if (ec) throw Error(o.out + ": cannot create the output directory: " + ec.message());
  return true;
}

PreparedScene prepare(Bake& b, Scene scene) {
  PreparedSceneOptions po;
  po.atlas = b.o.engine.atlas();
  po.name = b.o.scene;
  PreparedScene p = PreparedScene::build(std::move(scene), po);
  b.timings["bvh"] = p.timings().bvh;
  b.timings["atlas"] = p.timings().atlas;
  b.timings["gbuffer"] = p.timings().gbuffers;
  b.sw.lap();
  if (p.lights().empty()) log::warn("bake", "the scene has no lights: every image will be black");
  log::info("bake", std::to_string(p.atlas().objects.size()) + " lightmaps, " +
                        std::to_string(p.atlas().texel_count()) + " texels (" +
                        std::to_string(p.valid_texels()) + " on visible surfaces, " +
                        std::to_string(p.hidden_texels()) + " inside geometry)");
  return p;
}

// Lightmaps and the rays and seconds spent on them.
struct Lightmaps {
  std::vector<Lightmap> maps;
  std::uint64_t rays = 0;
  double seconds = 0.0;
};

// --method reference: the per-texel path tracer on the chosen backend (the device's
// reference.comp, or Embree).
Lightmaps reference_method(Bake& b, const PreparedScene& p, const PathTracerOptions& pto) {
  const auto reference = make_reference(b.bo, p.world(), p.rays(), p.lights(), pto);
  b.report["reference_backend"] = reference->describe();
  Lightmaps out;
  ReferenceLightmapStats stats;
  out.maps = reference->lightmaps(p.gbuffers(), b.o.lightmap_spp, &stats);
  out.rays = stats.rays;
  out.seconds = stats.seconds;
  b.timings["lightmaps"] = b.sw.lap();
  return out;
}

// The time and rays of each engine pass, summed over the updates.
struct PassTotals {
  explicit PassTotals(int bounces) : probes(bounces), scatter(bounces) {}
  void add(const UpdateStats& us) {
    direct.seconds += us.direct.seconds;
    direct.rays += us.direct.rays;
    for (std::size_t b = 0; b < probes.size(); ++b) {
      probes[b].seconds += us.probes[b].seconds;
      probes[b].rays += us.probes[b].rays;
      scatter[b].seconds += us.scatter[b].seconds;
      scatter[b].rays += us.scatter[b].rays;
    }
  }
  json to_json(bool unbiased) const {
    auto pass = [](const std::string& name, const PassTiming& t) {
      return json{{"pass", name},
                  {"seconds", t.seconds},
                  {"rays", t.rays},
                  {"rays_per_s", t.rays / std::max(1e-9, t.seconds)}};
    };
    json passes = json::array({pass("direct", direct)});
    for (std::size_t b = 0; b < probes.size(); ++b) {
      if (!unbiased) passes.push_back(pass("probes_" + std::to_string(b + 1), probes[b]));
      passes.push_back(pass("scatter_" + std::to_string(b + 1), scatter[b]));
    }
    return passes;
  }
  PassTiming direct;
  std::vector<PassTiming> probes, scatter;
};

// The engine's report: every parameter by name, then its probes (with the cube edge and the
// tracing range in metres that the parameters gave this scene), convergence and passes.
json engine_report(const Bake& b, const PreparedScene& p, const Engine& engine,
                   const PassTotals& passes) {
  const ProbeStats& ps = engine.probe_stats();
  json report = tools::params_json(b.ep);
  const float range = b.ep.tracing_range.resolve(p.world().bounds.max_extent());
  report.update({{"backend", engine.backend().describe()},
                 {"updates", engine.updates()},
                 {"texels", engine.texel_count()},
                 {"probes",
                  {{"count", ps.probes},
                   {"relocated", ps.relocated},
                   {"unusable", ps.unusable},
                   {"cell_m", engine.probes().cell},
                   {"tracing_range_m", b.ep.unbiased() ? json("inf") : json(range)}}},
                 {"mean_relative_error", engine.mean_relative_error()},
                 {"passes", passes.to_json(b.ep.unbiased())}});
  return report;
}

// The engine's methods (cells, vpl, irradiance-cache): --updates progressive updates.
Lightmaps engine_method(Bake& b, const PreparedScene& p) {
  const Options& o = b.o;
  const EngineParams& ep = b.ep;
  Engine engine(p.world(), p.atlas(), p.gbuffers(), p.rays(),
                make_backend(b.bo, p.world(), p.rays(), p.lights()).backend, ep, &p.lights());
  b.timings["engine_setup"] = b.sw.lap();
  const ProbeStats& ps = engine.probe_stats();
  if (ep.uses_probes())
    log::info("bake", std::to_string(ps.probes) + " probes (" + std::to_string(ps.relocated) +
                          " moved out of geometry, " + std::to_string(ps.unusable) + " unusable)");
  Lightmaps out;
  Progress progress("engine", static_cast<std::uint64_t>(o.updates), "updates");
  PassTotals passes(b.ep.indirect_bounces);
  for (int u = 0; u < o.updates; ++u) {
    UpdateStats us = engine.update();
    passes.add(us);
    out.rays += us.total_rays();
    out.seconds += us.total_seconds;
    progress.advance(1);
  }
  progress.finish();
  if (!engine.method_summary().empty())
    log::info("bake", method_name(ep.method) + ": " + engine.method_summary());
  DenoiseStats ds;
  out.maps = engine.published_lightmaps(&ds);
  if (ep.denoise)
    log::info("bake", "denoised: " + std::to_string(ds.filtered) + " texels filtered, " +
                          std::to_string(ds.kept) + " kept (outside their confidence), " +
                          std::to_string(ds.seams) + " across chart seams");
  b.timings["lightmaps"] = b.sw.lap();
  b.report["engine"] = engine_report(b, p, engine, passes);
  return out;
}

// Writes DIR/lightmaps/*.exr; returns their entries for the report.
json write_lightmaps(Bake& b, const PreparedScene& p, const std::vector<Lightmap>& maps) {
  const std::vector<Object> objects = p.scene().objects();
  json lightmaps = json::array();
  for (std::size_t i = 0; i < maps.size(); ++i) {
    const std::string& object_name = objects[i].name;
    if (p.world().objects[i].dynamic) {  // no lightmap (docs/DYNAMIC.md)
      lightmaps.push_back({{"object", object_name}, {"dynamic", true}});
      continue;
    }
    std::string name = std::to_string(i) + "_" + file_safe(object_name) + ".exr";
    ImageRGB img;
    img.width = maps[i].width;
    img.height = maps[i].height;
    img.pixels = maps[i].texels;
    write_exr((fs::path(b.o.out) / "lightmaps" / name).string(), img);
    lightmaps.push_back({{"file", "lightmaps/" + name},
                         {"object", object_name},
                         {"width", maps[i].width},
                         {"height", maps[i].height},
                         {"charts", p.atlas().objects[i].chart_count},
                         {"from_texcoord1", p.atlas().objects[i].from_file_uv1},
                         {"valid_texels", p.gbuffers()[i].valid_count()}});
  }
  b.timings["write_lightmaps"] = b.sw.lap();
  return lightmaps;
}

// The dynamic objects (docs/DYNAMIC.md) as a viewer draws them: their own ray scene and the probe
// volume the server would stream, refined from the lightmaps as many times as its running mean
// keeps (a server's volume after as many updates).
struct DynamicObjects {
  std::unique_ptr<RayScene> rays;
  std::unique_ptr<IrradianceVolumeBuilder> volume;
  const LightSampler* lights = nullptr;
  DynamicView view() const { return {rays.get(), volume ? &volume->volume() : nullptr, lights}; }
};

DynamicObjects light_dynamic_objects(Bake& b, const PreparedScene& p,
                                     const std::vector<Lightmap>& maps) {
  DynamicObjects d;
  const World& w = p.world();
  if (std::none_of(w.objects.begin(), w.objects.end(),
                   [](const WorldObject& o) { return o.dynamic; }))
    return d;
  d.rays = std::make_unique<RayScene>(w, true, RaySceneContent::Dynamic);
  d.lights = &p.lights();
  const IrradianceVolumeOptions vo;
  d.volume = std::make_unique<IrradianceVolumeBuilder>(w, p.rays(), p.atlas(), vo);
  for (int i = 0; i < vo.max_history; ++i) d.volume->refine(maps);
  b.timings["probe_volume"] = b.sw.lap();
  const VolumeGrid& g = d.volume->volume().grid;
  b.report["probe_volume"] = {{"probes", g.probe_count()},
                              {"counts", {g.counts.x, g.counts.y, g.counts.z}},
                              {"spacing", g.spacing},
                              {"switched_off", d.volume->switched_off()},
                              {"refines", vo.max_history}};
  log::info("bake", "probe volume for the dynamic objects: " + std::to_string(g.probe_count()) +
                        " probes, " + std::to_string(vo.max_history) + " refines");
  return d;
}

// Composes the view from the lightmaps (and the dynamic objects from the probe volume) and
// writes view.exr and view.png.
ImageRGB compose_view(Bake& b, const PreparedScene& p, const std::vector<Lightmap>& maps,
                      const DynamicObjects& dynamic, const CameraPose& camera,
                      const ToneMapOptions& tm) {
  const Options& o = b.o;
  ComposeStats cs;
  const DynamicView dv = dynamic.view();
  ImageRGB view =
      compose(p.world(), p.rays(), p.atlas(), maps, camera, o.width, o.height, &cs, &dv);
  b.timings["compose"] = b.sw.lap();
  write_exr((fs::path(o.out) / "view.exr").string(), view);
  write_png_tonemapped((fs::path(o.out) / "view.png").string(), view, tm);
  log::info("bake", "wrote " + (fs::path(o.out) / "view.exr").string() + " and view.png");
  b.add_rays("compose", cs.rays, cs.seconds);
  return view;
}

// --reference: the same view with the reference path tracer.
ImageRGB render_reference(Bake& b, const PreparedScene& p, const PathTracerOptions& pto,
                          const CameraPose& camera) {
  const Options& o = b.o;
  const auto reference = make_reference(b.bo, p.world(), p.rays(), p.lights(), pto);
  b.report["reference_view_backend"] = reference->describe();
  ReferenceLightmapStats rs;
  ImageRGB ref = reference->render(camera, o.width, o.height, o.reference_spp, &rs);
  b.timings["reference"] = b.sw.lap();
  b.add_rays("reference", rs.rays, rs.seconds);
  return ref;
}

// Writes reference.exr, reference.png and view_vs_reference.png (both at the view's exposure)
// and reports the error between the view and the reference.
void compare_with_reference(Bake& b, const ImageRGB& view, const ImageRGB& ref,
                            const ToneMapOptions& tm) {
  const Options& o = b.o;
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
  b.report["error"] = {{"rmse", err.rmse},
                       {"rel_mse", err.rel_mse},
                       {"mean_ratio", err.mean_ratio},
                       {"reference_spp", o.reference_spp}};
  log::info("bake", "view vs reference: RMSE " + std::to_string(err.rmse) + ", relative MSE " +
                        std::to_string(err.rel_mse) + ", mean ratio " +
                        std::to_string(err.mean_ratio));
}

// The report's sky: null without one, else its colour or map file and its strength.
json sky_json(const Sky& sky) {
  if (!sky.enabled()) return nullptr;
  json j = {{"strength", sky.strength}};
  if (sky.map.width > 0)
    j["file"] = sky.source, j["width"] = sky.map.width, j["height"] = sky.map.height;
  else
    j["color"] = {sky.color.x, sky.color.y, sky.color.z};
  return j;
}

// The report's --sun: null without one, else its direction of travel and irradiance.
json sun_json(const tools::SceneOptions& l) {
  if (!l.has_sun) return nullptr;
  return {{"direction", {l.sun_direction.x, l.sun_direction.y, l.sun_direction.z}},
          {"irradiance", l.sun_irradiance}};
}

// Writes DIR/report.json: the scene, settings, atlas, timings and rays.
void write_report(Bake& b, const PreparedScene& p, const ImageRGB& view, const ToneMapOptions& tm,
                  json lightmaps) {
  const Options& o = b.o;
  json& report = b.report;
  report["scene"] = {{"spec", o.scene},
                     {"name", p.scene().name},
                     {"objects", p.world().objects.size()},
                     {"triangles", p.scene().triangle_count()},
                     {"emissive_triangles", p.lights().emissive_triangles().size()},
                     {"punctual_lights", p.world().lights.size()},
                     {"sky", sky_json(p.scene().sky)},
                     {"sun", sun_json(b.lighting)}};
  report["settings"] = {
      {"exposure_ev", std::log2(exposure_scale(view, tm))},
      {"width", o.width},
      {"height", o.height},
      {"bounces", {{"direct", 1}, {"indirect", b.ep.indirect_bounces}}},
      {"lightmap_spp", o.lightmap_spp},
      {"texels_per_scene", o.engine.texels_per_scene},
      {"max_lightmap_size", o.engine.max_lightmap_size},
      {"seed", b.ep.seed},
      {"threads",
       o.threads > 0 ? o.threads : static_cast<int>(std::thread::hardware_concurrency())},
      {"method", o.method}};
  report["atlas"] = {{"texels", p.atlas().texel_count()},
                     {"valid_texels", p.valid_texels()},
                     {"hidden_texels", p.hidden_texels()},
                     {"lightmaps", std::move(lightmaps)}};
  report["timings_s"] = b.timings;
  report["rays"] = b.rays;
  report["rays_per_s"] = b.rays_per_s;
  std::string report_path = (fs::path(o.out) / "report.json").string();
  std::ofstream f(report_path);
  f << report.dump(2) << "\n";
  if (!f) throw Error(report_path + ": cannot write the report");
  log::info("bake", "wrote " + report_path + " (total " +
                        std::to_string(b.timings["total"].get<double>()) + " s)");
}

int run(const Options& o) {
  log::set_level(log::parse_level(o.log_level));
  Progress::set_enabled(!o.quiet);
  const ToneMapOptions tm = tone_map_options(o);
  Bake b(o);
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(o.threads));
  Scene scene;
  if (!load(b, scene)) return 0;
  const PreparedScene p = prepare(b, std::move(scene));
  CameraPose camera = default_camera(p.scene(), p.world());
  if (!o.camera.empty()) camera = parse_camera(o.camera, camera);

  PathTracerOptions pto;
  pto.indirect_bounces = b.ep.indirect_bounces;
  pto.seed = b.ep.seed;
  const Lightmaps lm = o.method == "reference" ? reference_method(b, p, pto) : engine_method(b, p);
  b.add_rays("lightmaps", lm.rays, lm.seconds);
  json lightmaps = write_lightmaps(b, p, lm.maps);
  const DynamicObjects dynamic = light_dynamic_objects(b, p, lm.maps);
  const ImageRGB view = compose_view(b, p, lm.maps, dynamic, camera, tm);
  // The reference sees the dynamic objects with camera rays only, as the viewers draw them.
  pto.camera_only = dynamic.rays.get();
  if (o.reference_spp > 0) compare_with_reference(b, view, render_reference(b, p, pto, camera), tm);
  b.timings["total"] = b.total.lap();
  write_report(b, p, view, tm, std::move(lightmaps));
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
  app.add_option("--scene", o.scene,
                 "cornell | rooms:N | sponza (the shared sample data, with a sky and a sun) | "
                 "FILE.gltf | FILE.glb");
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
  o.lighting.add_to(app);
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

// irradcast-bench-crossover: the number of users from which the shared GI server (one engine
// for everybody, each client composing its own view from the lightmaps) costs less CPU time than
// one reference path tracer per user, *at equal measured error* against a converged reference.
//
// Per scene and K fixed viewpoints:
//  - Reference: PathTracer::render at high spp (two independent halves, cached as EXR), the same
//    bounce count as the engine. The halves also measure the reference's own noise, which is
//    subtracted from every measured MSE (see error_of()).
//  - Shared engine: the real server's code path, EngineHost::step() (Engine::update, lightmaps,
//    TileStore::publish with RGB9E5 + zstd encoding), default parameters; a client decodes the
//    tiles that changed (wire::decode_tile) and composes its view (irradcast::compose) after
//    every update, on one thread. Process CPU time for the server, thread CPU time for the
//    client.
//  - Per-user path tracer: progressive PathTracer::render passes with seeds of their own,
//    process CPU time and error at checkpoints.
// The cross-over for a target error e is K* = server(e) / (pt(e) - client(e)). Prints a table,
// writes JSON and PNG plots (see docs/BENCHMARKS.md, "Cross-over at equal error").
#include <tbb/global_control.h>
#include <tbb/task_arena.h>
#include <time.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/wire/tile_codec.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/common/world.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kInf = std::numeric_limits<double>::infinity();

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

double cpu_seconds(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
// All threads of the process (the server's update and the path tracer use every core).
double process_cpu() {
  return cpu_seconds(CLOCK_PROCESS_CPUTIME_ID);
}
// The calling thread only (a client's work runs on one thread).
double thread_cpu() {
  return cpu_seconds(CLOCK_THREAD_CPUTIME_ID);
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, v);
  return buf;
}

std::string load_average() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0) {
      auto p = line.find(':');
      return p == std::string::npos ? line : line.substr(p + 2);
    }
  return "unknown";
}

std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

std::string file_key(const std::string& spec) {
  std::string k;
  for (char c : spec) k += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return k;
}

// ---------------------------------------------------------------------------------------------
// Viewpoints.

struct View {
  std::string name;
  CameraPose pose;
};

CameraPose look(glm::vec3 eye, glm::vec3 target, float fov_deg) {
  CameraPose p;
  p.eye = eye;
  p.forward = glm::normalize(target - eye);
  p.up = glm::vec3(0.0f, 1.0f, 0.0f);
  p.yfov = glm::radians(fov_deg);
  return p;
}

// Eight fixed, varied viewpoints per built-in scene, all looking at lit surfaces (the first is
// the scene's own camera). Other scenes get the default camera and views around the bounds.
std::vector<View> make_views(const std::string& spec, const Scene& scene, const World& world) {
  std::vector<View> v;
  v.push_back({"scene camera", default_camera(scene, world)});
  if (spec == "cornell") {
    // The box spans [0, 0.556] x [0, 0.549] x [0, 0.559] m, open towards -z; short block at
    // the front left, tall block at the back right.
    v.push_back({"front left, closer", look({0.10f, 0.36f, -0.35f}, {0.34f, 0.20f, 0.42f}, 50)});
    v.push_back({"front right, low", look({0.47f, 0.18f, -0.30f}, {0.20f, 0.26f, 0.45f}, 50)});
    v.push_back(
        {"inside, low, to the back left", look({0.48f, 0.07f, 0.06f}, {0.08f, 0.20f, 0.50f}, 60)});
    v.push_back(
        {"inside, up at the ceiling", look({0.28f, 0.05f, 0.03f}, {0.28f, 0.52f, 0.40f}, 60)});
    v.push_back(
        {"inside, down at the floor", look({0.28f, 0.52f, 0.03f}, {0.28f, 0.00f, 0.36f}, 62)});
    v.push_back({"tall block close-up", look({0.14f, 0.30f, 0.10f}, {0.44f, 0.20f, 0.40f}, 45)});
    v.push_back({"high, oblique", look({0.20f, 0.46f, -0.50f}, {0.36f, 0.15f, 0.36f}, 42)});
  } else if (spec == "rooms:2") {
    // Rooms are 4 m cells (interior [0.1, 3.9] per axis), 2.8 m high; rooms (1,0) and (0,1)
    // are lit, (0,0) and (1,1) only through the doorways (centred on the shared walls).
    v.push_back({"lit room (1,0), corner", look({7.6f, 1.7f, 0.4f}, {4.5f, 0.8f, 3.5f}, 60)});
    v.push_back({"lit room (0,1), corner", look({0.4f, 1.7f, 7.6f}, {3.5f, 0.8f, 4.5f}, 60)});
    v.push_back(
        {"unlit (0,0) to the door of (1,0)", look({0.5f, 1.5f, 2.0f}, {4.0f, 1.0f, 2.0f}, 60)});
    v.push_back({"unlit (1,1), corner", look({7.5f, 1.6f, 7.5f}, {4.5f, 0.9f, 4.5f}, 65)});
    v.push_back({"unlit (0,0), floor", look({3.5f, 2.2f, 3.5f}, {0.5f, 0.3f, 0.5f}, 60)});
    v.push_back({"lit (1,0) from the doorway", look({4.3f, 1.6f, 2.0f}, {7.5f, 0.3f, 3.0f}, 60)});
    v.push_back({"from (0,1) into unlit (0,0)", look({2.0f, 1.6f, 7.5f}, {2.0f, 1.0f, 3.0f}, 55)});
  } else {
    const glm::vec3 c = world.bounds.center();
    const glm::vec3 e = world.bounds.extent();
    for (int k = 1; k < 8; ++k) {
      float a = 6.2831853f * static_cast<float>(k) / 8.0f;
      glm::vec3 eye =
          c + glm::vec3(0.45f * e.x * std::cos(a), 0.2f * e.y, 0.45f * e.z * std::sin(a));
      v.push_back({"around " + std::to_string(k), look(eye, c, 60)});
    }
  }
  return v;
}

json pose_json(const CameraPose& p) {
  return {{"eye", {p.eye.x, p.eye.y, p.eye.z}},
          {"forward", {p.forward.x, p.forward.y, p.forward.z}},
          {"yfov_deg", glm::degrees(p.yfov)}};
}

// ---------------------------------------------------------------------------------------------
// The reference and the error metric.

struct Reference {
  ImageRGB image;          // (A + B) / 2
  double noise_mse = 0.0;  // mean over pixels and channels of ((A - B) / 2)^2
  double mean = 0.0;       // mean over pixels and channels of the image
  double cpu_s = 0.0;      // 0 when read from the cache
  bool cached = false;
  double rel_noise() const { return mean > 0 ? std::sqrt(noise_mse) / mean : 0.0; }
};

// Relative RMSE of linear radiance: sqrt(mean over pixels and channels of (img - ref)^2) /
// mean(ref). `raw` against the reference as it is; `corrected` with the reference's own noise
// subtracted from the MSE (E[(x - ref)^2] = E[(x - truth)^2] + E[(ref - truth)^2] when x and the
// reference are independent, and mean(((A - B) / 2)^2) estimates the second term without bias).
struct Err {
  double raw = 0.0, corrected = 0.0;
  double get(bool use_corrected) const { return use_corrected ? corrected : raw; }
};

Err error_of(const ImageRGB& img, const Reference& ref) {
  double se = 0.0;
  for (std::size_t i = 0; i < img.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      double d = static_cast<double>(img.pixels[i][c]) - ref.image.pixels[i][c];
      se += d * d;
    }
  const double mse = se / (3.0 * static_cast<double>(img.pixels.size()));
  Err e;
  e.raw = std::sqrt(mse) / ref.mean;
  e.corrected = std::sqrt(std::max(mse - ref.noise_mse, 0.0)) / ref.mean;
  return e;
}

ImageRGB weighted_mean(const std::vector<std::pair<const ImageRGB*, double>>& parts) {
  ImageRGB out(parts.front().first->width, parts.front().first->height);
  double total = 0.0;
  for (const auto& [img, w] : parts) total += w;
  for (std::size_t i = 0; i < out.pixels.size(); ++i) {
    glm::dvec3 s(0.0);
    for (const auto& [img, w] : parts) s += glm::dvec3(img->pixels[i]) * w;
    out.pixels[i] = glm::vec3(s / total);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Per scene state and measurements.

struct EngineStep {
  double server_cpu_s = 0, server_wall_s = 0;  // update + lightmaps + publish (RGB9E5 encode)
  double decode_cpu_s = 0;                     // the client: decode the changed tiles
  std::vector<double> compose_cpu_s;           // the client: one frame, per view
  std::size_t tiles_changed = 0;
  std::uint64_t bytes = 0;  // encoded payload of the changed tiles (what each client receives)
  double convergence = 0;
  std::vector<Err> err;  // per view
  double mean_err(bool c) const {
    double s = 0;
    for (const Err& e : err) s += e.get(c);
    return s / static_cast<double>(err.size());
  }
  double max_err(bool c) const {
    double m = 0;
    for (const Err& e : err) m = std::max(m, e.get(c));
    return m;
  }
  double mean_compose() const {
    double s = 0;
    for (double t : compose_cpu_s) s += t;
    return s / static_cast<double>(compose_cpu_s.size());
  }
};

struct PtPoint {
  int spp = 0;
  double cpu_s = 0, wall_s = 0;  // cumulative
  Err err;
};

struct Row {
  double target = 0;
  // Mean-error criterion: the first update whose error averaged over the views is <= target.
  int updates = -1;  // -1: never (below the engine's floor)
  double server_s = kInf, client_s = kInf, kstar = kInf;
  double client_compose_s = kInf;  // the compose part of client_s
  // Estimate for 1280x720 frames: the path tracer's and the compose's time scaled by the pixel
  // count (same samples per pixel for the same per-pixel error), server and decode unchanged.
  double kstar_720p = kInf;
  // Every-view criterion: the first update at which every view's error is <= target.
  int updates_all = -1;
  double server_all_s = kInf, client_all_s = kInf, kstar_all = kInf;
  double pt_s = kInf;       // mean over the views of the per-user path tracer's CPU time to target
  int pt_extrapolated = 0;  // views whose time comes from the 1/sqrt(t) law past the last point
  double mean_spp = 0;      // per-user samples per pixel at the target (mean over views)
};

struct SceneResult {
  std::string spec;
  std::size_t texels = 0, tiles = 0, lightmaps = 0, triangles = 0;
  double setup_cpu_s = 0, client_setup_cpu_s = 0;
  std::vector<View> views;
  std::vector<Reference> refs;
  std::vector<EngineStep> engine;
  std::vector<std::vector<PtPoint>> pt;  // per view
  std::vector<double> targets;
  std::vector<Row> rows;
  double floor_mean = kInf, floor_all = kInf;      // the engine's lowest errors over the run
  std::vector<ImageRGB> engine_at_mid, pt_at_mid;  // per view, for the picture
  int mid_update = -1;
  double mid_target = 0;
  std::vector<int> mid_spp;
};

double kstar_of(double server, double client, double pt) {
  if (!(server < kInf) || !(pt < kInf)) return kInf;
  if (!(pt > client)) return kInf;
  return server / (pt - client);
}

// Per-user path tracer CPU time to reach error e on one view: the first checkpoint at or below
// e, interpolated in log-log with the checkpoint before it; above the first checkpoint, the
// first checkpoint's time (nobody renders less than one pass); below the last checkpoint's error,
// extrapolated with the Monte Carlo law t ~ e^-2 fitted on the last three checkpoints.
double pt_time_to(const std::vector<PtPoint>& c, double e, bool corrected, bool* extrapolated,
                  double* spp) {
  *extrapolated = false;
  for (std::size_t i = 0; i < c.size(); ++i) {
    double ei = c[i].err.get(corrected);
    if (ei > e) continue;
    if (i == 0) {
      *spp = c[0].spp;
      return c[0].cpu_s;
    }
    double ep = c[i - 1].err.get(corrected);
    if (!(ei > 0) || !(ep > ei)) {
      *spp = c[i].spp;
      return c[i].cpu_s;
    }
    double a = (std::log(ep) - std::log(e)) / (std::log(ep) - std::log(ei));
    *spp = std::exp(std::log(c[i - 1].spp) + a * (std::log(c[i].spp) - std::log(c[i - 1].spp)));
    return std::exp(std::log(c[i - 1].cpu_s) +
                    a * (std::log(c[i].cpu_s) - std::log(c[i - 1].cpu_s)));
  }
  *extrapolated = true;
  std::vector<double> k, s;
  for (std::size_t i = c.size() >= 3 ? c.size() - 3 : 0; i < c.size(); ++i) {
    double ei = c[i].err.get(corrected);
    k.push_back(c[i].cpu_s * ei * ei);
    s.push_back(c[i].spp * ei * ei);
  }
  std::sort(k.begin(), k.end());
  std::sort(s.begin(), s.end());
  *spp = s[s.size() / 2] / (e * e);
  return k[k.size() / 2] / (e * e);
}

// 2 significant digits, rounded up (so that a level derived from the engine's floor stays
// reachable) or to nearest.
double round2(double v, bool up) {
  if (!(v > 0)) return v;
  double mag = std::pow(10.0, std::floor(std::log10(v)) - 1);
  double q = v / mag;
  return (up ? std::ceil(q - 1e-9) : std::round(q)) * mag;
}

void image_to_canvas(plot::Canvas& c, const ImageRGB& img, int x0, int y0, float exposure_ev) {
  ToneMapOptions tm;
  tm.auto_exposure = false;
  tm.exposure_ev = exposure_ev;
  std::vector<std::uint8_t> rgb = tonemap_srgb8(img, tm);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      std::size_t k = (static_cast<std::size_t>(y) * img.width + x) * 3;
      c.blend(x0 + x, y0 + y, {rgb[k], rgb[k + 1], rgb[k + 2]}, 1.0);
    }
}

struct Options {
  int width = 160, height = 120, views = 8, ref_spp = 1024, updates = 32, pt_max_spp = 1024;
  std::string cache, out;
  bool corrected = true;
  std::vector<double> targets;  // empty: automatic
  int levels = 5;
};

// ---------------------------------------------------------------------------------------------

SceneResult run_scene(const std::string& spec, const Options& o) {
  SceneResult r;
  r.spec = spec;
  std::fprintf(stderr, "[%s] setting up the server (EngineHost, default parameters) ...\n",
               spec.c_str());
  double c0 = process_cpu();
  EngineHostOptions ho;  // EngineParams, AtlasOptions and TileStoreOptions: the server's defaults
  EngineHost host(load_scene(spec), spec, ho);
  r.setup_cpu_s = process_cpu() - c0;
  const World& world = host.world();
  const Atlas& atlas = host.atlas();
  // The client's own ray scene (a real client builds it from the scene package); the path
  // tracer uses it as well.
  c0 = process_cpu();
  RayScene rays(world);
  r.client_setup_cpu_s = process_cpu() - c0;
  LightSampler lights(world);
  r.tiles = host.tiles().tile_count();
  r.lightmaps = atlas.objects.size();
  for (const auto& obj : world.objects) r.triangles += obj.triangles().size();

  std::vector<View> all_views = make_views(spec, host.scene(), world);
  if (o.views < static_cast<int>(all_views.size()))
    all_views.resize(static_cast<std::size_t>(o.views));
  r.views = all_views;
  const std::size_t nv = r.views.size();

  // 1. The references, two independent halves each, cached.
  PathTracerOptions pto;
  pto.indirect_bounces = EngineParams{}.indirect_bounces;
  fs::create_directories(o.cache);
  for (std::size_t v = 0; v < nv; ++v) {
    const CameraPose& p = r.views[v].pose;
    std::ostringstream key;
    // Keyed by everything that determines the image, including the scene's triangle count and
    // bounds (a changed built-in scene gets new references); bump v1 when the path tracer changes.
    key << "crossover-ref-v1|" << spec << "|" << r.triangles << "|" << world.bounds.lo.x << ","
        << world.bounds.lo.y << "," << world.bounds.lo.z << "," << world.bounds.hi.x << ","
        << world.bounds.hi.y << "," << world.bounds.hi.z << "|" << p.eye.x << "," << p.eye.y << ","
        << p.eye.z << "|" << p.forward.x << "," << p.forward.y << "," << p.forward.z << "|"
        << p.up.x << "," << p.up.y << "," << p.up.z << "|" << p.yfov << "|" << o.width << "x"
        << o.height << "|" << o.ref_spp << "|" << pto.indirect_bounces;
    char hex[17];
    std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(fnv1a(key.str())));
    ImageRGB half[2];
    Reference ref;
    ref.cached = true;
    for (int h = 0; h < 2; ++h) {
      fs::path file = fs::path(o.cache) / ("ref_" + file_key(spec) + "_v" + std::to_string(v) +
                                           "_" + hex + (h ? "_b.exr" : "_a.exr"));
      if (fs::exists(file)) {
        half[h] = read_exr(file.string());
        if (half[h].width == o.width && half[h].height == o.height) continue;
      }
      ref.cached = false;
      std::fprintf(stderr, "[%s] reference view %zu/%zu (%s), half %d: %d spp ...\n", spec.c_str(),
                   v + 1, nv, r.views[v].name.c_str(), h + 1, o.ref_spp / 2);
      PathTracerOptions hopt = pto;
      hopt.seed = 0x5EED0000ull + 2 * v + static_cast<std::uint64_t>(h);
      PathTracer tracer(world, rays, lights, hopt);
      double t0 = process_cpu();
      half[h] = tracer.render(p, o.width, o.height, std::max(1, o.ref_spp / 2));
      ref.cpu_s += process_cpu() - t0;
      write_exr(file.string(), half[h]);
    }
    ref.image = weighted_mean({{&half[0], 0.5}, {&half[1], 0.5}});
    double se = 0, sum = 0;
    for (std::size_t i = 0; i < ref.image.pixels.size(); ++i)
      for (int c = 0; c < 3; ++c) {
        double d = 0.5 * (static_cast<double>(half[0].pixels[i][c]) - half[1].pixels[i][c]);
        se += d * d;
        sum += ref.image.pixels[i][c];
      }
    const double n = 3.0 * static_cast<double>(ref.image.pixels.size());
    ref.noise_mse = se / n;
    ref.mean = sum / n;
    r.refs.push_back(std::move(ref));
  }

  // 2. The shared engine: server steps, one client decoding and composing.
  std::vector<std::uint32_t> changed;
  host.set_listener([&](const std::vector<std::uint32_t>& c) { changed = c; });
  std::vector<Lightmap> client_maps;
  for (const ObjectLightmap& obj : atlas.objects) client_maps.emplace_back(obj.width, obj.height);
  tbb::task_arena one_thread(1);
  std::vector<std::vector<ImageRGB>> engine_images;  // [update][view], to pick the picture
  for (int u = 0; u < o.updates; ++u) {
    EngineStep s;
    changed.clear();
    const auto w0 = Clock::now();
    const double s0 = process_cpu();
    host.step();
    s.server_cpu_s = process_cpu() - s0;
    s.server_wall_s = seconds_since(w0);
    s.tiles_changed = changed.size();
    s.convergence = host.stats().convergence;
    std::vector<ImageRGB> images(nv);
    one_thread.execute([&] {
      const double d0 = thread_cpu();
      for (std::uint32_t t : changed) {
        TileStore::Snapshot snap = host.tiles().snapshot(t, wire::TILE_RGB9E5_ZSTD);
        const TileStore::Tile& tile = host.tiles().tile(t);
        wire::decode_tile(*snap.payload, wire::TILE_RGB9E5_ZSTD, tile.rect,
                          client_maps[tile.lightmap]);
        s.bytes += snap.payload->size();
      }
      s.decode_cpu_s = thread_cpu() - d0;
      for (std::size_t v = 0; v < nv; ++v) {
        const double f0 = thread_cpu();
        images[v] = compose(world, rays, atlas, client_maps, r.views[v].pose, o.width, o.height);
        s.compose_cpu_s.push_back(thread_cpu() - f0);
      }
    });
    for (std::size_t v = 0; v < nv; ++v) s.err.push_back(error_of(images[v], r.refs[v]));
    std::fprintf(stderr,
                 "[%s] engine update %d/%d: server %.2f CPU s (%.2f s wall), client decode %.1f "
                 "ms + compose %.1f ms, %zu tiles, error mean %.4f max %.4f\n",
                 spec.c_str(), u + 1, o.updates, s.server_cpu_s, s.server_wall_s,
                 1e3 * s.decode_cpu_s, 1e3 * s.mean_compose(), s.tiles_changed,
                 s.mean_err(o.corrected), s.max_err(o.corrected));
    r.floor_mean = std::min(r.floor_mean, s.mean_err(o.corrected));
    r.floor_all = std::min(r.floor_all, s.max_err(o.corrected));
    r.engine.push_back(std::move(s));
    engine_images.push_back(std::move(images));
  }
  r.texels = 0;
  for (const Lightmap& m : client_maps) r.texels += m.texels.size();

  // 3. Targets: from the engine's first update (coarse) down to just above its floor, and one
  // level below the floor that the engine cannot reach.
  if (!o.targets.empty()) {
    r.targets = o.targets;
  } else {
    const double coarse = r.engine.front().mean_err(o.corrected);
    const double fine = r.floor_mean * 1.03;
    const int n = std::max(2, o.levels);
    for (int k = 0; k < n; ++k) {
      double t = coarse * std::pow(fine / coarse, static_cast<double>(k) / (n - 1));
      r.targets.push_back(round2(t, true));
    }
    r.targets.push_back(round2(r.floor_mean * 0.8, false));
    std::sort(r.targets.begin(), r.targets.end(), std::greater<>());
    r.targets.erase(std::unique(r.targets.begin(), r.targets.end()), r.targets.end());
  }
  // The path tracer runs until it is below the lowest target the engine reaches (below the
  // floor the cross-over is infinite whatever the path tracer's time, which is extrapolated).
  double lowest = kInf;
  for (double t : r.targets)
    if (t >= r.floor_mean) lowest = std::min(lowest, t);
  if (!(lowest < kInf)) lowest = *std::min_element(r.targets.begin(), r.targets.end());

  // 4. The per-user path tracer, progressive, until each view is below the lowest target.
  std::vector<int> checkpoints{1};  // 1, 2, 3, 4, 6, 8, 12, 16, 24 ...
  for (int p = 2; p <= o.pt_max_spp; p *= 2) {
    checkpoints.push_back(p);
    if (p + p / 2 <= o.pt_max_spp) checkpoints.push_back(p + p / 2);
  }
  r.pt.resize(nv);
  std::vector<std::vector<std::pair<int, ImageRGB>>> pt_images(nv);
  for (std::size_t v = 0; v < nv; ++v) {
    std::vector<glm::dvec3> sum(static_cast<std::size_t>(o.width) * o.height, glm::dvec3(0.0));
    int done = 0;
    double cpu = 0, wall = 0;
    for (std::size_t c = 0; c < checkpoints.size(); ++c) {
      PathTracerOptions copt = pto;
      copt.seed = 0xC0FFEE00ull + 1000 * v + c;  // never a reference seed
      PathTracer tracer(world, rays, lights, copt);
      const int n = checkpoints[c] - done;
      const auto w0 = Clock::now();
      const double t0 = process_cpu();
      ImageRGB chunk = tracer.render(r.views[v].pose, o.width, o.height, n);
      cpu += process_cpu() - t0;
      wall += seconds_since(w0);
      done = checkpoints[c];
      ImageRGB img(o.width, o.height);
      for (std::size_t i = 0; i < sum.size(); ++i) {
        sum[i] += glm::dvec3(chunk.pixels[i]) * static_cast<double>(n);
        img.pixels[i] = glm::vec3(sum[i] / static_cast<double>(done));
      }
      PtPoint pt{done, cpu, wall, error_of(img, r.refs[v])};
      r.pt[v].push_back(pt);
      pt_images[v].emplace_back(done, std::move(img));
      if (pt.err.get(o.corrected) <= 0.9 * lowest && done >= 4) break;
    }
    const PtPoint& last = r.pt[v].back();
    std::fprintf(stderr,
                 "[%s] path tracer view %zu/%zu (%s): %d spp, %.2f CPU s, error %.4f (1 spp: "
                 "%.4f)\n",
                 spec.c_str(), v + 1, nv, r.views[v].name.c_str(), last.spp, last.cpu_s,
                 last.err.get(o.corrected), r.pt[v].front().err.get(o.corrected));
  }

  // 5. The cross-over per target.
  for (double e : r.targets) {
    Row row;
    row.target = e;
    double server = 0, client = 0, compose_s = 0;
    for (std::size_t u = 0; u < r.engine.size(); ++u) {
      const EngineStep& s = r.engine[u];
      server += s.server_cpu_s;
      client += s.decode_cpu_s + s.mean_compose();
      compose_s += s.mean_compose();
      if (row.updates < 0 && s.mean_err(o.corrected) <= e) {
        row.updates = static_cast<int>(u) + 1;
        row.server_s = server;
        row.client_s = client;
        row.client_compose_s = compose_s;
      }
      if (row.updates_all < 0 && s.max_err(o.corrected) <= e) {
        row.updates_all = static_cast<int>(u) + 1;
        row.server_all_s = server;
        row.client_all_s = client;
      }
    }
    double pt_sum = 0, spp_sum = 0;
    for (std::size_t v = 0; v < nv; ++v) {
      bool ex = false;
      double spp = 0;
      pt_sum += pt_time_to(r.pt[v], e, o.corrected, &ex, &spp);
      spp_sum += spp;
      row.pt_extrapolated += ex;
    }
    row.pt_s = pt_sum / static_cast<double>(nv);
    row.mean_spp = spp_sum / static_cast<double>(nv);
    row.kstar = kstar_of(row.server_s, row.client_s, row.pt_s);
    row.kstar_all = kstar_of(row.server_all_s, row.client_all_s, row.pt_s);
    if (row.updates > 0) {
      const double q = 1280.0 * 720.0 / (static_cast<double>(o.width) * o.height);
      row.kstar_720p =
          kstar_of(row.server_s, row.client_s + (q - 1) * row.client_compose_s, q * row.pt_s);
    }
    r.rows.push_back(row);
  }

  // The picture: at the middle target, engine (the update that reaches it) and path tracer (the
  // first checkpoint per view at or below it).
  const Row* mid = nullptr;
  for (const Row& row : r.rows)
    if (row.updates > 0) mid = &row;
  if (mid) {
    std::vector<const Row*> reachable;
    for (const Row& row : r.rows)
      if (row.updates > 0) reachable.push_back(&row);
    mid = reachable[reachable.size() / 2];
    r.mid_update = mid->updates;
    r.mid_target = mid->target;
    for (std::size_t v = 0; v < nv; ++v) {
      r.engine_at_mid.push_back(engine_images[static_cast<std::size_t>(mid->updates - 1)][v]);
      std::size_t pick = pt_images[v].size() - 1;
      for (std::size_t c = 0; c < r.pt[v].size(); ++c)
        if (r.pt[v][c].err.get(o.corrected) <= mid->target) {
          pick = c;
          break;
        }
      r.mid_spp.push_back(pt_images[v][pick].first);
      r.pt_at_mid.push_back(pt_images[v][pick].second);
    }
  }
  return r;
}

std::string kstar_text(double k) {
  if (!(k < kInf)) return "inf";
  return fmt(k < 10 ? "%.2f" : "%.1f", k);
}

json num(double v) {
  return v < kInf ? json(v) : json(nullptr);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "irradcast-bench-crossover: users from which the shared engine (server + K clients) costs "
      "less CPU time than K path tracers, at equal error against a converged reference"};
  Options o;
  o.out = "out/crossover";
  o.cache = "out/crossover/cache";
  std::string scenes_text = "cornell,rooms:2", targets_text, json_path, metric = "corrected";
  int threads = 0;
  bool quick = false;
  app.add_option("--out", o.out, "directory for the JSON and the PNG plots");
  app.add_option("--cache", o.cache, "directory for the cached reference images (EXR)");
  app.add_option("--json", json_path, "JSON results file (default OUT/crossover.json)");
  app.add_option("--scenes", scenes_text, "scenes, comma separated");
  app.add_option("--size", o.width, "image width (height = 3/4 of it)")->check(CLI::Range(8, 4096));
  app.add_option("--views", o.views, "viewpoints per scene (at most 8 for the built-in scenes)")
      ->check(CLI::Range(1, 8));
  app.add_option("--ref-spp", o.ref_spp, "reference samples per pixel (two halves)")
      ->check(CLI::Range(2, 1 << 20));
  app.add_option("--updates", o.updates, "engine updates")->check(CLI::Range(1, 10000));
  app.add_option("--pt-max-spp", o.pt_max_spp, "per-user path tracer: most samples per pixel")
      ->check(CLI::Range(1, 1 << 20));
  app.add_option("--targets", targets_text,
                 "target errors, comma separated (default: automatic, from the engine's first "
                 "update to its floor, plus one below the floor)");
  app.add_option("--levels", o.levels, "automatic target levels above the floor")
      ->check(CLI::Range(2, 20));
  app.add_option("--metric", metric,
                 "corrected (the reference's own noise subtracted from the MSE) | raw")
      ->check(CLI::IsMember({"corrected", "raw"}));
  app.add_option("--threads", threads, "TBB threads (0: all cores)");
  app.add_flag(
      "--quick", quick,
      "smoke run: 64x48, 4 views, 64 reference spp, 4 updates, path tracer to 64 spp (unless "
      "given)");
  CLI11_PARSE(app, argc, argv);
  if (quick) {  // smaller defaults; options given explicitly keep their values
    auto unless_given = [&](const char* name, int& value, int quick_value) {
      if (app.count(name) == 0) value = quick_value;
    };
    unless_given("--size", o.width, 64);
    unless_given("--views", o.views, 4);
    unless_given("--ref-spp", o.ref_spp, 64);
    unless_given("--updates", o.updates, 4);
    unless_given("--pt-max-spp", o.pt_max_spp, 64);
  }
  o.height = std::max(1, o.width * 3 / 4);
  o.corrected = metric == "corrected";
  {
    std::stringstream ss(targets_text);
    std::string item;
    while (std::getline(ss, item, ','))
      if (!item.empty()) o.targets.push_back(std::stod(item));
  }

  try {
    Progress::set_enabled(false);
    log::set_level(log::Level::Warn);
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0)
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(threads));
    const int used_threads = static_cast<int>(
        tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
    fs::create_directories(o.out);
    if (json_path.empty()) json_path = (fs::path(o.out) / "crossover.json").string();
    const auto start = Clock::now();
    const double cpu_start = process_cpu();
    const std::string load_start = load_average();
    std::printf(
        "irradcast-bench-crossover: %s, %u hardware threads, %d TBB threads, load average %s\n"
        "%dx%d pixels, %d views, reference %d spp, %d engine updates, error metric: %s relative "
        "RMSE\n",
        cpu_model().c_str(), std::thread::hardware_concurrency(), used_threads, load_start.c_str(),
        o.width, o.height, o.views, o.ref_spp, o.updates, metric.c_str());

    std::vector<SceneResult> results;
    std::stringstream ss(scenes_text);
    std::string spec;
    while (std::getline(ss, spec, ','))
      if (!spec.empty()) results.push_back(run_scene(spec, o));

    json result;
    result["machine"] = {{"cpu", cpu_model()},
                         {"hardware_threads", std::thread::hardware_concurrency()},
                         {"tbb_threads", used_threads},
                         {"load_average_at_start", load_start}};
    result["params"] = {{"width", o.width},
                        {"height", o.height},
                        {"views", o.views},
                        {"reference_spp", o.ref_spp},
                        {"engine_updates", o.updates},
                        {"pt_max_spp", o.pt_max_spp},
                        {"metric", metric},
                        {"engine",
                         "EngineHostOptions defaults (EngineParams, AtlasOptions, "
                         "TileStoreOptions), as irradcast-server"},
                        {"indirect_bounces", EngineParams{}.indirect_bounces}};

    std::printf(
        "\nCross-over at equal error (CPU seconds; server = update + publish with RGB9E5 "
        "encoding, all threads;\nclient = per client: decode of the changed tiles + one compose "
        "per update, one thread; PT = per user, mean over the views)\n");
    std::printf("%-8s %8s | %4s %9s %9s | %9s %5s %7s | %8s %8s | %4s %8s | %8s\n", "scene",
                "target", "upd", "server s", "client s", "PT s/user", "spp", "extrap", "K*",
                "users", "upd*", "K*(all)", "K*@720p");
    json scenes = json::array();
    for (SceneResult& r : results) {
      for (const Row& row : r.rows) {
        const bool reach = row.updates > 0;
        std::printf(
            "%-8s %8.4f | %4s %9s %9s | %9.2f %5.0f %4d/%zu | %8s %8s | %4s %8s | %8s\n",
            r.spec.c_str(), row.target, reach ? std::to_string(row.updates).c_str() : "-",
            reach ? fmt("%.2f", row.server_s).c_str() : "-",
            reach ? fmt("%.3f", row.client_s).c_str() : "-", row.pt_s, row.mean_spp,
            row.pt_extrapolated, r.views.size(), kstar_text(row.kstar).c_str(),
            row.kstar < kInf
                ? std::to_string(static_cast<long long>(std::max(1.0, std::ceil(row.kstar))))
                      .c_str()
                : "never",
            row.updates_all > 0 ? std::to_string(row.updates_all).c_str() : "-",
            kstar_text(row.kstar_all).c_str(), kstar_text(row.kstar_720p).c_str());
      }
      double noise = 0;
      for (const Reference& ref : r.refs) noise += ref.rel_noise() / r.refs.size();
      std::printf(
          "%-8s engine floor (lowest error over %d updates): mean %.4f, every view %.4f; the "
          "reference's own noise: %.4f (relative RMS, mean over views)\n",
          r.spec.c_str(), o.updates, r.floor_mean, r.floor_all, noise);

      json js;
      js["scene"] = r.spec;
      js["texels_in_lightmaps"] = r.texels;
      js["tiles"] = r.tiles;
      js["lightmaps"] = r.lightmaps;
      js["triangles"] = r.triangles;
      js["server_setup_cpu_s"] = r.setup_cpu_s;
      js["client_setup_cpu_s_bvh"] = r.client_setup_cpu_s;
      js["engine_floor_mean"] = r.floor_mean;
      js["engine_floor_every_view"] = r.floor_all;
      js["reference_rel_noise_mean"] = noise;
      json views = json::array();
      for (std::size_t v = 0; v < r.views.size(); ++v) {
        json jv = pose_json(r.views[v].pose);
        jv["name"] = r.views[v].name;
        jv["reference_mean_radiance"] = r.refs[v].mean;
        jv["reference_rel_noise"] = r.refs[v].rel_noise();
        jv["reference_cpu_s"] = r.refs[v].cpu_s;
        jv["reference_cached"] = r.refs[v].cached;
        json pts = json::array();
        for (const PtPoint& p : r.pt[v])
          pts.push_back({{"spp", p.spp},
                         {"cpu_s", p.cpu_s},
                         {"wall_s", p.wall_s},
                         {"err_raw", p.err.raw},
                         {"err_corrected", p.err.corrected}});
        jv["path_tracer"] = pts;
        views.push_back(jv);
      }
      js["views"] = views;
      json eng = json::array();
      for (const EngineStep& s : r.engine) {
        json errs_raw = json::array(), errs_cor = json::array();
        for (const Err& e : s.err) {
          errs_raw.push_back(e.raw);
          errs_cor.push_back(e.corrected);
        }
        eng.push_back({{"server_cpu_s", s.server_cpu_s},
                       {"server_wall_s", s.server_wall_s},
                       {"client_decode_cpu_s", s.decode_cpu_s},
                       {"client_compose_cpu_s", s.compose_cpu_s},
                       {"tiles_changed", s.tiles_changed},
                       {"bytes", s.bytes},
                       {"convergence", s.convergence},
                       {"err_raw", errs_raw},
                       {"err_corrected", errs_cor}});
      }
      js["engine_updates"] = eng;
      json rows = json::array();
      for (const Row& row : r.rows)
        rows.push_back({{"target", row.target},
                        {"updates", row.updates},
                        {"server_cpu_s", num(row.server_s)},
                        {"client_cpu_s", num(row.client_s)},
                        {"pt_cpu_s_per_user", num(row.pt_s)},
                        {"pt_mean_spp", row.mean_spp},
                        {"pt_views_extrapolated", row.pt_extrapolated},
                        {"kstar", num(row.kstar)},
                        {"updates_every_view", row.updates_all},
                        {"server_cpu_s_every_view", num(row.server_all_s)},
                        {"client_cpu_s_every_view", num(row.client_all_s)},
                        {"kstar_every_view", num(row.kstar_all)},
                        {"client_compose_cpu_s", num(row.client_compose_s)},
                        {"kstar_1280x720_estimate", num(row.kstar_720p)}});
      js["crossover"] = rows;
      scenes.push_back(js);
    }
    std::printf(
        "upd: engine updates until the error averaged over the views is <= target ('-': never, "
        "below the engine's floor); K* = server / (PT - client), users = the smallest whole "
        "K;\nupd*, K*(all): the same when every view must be <= target. extrap: views whose "
        "PT time is extrapolated (t ~ e^-2) past the last checkpoint.\nK*@720p: an estimate "
        "for 1280x720 frames, the PT and compose times scaled by the pixel count.\n");
    result["scenes"] = scenes;

    // Plots.
    for (const SceneResult& r : results) {
      const std::string key = file_key(r.spec);
      // (a) Error against CPU seconds.
      plot::XYPlot a;
      a.title = r.spec + ": error vs CPU time";
      a.note = std::to_string(r.views.size()) + " views at " + std::to_string(o.width) + "x" +
               std::to_string(o.height) + ", " + metric + " relative RMSE (mean over views) vs a " +
               std::to_string(o.ref_spp) + " spp reference; " + std::to_string(used_threads) +
               " threads";
      a.x_label = "CPU seconds (log)";
      a.y_label = "relative RMSE (log)";
      a.x_log = a.y_log = true;
      a.legend = plot::XYPlot::Legend::TopRight;
      plot::Series pt, srv, srv1;
      // The path tracer as the cross-over sees it: for each error e, the mean over the views of
      // the CPU time to reach e; thin where a view's time is extrapolated (t ~ e^-2).
      pt.label = "path tracer, 1 user (mean over views)";
      pt.color = plot::kOrange;
      pt.lines = true;
      pt.points = false;
      pt.line_width = 2.5;
      plot::Series ptx;
      ptx.label = "  extrapolated, t ~ 1/error^2";
      ptx.color = plot::kOrange;
      ptx.lines = true;
      ptx.points = false;
      ptx.line_width = 1.0;
      {
        double e_hi = 0, e_lo = kInf;
        for (const auto& c : r.pt) e_hi = std::max(e_hi, c.front().err.get(o.corrected));
        for (double t : r.targets) e_lo = std::min(e_lo, t);
        for (const auto& c : r.pt) e_lo = std::min(e_lo, c.back().err.get(o.corrected));
        const int n = 48;
        for (int k = 0; k <= n; ++k) {
          const double e = e_hi * std::pow(e_lo / e_hi, static_cast<double>(k) / n);
          double t = 0, spp = 0;
          bool any = false;
          for (const auto& c : r.pt) {
            bool ex = false;
            t += pt_time_to(c, e, o.corrected, &ex, &spp) / static_cast<double>(r.pt.size());
            any = any || ex;
          }
          if (!any) {
            pt.x.push_back(t);
            pt.y.push_back(e);
            continue;
          }
          if (ptx.x.empty() && !pt.x.empty()) {  // starts where the measured part ends
            ptx.x.push_back(pt.x.back());
            ptx.y.push_back(pt.y.back());
          }
          ptx.x.push_back(t);
          ptx.y.push_back(e);
        }
      }
      srv.label = "engine: server alone (updates 1, 2 ...)";
      srv.color = plot::kBlue;
      srv.lines = true;
      srv1.label = "engine: server + 1 client";
      srv1.color = plot::kGreen;
      srv1.lines = true;
      srv1.points = false;
      double s = 0, c = 0;
      for (const EngineStep& st : r.engine) {
        s += st.server_cpu_s;
        c += st.decode_cpu_s + st.mean_compose();
        srv.x.push_back(s);
        srv.y.push_back(st.mean_err(o.corrected));
        srv1.x.push_back(s + c);
        srv1.y.push_back(st.mean_err(o.corrected));
      }
      plot::Series noise;
      double nz = 0;
      for (const Reference& ref : r.refs) nz += ref.rel_noise() / r.refs.size();
      noise.label = "reference noise" + std::string(o.corrected ? " (subtracted)" : "");
      noise.color = plot::kDarkGrey;
      noise.points = false;
      noise.lines = true;
      noise.line_width = 1.0;
      double xlo = std::min(pt.x.empty() ? 1.0 : pt.x.front(), srv.x.front());
      double xhi = std::max(pt.x.empty() ? 1.0 : pt.x.back(), srv1.x.back());
      noise.x = {xlo, xhi};
      noise.y = {nz, nz};
      a.series = {pt, srv, srv1, noise};
      if (!ptx.x.empty()) a.series.insert(a.series.begin() + 1, ptx);
      std::string png = (fs::path(o.out) / ("crossover_error_" + key + ".png")).string();
      plot::write_xy_plot(png, a);
      std::printf("wrote %s\n", png.c_str());

      // (b) CPU seconds to reach a target against users, for up to three targets.
      std::vector<const Row*> picks;
      {
        std::vector<const Row*> reach;
        for (const Row& row : r.rows)
          if (row.updates > 0) reach.push_back(&row);
        if (!reach.empty()) {
          picks.push_back(reach.front());
          if (reach.size() > 2) picks.push_back(reach[reach.size() / 2]);
          if (reach.size() > 1) picks.push_back(reach.back());
        }
      }
      double kmax = 8;
      for (const Row* row : picks)
        if (row->kstar < kInf) kmax = std::max(kmax, std::ceil(1.5 * row->kstar));
      kmax = std::min(kmax, 64.0);
      plot::XYPlot b;
      b.title = r.spec + ": CPU time to reach a target error vs users";
      b.note =
          "lines: K path tracers; with dots: server + K clients; black dot: the cross-over K*; " +
          std::to_string(o.width) + "x" + std::to_string(o.height) + " pixels";
      b.x_label = "users K";
      b.y_log = true;
      b.y_headroom = 0.6;
      b.y_label = "CPU seconds to reach the target (log)";
      const plot::Color colors[3] = {plot::kBlue, plot::kGreen, plot::kRed};
      for (std::size_t k = 0; k < picks.size(); ++k) {
        const Row& row = *picks[k];
        plot::Series p, e, x;
        p.label = "path tracers, error " + fmt("%.3f", row.target);
        p.color = colors[k];
        p.points = false;
        p.lines = true;
        e.label =
            "shared engine, error " + fmt("%.3f", row.target) + ", K* = " + kstar_text(row.kstar);
        e.color = colors[k];
        e.lines = true;
        e.line_width = 1.0;
        // From half a user (K* can be below 1), finely enough for a smooth line on the log axis.
        for (int q = 2; q <= 4 * static_cast<int>(kmax); ++q) {
          const double K = 0.25 * q;
          p.x.push_back(K);
          p.y.push_back(K * row.pt_s);
          const int step = std::max(1, static_cast<int>(kmax) / 16);
          if (q % 4 == 0 && (q / 4) % step == 0) {
            e.x.push_back(K);
            e.y.push_back(row.server_s + K * row.client_s);
          }
        }
        b.series.push_back(p);
        b.series.push_back(e);
        if (row.kstar < kInf) {
          x.label = "";
          x.color = plot::kBlack;
          x.x = {row.kstar};
          x.y = {row.kstar * row.pt_s};
          x.labels = {"K* = " + kstar_text(row.kstar)};
          x.labels_above_left = true;
          b.series.push_back(x);
        }
      }
      png = (fs::path(o.out) / ("crossover_users_" + key + ".png")).string();
      plot::write_xy_plot(png, b);
      std::printf("wrote %s\n", png.c_str());

      // (c) The views at the middle target: reference | engine | path tracer.
      if (!r.engine_at_mid.empty()) {
        const int w = o.width, h = o.height, gap = 6, head = 60, label = 18;
        const int nv = static_cast<int>(r.views.size());
        const int cols = nv > 4 ? 2 : 1, rows = (nv + cols - 1) / cols;
        const int cw = 3 * w + 2 * gap + 3 * gap;
        plot::Canvas cv(std::max(cols * cw + gap, 760), head + rows * (h + label + gap) + gap);
        const double target = r.mid_target;
        cv.text(cv.width() / 2.0, 8, r.spec + ": reference | shared engine | path tracer", 2.0,
                plot::kBlack, plot::Align::Center);
        cv.text(cv.width() / 2.0, 32,
                "engine after " + std::to_string(r.mid_update) +
                    " updates, path tracer at the first checkpoint with error <= " +
                    fmt("%.3f", target) + " per view; same exposure per view",
                1.2, plot::kDarkGrey, plot::Align::Center);
        for (int v = 0; v < nv; ++v) {
          const int x0 = gap + (v / rows) * cw, y0 = head + (v % rows) * (h + label + gap);
          ToneMapOptions tm;
          const float ev = std::log2(exposure_scale(r.refs[static_cast<std::size_t>(v)].image, tm));
          const std::size_t sv = static_cast<std::size_t>(v);
          image_to_canvas(cv, r.refs[sv].image, x0, y0 + label, ev);
          image_to_canvas(cv, r.engine_at_mid[sv], x0 + w + gap, y0 + label, ev);
          image_to_canvas(cv, r.pt_at_mid[sv], x0 + 2 * (w + gap), y0 + label, ev);
          const Err ee = error_of(r.engine_at_mid[sv], r.refs[sv]);
          const Err pe = error_of(r.pt_at_mid[sv], r.refs[sv]);
          cv.text(x0, y0 + 3,
                  std::to_string(v + 1) + ". " + r.views[sv].name + ": engine " +
                      fmt("%.3f", ee.get(o.corrected)) + ", PT " + std::to_string(r.mid_spp[sv]) +
                      " spp " + fmt("%.3f", pe.get(o.corrected)),
                  1.0, plot::kBlack);
        }
        png = (fs::path(o.out) / ("crossover_views_" + key + ".png")).string();
        cv.write_png(png);
        std::printf("wrote %s\n", png.c_str());
      }
    }

    result["machine"]["load_average_at_end"] = load_average();
    result["total_wall_s"] = seconds_since(start);
    result["total_cpu_s"] = process_cpu() - cpu_start;
    std::ofstream(json_path) << result.dump(2) << "\n";
    std::printf("wrote %s (total %.1f s wall, %.1f s CPU; load average at start %s, at end %s)\n",
                json_path.c_str(), seconds_since(start), process_cpu() - cpu_start,
                load_start.c_str(), load_average().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-crossover: error: %s\n", e.what());
    return 1;
  }
  return 0;
}

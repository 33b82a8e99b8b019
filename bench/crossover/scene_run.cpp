// irradcast-bench-crossover: the measurements of one scene. In order: the server (EngineHost,
// default parameters) and the client's ray scene; the references, two independent halves per
// view, cached as EXR; the shared engine, server steps with one client decoding the changed tiles
// and composing every view; the target errors; the per-user path tracer, progressive, per view;
// the cross-over per target; and the images for the picture at the middle target.
#include <tbb/task_arena.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <sstream>

#include "bench_util.h"
#include "crossover.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast::bench {

namespace {

std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

CameraPose look(glm::vec3 eye, glm::vec3 target, float fov_deg) {
  CameraPose p;
  p.eye = eye;
  p.forward = glm::normalize(target - eye);
  p.up = glm::vec3(0.0f, 1.0f, 0.0f);
  p.yfov = glm::radians(fov_deg);
  return p;
}

}  // namespace

std::string file_key(const std::string& spec) {
  std::string k;
  for (char c : spec) k += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return k;
}

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
  } else if (spec == "sponza") {
    // The atrium runs along x (about -15 to 15 m), the courtyard floor at y = 0, the arcades
    // on both sides in z; sun and sky through the open roof.
    v.push_back(
        {"east end, back down the hall", look({12.0f, 1.6f, 0.5f}, {-6.0f, 4.0f, -1.0f}, 70)});
    v.push_back({"under the south arcade", look({-6.0f, 1.5f, -4.6f}, {6.0f, 2.0f, -3.5f}, 70)});
    v.push_back({"up at the north gallery", look({0.0f, 1.0f, -2.0f}, {4.0f, 9.0f, 5.0f}, 65)});
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

namespace {

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

// 2 significant digits, rounded up (so that a level derived from the engine's floor stays
// reachable) or to nearest.
double round2(double v, bool up) {
  if (!(v > 0)) return v;
  double mag = std::pow(10.0, std::floor(std::log10(v)) - 1);
  double q = v / mag;
  return (up ? std::ceil(q - 1e-9) : std::round(q)) * mag;
}

// What the steps of one scene's run share.
struct SceneContext {
  const std::string& spec;
  const Options& o;
  const World& world;
  const RayScene& rays;
  const LightSampler& lights;
  PathTracerOptions pto;
};

// 1. The reference of view v, two independent halves, cached.
Reference make_reference(const SceneContext& c, const SceneResult& r, std::size_t v) {
  const Options& o = c.o;
  const World& world = c.world;
  const std::string& spec = c.spec;
  const std::size_t nv = r.views.size();
  const CameraPose& p = r.views[v].pose;
  std::ostringstream key;
  // Keyed by everything that determines the image, including the scene's triangle count and
  // bounds (a changed built-in scene gets new references); bump v1 when the path tracer changes.
  key << "crossover-ref-v1|" << spec << "|" << r.triangles << "|" << world.bounds.lo.x << ","
      << world.bounds.lo.y << "," << world.bounds.lo.z << "," << world.bounds.hi.x << ","
      << world.bounds.hi.y << "," << world.bounds.hi.z << "|" << p.eye.x << "," << p.eye.y << ","
      << p.eye.z << "|" << p.forward.x << "," << p.forward.y << "," << p.forward.z << "|" << p.up.x
      << "," << p.up.y << "," << p.up.z << "|" << p.yfov << "|" << o.width << "x" << o.height << "|"
      << o.ref_spp << "|" << c.pto.indirect_bounces;
  char hex[17];
  std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(fnv1a(key.str())));
  ImageRGB half[2];
  Reference ref;
  ref.cached = true;
  for (int h = 0; h < 2; ++h) {
    fs::path file = fs::path(o.cache) / ("ref_" + file_key(spec) + "_v" + std::to_string(v) + "_" +
                                         hex + (h ? "_b.exr" : "_a.exr"));
    if (fs::exists(file)) {
      half[h] = read_exr(file.string());
      if (half[h].width == o.width && half[h].height == o.height) continue;
    }
    ref.cached = false;
    std::fprintf(stderr, "[%s] reference view %zu/%zu (%s), half %d: %d spp ...\n", spec.c_str(),
                 v + 1, nv, r.views[v].name.c_str(), h + 1, o.ref_spp / 2);
    PathTracerOptions hopt = c.pto;
    hopt.seed = 0x5EED0000ull + 2 * v + static_cast<std::uint64_t>(h);
    PathTracer tracer(world, c.rays, c.lights, hopt);
    double t0 = process_cpu_seconds();
    half[h] = tracer.render(p, o.width, o.height, std::max(1, o.ref_spp / 2));
    ref.cpu_s += process_cpu_seconds() - t0;
    write_exr(file.string(), half[h]);
  }
  ref.image = weighted_mean({{&half[0], 0.5}, {&half[1], 0.5}});
  // The noise MSE's standard error: the spread of the per-sample terms over their count (the
  // pixels' noise is independent).
  double se = 0, se2 = 0, sum = 0;
  for (std::size_t i = 0; i < ref.image.pixels.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) {
      double d = 0.5 * (static_cast<double>(half[0].pixels[i][ch]) - half[1].pixels[i][ch]);
      se += d * d;
      se2 += d * d * d * d;
      sum += ref.image.pixels[i][ch];
    }
  const double n = 3.0 * static_cast<double>(ref.image.pixels.size());
  ref.noise_mse = se / n;
  ref.mean = sum / n;
  ref.noise_mse_se = std::sqrt(std::max(se2 / n - ref.noise_mse * ref.noise_mse, 0.0) / n);
  return ref;
}

// The client of the shared engine: its lightmaps, updated from the changed tiles.
struct EngineClient {
  std::vector<Lightmap> maps;
  std::vector<std::uint32_t> changed;  // the tiles the last step changed
};

// 2. One server step and one client decoding the changed tiles and composing every view, on one
// thread; the composed images go to `images`.
EngineStep engine_step(const SceneContext& c, EngineHost& host, EngineClient& client,
                       tbb::task_arena& one_thread, const SceneResult& r,
                       std::vector<ImageRGB>& images) {
  const std::size_t nv = r.views.size();
  EngineStep s;
  client.changed.clear();
  const auto w0 = Clock::now();
  const double s0 = process_cpu_seconds();
  host.step();
  s.server_cpu_s = process_cpu_seconds() - s0;
  s.server_wall_s = seconds_since(w0);
  s.tiles_changed = client.changed.size();
  s.convergence = host.stats().convergence;
  images.assign(nv, ImageRGB());
  one_thread.execute([&] {
    const double d0 = thread_cpu_seconds();
    for (std::uint32_t t : client.changed) {
      TileStore::Snapshot snap = host.tiles().snapshot(t, wire::TILE_RGB9E5_ZSTD);
      const TileStore::Tile& tile = host.tiles().tile(t);
      wire::decode_tile(*snap.payload, wire::TILE_RGB9E5_ZSTD, tile.rect,
                        client.maps[tile.lightmap]);
      s.bytes += snap.payload->size();
    }
    s.decode_cpu_s = thread_cpu_seconds() - d0;
    for (std::size_t v = 0; v < nv; ++v) {
      const double f0 = thread_cpu_seconds();
      images[v] = compose(c.world, c.rays, host.atlas(), client.maps, r.views[v].pose, c.o.width,
                          c.o.height);
      s.compose_cpu_s.push_back(thread_cpu_seconds() - f0);
    }
  });
  for (std::size_t v = 0; v < nv; ++v) s.err.push_back(error_of(images[v], r.refs[v]));
  return s;
}

// 2. The shared engine: every update, its images per view ([update][view], for the picture).
std::vector<std::vector<ImageRGB>> run_engine(const SceneContext& c, EngineHost& host,
                                              SceneResult& r) {
  const Options& o = c.o;
  EngineClient client;
  host.set_listener([&](const std::vector<std::uint32_t>& ch) { client.changed = ch; });
  for (const ObjectLightmap& obj : host.atlas().objects)
    client.maps.emplace_back(obj.width, obj.height);
  tbb::task_arena one_thread(1);
  std::vector<std::vector<ImageRGB>> engine_images;
  for (int u = 0; u < o.updates; ++u) {
    std::vector<ImageRGB> images;
    EngineStep s = engine_step(c, host, client, one_thread, r, images);
    std::fprintf(stderr,
                 "[%s] engine update %d/%d: server %.2f CPU s (%.2f s wall), client decode %.1f "
                 "ms + compose %.1f ms, %zu tiles, error mean %.4f max %.4f\n",
                 c.spec.c_str(), u + 1, o.updates, s.server_cpu_s, s.server_wall_s,
                 1e3 * s.decode_cpu_s, 1e3 * s.mean_compose(), s.tiles_changed,
                 s.mean_err(o.corrected), s.max_err(o.corrected));
    r.floor_mean = std::min(r.floor_mean, s.mean_err(o.corrected));
    r.floor_all = std::min(r.floor_all, s.max_err(o.corrected));
    r.engine.push_back(std::move(s));
    engine_images.push_back(std::move(images));
  }
  host.set_listener(nullptr);
  r.texels = 0;
  for (const Lightmap& m : client.maps) r.texels += m.texels.size();
  return engine_images;
}

// 3. Targets: from the engine's first update (coarse) down to just above its floor, and one
// level below the floor that the engine cannot reach. Returns the lowest target the engine
// reaches (below the floor the cross-over is infinite whatever the path tracer's time, which is
// extrapolated): the path tracer runs until it is below it.
double choose_targets(const Options& o, SceneResult& r) {
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
  double lowest = kInf;
  for (double t : r.targets)
    if (t >= r.floor_mean) lowest = std::min(lowest, t);
  if (!(lowest < kInf)) lowest = *std::min_element(r.targets.begin(), r.targets.end());
  return lowest;
}

using PtImages = std::vector<std::pair<int, ImageRGB>>;  // spp and image per checkpoint

// 4. The per-user path tracer on view v, progressive, until it is below `lowest`.
PtImages run_path_tracer(const SceneContext& c, SceneResult& r, std::size_t v,
                         const std::vector<int>& checkpoints, double lowest) {
  const Options& o = c.o;
  PtImages images;
  std::vector<glm::dvec3> sum(static_cast<std::size_t>(o.width) * o.height, glm::dvec3(0.0));
  int done = 0;
  double cpu = 0, wall = 0;
  for (std::size_t k = 0; k < checkpoints.size(); ++k) {
    PathTracerOptions copt = c.pto;
    copt.seed = 0xC0FFEE00ull + 1000 * v + k;  // never a reference seed
    PathTracer tracer(c.world, c.rays, c.lights, copt);
    const int n = checkpoints[k] - done;
    const auto w0 = Clock::now();
    const double t0 = process_cpu_seconds();
    ImageRGB chunk = tracer.render(r.views[v].pose, o.width, o.height, n);
    cpu += process_cpu_seconds() - t0;
    wall += seconds_since(w0);
    done = checkpoints[k];
    ImageRGB img(o.width, o.height);
    for (std::size_t i = 0; i < sum.size(); ++i) {
      sum[i] += glm::dvec3(chunk.pixels[i]) * static_cast<double>(n);
      img.pixels[i] = glm::vec3(sum[i] / static_cast<double>(done));
    }
    PtPoint pt{done, cpu, wall, error_of(img, r.refs[v])};
    r.pt[v].push_back(pt);
    images.emplace_back(done, std::move(img));
    if (pt.err.get(o.corrected) <= 0.9 * lowest && done >= 4) break;
  }
  const PtPoint& last = r.pt[v].back();
  std::fprintf(stderr,
               "[%s] path tracer view %zu/%zu (%s): %d spp, %.2f CPU s, error %.4f (1 spp: "
               "%.4f)\n",
               c.spec.c_str(), v + 1, r.views.size(), r.views[v].name.c_str(), last.spp, last.cpu_s,
               last.err.get(o.corrected), r.pt[v].front().err.get(o.corrected));
  return images;
}

// 5. The cross-over at target e.
Row crossover_row(const Options& o, const SceneResult& r, double e) {
  const std::size_t nv = r.views.size();
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
  return row;
}

// The picture: at the middle target, engine (the update that reaches it) and path tracer (the
// first checkpoint per view at or below it).
void pick_picture(const Options& o, const std::vector<std::vector<ImageRGB>>& engine_images,
                  const std::vector<PtImages>& pt_images, SceneResult& r) {
  std::vector<const Row*> reachable;
  for (const Row& row : r.rows)
    if (row.updates > 0) reachable.push_back(&row);
  if (reachable.empty()) return;
  const Row* mid = reachable[reachable.size() / 2];
  r.mid_update = mid->updates;
  r.mid_target = mid->target;
  for (std::size_t v = 0; v < r.views.size(); ++v) {
    r.engine_at_mid.push_back(engine_images[static_cast<std::size_t>(mid->updates - 1)][v]);
    std::size_t pick = pt_images[v].size() - 1;
    for (std::size_t k = 0; k < r.pt[v].size(); ++k)
      if (r.pt[v][k].err.get(o.corrected) <= mid->target) {
        pick = k;
        break;
      }
    r.mid_spp.push_back(pt_images[v][pick].first);
    r.pt_at_mid.push_back(pt_images[v][pick].second);
  }
}

}  // namespace

Reference view_reference(const std::string& spec, const Options& o, const World& world,
                         const std::vector<View>& views, std::size_t v) {
  RayScene rays(world);
  LightSampler lights(world);
  SceneContext c{spec, o, world, rays, lights, PathTracerOptions{}};
  c.pto.indirect_bounces = o.engine.engine.indirect_bounces;
  SceneResult r;
  r.views = views;
  for (const auto& obj : world.objects) r.triangles += obj.triangles().size();
  fs::create_directories(o.cache);
  return make_reference(c, r, v);
}

SceneResult run_scene(const std::string& spec, const Options& o) {
  SceneResult r;
  r.spec = spec;
  std::fprintf(stderr, "[%s] setting up the server (EngineHost, default parameters) ...\n",
               spec.c_str());
  double c0 = process_cpu_seconds();
  EngineHost host(load_scene(spec), spec, o.engine);
  r.setup_cpu_s = process_cpu_seconds() - c0;
  const World& world = host.world();
  // The client's own ray scene (a real client builds it from the scene package); the path
  // tracer uses it as well.
  c0 = process_cpu_seconds();
  RayScene rays(world);
  r.client_setup_cpu_s = process_cpu_seconds() - c0;
  LightSampler lights(world);
  r.tiles = host.tiles().tile_count();
  r.lightmaps = host.atlas().objects.size();
  for (const auto& obj : world.objects) r.triangles += obj.triangles().size();
  r.views = make_views(spec, host.scene(), world);
  if (o.views < static_cast<int>(r.views.size())) r.views.resize(static_cast<std::size_t>(o.views));
  const std::size_t nv = r.views.size();

  SceneContext c{spec, o, world, rays, lights, PathTracerOptions{}};
  c.pto.indirect_bounces = o.engine.engine.indirect_bounces;
  fs::create_directories(o.cache);
  for (std::size_t v = 0; v < nv; ++v) r.refs.push_back(make_reference(c, r, v));
  const std::vector<std::vector<ImageRGB>> engine_images = run_engine(c, host, r);
  const double lowest = choose_targets(o, r);
  std::vector<int> checkpoints{1};  // 1, 2, 3, 4, 6, 8, 12, 16, 24 ...
  for (int p = 2; p <= o.pt_max_spp; p *= 2) {
    checkpoints.push_back(p);
    if (p + p / 2 <= o.pt_max_spp) checkpoints.push_back(p + p / 2);
  }
  r.pt.resize(nv);
  std::vector<PtImages> pt_images(nv);
  for (std::size_t v = 0; v < nv; ++v) pt_images[v] = run_path_tracer(c, r, v, checkpoints, lowest);
  for (double e : r.targets) r.rows.push_back(crossover_row(o, r, e));
  pick_picture(o, engine_images, pt_images, r);
  return r;
}

}  // namespace irradcast::bench

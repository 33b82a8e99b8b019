// irradcast-bench-edit: how fast a scene edit reaches a viewer. For each scene and edit (a light
// move and an object move by default): a server converges on the scene, a viewer holds every
// tile, the edit is submitted, and the viewer's lightmaps are recorded as tiles arrive until the
// server is idle again. Reports the time from the edit to (a) the first updated tile at the
// viewer, (b) 90 % and (c) 99 % of the final change reached (progress = 1 - RMS(now - final) /
// RMS(before - final), over the mean luminance of the tiles the edit changes, from the first
// moment it stays above the level), and the same for recomputing from scratch (a new engine
// host on the edited scene: set-up plus updates, measured at its tile store, so without the
// network and the scene download a restarted server would also need). Writes JSON and a PNG
// plot (docs/BENCHMARKS.md, "Scene edits").
#include <tbb/global_control.h>
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_options.h"
#include "bench_util.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;
using namespace std::chrono_literals;

namespace {

using irradcast::bench::Clock;
using irradcast::bench::seconds_since;

// Mean luminance of every 32 x 32 tile of every lightmap (the unit the server streams): per
// texel, Monte Carlo noise would swamp a local change.
std::vector<float> luminances(const std::vector<Lightmap>& maps) {
  constexpr int kTile = 32;
  std::vector<float> out;
  for (const Lightmap& m : maps)
    for (int ty = 0; ty < m.height; ty += kTile)
      for (int tx = 0; tx < m.width; tx += kTile) {
        double sum = 0.0;
        int n = 0;
        for (int y = ty; y < std::min(ty + kTile, m.height); ++y)
          for (int x = tx; x < std::min(tx + kTile, m.width); ++x) {
            sum += luminance(m.texels[static_cast<std::size_t>(y) * m.width + x]);
            ++n;
          }
        out.push_back(static_cast<float>(sum / std::max(n, 1)));
      }
  return out;
}

// RMS difference over the texels of `mask`.
double rms_difference(const std::vector<float>& a, const std::vector<float>& b,
                      const std::vector<std::uint8_t>& mask) {
  double d2 = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!mask[i]) continue;
    d2 += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
    ++n;
  }
  return std::sqrt(d2 / static_cast<double>(std::max<std::size_t>(n, 1)));
}

// The tiles the edit changes: their mean by more than 5 % between `before` and a converged
// bake of the edited scene (and by more than 0.5 % of the scene's mean level). Unchanged tiles
// only carry noise, which would swamp a local change in an RMS over the whole scene.
std::vector<std::uint8_t> changed_texels(const std::vector<float>& before,
                                         const std::vector<float>& after) {
  double mean = 0.0;
  for (float v : before) mean += v;
  mean /= static_cast<double>(std::max<std::size_t>(before.size(), 1));
  std::vector<std::uint8_t> mask(before.size(), 0);
  for (std::size_t i = 0; i < before.size(); ++i)
    mask[i] = std::abs(double(after[i]) - before[i]) >
              0.05 * std::max(static_cast<double>(before[i]), 0.1 * mean);
  return mask;
}

struct Sample {
  double t = 0.0;  // seconds since the edit
  std::vector<float> lum;
};

struct Curve {
  std::vector<double> t, progress;
  double first_tile = -1.0;  // seconds to the first updated tile
  double t90 = -1.0, t99 = -1.0;
  double total = 0.0;  // seconds until idle again
};

// Progress of every sample towards the last one, and the first times it stays above a level.
Curve progress_curve(const std::vector<float>& before, const std::vector<Sample>& samples,
                     const std::vector<std::uint8_t>& mask) {
  Curve c;
  if (samples.empty()) return c;
  const std::vector<float>& final_lum = samples.back().lum;
  const double change = std::max(rms_difference(before, final_lum, mask), 1e-12);
  for (const Sample& s : samples) {
    c.t.push_back(s.t);
    c.progress.push_back(1.0 - rms_difference(s.lum, final_lum, mask) / change);
  }
  c.first_tile = samples.front().t;
  c.total = samples.back().t;
  auto reached = [&](double level) {
    for (std::size_t i = c.progress.size(); i-- > 0;)
      if (c.progress[i] < level) return i + 1 < c.t.size() ? c.t[i + 1] : c.t.back();
    return c.t.front();
  };
  c.t90 = reached(0.9);
  c.t99 = reached(0.99);
  return c;
}

struct EditCase {
  std::string scene, kind, json;
};

// The first lit room's light and its first furniture piece: what to move in rooms:N.
std::pair<std::string, std::string> rooms_targets(const Scene& s) {
  std::string light;
  for (const Node& n : s.nodes)
    if (n.mesh >= 0 && n.name.rfind("light_", 0) == 0) {
      light = n.name;
      break;
    }
  if (light.empty()) throw Error("rooms scene without a light");
  const std::string room = "room_" + light.substr(6) + "_";
  for (const Node& n : s.nodes)
    if (n.mesh >= 0 && n.name.rfind(room, 0) == 0 && n.name != room + "walls" &&
        n.name != room + "floor" && n.name != room + "ceiling")
      return {light, n.name};
  throw Error("rooms scene without furniture in " + room);
}

std::vector<EditCase> default_cases(const std::vector<std::string>& scenes) {
  std::vector<EditCase> out;
  for (const std::string& s : scenes) {
    if (s == "cornell") {
      out.push_back(
          {s, "light move", R"({"op": "move", "node": "light", "by": [0.1, -0.05, 0.08]})"});
      out.push_back(
          {s, "object move", R"({"op": "move", "node": "tall_block", "by": [-0.1, 0, -0.12]})"});
    } else {
      const auto [light, object] = rooms_targets(load_scene(s, 1.0f));
      out.push_back({s, "light move",
                     R"({"op": "move", "node": ")" + light + R"(", "by": [0.8, -0.3, 0.6]})"});
      out.push_back({s, "object move",
                     R"({"op": "move", "node": ")" + object + R"(", "by": [-0.3, 0, 0.3]})"});
    }
  }
  return out;
}

// The price of editability: closest-hit rays (cosine-distributed from random surface points) on
// the static single-level BVH and on the server's editable two-level one, over the same world,
// interleaved in rounds. Returns seconds per million rays, {static, editable}.
std::pair<double, double> trace_cost(const Scene& scene) {
  const World world = World::build(scene);
  const RayScene fixed(world, false), editable(world, true);
  Rng rng(7);
  std::vector<Ray> rays;
  for (int i = 0; i < 200000; ++i) {
    const WorldObject& o =
        world.objects[static_cast<std::size_t>(rng.next_u32() % world.objects.size())];
    const auto t = static_cast<std::uint32_t>(rng.next_u32() % o.triangles().size());
    float u = rng.next_float(), v = rng.next_float();
    if (u + v > 1.0f) {
      u = 1.0f - u;
      v = 1.0f - v;
    }
    const glm::vec3 n = o.geometric_normal(t);
    Ray r;
    r.direction =
        Frame(n).to_world(cosine_hemisphere(glm::vec2(rng.next_float(), rng.next_float())));
    r.origin = fixed.offset(o.position(t, u, v), n, r.direction);
    rays.push_back(r);
  }
  double seconds[2] = {0.0, 0.0};
  std::uint64_t sink = 0;
  for (int round = 0; round < 6; ++round)
    for (int k = 0; k < 2; ++k) {
      const RayScene& rs = k == 0 ? fixed : editable;
      const Clock::time_point t0 = Clock::now();
      std::atomic<std::uint64_t> hits{0};
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 1024),
                        [&](const tbb::blocked_range<std::size_t>& b) {
                          std::uint64_t h = 0;
                          for (std::size_t i = b.begin(); i < b.end(); ++i)
                            h += rs.intersect(rays[i]).valid();
                          hits += h;
                        });
      if (round > 0) seconds[k] += seconds_since(t0);  // round 0 warms up
      sink += hits;
    }
  if (sink == 0) std::fprintf(stderr, "no ray hit anything\n");
  const double per_million = 5.0 * static_cast<double>(rays.size()) / 1e6;
  return {seconds[0] / per_million, seconds[1] / per_million};
}

struct Result {
  EditCase c;
  Curve edit, edit_no_blend, scratch;
  double apply_ms = 0.0;
  std::size_t texels = 0;
  double changed = 0.0;  // fraction of the tiles the edit changes (see changed_texels)
};

// The edit path: a server on the scene with the given options, a viewer holding every tile;
// returns the viewer's tile means before the edit and as tiles arrive after it.
struct EditRun {
  std::vector<float> before;
  std::vector<Sample> samples;
  double apply_ms = 0.0;
  std::size_t texels = 0;
};

EditRun run_edit(const Scene& scene, const EditCase& ec, const SceneEdit& edit,
                 const EngineHostOptions& options) {
  EditRun run;
  EngineHost host(scene, ec.scene, options);
  run.texels = host.stats().texels;
  ServerOptions so;
  so.bind = "127.0.0.1";
  so.port = 0;
  Server server(host, so);
  server.start();
  host.start();
  ViewClientOptions vo;
  vo.port = server.port();
  vo.name = "bench-edit";
  ViewClient client(vo);
  client.connect();
  // The viewer looks through the scene's camera: its tiles come first after the edit.
  client.send_camera(camera_pose(scene, scene.first_camera_node()));
  std::fprintf(stderr, "  %s / %s (edit blend %.1f): converging before the edit ...\n",
               ec.scene.c_str(), ec.kind.c_str(), options.engine.edit_blend);
  for (;;) {
    client.poll(50ms);
    if (!host.stats().idle || !client.all_tiles_received()) continue;
    auto s = client.request_stats(5s);
    if (s && s->engine_idle() && s->queue_depth() == 0) break;
  }
  client.poll(100ms);
  run.before = luminances(client.lightmaps());
  const Clock::time_point t0 = Clock::now();
  host.submit_edit(edit);
  auto last_check = Clock::now();
  for (;;) {
    if (client.poll(20ms) > 0)
      run.samples.push_back({seconds_since(t0), luminances(client.lightmaps())});
    if (Clock::now() - last_check < 200ms) continue;
    last_check = Clock::now();
    if (host.revision() < 1 || !host.stats().idle) continue;
    auto s = client.request_stats(5s);
    if (s && s->engine_idle() && s->queue_depth() == 0) {
      if (client.poll(50ms) > 0)
        run.samples.push_back({seconds_since(t0), luminances(client.lightmaps())});
      break;
    }
  }
  run.apply_ms = host.stats().last_edit_ms;
  client.close();
  host.stop();
  server.stop();
  if (run.samples.empty()) throw Error(ec.scene + ": no tiles after the edit");
  return run;
}

Result run_case(const EditCase& ec, const EngineHostOptions& options) {
  Result r;
  r.c = ec;
  const SceneEdit edit = parse_edit_json(ec.json);
  const Scene scene = load_scene(ec.scene, 1.0f);
  Scene edited = scene;
  apply_edit(edited, edit);
  {
    // Texel by texel comparisons need the same atlas and probe grid: the bounds must not move.
    const Bounds a = World::build(scene).bounds, b = World::build(edited).bounds;
    if (a.lo != b.lo || a.hi != b.hi)
      throw Error(ec.scene + " / " + ec.kind +
                  ": the edit changes the scene's bounds; pick one "
                  "that stays inside");
  }
  const EditRun blended = run_edit(scene, ec, edit, options);
  EngineHostOptions no_blend = options;
  no_blend.engine.edit_blend = 0.0f;
  const EditRun direct = run_edit(scene, ec, edit, no_blend);
  r.apply_ms = blended.apply_ms;
  r.texels = blended.texels;

  // From scratch: a new host on the edited scene (set-up plus updates).
  std::fprintf(stderr, "  %s / %s: from scratch ...\n", ec.scene.c_str(), ec.kind.c_str());
  std::vector<Sample> scratch;
  const Clock::time_point t1 = Clock::now();
  EngineHost fresh(edited, ec.scene, options);
  while (!fresh.stats().idle) {
    fresh.step();
    scratch.push_back({seconds_since(t1), luminances(fresh.tiles().published())});
  }
  const std::vector<std::uint8_t> mask = changed_texels(blended.before, scratch.back().lum);
  r.changed = static_cast<double>(std::count(mask.begin(), mask.end(), 1)) /
              static_cast<double>(std::max<std::size_t>(mask.size(), 1));
  r.edit = progress_curve(blended.before, blended.samples, mask);
  r.edit_no_blend = progress_curve(direct.before, direct.samples, mask);
  r.scratch = progress_curve(blended.before, scratch, mask);
  return r;
}

// Progress curves from the JSON this tool writes (also --replot).
void write_plot(const std::string& path, const json& edits) {
  plot::XYPlot p;
  p.title = "Scene edits: progress after an edit";
  p.x_label = "seconds since the edit";
  p.y_label = "progress (1 = final)";
  p.note = "thick: incremental, at a viewer; thin: from scratch, at the tile store";
  p.legend = plot::XYPlot::Legend::BottomRight;
  const plot::Color colors[] = {plot::kBlue, plot::kOrange, plot::kGreen, plot::kRed,
                                plot::kDarkGrey};
  auto clamped = [](const json& v) {
    std::vector<double> out = v.get<std::vector<double>>();
    for (double& x : out) x = std::clamp(x, -0.2, 1.0);
    return out;
  };
  for (std::size_t i = 0; i < edits.size(); ++i) {
    const json& e = edits[i];
    plot::Series a;
    a.label = e["scene"].get<std::string>() + " " + e["edit"].get<std::string>();
    a.x = e["incremental"]["t"].get<std::vector<double>>();
    a.y = clamped(e["incremental"]["progress"]);
    a.color = colors[i % 5];
    a.points = false;
    a.lines = true;
    a.line_width = 2.5;
    p.series.push_back(a);
    plot::Series b = a;
    b.label.clear();
    b.x = e["scratch"]["t"].get<std::vector<double>>();
    b.y = clamped(e["scratch"]["progress"]);
    b.line_width = 1.0;
    p.series.push_back(b);
  }
  p.y_from_zero = false;
  p.x_log = true;
  write_xy_plot(path, p);
}

// Prints the table of every edit and returns their JSON.
json report_edits(const std::vector<Result>& results) {
  std::printf("\n%-8s %-11s %7s %7s %8s | %8s %6s %6s | %6s %6s | %8s %6s %6s | %5s %5s %5s\n",
              "scene", "edit", "texels", "changed", "apply ms", "1st tile", "90%", "99%", "90% nb",
              "99% nb", "scratch", "90%", "99%", "x 1st", "x 90", "x 99");
  json j = json::array();
  for (const Result& r : results) {
    const double x90 = r.scratch.t90 / std::max(r.edit.t90, 1e-9);
    const double x99 = r.scratch.t99 / std::max(r.edit.t99, 1e-9);
    const double x1 = r.scratch.first_tile / std::max(r.edit.first_tile, 1e-9);
    std::printf(
        "%-8s %-11s %7zu %6.1f%% %8.0f | %8.3f %6.2f %6.2f | %6.2f %6.2f | %8.3f %6.2f %6.2f | "
        "%5.2f %5.2f %5.2f\n",
        r.c.scene.c_str(), r.c.kind.c_str(), r.texels, 100.0 * r.changed, r.apply_ms,
        r.edit.first_tile, r.edit.t90, r.edit.t99, r.edit_no_blend.t90, r.edit_no_blend.t99,
        r.scratch.first_tile, r.scratch.t90, r.scratch.t99, x1, x90, x99);
    json e;
    e["scene"] = r.c.scene;
    e["edit"] = r.c.kind;
    e["edit_json"] = r.c.json;
    e["texels"] = r.texels;
    e["apply_ms"] = r.apply_ms;
    for (const auto& [name, curve] : {std::pair<const char*, const Curve*>{"incremental", &r.edit},
                                      {"incremental_no_blend", &r.edit_no_blend},
                                      {"scratch", &r.scratch}}) {
      e[name]["first_tile_s"] = curve->first_tile;
      e[name]["t90_s"] = curve->t90;
      e[name]["t99_s"] = curve->t99;
      e[name]["total_s"] = curve->total;
      e[name]["t"] = curve->t;
      e[name]["progress"] = curve->progress;
    }
    e["changed_fraction"] = r.changed;
    e["speedup_first_tile"] = x1;
    e["speedup_90"] = x90;
    e["speedup_99"] = x99;
    j.push_back(e);
  }
  return j;
}

// Prints the trace cost of the editable BVH per scene and returns its JSON.
json report_trace_cost(const std::vector<std::string>& scenes) {
  std::printf("\nTrace cost of the editable (two-level) BVH, closest-hit rays, interleaved:\n");
  json trace = json::array();
  for (const std::string& name : scenes) {
    const auto [fixed, editable] = trace_cost(load_scene(name, 1.0f));
    std::printf("%-10s static %.3f s / M rays, editable %.3f s / M rays: %.2fx\n", name.c_str(),
                fixed, editable, editable / fixed);
    trace.push_back({{"scene", name},
                     {"static_s_per_mray", fixed},
                     {"editable_s_per_mray", editable},
                     {"ratio", editable / fixed}});
  }
  return trace;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "irradcast-bench-edit: time from a scene edit to the updated lightmaps at a viewer, "
      "against recomputing from scratch"};
  std::string scenes_arg = "cornell,rooms:2";
  std::string out_dir = "out/edit";
  std::uint32_t updates = 24;
  float density = 0.0f;
  int threads = 0;
  bool verbose = false;
  std::string replot;
  app.add_option("--scenes", scenes_arg, "comma-separated built-in scenes")->capture_default_str();
  app.add_option("--updates", updates, "engine updates to converge (max_updates)")
      ->capture_default_str();
  irradcast::bench::add_texels_per_scene(app, density, "0: the default");
  app.add_option("--threads", threads, "worker threads (0 = all cores)");
  app.add_flag("--verbose", verbose, "log the server's info lines (edit timings)");
  app.add_option("--replot", replot, "only redraw the plot from an edit.json this tool wrote");
  app.add_option("--out", out_dir, "output directory (JSON, PNG)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    bench::quiet_run(verbose);
    if (!replot.empty()) {
      std::ifstream in(replot);
      if (!in) throw Error("cannot read " + replot);
      fs::create_directories(out_dir);
      write_plot(out_dir + "/edit_progress.png", json::parse(in)["edits"]);
      std::printf("wrote %s/edit_progress.png\n", out_dir.c_str());
      return 0;
    }
    const auto limit = irradcast::bench::limit_threads(threads);
    const std::vector<std::string> scenes = irradcast::bench::split_list(scenes_arg);
    EngineHostOptions options;
    options.max_updates = updates;
    options.engine_nice = 0;
    if (density > 0.0f) options.atlas.texels_per_scene = density;
    fs::create_directories(out_dir);
    std::vector<Result> results;
    for (const EditCase& c : default_cases(scenes)) results.push_back(run_case(c, options));

    const json j = report_edits(results);
    const json trace = report_trace_cost(scenes);
    irradcast::bench::write_json(out_dir + "/edit.json", json{{"edits", j}, {"trace_cost", trace}},
                                 1);

    write_plot(out_dir + "/edit_progress.png", j);
    std::printf("\nwrote %s/edit.json and %s/edit_progress.png\n", out_dir.c_str(),
                out_dir.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-edit: %s\n", e.what());
    return 1;
  }
}

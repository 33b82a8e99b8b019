// irradcast-bench-edit: how fast a scene edit reaches a viewer. For each scene and edit (a light
// move and an object move by default): a server converges on the scene, a viewer holds every
// tile, the edit is submitted, and the viewer's lightmaps are recorded as tiles arrive until the
// server is idle again. Reports the time from the edit to (a) the first updated tile at the
// viewer, (b) 90 % and (c) 99 % of the final change reached (progress = 1 - RMS(now - final) /
// RMS(before - final), in luminance over every texel, from the first moment it stays above the
// level), and the same for recomputing from scratch (a new engine host on the edited scene:
// set-up plus updates, measured at its tile store, so without the network and the scene
// download a restarted server would also need). Writes JSON and a PNG plot
// (docs/BENCHMARKS.md, "Scene edits").
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/builtin.h"
#include "irradcast/engine_host.h"
#include "irradcast/error.h"
#include "irradcast/log.h"
#include "irradcast/net_server.h"
#include "irradcast/progress.h"
#include "irradcast/sampling.h"
#include "irradcast/scene_edit.h"
#include "irradcast/view_client.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;
using namespace std::chrono_literals;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::vector<float> luminances(const std::vector<Lightmap>& maps) {
  std::vector<float> out;
  for (const Lightmap& m : maps)
    for (const glm::vec3& t : m.texels) out.push_back(static_cast<float>(luminance(t)));
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

// The texels the edit changes: by more than 10 % between `before` and a converged bake of the
// edited scene (and more than 1 % of the mean level). Unchanged texels only carry noise, which
// would swamp a local change in an RMS over the whole scene.
std::vector<std::uint8_t> changed_texels(const std::vector<float>& before,
                                         const std::vector<float>& after) {
  double mean = 0.0;
  for (float v : before) mean += v;
  mean /= static_cast<double>(std::max<std::size_t>(before.size(), 1));
  std::vector<std::uint8_t> mask(before.size(), 0);
  for (std::size_t i = 0; i < before.size(); ++i)
    mask[i] = std::abs(double(after[i]) - before[i]) >
              0.1 * std::max(static_cast<double>(before[i]), 0.1 * mean);
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
                     R"({"op": "move", "node": ")" + object + R"(", "by": [0.6, 0, -0.5]})"});
    }
  }
  return out;
}

struct Result {
  EditCase c;
  Curve edit, scratch;
  double apply_ms = 0.0;
  std::size_t texels = 0;
  double changed = 0.0;  // fraction of the lightmap texels the edit changes (see changed_texels)
};

Result run_case(const EditCase& ec, const EngineHostOptions& options) {
  Result r;
  r.c = ec;
  const SceneEdit edit = parse_edit_json(ec.json);
  const Scene scene = load_scene(ec.scene, 1.0f);

  // The edit path: a server on the scene, a viewer holding every tile.
  {
    EngineHost host(scene, ec.scene, options);
    r.texels = host.stats().texels;
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
    std::fprintf(stderr, "  %s / %s: converging before the edit ...\n", ec.scene.c_str(),
                 ec.kind.c_str());
    for (;;) {
      client.poll(50ms);
      if (!host.stats().idle || !client.all_tiles_received()) continue;
      auto s = client.request_stats(5s);
      if (s && s->engine_idle() && s->queue_depth() == 0) break;
    }
    client.poll(100ms);
    const std::vector<float> before = luminances(client.lightmaps());
    std::vector<Sample> samples;
    const Clock::time_point t0 = Clock::now();
    host.submit_edit(edit);
    auto last_check = Clock::now();
    for (;;) {
      if (client.poll(20ms) > 0)
        samples.push_back({seconds_since(t0), luminances(client.lightmaps())});
      if (Clock::now() - last_check < 200ms) continue;
      last_check = Clock::now();
      if (host.revision() < 1 || !host.stats().idle) continue;
      auto s = client.request_stats(5s);
      if (s && s->engine_idle() && s->queue_depth() == 0) {
        if (client.poll(50ms) > 0)
          samples.push_back({seconds_since(t0), luminances(client.lightmaps())});
        break;
      }
    }
    r.apply_ms = host.stats().last_edit_ms;
    client.close();
    host.stop();
    server.stop();
    // From scratch, on the same machine after the edit path is done: the before state is the
    // same converged view.
    std::fprintf(stderr, "  %s / %s: from scratch ...\n", ec.scene.c_str(), ec.kind.c_str());
    Scene edited = scene;
    apply_edit(edited, edit);
    std::vector<Sample> scratch;
    const Clock::time_point t1 = Clock::now();
    EngineHost fresh(edited, ec.scene, options);
    while (!fresh.stats().idle) {
      fresh.step();
      scratch.push_back({seconds_since(t1), luminances(fresh.tiles().published())});
    }
    if (scratch.empty() || samples.empty()) throw Error(ec.scene + ": no tiles after the edit");
    const std::vector<std::uint8_t> mask = changed_texels(before, scratch.back().lum);
    r.changed = static_cast<double>(std::count(mask.begin(), mask.end(), 1)) /
                static_cast<double>(std::max<std::size_t>(mask.size(), 1));
    r.edit = progress_curve(before, samples, mask);
    r.scratch = progress_curve(before, scratch, mask);
  }
  return r;
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
  app.add_option("--scenes", scenes_arg, "comma-separated built-in scenes")->capture_default_str();
  app.add_option("--updates", updates, "engine updates to converge (max_updates)")
      ->capture_default_str();
  app.add_option("--density", density, "atlas texels per scene unit (0 = default)");
  app.add_option("--threads", threads, "worker threads (0 = all cores)");
  app.add_flag("--verbose", verbose, "log the server's info lines (edit timings)");
  app.add_option("--out", out_dir, "output directory (JSON, PNG)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    Progress::set_enabled(false);
    log::set_level(verbose ? log::Level::Info : log::Level::Warn);
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0)
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    threads);
    std::vector<std::string> scenes;
    {
      std::stringstream ss(scenes_arg);
      for (std::string s; std::getline(ss, s, ',');)
        if (!s.empty()) scenes.push_back(s);
    }
    EngineHostOptions options;
    options.max_updates = updates;
    options.engine_nice = 0;
    if (density > 0.0f) options.atlas.texels_per_scene = density;
    fs::create_directories(out_dir);
    std::vector<Result> results;
    for (const EditCase& c : default_cases(scenes)) results.push_back(run_case(c, options));

    std::printf("\n%-10s %-12s %8s %8s %9s %10s %8s %8s | %11s %8s %8s | %6s %6s %6s\n", "scene",
                "edit", "texels", "changed", "apply ms", "1st tile s", "90% s", "99% s",
                "scratch 1st", "90% s", "99% s", "x 1st", "x 90%", "x 99%");
    json j = json::array();
    for (const Result& r : results) {
      const double x90 = r.scratch.t90 / std::max(r.edit.t90, 1e-9);
      const double x99 = r.scratch.t99 / std::max(r.edit.t99, 1e-9);
      const double x1 = r.scratch.first_tile / std::max(r.edit.first_tile, 1e-9);
      std::printf(
          "%-10s %-12s %8zu %7.1f%% %9.1f %10.3f %8.3f %8.3f | %11.3f %8.3f %8.3f | %6.2f %6.2f "
          "%6.2f\n",
          r.c.scene.c_str(), r.c.kind.c_str(), r.texels, 100.0 * r.changed, r.apply_ms,
          r.edit.first_tile, r.edit.t90, r.edit.t99, r.scratch.first_tile, r.scratch.t90,
          r.scratch.t99, x1, x90, x99);
      json e;
      e["scene"] = r.c.scene;
      e["edit"] = r.c.kind;
      e["edit_json"] = r.c.json;
      e["texels"] = r.texels;
      e["apply_ms"] = r.apply_ms;
      for (const auto& [name, curve] :
           {std::pair<const char*, const Curve*>{"incremental", &r.edit},
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
    std::ofstream(out_dir + "/edit.json") << j.dump(1) << "\n";

    plot::XYPlot p;
    p.title = "Scene edits: progress towards the final lightmaps after an edit";
    p.x_label = "seconds since the edit";
    p.y_label = "progress (1 = final)";
    p.note = "solid: incremental (at a viewer); thin: recompute from scratch (at the tile store)";
    p.legend = plot::XYPlot::Legend::BottomRight;
    const plot::Color colors[] = {plot::kBlue, plot::kOrange, plot::kGreen, plot::kRed,
                                  plot::kDarkGrey};
    for (std::size_t i = 0; i < results.size(); ++i) {
      const Result& r = results[i];
      auto clamp01 = [](std::vector<double> v) {
        for (double& x : v) x = std::clamp(x, -0.2, 1.0);
        return v;
      };
      plot::Series a;
      a.label = r.c.scene + " " + r.c.kind;
      a.x = r.edit.t;
      a.y = clamp01(r.edit.progress);
      a.color = colors[i % 5];
      a.points = false;
      a.lines = true;
      a.line_width = 2.5;
      p.series.push_back(a);
      plot::Series b = a;
      b.label.clear();
      b.x = r.scratch.t;
      b.y = clamp01(r.scratch.progress);
      b.line_width = 1.0;
      p.series.push_back(b);
    }
    p.y_from_zero = false;
    p.x_log = true;
    write_xy_plot(out_dir + "/edit_progress.png", p);
    std::printf("\nwrote %s/edit.json and %s/edit_progress.png\n", out_dir.c_str(),
                out_dir.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-edit: %s\n", e.what());
    return 1;
  }
}

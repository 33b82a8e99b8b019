// irradcast-bench-crossover --join: how long a new viewer takes to get a converged first image.
// Per scene, on loopback in this process (the server's EngineHost and Server, the viewer's
// ViewClient, as irradcast-server and irradcast-view run them), looking through the scene's
// camera (view 1 of the cross-over) at --width x --height:
//  (a) converged server: the engine has run its --updates (then it is idle); a new viewer
//      connects, downloads the scene, receives every tile, composes its frame and writes it as
//      a PNG. Timed from connect() to the file written. Its error against the cross-over's
//      reference (same cache) is the converged level.
//  (b) fresh server: the viewer connects as soon as the server listens (its set-up is timed
//      apart) and composes a frame after each update's tiles have arrived; timed from connect()
//      until the frame's error is within 10 % of the converged level, and until it reaches it.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <thread>
#include <utility>

#include "bench_util.h"
#include "crossover.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/tonemap.h"
#include "irradcast/service/net_server.h"

namespace irradcast::bench {

namespace {

using namespace std::chrono_literals;

// An engine host and its server on a free loopback port, both running.
struct Served {
  EngineHost host;
  Server server;
  Served(const std::string& spec, const EngineHostOptions& options)
      : host(load_scene(spec), spec, options), server(host, server_options()) {
    server.start();
    host.start();
  }
  ~Served() {
    host.stop();
    server.stop();
  }
  static ServerOptions server_options() {
    ServerOptions so;
    so.bind = "127.0.0.1";
    so.port = 0;
    return so;
  }
  ViewClientOptions viewer(const std::string& name) const {
    ViewClientOptions vo;
    vo.port = server.port();
    vo.name = name;  // no cache_dir: a new viewer downloads the scene
    return vo;
  }
};

struct JoinPoint {
  double t = 0;  // seconds since connect() began, when the frame was composed
  std::uint64_t updates = 0;
  double err = 0;
};

struct JoinResult {
  std::string spec;
  double level = 0, ref_noise = 0;
  // (a)
  double connect_s = 0, tiles_s = 0, compose_s = 0, written_s = 0;
  std::uint64_t bytes = 0;  // what the viewer received: scene package and tiles
  // (b)
  double fresh_setup_s = 0, within10_s = kInf, level_s = kInf;
  std::vector<JoinPoint> curve;
};

// (a) A new viewer on a server whose engine has finished its updates. Returns the view and the
// reference (made while the engine is idle, from its world: the cross-over's cache key).
std::pair<CameraPose, Reference> join_converged(const std::string& spec, const Options& o,
                                                JoinResult& j) {
  EngineHostOptions options = o.engine;
  options.max_updates = static_cast<std::uint32_t>(o.updates);
  Served s(spec, options);
  s.host.wait_for_updates(options.max_updates);
  const std::vector<View> views = make_views(spec, s.host.scene(), s.host.world());
  const CameraPose pose = views[0].pose;
  Reference ref = view_reference(spec, o, s.host.world(), views, 0);
  std::fprintf(stderr, "[%s] join: server converged (%llu updates); a new viewer connects ...\n",
               spec.c_str(), static_cast<unsigned long long>(s.host.stats().updates));
  const Clock::time_point t0 = Clock::now();
  ViewClient c(s.viewer("bench-join-converged"));
  c.connect();
  j.connect_s = seconds_since(t0);
  while (!c.all_tiles_received()) c.poll(20ms);
  j.tiles_s = seconds_since(t0);
  const ImageRGB img = c.compose(pose, o.width, o.height);
  j.compose_s = seconds_since(t0);
  const std::string png = (fs::path(o.out) / ("join_" + file_key(spec) + ".png")).string();
  write_png(png, img.width, img.height, tonemap_srgb8(img, ToneMapOptions{}));
  j.written_s = seconds_since(t0);
  j.bytes = c.counters().bytes_received;
  j.level = error_of(img, ref).get(o.corrected);
  c.close();
  return {pose, std::move(ref)};
}

// (b) A new viewer on a fresh server, until its frame reaches the converged level.
void join_fresh(const std::string& spec, const Options& o, const CameraPose& pose,
                const Reference& ref, JoinResult& j) {
  EngineHostOptions options = o.engine;
  options.max_updates = static_cast<std::uint32_t>(o.updates);
  const Clock::time_point s0 = Clock::now();
  Served s(spec, options);
  j.fresh_setup_s = seconds_since(s0);
  const Clock::time_point t0 = Clock::now();
  ViewClient c(s.viewer("bench-join-fresh"));
  c.connect();
  bool pending = false;  // tiles arrived since the last frame
  for (;;) {
    if (c.poll(100ms) != 0) {
      pending = true;
      continue;
    }
    if (pending && c.all_tiles_received()) {  // a frame once the tiles stop (100 ms quiet)
      pending = false;
      const ImageRGB img = c.compose(pose, o.width, o.height);
      JoinPoint p{seconds_since(t0), s.host.stats().updates, error_of(img, ref).get(o.corrected)};
      j.curve.push_back(p);
      std::fprintf(stderr, "[%s] join, fresh server: %.1f s, update %llu, error %.4f\n",
                   spec.c_str(), p.t, static_cast<unsigned long long>(p.updates), p.err);
      if (p.err <= 1.1 * j.level) j.within10_s = std::min(j.within10_s, p.t);
      if (p.err <= 1.001 * j.level) {
        j.level_s = p.t;
        break;
      }
      continue;
    }
    if (!s.host.stats().idle) continue;
    const auto st = c.request_stats(5s);  // done: the engine idle and nothing left to send
    if (st && st->engine_idle() && st->queue_depth() == 0 && c.poll(100ms) == 0 && !pending) break;
  }
  c.close();
}

void plot_join(const JoinResult& j, const Options& o) {
  plot::XYPlot p;
  p.title = j.spec + ": a new viewer's error vs time";
  p.note = std::to_string(o.width) + "x" + std::to_string(o.height) +
           ", scene camera; error against the " + std::to_string(o.ref_spp) + " spp reference (" +
           (o.corrected ? "corrected" : "raw") + " relative RMSE)";
  p.x_label = "seconds since the viewer connected";
  p.y_label = "relative RMSE (log)";
  p.y_log = true;
  p.legend = plot::XYPlot::Legend::TopRight;
  plot::Series fresh, level, conv;
  fresh.label = "fresh server (set-up " + fmt("%.1f", j.fresh_setup_s) + " s before)";
  fresh.color = plot::kOrange;
  fresh.lines = true;
  for (const JoinPoint& q : j.curve) {
    fresh.x.push_back(q.t);
    fresh.y.push_back(q.err);
  }
  const double xhi = fresh.x.empty() ? j.written_s : std::max(fresh.x.back(), j.written_s);
  level.label = "converged level " + fmt("%.4f", j.level);
  level.color = plot::kDarkGrey;
  level.lines = true;
  level.points = false;
  level.line_width = 1.0;
  level.x = {0.0, xhi};
  level.y = {j.level, j.level};
  conv.label = "converged server: image written at " + fmt("%.2f", j.written_s) + " s";
  conv.color = plot::kBlue;
  conv.x = {j.written_s};
  conv.y = {j.level};
  p.series = {fresh, level, conv};
  const std::string png =
      (fs::path(o.out) / ("crossover_join_" + file_key(j.spec) + ".png")).string();
  plot::write_xy_plot(png, p);
  std::printf("wrote %s\n", png.c_str());
}

json join_json(const JoinResult& j) {
  json curve = json::array();
  for (const JoinPoint& q : j.curve)
    curve.push_back({{"t_s", q.t}, {"updates", q.updates}, {"err", q.err}});
  auto num = [](double v) { return v < kInf ? json(v) : json(nullptr); };
  return {{"scene", j.spec},
          {"converged_level", j.level},
          {"reference_rel_noise", j.ref_noise},
          {"converged_server",
           {{"connect_s", j.connect_s},
            {"all_tiles_s", j.tiles_s},
            {"composed_s", j.compose_s},
            {"image_written_s", j.written_s},
            {"bytes_received", j.bytes}}},
          {"fresh_server",
           {{"server_setup_s", j.fresh_setup_s},
            {"within_10pct_of_level_s", num(j.within10_s)},
            {"at_level_s", num(j.level_s)},
            {"curve", curve}}}};
}

}  // namespace

json run_join(const std::vector<std::string>& scenes, const Options& o) {
  json out = json::array();
  std::printf(
      "\nA new viewer's first converged image (wall seconds from connect(); %dx%d, scene "
      "camera)\n%-8s | %8s %8s %8s %8s | %9s | %8s %9s %9s\n",
      o.width, o.height, "scene", "connect", "tiles", "compose", "written", "level", "setup",
      "fresh 10%", "fresh lvl");
  for (const std::string& spec : scenes) {
    JoinResult j;
    j.spec = spec;
    const auto [pose, ref] = join_converged(spec, o, j);
    j.ref_noise = ref.rel_noise();
    join_fresh(spec, o, pose, ref, j);
    std::printf("%-8s | %8.2f %8.2f %8.2f %8.2f | %9.4f | %8.2f %9s %9s\n", spec.c_str(),
                j.connect_s, j.tiles_s, j.compose_s, j.written_s, j.level, j.fresh_setup_s,
                j.within10_s < kInf ? fmt("%.1f", j.within10_s).c_str() : "never",
                j.level_s < kInf ? fmt("%.1f", j.level_s).c_str() : "never");
    plot_join(j, o);
    out.push_back(join_json(j));
  }
  return out;
}

}  // namespace irradcast::bench

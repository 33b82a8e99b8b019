// irradcast-bench-fanout: one irradcast-server, more and more simulated thin users.
//
// Starts irradcast-server as a child process on a free loopback port, lets its engine refine
// for a number of updates (a server that has been up a while: the service's steady state), then
// for each user count N runs irradcast-load's users (in this process, thin mode) for long enough
// that every user downloads the scene and all tiles and then follows the refinement for a
// measuring window. Per N it records:
//   - tile latency (server version time stamp -> user's apply) of the tiles applied once every
//     user has its first full image (steady state) and of every live tile, p50/p95/p99;
//   - the server's CPU, from /proc/PID/task/*/stat: its network threads ("irradcast-io") apart
//     from the engine (its thread and the TBB workers), in cores;
//   - this process's CPU (the simulated users) in cores;
//   - bytes to the first full image per user and steady-state bytes/s per user.
// Prints a table, writes JSON and two PNG plots (see docs/BENCHMARKS.md).
// With --gateways 0,1,2,4 it measures the users spread over irradcast-gateways fed through NATS
// instead (bench/fanout/gateways.cpp); bench/fanout/fanout_common.cpp holds what both modes share.
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "fanout_common.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;
using namespace irradcast::fanout;
using Clock = std::chrono::steady_clock;

namespace {

struct Point {
  int users = 0;
  LoadReport report;
  double seconds = 0.0;
  double io_cores = 0.0, engine_cores = 0.0, load_cores = 0.0;
  std::uint64_t updates = 0;
};

// One run of n users: latency and the CPU of the server's threads and of the load generator.
Point run_users(const Options& o, std::uint16_t port, const Child& server, int n) {
  Point p;
  p.users = n;
  const ThreadCpu c0 = thread_cpu(server.pid());
  const double self0 = self_cpu();
  const auto t0 = Clock::now();
  p.report = run_thin_users(o, {{"127.0.0.1", port}}, n);
  p.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  const ThreadCpu c1 = thread_cpu(server.pid());
  p.io_cores = (c1.io - c0.io) / p.seconds;
  p.engine_cores = (c1.rest - c0.rest) / p.seconds;
  p.load_cores = (self_cpu() - self0) / p.seconds;
  const LoadReport& r = p.report;
  std::printf(
      "%4d users: %d/%d ok, steady latency p50 %s p99 %s ms (%zu tiles), all live p99 %s ms, "
      "full image p99 %s ms, %.1f kB to full image, %.1f kB/s steady; server io %.2f + "
      "engine %.2f cores, users %.2f cores\n",
      n, r.connected - r.failed, n, ms(r.steady_tile_latency_ms.p50).c_str(),
      ms(r.steady_tile_latency_ms.p99).c_str(), r.steady_tile_latency_ms.count,
      ms(r.tile_latency_ms.p99).c_str(), ms(r.full_image_ms.p99).c_str(),
      r.bytes_to_full_image.mean / 1e3, r.steady_bytes_per_s.mean / 1e3, p.io_cores, p.engine_cores,
      p.load_cores);
  std::fflush(stdout);
  return p;
}

// OUT/fanout.json.
fs::path write_report(const Options& o, const std::vector<Point>& points) {
  json j = report_header(o);
  for (const Point& p : points) {
    json pj = json::parse(p.report.json(false));
    pj["server_io_cores"] = p.io_cores;
    pj["server_engine_cores"] = p.engine_cores;
    pj["load_generator_cores"] = p.load_cores;
    pj["seconds"] = p.seconds;
    j["runs"].push_back(pj);
  }
  const fs::path json_path = fs::path(o.out) / "fanout.json";
  std::ofstream(json_path) << j.dump(2) << "\n";

  return json_path;
}

// OUT/fanout_latency.png: steady-state tile latency against users.
void plot_latency(const Options& o, const std::vector<Point>& points) {
  plot::XYPlot lat;
  lat.title = "Tile latency vs thin users (" + o.scene + ", " +
              std::to_string(std::thread::hardware_concurrency()) + " cores)";
  lat.x_label = "simulated thin users";
  lat.y_label = "tile latency, ms (server version -> user's apply)";
  lat.x_log = true;
  lat.y_log = true;
  lat.note = "steady state: tiles applied once every user had its first full image";
  plot::Series p50 = series("p50", plot::kBlue, true);
  plot::Series p99 = series("p99", plot::kRed, true);
  plot::Series goal = series("goal: p99 < 100 ms", plot::kDarkGrey, false);
  for (const Point& p : points) {
    if (p.report.steady_tile_latency_ms.count == 0) continue;
    p50.x.push_back(p.users);
    p50.y.push_back(std::max(0.01, p.report.steady_tile_latency_ms.p50));
    p99.x.push_back(p.users);
    p99.y.push_back(std::max(0.01, p.report.steady_tile_latency_ms.p99));
  }
  if (!points.empty()) {
    goal.x = {static_cast<double>(points.front().users), static_cast<double>(points.back().users)};
    goal.y = {100.0, 100.0};
  }
  lat.series = {p50, p99, goal};
  plot::write_xy_plot((fs::path(o.out) / "fanout_latency.png").string(), lat);
}

// OUT/fanout_cpu.png: server and load-generator CPU against users.
void plot_cpu(const Options& o, const std::vector<Point>& points) {
  plot::XYPlot cpu;
  cpu.title = "Server CPU vs thin users (" + o.scene + ")";
  cpu.x_label = "simulated thin users";
  cpu.y_label = "CPU, cores";
  cpu.x_log = true;
  cpu.note = "the engine refines with what the network threads leave (nice 10)";
  plot::Series io = series("server network threads", plot::kBlue, true);
  plot::Series eng = series("server engine", plot::kGreen, true);
  plot::Series users = series("simulated users (load generator)", plot::kOrange, true);
  for (const Point& p : points) {
    io.x.push_back(p.users);
    io.y.push_back(p.io_cores);
    eng.x.push_back(p.users);
    eng.y.push_back(p.engine_cores);
    users.x.push_back(p.users);
    users.y.push_back(p.load_cores);
  }
  cpu.series = {io, eng, users};
  cpu.legend = plot::XYPlot::Legend::TopLeft;
  cpu.y_headroom = 0.25;
  plot::write_xy_plot((fs::path(o.out) / "fanout_cpu.png").string(), cpu);
}

// The users of one server, row by row (--users), after the engine's warm-up.
void run_users_bench(const Options& o) {
  const std::uint16_t port = free_port();
  Child server(server_command(o, port), fs::path(o.out) / "fanout_server.log");
  std::printf("irradcast-bench-fanout: %s on port %u (pid %d), %u cores\n", o.scene.c_str(), port,
              server.pid(), std::thread::hardware_concurrency());

  warm_up(o, port, server);
  std::vector<Point> points;
  for (int n : o.users) {
    points.push_back(run_users(o, port, server, n));
    std::this_thread::sleep_for(std::chrono::seconds(2));  // let the sessions close
  }
  const fs::path json_path = write_report(o, points);
  plot_latency(o, points);
  plot_cpu(o, points);
  std::printf("wrote %s, fanout_latency.png, fanout_cpu.png\n", json_path.string().c_str());
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  std::string users_list, gateways_list;
  CLI::App app{
      "irradcast-bench-fanout: tile latency and server CPU against the number of thin "
      "users of one irradcast-server (see docs/BENCHMARKS.md)",
      "irradcast-bench-fanout"};
  app.option_defaults()->always_capture_default();
  app.add_option("--server", o.server, "irradcast-server binary");
  app.add_option("--scene", o.scene, "scene of the server");
  app.add_option("--users", users_list, "comma-separated user counts (default 1,2,...,512)");
  app.add_option("--warmup-updates", o.warmup_updates, "engine updates before the first run");
  app.add_option("--window", o.window_s, "seconds measured after the users are in sync");
  app.add_option("--sync-per-user", o.sync_s_per_user,
                 "seconds allowed per user for the scene and the first full image");
  app.add_option("--out", o.out, "directory for the JSON and PNG results");
  app.add_option("--server-arg", o.server_args, "extra argument for irradcast-server (repeat)");
  app.add_option("--gateways", gateways_list,
                 "comma-separated gateway counts (0 = users of the origin itself): starts "
                 "nats-server, an origin with --nats and irradcast-gateways, and spreads the "
                 "users over them (default users: 1024)");
  app.add_option("--gateway", o.gateway, "irradcast-gateway binary");
  app.add_flag("--presence", o.presence,
               "the servers run with --presence and every user shows itself as an avatar (the "
               "rows add the avatars each user gets)");
  app.add_option("--nats-server", o.nats_server,
                 "nats-server binary (default: found in PATH dirs)");
  app.add_flag("--quick", o.quick, "1, 4 and 16 users, short windows (a smoke run)");
  bool fresh = false;
  FreshOptions fo;
  app.add_flag("--fresh", fresh,
               "issue 22 part 5: --users N (default 128) thin users join a fresh server at once "
               "for --duration s; per --compare server, users decoding each tile or sharing "
               "decodes; writes fanout_fresh.json and .png");
  app.add_option("--duration", fo.duration_s, "--fresh: seconds of each run");
  app.add_option("--repeat", fo.repeat,
                 "--fresh: interleaved runs per variant (the median p99 is kept)");
  app.add_option("--pin-load", fo.pin_load, "--fresh: CPU for the simulated users (-1: all)");
  app.add_option("--compare", fo.compare, "--fresh: LABEL=SERVER_PATH (repeat; default: --server)");
  CLI11_PARSE(app, argc, argv);
  log::set_level(log::Level::Warn);
  try {
    if (!gateways_list.empty()) {
      o.gateways = irradcast::bench::parse_ints(gateways_list);
      if (users_list.empty()) o.users = {1024};
    }
    if (!users_list.empty()) {
      o.users = irradcast::bench::parse_ints(users_list);
    }
    if (o.quick) {
      o.users = {1, 4, 16};
      o.warmup_updates = std::min(o.warmup_updates, 4);
      o.window_s = 4.0;
    }
    fs::create_directories(o.out);
    if (fresh) {
      if (!users_list.empty()) fo.users = o.users.front();
      run_fresh_bench(o, fo);
      return 0;
    }
    if (!o.gateways.empty()) {
      run_gateway_bench(o);
      return 0;
    }
    run_users_bench(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-fanout: error: %s\n", e.what());
    return 1;
  }
  return 0;
}

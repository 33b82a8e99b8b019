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
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <asio.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;
using Clock = std::chrono::steady_clock;

extern char** environ;

namespace {

struct Options {
  std::string server = IRRADCAST_SERVER_EXE;
  std::string scene = "cornell";
  std::vector<int> users = {1, 2, 4, 8, 16, 32, 64, 128, 256, 512};
  int warmup_updates = 24;
  double window_s = 10.0;  // measuring time after the last user's expected full image
  double sync_s_per_user = 0.04;
  std::string out = "docs/images";
  std::vector<std::string> server_args;
  bool quick = false;
};

struct CpuTimes {
  double io = 0.0, engine = 0.0;  // seconds
};

// CPU seconds of a process's threads, by thread name.
CpuTimes process_cpu(pid_t pid) {
  CpuTimes t;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/proc/" + std::to_string(pid) + "/task", ec)) {
    std::ifstream f(e.path() / "stat");
    std::string line;
    if (!std::getline(f, line)) continue;
    const auto open = line.find('('), close = line.rfind(')');
    if (open == std::string::npos || close == std::string::npos) continue;
    const std::string comm = line.substr(open + 1, close - open - 1);
    std::istringstream rest(line.substr(close + 2));
    std::string field;
    std::vector<std::string> fields;
    while (rest >> field) fields.push_back(field);
    if (fields.size() < 13) continue;
    // Fields after the name start at 3 (state); utime and stime are 14 and 15.
    const double cpu = (std::stod(fields[11]) + std::stod(fields[12])) / tick;
    (comm == "irradcast-io" ? t.io : t.engine) += cpu;
  }
  return t;
}

double self_cpu() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

std::uint16_t free_port() {
  asio::io_context io;
  asio::ip::tcp::acceptor a(io, asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  return a.local_endpoint().port();
}

class ServerProcess {
 public:
  ServerProcess(const Options& o, std::uint16_t port, const fs::path& log) {
    std::vector<std::string> args = {o.server, "--scene", o.scene, "--bind", "127.0.0.1", "--port",
                                     std::to_string(port), "--status-every", "5", "--idle-timeout",
                                     "120",
                                     // every simulated user comes from 127.0.0.1
                                     "--max-clients-per-peer", "0"};
    args.insert(args.end(), o.server_args.begin(), o.server_args.end());
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    const int rc = posix_spawn(&pid_, o.server.c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw Error("cannot start " + o.server + ": " + std::strerror(rc));
  }
  ~ServerProcess() {
    if (pid_ <= 0) return;
    kill(pid_, SIGINT);
    int status = 0;
    waitpid(pid_, &status, 0);
  }
  pid_t pid() const { return pid_; }
  bool alive() const {
    int status = 0;
    return waitpid(pid_, &status, WNOHANG) == 0;
  }

 private:
  pid_t pid_ = -1;
};

struct Point {
  int users = 0;
  LoadReport report;
  double seconds = 0.0;
  double io_cores = 0.0, engine_cores = 0.0, load_cores = 0.0;
  std::uint64_t updates = 0;
};

plot::Series series(const std::string& label, plot::Color color, bool points) {
  plot::Series s;
  s.label = label;
  s.color = color;
  s.points = points;
  s.lines = true;
  return s;
}

std::string ms(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", v);
  return b;
}

// Warm-up: let the engine refine as a server that has been up a while would have.
void warm_up(const Options& o, std::uint16_t port, const ServerProcess& server) {
  ViewClientOptions vo;
  vo.port = port;
  vo.name = "bench-warmup";
  vo.connect_timeout = std::chrono::milliseconds(60000);
  auto updates_now = [&]() -> std::uint64_t {
    ViewClient c(vo);
    c.connect();
    auto s = c.request_stats(std::chrono::milliseconds(10000));
    c.close();
    return s ? s->updates() : 0;
  };
  const auto warm_start = Clock::now();
  for (;;) {
    if (!server.alive()) throw Error("irradcast-server exited; see its log in " + o.out);
    const std::uint64_t u = updates_now();
    std::fprintf(stderr, "[fanout] warm-up: %llu/%d engine updates, %.0f s\n",
                 static_cast<unsigned long long>(u), o.warmup_updates,
                 std::chrono::duration<double>(Clock::now() - warm_start).count());
    if (u >= static_cast<std::uint64_t>(o.warmup_updates)) break;
    std::this_thread::sleep_for(std::chrono::seconds(5));
  }
}

// One run of n users: latency and the CPU of the server's threads and of the load generator.
Point run_users(const Options& o, std::uint16_t port, const ServerProcess& server, int n) {
  Point p;
  p.users = n;
  LoadOptions lo;
  lo.port = port;
  lo.users = n;
  lo.ramp_s = std::min(2.0, 0.01 * n);
  lo.duration_s = 3.0 + lo.ramp_s + o.sync_s_per_user * n + o.window_s;
  lo.camera_hz = 5.0;
  lo.threads = 0;
  lo.name = "fanout";
  const CpuTimes c0 = process_cpu(server.pid());
  const double self0 = self_cpu();
  const auto t0 = Clock::now();
  p.report = run_load(lo, [&](const LoadProgress& pr) {
    if (static_cast<int>(pr.elapsed_s) % 5 == 0)
      std::fprintf(stderr, "[fanout] %d users: %.0f/%.0f s, %d full, %d failed, p99 %.1f ms\n", n,
                   pr.elapsed_s, lo.duration_s, pr.full_image, pr.failed, pr.latency_p99_ms);
  });
  p.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  const CpuTimes c1 = process_cpu(server.pid());
  p.io_cores = (c1.io - c0.io) / p.seconds;
  p.engine_cores = (c1.engine - c0.engine) / p.seconds;
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
  json j;
  j["scene"] = o.scene;
  j["cores"] = std::thread::hardware_concurrency();
  j["warmup_updates"] = o.warmup_updates;
  j["window_s"] = o.window_s;
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) > 0) j["load_average"] = {load[0], load[1], load[2]};
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

}  // namespace

int main(int argc, char** argv) {
  Options o;
  std::string users_list;
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
  app.add_flag("--quick", o.quick, "1, 4 and 16 users, short windows (a smoke run)");
  CLI11_PARSE(app, argc, argv);
  log::set_level(log::Level::Warn);
  try {
    if (!users_list.empty()) {
      o.users = irradcast::bench::parse_ints(users_list);
    }
    if (o.quick) {
      o.users = {1, 4, 16};
      o.warmup_updates = std::min(o.warmup_updates, 4);
      o.window_s = 4.0;
    }
    fs::create_directories(o.out);
    const std::uint16_t port = free_port();
    ServerProcess server(o, port, fs::path(o.out) / "fanout_server.log");
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
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-fanout: error: %s\n", e.what());
    return 1;
  }
  return 0;
}

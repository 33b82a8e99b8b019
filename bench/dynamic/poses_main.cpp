// irradcast-bench-poses: poses of dynamic nodes streamed through one irradcast-server to many thin
// viewers (issue 32 part 6, docs/BENCHMARKS.md "Dynamic objects"). One server child process on
// the Cornell box with --nodes dynamic spheres (a glTF written here), converged and idle; --users
// thin users (irradcast-load's generator, in this process); then, row by row, irradcast-edit
// --stream moving 0, 1, 16 and 64 of the spheres (--moving) at 60 poses a second each for
// --window-s seconds. Per row: the poses the server took per second, its network threads' CPU
// (cores) and the bytes each viewer received per second, measured in the window; the first row
// (nothing moving) is the baseline the others are read against, side by side in one run. Then
// presence (docs/DYNAMIC.md#presence; the server runs with --presence): every user's camera
// walking at 10 updates a second, first without avatars ("cameras"), then with each user shown
// as one and sent the nearest 32 others' ("avatars").
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../fanout/fanout_common.h"
#include "balls_scene.h"
#include "bench_util.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/common/error.h"

using namespace irradcast;
using namespace irradcast::bench;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct Options {
  int nodes = 64;
  std::string moving = "0,1,16,64";
  int users = 256;
  double window_s = 4.0;
  std::string out = "out/bench-poses";
  bool presence_rows = true;
};

struct Row {
  std::string label;
  int moving = 0;         // spheres streaming poses
  bool presence = false;  // users shown as avatars, sent the others'
  double camera_hz = 1.0;
};

const char* kToken = "bench-poses-token-0123456789";

// `moving` spheres, each stepping 60 times a second for `seconds`, the lines interleaved.
std::string pose_lines(int moving, double seconds) {
  std::ostringstream out;
  const int steps = static_cast<int>(60.0 * seconds);
  for (int t = 0; t < steps; ++t)
    for (int b = 0; b < moving; ++b)
      out << R"({"op": "move", "node": "ball)" << b << R"(", "by": [)"
          << (t % 120 < 60 ? 0.001 : -0.001) << ", 0, 0]}\n";
  return out.str();
}

// The rows: --moving's counts, then the presence rows.
std::vector<Row> rows_of(const Options& o) {
  std::vector<Row> rows;
  std::stringstream ss(o.moving);
  std::string part;
  while (std::getline(ss, part, ',')) rows.push_back({part, std::stoi(part), false, 1.0});
  for (const Row& row : rows)
    if (row.moving < 0 || row.moving > o.nodes)
      throw Error("--moving: " + row.label + " is not in 0.." + std::to_string(o.nodes));
  if (o.presence_rows) {
    rows.push_back({"cameras", 0, false, 10.0});
    rows.push_back({"avatars", 0, true, 10.0});
  }
  return rows;
}

// irradcast-edit --stream of `lines` to the server; its output.
std::string stream_poses(std::uint16_t port, const fs::path& lines) {
  const std::string cmd = std::string(IRRADCAST_EDIT_EXE) +
                          " --connect 127.0.0.1:" + std::to_string(port) + " --token " + kToken +
                          " --stream " + lines.string() + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) throw Error("cannot run irradcast-edit");
  char buf[512];
  std::string output;
  while (std::fgets(buf, sizeof buf, p)) output += buf;
  pclose(p);
  return output;
}

// The bytes all users had received, once a second (the load generator's progress).
struct Received {
  std::mutex mutex;
  std::vector<std::pair<double, std::uint64_t>> samples;  // (elapsed s, bytes)

  void add(const LoadProgress& p) {
    std::lock_guard lock(mutex);
    samples.emplace_back(p.elapsed_s, p.bytes_received);
  }
  // At `t` s, interpolated between the samples.
  double at(double t) {
    std::lock_guard lock(mutex);
    for (std::size_t i = 1; i < samples.size(); ++i)
      if (samples[i].first >= t) {
        const auto& [ta, ba] = samples[i - 1];
        const auto& [tb, bb] = samples[i];
        const double f = tb > ta ? (t - ta) / (tb - ta) : 1.0;
        return double(ba) + f * (double(bb) - double(ba));
      }
    return samples.empty() ? 0.0 : double(samples.back().second);
  }
};

struct Measured {
  double window = 0.0, poses_per_s = 0.0, cores = 0.0, bytes_per_viewer = 0.0;
  unsigned long long refused = 0;
  LoadReport report;
};

// One row: the users connect, and once every one has its image the row's poses stream for the
// window, the server's network threads timed.
Measured measure(const Options& o, const Row& row, std::uint16_t port, pid_t server) {
  const fs::path lines = fs::path(o.out) / ("poses_" + std::to_string(row.moving) + ".jsonl");
  std::ofstream(lines) << pose_lines(row.moving, o.window_s);
  LoadOptions lo;
  lo.port = port;
  lo.users = o.users;
  lo.ramp_s = 1.0;
  const double start_s = 4.0;  // every user has its full image by then (a tiny scene)
  lo.duration_s = start_s + o.window_s + 2.0;
  lo.camera_hz = row.camera_hz;
  lo.camera_path = row.camera_hz > 1.0 ? "random-walk" : "orbit";
  lo.presence = row.presence;
  lo.name = "bench-poses";
  Received received;
  Measured m;
  std::thread load(
      [&] { m.report = run_load(lo, [&](const LoadProgress& p) { received.add(p); }); });
  const auto t0 = Clock::now();
  std::this_thread::sleep_until(t0 + std::chrono::milliseconds(static_cast<int>(1e3 * start_s)));
  const fanout::ThreadCpu cpu0 = fanout::thread_cpu(server);
  const auto w0 = Clock::now();
  std::string edit_output = "no poses";
  if (row.moving > 0)
    edit_output = stream_poses(port, lines);
  else
    std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int>(1e3 * o.window_s)));
  const auto w1 = Clock::now();
  const fanout::ThreadCpu cpu1 = fanout::thread_cpu(server);
  load.join();
  m.window = std::chrono::duration<double>(w1 - w0).count();
  const double from = std::chrono::duration<double>(w0 - t0).count(), to = from + m.window;
  m.bytes_per_viewer = (received.at(to) - received.at(from)) / m.window / o.users;
  m.cores = (cpu1.io - cpu0.io) / m.window;
  unsigned long long taken = 0;
  if (const auto at = edit_output.find("streamed "); at != std::string::npos)
    std::sscanf(edit_output.c_str() + at, "streamed %llu poses from %*u lines in %*f s, %llu",
                &taken, &m.refused);
  m.poses_per_s = static_cast<double>(taken) / m.window;
  return m;
}

int run(const Options& o) {
  const std::vector<Row> rows = rows_of(o);
  fs::create_directories(o.out);
  const fs::path gltf = fs::path(o.out) / "balls.glb";
  write_balls_gltf(o.nodes, gltf.string());

  fanout::Options fo;
  fo.scene = gltf.string();
  fo.out = o.out;
  fo.server_args = {"--control-token", kToken, "--texels-per-scene", "32",   "--max-updates", "4",
                    "--io-threads",    "2",    "--log-level",        "warn", "--presence"};
  const std::uint16_t port = fanout::free_port();
  fanout::Child server(fanout::server_command(fo, port), fs::path(o.out) / "server.log");
  fanout::wait_listening(port, 120.0, "irradcast-server");

  nlohmann::json j;
  j["bench"] = "irradcast-bench-poses";
  j["machine"] = machine_json(0);
  j["users"] = o.users;
  j["nodes"] = o.nodes;
  j["window_s"] = o.window_s;
  std::printf(
      "%d thin users of one irradcast-server, %d dynamic spheres; each row streams "
      "poses of `moving` spheres at 60/s for %.1f s\n",
      o.users, o.nodes, o.window_s);
  std::printf("%-8s %12s %14s %18s %14s\n", "moving", "poses/s in", "server cores",
              "bytes/viewer/s", "edit refused");
  double base_cores = 0.0, base_bytes = 0.0;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const Measured m = measure(o, rows[r], port, server.pid());
    if (r == 0) {
      base_cores = m.cores;
      base_bytes = m.bytes_per_viewer;
    }
    std::printf("%-8s %12.0f %14.3f %18.0f %14llu\n", rows[r].label.c_str(), m.poses_per_s, m.cores,
                m.bytes_per_viewer, m.refused);
    std::fflush(stdout);
    j["rows"].push_back({{"row", rows[r].label},
                         {"moving", rows[r].moving},
                         {"presence", rows[r].presence},
                         {"camera_hz", rows[r].camera_hz},
                         {"avatar_messages", m.report.avatar_messages},
                         {"avatars_per_message", m.report.avatars_per_message},
                         {"poses_per_s", m.poses_per_s},
                         {"server_network_cores", m.cores},
                         {"server_network_cores_over_baseline", m.cores - base_cores},
                         {"bytes_per_viewer_per_s", m.bytes_per_viewer},
                         {"bytes_per_viewer_per_s_over_baseline", m.bytes_per_viewer - base_bytes},
                         {"poses_refused", m.refused},
                         {"users_failed", m.report.failed},
                         {"window_s", m.window}});
  }
  const std::string path = (fs::path(o.out) / "poses.json").string();
  write_json(path, j);
  std::printf("wrote %s\n", path.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"irradcast-bench-poses: poses streamed through one server to many thin viewers"};
  app.add_option("--nodes", o.nodes, "dynamic spheres in the scene");
  app.add_option("--moving", o.moving,
                 "spheres streaming per row, comma-separated (first: baseline)");
  app.add_option("--users", o.users, "thin viewers");
  app.add_option("--window-s", o.window_s, "seconds of streaming per row");
  app.add_option("--out", o.out, "output directory");
  app.add_option("--presence-rows", o.presence_rows,
                 "add the rows 'cameras' (every user's camera walking at 10 Hz) and 'avatars' "
                 "(the same, each user shown as an avatar and sent the nearest others')");
  CLI11_PARSE(app, argc, argv);
  return run_guarded("irradcast-bench-poses: ", [&] { return run(o); });
}

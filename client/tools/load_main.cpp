// irradcast-load: simulated users against an irradcast-server. Each user is a full protocol
// client (scene download, subscription, camera updates, tile decoding; frames in render mode),
// all on one Asio io_context. A live progress line while it runs; at the end a report as text
// and, with --json, as JSON. Run several processes (or machines) for more users than one
// process can drive; their JSON reports add up.
#include <sys/resource.h>
#include <unistd.h>
#include "irradcast/common/cli.h"

#include <cstdio>
#include <fstream>
#include <string>

#include "irradcast/client/host_port.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "tool_main.h"

namespace {

struct Options {
  std::string connect;
  irradcast::ClientTls tls;
  int users = 8;
  double duration = 10.0;
  std::string mode = "thin";
  bool decode_per_user = false;
  bool presence = false;
  int width = 320, height = 240;
  double fps = 30.0;
  double camera_hz = 10.0;
  std::string camera_path = "orbit";
  double ramp = 0.0;
  int threads = 0;
  std::string encoding = "rgb9e5";
  std::string json;
  std::string name = "irradcast-load";
  std::string log_level = "warn";
  bool quiet = false;
};

// One socket per user: raise the descriptor limit to what the system allows.
void raise_fd_limit(int users) {
  rlimit lim{};
  if (getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
  const rlim_t want = static_cast<rlim_t>(users) + 64;
  if (lim.rlim_cur >= want) return;
  lim.rlim_cur = std::min(want, lim.rlim_max);
  setrlimit(RLIMIT_NOFILE, &lim);
  if (lim.rlim_cur < want)
    irradcast::log::warn("load", "only " + std::to_string(lim.rlim_cur) +
                                     " file descriptors allowed; some users will fail to "
                                     "connect (raise ulimit -n or run more processes)");
}

int run(const Options& o) {
  using namespace irradcast;
  LoadOptions lo;
  lo.servers = tools::start_run(o.log_level, o.connect);
  lo.tls = irradcast::tools::tls_of(o.tls);
  lo.users = o.users;
  lo.duration_s = o.duration;
  if (o.mode != "thin" && o.mode != "render")
    throw Error("--mode must be thin or render, not '" + o.mode + "'");
  lo.render = o.mode == "render";
  lo.decode_per_user = o.decode_per_user;
  lo.presence = o.presence;
  lo.width = o.width;
  lo.height = o.height;
  lo.fps = o.fps;
  lo.camera_hz = o.camera_hz;
  lo.camera_path = o.camera_path;
  lo.ramp_s = o.ramp;
  lo.threads = o.threads;
  lo.name = o.name;
  lo.encoding = tools::parse_encoding(o.encoding);
  raise_fd_limit(o.users);

  const bool tty = isatty(fileno(stderr)) != 0;
  auto progress = [&](const LoadProgress& p) {
    if (o.quiet) return;
    char line[320];
    std::snprintf(line, sizeof line,
                  "[load] %5.1f/%.0f s  users %d/%d connected, %d scene, %d full, %d failed  "
                  "tiles %llu  rx %.1f MB  p99 %.1f ms  errors %llu  reconnects %llu",
                  p.elapsed_s, o.duration, p.connected, p.users, p.scene_loaded, p.full_image,
                  p.failed, static_cast<unsigned long long>(p.tiles_applied),
                  static_cast<double>(p.bytes_received) / 1e6, p.latency_p99_ms,
                  static_cast<unsigned long long>(p.errors),
                  static_cast<unsigned long long>(p.reconnects));
    // A live line on a terminal; a line every 5 s in a log.
    if (tty)
      std::fprintf(stderr, "\r%s\x1b[K", line);
    else if (static_cast<int>(p.elapsed_s + 0.5) % 5 == 0)
      std::fprintf(stderr, "%s\n", line);
  };
  const LoadReport report = run_load(lo, progress);
  if (tty && !o.quiet) std::fprintf(stderr, "\n");
  std::fputs(report.text().c_str(), stdout);
  if (!o.json.empty()) {
    std::ofstream f(o.json);
    f << report.json() << "\n";
    if (!f) throw Error("cannot write the report to '" + o.json + "'");
  }
  // Exit 0 only when every user connected and none failed.
  return report.failed == 0 && report.connected == report.users ? 0 : 3;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-load: simulated users against an irradcast-server. Each user downloads the "
      "scene, subscribes, sends camera updates along its path and applies every tile (and "
      "composes frames in render mode). Prints a live progress line and a report: users "
      "connected/failed, time to scene and to the first full image, tile latency, bandwidth, "
      "frame rate, reconnects and errors by kind. A user whose connection drops reconnects with "
      "back-off until the end of the run and resumes. Exits 3 when a user failed.",
      "irradcast-load"};
  app.option_defaults()->always_capture_default();
  irradcast::tools::add_connect_flags(app, o.connect, o.tls);
  app.add_option("--users", o.users, "simulated users")->check(CLI::Range(1, 100000));
  app.add_option("--duration", o.duration, "seconds from start to the users' Bye")
      ->check(CLI::PositiveNumber);
  app.add_option("--mode", o.mode, "thin (network + tile decoding) | render (also frames)");
  app.add_flag("--decode-per-user", o.decode_per_user,
               "every user decodes every tile into its own lightmaps (default: the users share "
               "the decode of byte-identical tiles, as N clients' decodes run on N machines, not "
               "on this one; thin users keep a reference to it, render users copy it)");
  app.add_flag("--presence", o.presence,
               "every user shows itself as an avatar at its camera and receives the nearest "
               "others' (irradcast-server --presence; the report adds their rate and bytes)");
  app.add_option("--width", o.width, "frame width (render mode)")->check(CLI::Range(1, 8192));
  app.add_option("--height", o.height, "frame height (render mode)")->check(CLI::Range(1, 8192));
  app.add_option("--fps", o.fps, "render mode: frames per second per user at most (0 = no cap)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--camera-hz", o.camera_hz, "camera updates per second per user")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--camera-path", o.camera_path,
                 "orbit | random-walk | FILE of keyframes 't ex ey ez tx ty tz [yfov_deg]'");
  app.add_option("--ramp", o.ramp, "connect the users evenly over this many seconds")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--threads", o.threads, "I/O threads (0 = one per core)")
      ->check(CLI::Range(0, 256));
  app.add_option("--encoding", o.encoding, "tile encoding: rgb9e5 | half");
  app.add_option("--json", o.json, "also write the report as JSON here");
  app.add_option("--name", o.name, "client name prefix in the server's logs");
  app.add_option("--log-level", o.log_level, "debug | info | warn | error | off");
  app.add_flag("--quiet", o.quiet, "no progress line");
  return irradcast::tools::parse_and_run(app, argc, argv, [&] { return run(o); });
}

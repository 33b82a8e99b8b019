// What irradcast-bench-fanout's two modes share (bench/fanout/main.cpp: users of one
// irradcast-server; bench/fanout/gateways.cpp: users spread over irradcast-gateways fed through
// NATS): the options, child processes on loopback, CPU time of a process's threads by thread
// name (/proc/PID/task/*/stat), the warm-up of the origin's engine and one run of simulated thin
// users (irradcast-load's generator, in the bench's process).
#pragma once

#include <sys/types.h>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "irradcast/client/host_port.h"
#include "irradcast/client/load_generator.h"
#include "plot.h"

namespace irradcast::fanout {

namespace fs = std::filesystem;

struct Options {
  std::string server = IRRADCAST_SERVER_EXE;
  std::string gateway = IRRADCAST_GATEWAY_EXE;
  std::string nats_server;  // empty: the first of /usr/sbin, /usr/bin, /usr/local/bin
  std::string scene = "cornell";
  std::vector<int> users = {1, 2, 4, 8, 16, 32, 64, 128, 256, 512};
  std::vector<int> gateways;  // empty: direct users of one server only; 0 = the direct row
  int warmup_updates = 24;
  double window_s = 10.0;  // measuring time after the last user's expected full image
  double sync_s_per_user = 0.04;
  std::string out = "docs/images";
  std::vector<std::string> server_args;
  bool quick = false;
  // --presence: the origin and gateways run with --presence and every user shows itself as an
  // avatar (docs/DYNAMIC.md#presence); the rows add Avatars per user per second and their bytes.
  bool presence = false;
};

// CPU seconds of a process's threads: the network threads ("irradcast-io"), the NATS threads
// ("irradcast-nats": the origin's publisher or the gateway's reader, and the NATS client library's
// threads they start) and the rest (the engine thread, its TBB workers and the idle main thread).
struct ThreadCpu {
  double io = 0.0, nats = 0.0, rest = 0.0;
  double network() const { return io + nats; }
  double total() const { return io + nats + rest; }
};
ThreadCpu thread_cpu(pid_t pid);
// CPU seconds of this process (the simulated users).
double self_cpu();

std::uint16_t free_port();

// A child process (its stdout and stderr into `log`), stopped with SIGINT when destroyed.
class Child {
 public:
  Child(std::vector<std::string> args, const fs::path& log);
  ~Child();
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  pid_t pid() const { return pid_; }
  bool alive() const;

 private:
  pid_t pid_ = -1;
};

// irradcast-server's command line for the bench (loopback, every user from 127.0.0.1).
std::vector<std::string> server_command(const Options& o, std::uint16_t port);
// Polls until the server on `port` has published o.warmup_updates updates.
void warm_up(const Options& o, std::uint16_t port, const Child& server);
// Waits until something listens on 127.0.0.1:port (or throws after `seconds`).
void wait_listening(std::uint16_t port, double seconds, const std::string& what);

// n thin users over `servers` (user i first on server i mod size), for long enough that every
// user has its first full image and then o.window_s seconds.
LoadReport run_thin_users(const Options& o, const std::vector<HostPort>& servers, int n);

// The JSON report's fields that describe the run (scene, cores, warm-up, window, load average).
nlohmann::json report_header(const Options& o);

plot::Series series(const std::string& label, plot::Color color, bool points);
std::string ms(double v);

// The gateway mode (bench/fanout/gateways.cpp).
void run_gateway_bench(const Options& o);

// --fresh (bench/fanout/fresh.cpp): N thin users joining a fresh server at once.
struct FreshOptions {
  int users = 128;
  double duration_s = 20.0;
  int repeat = 2;
  int pin_load = -1;                 // CPU for the simulated users (-1: every CPU)
  std::vector<std::string> compare;  // LABEL=SERVER_PATH (default: this build's server)
};
void run_fresh_bench(const Options& o, const FreshOptions& f);

}  // namespace irradcast::fanout

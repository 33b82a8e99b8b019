// irradcast-bench-fanout's shared pieces (bench/fanout/fanout_common.h).
#include "fanout_common.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <asio.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>

#include "irradcast/client/view_client.h"
#include "irradcast/common/error.h"

extern char** environ;

namespace irradcast::fanout {

using Clock = std::chrono::steady_clock;

ThreadCpu thread_cpu(pid_t pid) {
  ThreadCpu t;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/proc/" + std::to_string(pid) + "/task", ec)) {
    std::ifstream f(e.path() / "stat");
    std::string line;
    if (!std::getline(f, line)) continue;
    const auto open = line.find('('), close = line.rfind(')');
    if (open == std::string::npos || close == std::string::npos || close + 2 > line.size())
      continue;
    const std::string comm = line.substr(open + 1, close - open - 1);
    std::istringstream rest(line.substr(close + 2));
    std::string field;
    std::vector<std::string> fields;
    while (rest >> field) fields.push_back(field);
    if (fields.size() < 13) continue;
    // Fields after the name start at 3 (state); utime and stime are 14 and 15.
    const double cpu = (std::stod(fields[11]) + std::stod(fields[12])) / tick;
    (comm == "irradcast-io" ? t.io : comm == "irradcast-nats" ? t.nats : t.rest) += cpu;
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

Child::Child(std::vector<std::string> args, const fs::path& log) {
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  const int rc = posix_spawn(&pid_, args[0].c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw Error("cannot start " + args[0] + ": " + std::strerror(rc));
}

Child::~Child() {
  if (pid_ <= 0) return;
  kill(pid_, SIGINT);
  int status = 0;
  waitpid(pid_, &status, 0);
}

bool Child::alive() const {
  int status = 0;
  return waitpid(pid_, &status, WNOHANG) == 0;
}

std::vector<std::string> server_command(const Options& o, std::uint16_t port) {
  std::vector<std::string> args = {o.server, "--scene", o.scene, "--bind", "127.0.0.1", "--port",
                                   std::to_string(port), "--status-every", "5", "--idle-timeout",
                                   "120",
                                   // every simulated user comes from 127.0.0.1
                                   "--max-clients-per-peer", "0"};
  args.insert(args.end(), o.server_args.begin(), o.server_args.end());
  if (o.presence) args.push_back("--presence");
  return args;
}

// Warm-up: let the engine refine as a server that has been up a while would have.
void warm_up(const Options& o, std::uint16_t port, const Child& server) {
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

void wait_listening(std::uint16_t port, double seconds, const std::string& what) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  for (;;) {
    asio::io_context io;
    asio::ip::tcp::socket s(io);
    std::error_code ec;
    s.connect({asio::ip::make_address("127.0.0.1"), port}, ec);
    if (!ec) return;
    if (Clock::now() > deadline)
      throw Error(what + " does not listen on port " + std::to_string(port) +
                  "; see its log in the output");
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
}

LoadReport run_thin_users(const Options& o, const std::vector<HostPort>& servers, int n) {
  LoadOptions lo;
  lo.servers = servers;
  lo.users = n;
  lo.ramp_s = std::min(2.0, 0.01 * n);
  lo.duration_s = 3.0 + lo.ramp_s + o.sync_s_per_user * n + o.window_s;
  lo.camera_hz = 5.0;
  lo.threads = 0;
  lo.name = "fanout";
  lo.presence = o.presence;
  return run_load(lo, [&](const LoadProgress& pr) {
    if (static_cast<int>(pr.elapsed_s) % 5 == 0)
      std::fprintf(stderr, "[fanout] %d users: %.0f/%.0f s, %d full, %d failed, p99 %.1f ms\n", n,
                   pr.elapsed_s, lo.duration_s, pr.full_image, pr.failed, pr.latency_p99_ms);
  });
}

nlohmann::json report_header(const Options& o) {
  nlohmann::json j;
  j["scene"] = o.scene;
  j["cores"] = std::thread::hardware_concurrency();
  j["warmup_updates"] = o.warmup_updates;
  j["window_s"] = o.window_s;
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) > 0) j["load_average"] = {load[0], load[1], load[2]};
  return j;
}

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

}  // namespace irradcast::fanout

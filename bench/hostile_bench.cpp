// irradcast-bench-hostile: what the defences against hostile clients (issue 16) cost where they
// touch the hot path, measured side by side in one run: the same in-process engine host and
// scene, one server per configuration, the same simulated users (irradcast-load's, thin mode),
// the configurations interleaved round by round so that a busy machine affects all alike.
//
//   plain        the defaults: write-stall watch, incomplete-frame accounting, hello timeout
//   no-watch     the same without the write-stall watch (write_stall_timeout = 0)
//   tls          the defaults over TLS (a certificate made for the run)
//
// Per round and configuration: every user connects fresh (no scene cache), downloads the scene
// package and every tile, and follows for the rest of the window. Reported: time to the first
// full image (p50 over users), bytes the server sent, and the CPU of the server's network
// threads ("irradcast-io", from /proc/self/task) per MB sent; medians over rounds and ratios to
// plain. docs/BENCHMARKS.md ("Hostile-input costs") has a run.
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "irradcast/client/load_generator.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/loopback_tls.h"

namespace fs = std::filesystem;
using namespace irradcast;

namespace {

// CPU seconds of this process's threads named "irradcast-io" (the server's network threads),
// from /proc/self/task/*/schedstat (nanoseconds, not clock ticks).
double io_cpu_seconds() {
  double total = 0.0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/proc/self/task", ec)) {
    std::string comm;
    std::ifstream cf(e.path() / "comm");
    std::getline(cf, comm);
    if (comm != "irradcast-io") continue;
    std::ifstream f(e.path() / "schedstat");
    double ns = 0.0;
    if (f >> ns) total += ns * 1e-9;
  }
  return total;
}

struct Sample {
  double full_image_ms = 0.0, mb_sent = 0.0, io_cpu_s = 0.0;
  int failed = 0;
};

// One configuration ("plain", "no-watch" or "tls") for one window of `users` users.
Sample run_config(EngineHost& host, const std::string& c, const wire::LoopbackTlsFiles& tls,
                  int users, double window_s) {
  ServerOptions so;
  so.bind = "127.0.0.1";
  so.port = 0;
  so.max_clients_per_peer = 0;
  if (c == "no-watch") so.write_stall_timeout = std::chrono::milliseconds(0);
  if (c == "tls") {
    so.tls_cert = tls.cert;
    so.tls_key = tls.key;
  }
  Server server(host, so);
  server.start();
  LoadOptions lo;
  lo.port = server.port();
  lo.users = users;
  lo.duration_s = window_s;
  lo.threads = 1;
  if (c == "tls") lo.tls = {true, tls.ca};
  const double cpu0 = io_cpu_seconds();
  const LoadReport rep = run_load(lo);
  Sample s;
  s.io_cpu_s = io_cpu_seconds() - cpu0;
  s.mb_sent = static_cast<double>(server.stats().bytes_sent) * 1e-6;
  s.full_image_ms = rep.full_image_ms.p50;
  s.failed = rep.failed;
  server.stop();
  return s;
}

// Prints the medians and their ratios to "plain"; returns the JSON of every sample and median.
nlohmann::json report(const std::string& scene, int users, int rounds,
                      const std::vector<std::string>& configs,
                      std::map<std::string, std::vector<Sample>>& samples) {
  nlohmann::json out;
  out["scene"] = scene;
  out["users"] = users;
  out["rounds"] = rounds;
  std::map<std::string, std::pair<double, double>> med;  // full image ms, io ms per MB
  for (const std::string& c : configs) {
    std::vector<double> fi, cpu;
    for (const Sample& s : samples[c]) {
      fi.push_back(s.full_image_ms);
      cpu.push_back(1e3 * s.io_cpu_s / std::max(s.mb_sent, 1e-9));
      out["samples"][c].push_back({{"full_image_ms", s.full_image_ms},
                                   {"mb_sent", s.mb_sent},
                                   {"io_cpu_s", s.io_cpu_s},
                                   {"failed", s.failed}});
    }
    med[c] = {irradcast::bench::upper_median(fi), irradcast::bench::upper_median(cpu)};
    out["median"][c] = {{"full_image_ms", med[c].first}, {"io_cpu_ms_per_mb", med[c].second}};
  }
  std::printf("%d users, %s, %d rounds (medians; ratio to plain)\n", users, scene.c_str(), rounds);
  std::printf("%-9s %18s %10s %22s %10s\n", "config", "full image p50 ms", "ratio",
              "network CPU ms per MB", "ratio");
  for (const std::string& c : configs)
    std::printf("%-9s %18.1f %10.2f %22.2f %10.2f\n", c.c_str(), med[c].first,
                med[c].first / std::max(med["plain"].first, 1e-9), med[c].second,
                med[c].second / std::max(med["plain"].second, 1e-9));
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene = "cornell";
  int users = 16, rounds = 3;
  double window_s = 4.0;
  std::string json_path;
  CLI::App app{"irradcast-bench-hostile: the hot-path cost of the hostile-input defences and TLS",
               "irradcast-bench-hostile"};
  app.add_option("--scene", scene, "cornell | rooms:N | FILE");
  app.add_option("--users", users, "simulated users per configuration and round");
  app.add_option("--rounds", rounds, "rounds (configurations interleaved)");
  app.add_option("--window", window_s, "seconds per configuration and round");
  app.add_option("--json", json_path, "write the samples and medians here");
  CLI11_PARSE(app, argc, argv);
  try {
    bench::quiet_run();
    const fs::path dir =
        fs::temp_directory_path() / ("irradcast_bench_hostile_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const wire::LoopbackTlsFiles tls = wire::make_loopback_tls_files(dir.string());

    EngineHostOptions ho;
    ho.max_updates = 8;
    EngineHost host(load_scene(scene), scene, ho);
    host.start();
    while (!host.stats().idle) std::this_thread::sleep_for(std::chrono::milliseconds(50));

    const std::vector<std::string> configs = {"plain", "no-watch", "tls"};
    std::map<std::string, std::vector<Sample>> samples;
    for (int r = 0; r < rounds; ++r) {
      for (const std::string& c : configs) {
        const Sample s = run_config(host, c, tls, users, window_s);
        samples[c].push_back(s);
        std::fprintf(stderr,
                     "[hostile] round %d %-8s: full image p50 %.1f ms, %.2f MB sent, io CPU "
                     "%.3f s (%.1f ms/MB), %d failed\n",
                     r + 1, c.c_str(), s.full_image_ms, s.mb_sent, s.io_cpu_s,
                     1e3 * s.io_cpu_s / std::max(s.mb_sent, 1e-9), s.failed);
      }
    }
    host.stop();

    const nlohmann::json out = report(scene, users, rounds, configs, samples);
    if (!json_path.empty()) irradcast::bench::write_json(json_path, out);
    fs::remove_all(dir);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-bench-hostile: error: %s\n", e.what());
    return 1;
  }
}

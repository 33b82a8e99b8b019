// irradcast-bench-fanout --fresh: issue 22 part 5's run, side by side. Each run starts a fresh
// irradcast-server (no warm-up: the engine converges while the users join) and lets N thin users
// join at once for D seconds (irradcast-load --users N --duration D --mode thin, in this process),
// then stops the server. The variants: each server binary of --compare (default: this build's)
// times the load generator's decoding (every user decodes every tile itself, as before, or the
// users share the decode of byte-identical tiles, the default of irradcast-load), optionally with
// the simulated users pinned to one CPU (--pin-load, the issue's `taskset -c 1`: the server keeps
// every CPU). Repetitions are interleaved; per variant the repetition with the median p99 is
// kept (the lower middle one for an even count), and every repetition's p50 and p99 are listed.
// Per run: tile latency p50/p99 (every tile version computed after the user subscribed, server
// time stamp to the user's apply), bytes/s per user, the server's network and engine CPU, the
// load generator's CPU. Writes OUT/fanout_fresh.json and OUT/fanout_fresh.png.
#include <sched.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "fanout_common.h"
#include "irradcast/common/error.h"

namespace irradcast::fanout {

namespace {

// A chart label ("server\nshared decode") on one line of text.
std::string one_line(std::string label) {
  std::replace(label.begin(), label.end(), '\n', ' ');
  return label;
}

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

struct Variant {
  std::string label, server;
  bool decode_per_user = false;
  bool copy_shared_texels = false;
};

struct Run {
  LoadReport report;
  double io_cores = 0.0, engine_cores = 0.0, load_cores = 0.0, seconds = 0.0;
};

// Pins this thread (and the load generator's threads, which it starts) to `cpu`; -1: every CPU.
void pin_this_thread(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  const int n = static_cast<int>(std::thread::hardware_concurrency());
  for (int c = 0; c < n; ++c)
    if (cpu < 0 || c == cpu) CPU_SET(c, &set);
  if (sched_setaffinity(0, sizeof set, &set) != 0)
    throw Error("cannot pin the load generator to CPU " + std::to_string(cpu));
}

Run run_once(const Options& o, const FreshOptions& f, const Variant& v, int rep) {
  Options so = o;
  so.server = v.server;
  const std::uint16_t port = free_port();
  Child server(server_command(so, port),
               fs::path(o.out) / ("fanout_fresh_server_" + std::to_string(rep) + ".log"));
  wait_listening(port, 60, "irradcast-server");
  LoadOptions lo;
  lo.servers = {{"127.0.0.1", port}};
  lo.users = f.users;
  lo.duration_s = f.duration_s;
  lo.decode_per_user = v.decode_per_user;
  lo.copy_shared_texels = v.copy_shared_texels;
  lo.name = "fresh";
  Run r;
  const ThreadCpu s0 = thread_cpu(server.pid());
  const double self0 = self_cpu();
  const auto t0 = Clock::now();
  if (f.pin_load >= 0) pin_this_thread(f.pin_load);
  r.report = run_load(lo);
  if (f.pin_load >= 0) pin_this_thread(-1);
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  const ThreadCpu s1 = thread_cpu(server.pid());
  r.io_cores = (s1.io - s0.io) / r.seconds;
  r.engine_cores = (s1.rest - s0.rest) / r.seconds;
  r.load_cores = (self_cpu() - self0) / r.seconds;
  const Percentiles& l = r.report.tile_latency_ms;
  std::printf(
      "%-28s rep %d: %d/%d users ok, tile latency p50 %s p99 %s ms (%zu tiles), %.1f kB/s per "
      "user; server network %.2f + engine %.2f cores, load generator %.2f cores\n",
      one_line(v.label).c_str(), rep, r.report.connected - r.report.failed, f.users,
      ms(l.p50).c_str(), ms(l.p99).c_str(), l.count, r.report.bytes_per_s.mean / 1e3, r.io_cores,
      r.engine_cores, r.load_cores);
  std::fflush(stdout);
  return r;
}

void write_outputs(const Options& o, const FreshOptions& f, const std::vector<Variant>& variants,
                   const std::vector<std::vector<Run>>& runs) {
  json j = report_header(o);
  j["users"] = f.users;
  j["duration_s"] = f.duration_s;
  j["repeat"] = f.repeat;
  j["pin_load"] = f.pin_load;
  plot::BarChart chart;
  chart.title = "Fresh server, " + std::to_string(f.users) + " thin users joining at once (" +
                o.scene + ", " + std::to_string(std::thread::hardware_concurrency()) + " cores)";
  chart.y_label = "tile latency, ms (server version -> user's apply)";
  chart.note = "every tile computed after the user subscribed; the median p99 of " +
               std::to_string(f.repeat) + " interleaved runs" +
               (f.pin_load >= 0 ? "; users pinned to CPU " + std::to_string(f.pin_load) : "");
  chart.series_labels = {"p50", "p99"};
  chart.colors = {plot::kBlue, plot::kRed};
  chart.values.assign(2, {});
  chart.mark_label = "goal: p99 < 250 ms";
  for (std::size_t i = 0; i < variants.size(); ++i) {
    const Run& r = runs[i][(runs[i].size() - 1) / 2];
    json rj = json::parse(r.report.json(false));
    rj["variant"] = one_line(variants[i].label);
    for (const Run& each : runs[i])
      rj["repetitions"].push_back({{"p50_ms", each.report.tile_latency_ms.p50},
                                   {"p99_ms", each.report.tile_latency_ms.p99}});
    rj["server"] = variants[i].server;
    rj["server_io_cores"] = r.io_cores;
    rj["server_engine_cores"] = r.engine_cores;
    rj["load_generator_cores"] = r.load_cores;
    rj["seconds"] = r.seconds;
    j["runs"].push_back(rj);
    chart.categories.push_back(variants[i].label);
    chart.values[0].push_back(r.report.tile_latency_ms.p50);
    chart.values[1].push_back(r.report.tile_latency_ms.p99);
    chart.marks.push_back(250.0);
  }
  std::ofstream(fs::path(o.out) / "fanout_fresh.json") << j.dump(2) << "\n";
  plot::write_bar_chart((fs::path(o.out) / "fanout_fresh.png").string(), chart);
}

}  // namespace

void run_fresh_bench(const Options& o, const FreshOptions& f) {
  if (f.users < 1 || !(f.duration_s > 0.0) || f.repeat < 1)
    throw Error("--fresh needs --users >= 1, --duration > 0 and --repeat >= 1");
  std::vector<std::pair<std::string, std::string>> servers;
  for (const std::string& c : f.compare) {
    const std::size_t eq = c.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == c.size())
      throw Error("--compare takes LABEL=PATH, not '" + c + "'");
    servers.emplace_back(c.substr(0, eq), c.substr(eq + 1));
  }
  if (servers.empty()) servers.emplace_back("server", o.server);
  std::vector<Variant> variants;
  for (const auto& [label, path] : servers) {
    variants.push_back({label + "\nusers decode each", path, true, false});
    variants.push_back({label + "\nshared, copied", path, false, true});
    variants.push_back({label + "\nshared, referenced", path, false, false});
  }
  std::vector<std::vector<Run>> runs(variants.size());
  for (int rep = 0; rep < f.repeat; ++rep)
    for (std::size_t i = 0; i < variants.size(); ++i)
      runs[i].push_back(run_once(o, f, variants[i], rep));
  for (std::vector<Run>& v : runs)
    std::sort(v.begin(), v.end(), [](const Run& a, const Run& b) {
      return a.report.tile_latency_ms.p99 < b.report.tile_latency_ms.p99;
    });
  write_outputs(o, f, variants, runs);
  std::printf("wrote %s/fanout_fresh.json and fanout_fresh.png\n", o.out.c_str());
}

}  // namespace irradcast::fanout

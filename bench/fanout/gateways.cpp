// irradcast-bench-fanout --gateways 0,1,2,4: users spread over irradcast-gateways fed through
// NATS (docs/DISTRIBUTION.md) against users of the origin itself.
//
// Per row (a gateway count G, 0 being the direct row where the users connect to the origin,
// and a user count N) starts nats-server (JetStream, storage in a temporary folder) on a
// loopback port, one irradcast-server --nats (the origin), lets its engine refine (warm-up),
// starts G irradcast-gateway processes and N thin users spread over them (user i on gateway
// i mod G, irradcast-load's --connect list). Every row gets an origin of the same age: the
// number of tile versions falls as the engine converges, so one origin shared by the rows
// gave the later rows less to carry. Per row it records the steady tile latency
// p50/p99 (origin's version time stamp -> user's apply, so through a gateway it includes the
// NATS hop), the origin's network CPU (its "irradcast-io" and "irradcast-nats" threads), its
// engine CPU (the rest), the gateways' CPU (all their threads, summed), nats-server's CPU and
// the load generator's. Writes OUT/fanout_gateways.json and two PNG bar charts.
#include <unistd.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "fanout_common.h"
#include "irradcast/common/error.h"

namespace irradcast::fanout {

namespace {

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

struct Row {
  int gateways = 0, users = 0;
  LoadReport report;
  double seconds = 0.0;
  double origin_network = 0.0, origin_engine = 0.0, gateway_cores = 0.0, nats_cores = 0.0,
         load_cores = 0.0;  // cores
};

std::string nats_server_exe(const Options& o) {
  if (!o.nats_server.empty()) return o.nats_server;
  for (const char* p :
       {"/usr/sbin/nats-server", "/usr/bin/nats-server", "/usr/local/bin/nats-server"})
    if (::access(p, X_OK) == 0) return p;
  throw Error("no nats-server (apt-get install nats-server, or --nats-server PATH)");
}

struct Gateway {
  std::uint16_t port = 0;
  std::unique_ptr<Child> process;
};

// Starts or stops gateways until `count` run.
void resize_gateways(const Options& o, const std::string& url, std::vector<Gateway>& gws,
                     int count) {
  while (static_cast<int>(gws.size()) > count) gws.pop_back();
  while (static_cast<int>(gws.size()) < count) {
    Gateway g;
    g.port = free_port();
    const std::string i = std::to_string(gws.size());
    std::vector<std::string> args{o.gateway,
                                  "--nats",
                                  url,
                                  "--scene",
                                  o.scene,
                                  "--bind",
                                  "127.0.0.1",
                                  "--port",
                                  std::to_string(g.port),
                                  "--status-every",
                                  "5",
                                  "--idle-timeout",
                                  "120",
                                  "--max-clients-per-peer",
                                  "0"};
    if (o.presence) args.push_back("--presence");
    g.process = std::make_unique<Child>(args, fs::path(o.out) / ("fanout_gateway_" + i + ".log"));
    wait_listening(g.port, 60, "irradcast-gateway " + i);
    gws.push_back(std::move(g));
  }
}

double cpu_total(pid_t pid) {
  return thread_cpu(pid).total();
}

Row run_row(const Options& o, const Child& origin, std::uint16_t origin_port, const Child& nats,
            const std::vector<Gateway>& gws, int n) {
  Row r;
  r.gateways = static_cast<int>(gws.size());
  r.users = n;
  std::vector<HostPort> servers;
  for (const Gateway& g : gws) servers.push_back({"127.0.0.1", g.port});
  if (servers.empty()) servers.push_back({"127.0.0.1", origin_port});
  auto gateways_cpu = [&] {
    double s = 0.0;
    for (const Gateway& g : gws) s += cpu_total(g.process->pid());
    return s;
  };
  const ThreadCpu o0 = thread_cpu(origin.pid());
  const double g0 = gateways_cpu(), n0 = cpu_total(nats.pid()), self0 = self_cpu();
  const auto t0 = Clock::now();
  r.report = run_thin_users(o, servers, n);
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  const ThreadCpu o1 = thread_cpu(origin.pid());
  r.origin_network = (o1.network() - o0.network()) / r.seconds;
  r.origin_engine = (o1.rest - o0.rest) / r.seconds;
  r.gateway_cores = (gateways_cpu() - g0) / r.seconds;
  r.nats_cores = (cpu_total(nats.pid()) - n0) / r.seconds;
  r.load_cores = (self_cpu() - self0) / r.seconds;
  const LoadReport& l = r.report;
  std::printf(
      "%d gateways, %4d users: %d/%d ok, steady latency p50 %s p99 %s ms (%zu tiles); origin "
      "network %.3f + engine %.2f cores, gateways %.3f, nats-server %.3f, users %.2f cores\n",
      r.gateways, n, l.connected - l.failed, n, ms(l.steady_tile_latency_ms.p50).c_str(),
      ms(l.steady_tile_latency_ms.p99).c_str(), l.steady_tile_latency_ms.count, r.origin_network,
      r.origin_engine, r.gateway_cores, r.nats_cores, r.load_cores);
  if (o.presence)
    std::printf(
        "  presence: %.2f avatars per message, %.1f Avatars and %.0f bytes per user per s\n",
        l.avatars_per_message, l.avatar_messages_per_s.mean, l.avatar_bytes_per_s.mean);
  std::fflush(stdout);
  return r;
}

std::string row_label(const Row& r) {
  const std::string where = r.gateways == 0   ? std::string("direct")
                            : r.gateways == 1 ? std::string("1 gateway")
                                              : std::to_string(r.gateways) + " gateways";
  return where + "\n" + std::to_string(r.users) + " users";
}

void write_json(const Options& o, const std::vector<Row>& rows) {
  json j = report_header(o);
  for (const Row& r : rows) {
    json rj = json::parse(r.report.json(false));
    rj["gateways"] = r.gateways;
    rj["origin_network_cores"] = r.origin_network;
    rj["origin_engine_cores"] = r.origin_engine;
    rj["gateway_cores"] = r.gateway_cores;
    rj["nats_server_cores"] = r.nats_cores;
    rj["load_generator_cores"] = r.load_cores;
    rj["seconds"] = r.seconds;
    j["runs"].push_back(rj);
  }
  std::ofstream(fs::path(o.out) / "fanout_gateways.json") << j.dump(2) << "\n";
}

// OUT/fanout_gateways_cpu.png and OUT/fanout_gateways_latency.png: one group of bars per row.
void write_charts(const Options& o, const std::vector<Row>& rows) {
  plot::BarChart cpu;
  cpu.title = "Who carries the users: origin, gateways, NATS (" + o.scene + ", " +
              std::to_string(std::thread::hardware_concurrency()) + " cores)";
  cpu.y_label = "CPU, cores";
  cpu.note = "origin network = its irradcast-io and irradcast-nats threads";
  cpu.series_labels = {"origin network", "gateways (all)", "nats-server"};
  cpu.colors = {plot::kBlue, plot::kOrange, plot::kGreen};
  cpu.values.assign(3, {});
  cpu.value_decimals = 3;
  plot::BarChart lat;
  lat.title = "Steady tile latency, direct vs through gateways (" + o.scene + ")";
  lat.y_label = "ms (origin version -> user's apply)";
  lat.note = "tiles applied once every user had its first full image";
  lat.series_labels = {"p50", "p99"};
  lat.colors = {plot::kBlue, plot::kRed};
  lat.values.assign(2, {});
  for (const Row& r : rows) {
    cpu.categories.push_back(row_label(r));
    cpu.values[0].push_back(r.origin_network);
    cpu.values[1].push_back(r.gateway_cores);
    cpu.values[2].push_back(r.nats_cores);
    lat.categories.push_back(row_label(r));
    lat.values[0].push_back(r.report.steady_tile_latency_ms.p50);
    lat.values[1].push_back(r.report.steady_tile_latency_ms.p99);
  }
  plot::write_bar_chart((fs::path(o.out) / "fanout_gateways_cpu.png").string(), cpu);
  plot::write_bar_chart((fs::path(o.out) / "fanout_gateways_latency.png").string(), lat);
}

}  // namespace

void run_gateway_bench(const Options& o) {
  const fs::path store =
      fs::temp_directory_path() / ("irradcast_fanout_nats_" + std::to_string(::getpid()));
  fs::create_directories(store);
  const std::uint16_t nats_port = free_port();
  const std::string url = "nats://127.0.0.1:" + std::to_string(nats_port);
  std::vector<Row> rows;
  for (int g : o.gateways) {
    if (g < 0 || g > static_cast<int>(kMaxServerAddresses))
      throw Error("--gateways: " + std::to_string(g) + " is not in 0.." +
                  std::to_string(kMaxServerAddresses));
    for (int n : o.users) {
      const fs::path store =
          fs::temp_directory_path() / ("irradcast_fanout_nats_" + std::to_string(::getpid()));
      fs::create_directories(store);
      const std::uint16_t nats_port = free_port();
      const std::string url = "nats://127.0.0.1:" + std::to_string(nats_port);
      {
        Child nats({nats_server_exe(o), "-js", "-sd", store.string(), "-p",
                    std::to_string(nats_port), "-a", "127.0.0.1"},
                   fs::path(o.out) / "fanout_gateways_nats.log");
        wait_listening(nats_port, 20, "nats-server");
        const std::uint16_t port = free_port();
        std::vector<std::string> args = server_command(o, port);
        args.insert(args.end(), {"--nats", url});
        Child origin(args, fs::path(o.out) / "fanout_gateways_origin.log");
        std::printf(
            "irradcast-bench-fanout --gateways: %d gateways, %d users: %s, origin on port %u "
            "(pid %d), %s, %u cores\n",
            g, n, o.scene.c_str(), port, origin.pid(), url.c_str(),
            std::thread::hardware_concurrency());
        warm_up(o, port, origin);
        std::vector<Gateway> gws;
        resize_gateways(o, url, gws, g);
        rows.push_back(run_row(o, origin, port, nats, gws, n));
      }
      std::error_code ec;
      fs::remove_all(store, ec);
    }
  }
  write_json(o, rows);
  write_charts(o, rows);
  std::printf(
      "wrote %s/fanout_gateways.json, fanout_gateways_cpu.png, fanout_gateways_latency.png\n",
      o.out.c_str());
}

}  // namespace irradcast::fanout

// irradcast-bench-metrics: the /metrics endpoint under load, in one process.
//
// An in-process MetricsEndpoint on a loopback port serves a realistic exposition text (the
// formatter's output for a small server). Measured, side by side in one run:
//   - a burst: N clients connect at once, then all send GET /metrics; how many get a 200, and the
//     time until the last response;
//   - scrape latency (connect, GET, read to the end), p50/p99/max over sequential scrapes, with no
//     other connection open and with N stalled connections held open (half of them sent half a
//     request, half sent nothing), in alternating rounds; a failed scrape (no 200 within 2 s)
//     counts apart.
// Uses only the endpoint's constructor, start() and port(), so the same file measures an older
// endpoint too. Numbers: docs/BENCHMARKS.md, "Metrics endpoint".
#include <sys/resource.h>
#include "irradcast/common/cli.h"

#include <asio.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/common/log.h"
#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/metrics_text.h"

using namespace irradcast;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;

namespace {

struct Client {
  explicit Client(asio::io_context& io) : socket(io) {}
  tcp::socket socket;
  bool connected = false, closed = false;
  std::string received;
  std::array<char, 4096> buffer{};
};
using Clients = std::vector<std::unique_ptr<Client>>;

void read_to_end(Client* c) {
  c->socket.async_read_some(asio::buffer(c->buffer), [c](std::error_code ec, std::size_t n) {
    c->received.append(c->buffer.data(), n);
    if (ec) {
      c->closed = ec != asio::error::operation_aborted;
      return;
    }
    read_to_end(c);
  });
}

Clients connect_all(asio::io_context& io, const tcp::endpoint& at, int n) {
  Clients clients;
  for (int i = 0; i < n; ++i) {
    clients.push_back(std::make_unique<Client>(io));
    Client* c = clients.back().get();
    c->socket.async_connect(at, [c](std::error_code ec) { c->connected = !ec; });
  }
  io.restart();
  io.run_for(std::chrono::seconds(20));
  return clients;
}

bool ok_response(const std::string& r) {
  return r.rfind("HTTP/1.1 200 ", 0) == 0 && r.find("\r\n\r\n") != std::string::npos;
}

const std::string kRequest =
    "GET /metrics HTTP/1.1\r\nHost: localhost\r\nUser-Agent: bench\r\n\r\n";

// One scrape: seconds, or a negative number when it got no 200 within 2 s.
double scrape(const tcp::endpoint& at) {
  asio::io_context io;
  Client c(io);
  const auto t0 = Clock::now();
  std::error_code ec;
  c.socket.connect(at, ec);
  if (ec) return -1.0;
  asio::write(c.socket, asio::buffer(kRequest), ec);
  if (ec) return -1.0;
  read_to_end(&c);
  io.run_for(std::chrono::seconds(2));
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  return c.closed && ok_response(c.received) ? s : -1.0;
}

struct Latency {
  std::vector<double> seconds;
  int failed = 0;
  double quantile(double q) {
    if (seconds.empty()) return 0.0;
    std::sort(seconds.begin(), seconds.end());
    const std::size_t i = std::min(
        seconds.size() - 1, static_cast<std::size_t>(q * static_cast<double>(seconds.size())));
    return seconds[i];
  }
};

void print_latency(const char* what, Latency& l) {
  std::printf("%-34s %9.3f %9.3f %9.3f %7d\n", what, l.quantile(0.5) * 1e3, l.quantile(0.99) * 1e3,
              l.quantile(1.0) * 1e3, l.failed);
}

// Raises the descriptor limit to its maximum; prints it.
void raise_descriptor_limit() {
  rlimit lim{};
  getrlimit(RLIMIT_NOFILE, &lim);
  lim.rlim_cur = lim.rlim_max;
  setrlimit(RLIMIT_NOFILE, &lim);
  getrlimit(RLIMIT_NOFILE, &lim);
  std::printf("descriptor limit %llu\n", static_cast<unsigned long long>(lim.rlim_cur));
}

// The burst: `connections` concurrent scrapes.
void burst(const tcp::endpoint& at, int connections) {
  asio::io_context io;
  Clients clients = connect_all(io, at, connections);
  const auto t0 = Clock::now();
  for (auto& client : clients) {
    Client* c = client.get();
    if (!c->connected) continue;
    asio::async_write(c->socket, asio::buffer(kRequest), [c](std::error_code ec, std::size_t) {
      if (!ec) read_to_end(c);
    });
  }
  io.restart();
  io.run_for(std::chrono::seconds(20));
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  int connected = 0, answered = 0;
  for (const auto& c : clients) {
    connected += c->connected ? 1 : 0;
    answered += c->closed && ok_response(c->received) ? 1 : 0;
  }
  std::printf("burst: %d connections (%d connected), %d answered 200, all done in %.1f ms\n\n",
              connections, connected, answered, s * 1e3);
}

// `scrapes` sequential scrapes into l.
void scrape_into(Latency& l, const tcp::endpoint& at, int scrapes) {
  for (int i = 0; i < scrapes; ++i) {
    const double s = scrape(at);
    if (s < 0)
      ++l.failed;
    else
      l.seconds.push_back(s);
  }
}

// One round with `connections` stalled connections (half of them mid-request): scrape latency
// into `loaded`; returns how many of them the endpoint closed meanwhile.
int stalled_round(const tcp::endpoint& at, int connections, int scrapes, Latency& loaded,
                  int& stalled_total) {
  asio::io_context io;
  Clients stalled = connect_all(io, at, connections);
  for (std::size_t i = 0; i < stalled.size(); i += 2) {
    std::error_code ec;
    if (stalled[i]->connected)
      asio::write(stalled[i]->socket, asio::buffer(std::string("GET /metrics HTTP/1.1\r\nHo")), ec);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // accepted by now
  scrape_into(loaded, at, scrapes);
  // How many of the stalled connections the endpoint closed meanwhile.
  for (auto& c : stalled)
    if (c->connected) read_to_end(c.get());
  io.restart();
  io.run_for(std::chrono::milliseconds(20));
  for (auto& c : stalled) {
    std::error_code ignored;
    c->socket.cancel(ignored);
  }
  io.restart();
  io.run();
  int closed = 0;
  for (const auto& c : stalled) closed += c->closed ? 1 : 0;
  stalled_total += static_cast<int>(stalled.size());
  return closed;
}

}  // namespace

int main(int argc, char** argv) {
  int connections = 1000, rounds = 5, scrapes = 100;
  CLI::App app{"irradcast-bench-metrics: the /metrics endpoint under load"};
  app.add_option("--connections", connections, "concurrent / stalled connections")
      ->check(CLI::Range(1, 100000));
  app.add_option("--rounds", rounds, "alternating rounds of latency measurements")
      ->check(CLI::Range(1, 1000));
  app.add_option("--scrapes", scrapes, "sequential scrapes per round and condition")
      ->check(CLI::Range(1, 100000));
  CLI11_PARSE(app, argc, argv);
  log::set_level(log::Level::Warn);

  raise_descriptor_limit();

  MetricsSnapshot m;
  m.scene = "rooms:3";
  m.backend = "embree";
  m.engine.passes = {{"direct", 0, 0.001, 1000, 0.009, 9000},
                     {"probes", 1, 0.002, 2000, 0.018, 18000},
                     {"scatter", 1, 0.003, 3000, 0.027, 27000}};
  const std::string text = format_metrics(m);
  MetricsEndpointOptions o;
  o.bind = "127.0.0.1";
  o.port = 0;
  MetricsEndpoint ep([&] { return text; }, o);
  ep.start();
  const tcp::endpoint at(asio::ip::make_address("127.0.0.1"), ep.port());
  std::printf("metrics text %zu bytes\n\n", text.size());

  burst(at, connections);

  Latency idle, loaded;
  int stalled_closed = 0, stalled_total = 0;
  for (int r = 0; r < rounds; ++r) {
    scrape_into(idle, at, scrapes);
    stalled_closed += stalled_round(at, connections, scrapes, loaded, stalled_total);
  }
  std::printf("%-34s %9s %9s %9s %7s\n", "scrape latency (ms)", "p50", "p99", "max", "failed");
  print_latency("no other connection", idle);
  const std::string with = "with " + std::to_string(connections) + " stalled connections";
  print_latency(with.c_str(), loaded);
  std::printf("\nstalled connections closed by the endpoint during the rounds: %d of %d\n",
              stalled_closed, stalled_total);
  ep.stop();
  return 0;
}

// irradcast-gateway: serves viewers a scene that an origin (irradcast-server --nats) computes,
// with no engine of its own: its tile store, scene package and stats come from NATS
// (NatsGateway), and the same Server as irradcast-server serves them (protocol, resume, limits,
// TLS, metrics). Viewers' cameras and edits go to the origin through NATS. Keeps serving what it
// has while NATS or the origin is away. Stops cleanly on SIGINT / SIGTERM. docs/DISTRIBUTION.md.
#include "irradcast/common/cli.h"

#include <csignal>
#include <cstdio>
#include <ctime>
#include <memory>
#include <string>
#include <thread>

#include <pthread.h>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/world.h"
#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/service/nats_gateway.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/scene_package.h"
#include "nats_options.h"
#include "network_options.h"

namespace {

struct Options {
  irradcast::tools::NatsOptions nats;
  std::string scene = "cornell";
  irradcast::tools::NetworkOptions net;
};

// Waits for a stop signal for up to `limit`; returns it, or 0.
int take_signal(const sigset_t& signals, std::chrono::milliseconds limit) {
  timespec ts{static_cast<time_t>(limit.count() / 1000),
              static_cast<long>(limit.count() % 1000) * 1000000L};
  const int sig = sigtimedwait(&signals, nullptr, &ts);
  return sig > 0 ? sig : 0;
}

void status_line(const irradcast::Server& server, const irradcast::NatsGateway& gateway) {
  const irradcast::NatsGatewayStats gs = gateway.nats_stats();
  char line[192];
  std::snprintf(line, sizeof line,
                "NATS %s, revision %llu, %llu tiles received (%llu new), lag %.3f s",
                gs.connected ? "connected" : "away", static_cast<unsigned long long>(gs.revision),
                static_cast<unsigned long long>(gs.tiles_received),
                static_cast<unsigned long long>(gs.tiles_installed), gs.lag_seconds);
  irradcast::log::info("status",
                       std::string(line) + ", " + irradcast::tools::traffic_status(server.stats()));
}

int run(const Options& o, const sigset_t& signals) {
  using namespace irradcast;
  const auto token = o.net.begin_serving();
  ServerOptions so = o.net.server_options(token, "gateway");
  NatsGatewayOptions go;
  go.url = o.nats.url;
  go.credentials = o.nats.credentials;
  go.scene_id = o.scene;
  go.presence = o.net.presence;
  go.presence_every = o.net.presence_every();
  NatsGateway gateway(go);
  // The tile layout and scene package come from the origin: wait for them.
  for (int waited = 0; !gateway.wait_ready(std::chrono::milliseconds(0)); waited += 200) {
    const int sig = take_signal(signals, std::chrono::milliseconds(200));
    if (sig == SIGINT || sig == SIGTERM) return 0;  // (SIGHUP: nothing served yet to reload)
    if (waited > 0 && waited % 5000 == 0)
      log::info("gateway", "waiting for scene '" + o.scene + "' from the origin (NATS " +
                               (gateway.nats_stats().connected ? "connected" : "not connected") +
                               ")");
  }
  if (so.presence) {
    // The avatars are the origin's height when it shows them too (NatsPresence.height); else
    // this gateway's, from the scene as irradcast-server's.
    const wire::UnpackedScene scene = wire::open_scene_package(gateway.package()->bytes, "");
    so.presence_height =
        o.net.presence_default_height(World::build(scene.scene).bounds.max_extent());
  }
  Server server(gateway, so);
  server.start();
  std::unique_ptr<MetricsEndpoint> metrics =
      o.net.start_metrics([&server, &gateway](const MetricsEndpoint* endpoint) {
        return format_metrics(collect_metrics(server, gateway, endpoint)) +
               format_nats_gateway_metrics(gateway.nats_stats());
      });
  int sig = 0;
  auto next = std::chrono::steady_clock::now() + std::chrono::seconds(o.net.status_every_s);
  while ((sig = take_signal(signals, std::chrono::milliseconds(100))) == 0 || sig == SIGHUP) {
    if (sig == SIGHUP) irradcast::tools::reload_tls("gateway", server, metrics.get());
    if (o.net.status_every_s <= 0 || std::chrono::steady_clock::now() < next) continue;
    next += std::chrono::seconds(o.net.status_every_s);
    status_line(server, gateway);
  }
  log::info("gateway",
            std::string("received ") + (sig == SIGINT ? "SIGINT" : "SIGTERM") + ", shutting down");
  if (metrics) metrics->stop();
  server.stop();
  const ServerStats ss = server.stats();
  log::info("gateway", "stopped: " + std::to_string(ss.connections) + " connections, " +
                           std::to_string(ss.bytes_sent) + " bytes sent");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-gateway: serves viewers the lightmap tiles of a scene that irradcast-server "
      "--nats computes, read from NATS JetStream; no engine. Same protocol, limits and options "
      "as irradcast-server; cameras and (with the control token) edits go to the origin.",
      "irradcast-gateway"};
  app.option_defaults()->always_capture_default();
  o.nats.add_to(app, "the NATS server the origin publishes to (nats:// or tls://HOST:PORT)");
  app.get_option("--nats")->required();
  app.add_option("--scene", o.scene, "the scene id the origin serves (its --scene)");
  o.net.add_to(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return irradcast::tools::run_service("irradcast-gateway",
                                       [&o](const sigset_t& signals) { return run(o, signals); });
}

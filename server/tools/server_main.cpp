// irradcast-server: runs the GI engine on a scene continuously and streams its irradiance tiles
// to any number of clients (docs/PROTOCOL.md). Stops cleanly on SIGINT / SIGTERM.
#include <tbb/global_control.h>
#include "irradcast/common/cli.h"

#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <utility>

#include <pthread.h>

#include "engine_options.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/vulkan_device.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/service/nats_origin.h"
#include "irradcast/service/net_server.h"
#include "nats_options.h"
#include "network_options.h"
#include "scene_options.h"

namespace {

struct Options {
  std::string scene = "cornell";
  std::string scene_root;
  std::string sky_dir;
  std::string state_dir;
  std::uint32_t journal_compact_after = 1000;
  float detail = 1.0f;
  int threads = 0;
  int tile_size = 32;
  float tile_threshold = 0.01f;
  float tile_refresh = 2.0f;
  int engine_nice = 10;
  std::uint32_t max_updates = 0;
  irradcast::tools::NatsOptions nats;  // --nats URL: also publish to NATS (docs/DISTRIBUTION.md)
  bool nats_replace_newer = false;
  irradcast::tools::NetworkOptions net;
  irradcast::tools::EngineOptions engine;
  irradcast::tools::SceneOptions lighting;
};

// The scene with the --sky and --sun of the options; logs what lights it.
irradcast::Scene load_lit_scene(const Options& o) {
  using namespace irradcast;
  log::info("server", "loading " + o.scene);
  Scene scene = load_scene(o.scene, o.detail, o.scene_root);
  tools::SceneOptions lighting = o.lighting;
  lighting.apply(scene);
  log::info("server", "lit by " + lighting.describe(scene));
  return scene;
}

// The engine host's options from the command line.
irradcast::EngineHostOptions host_options(const Options& o) {
  irradcast::EngineHostOptions ho;
  ho.engine = o.engine.params();
  ho.backend = o.engine.backend_options();
  ho.atlas = o.engine.atlas();
  ho.tiles.tile_size = o.tile_size;
  ho.tiles.change_threshold = o.tile_threshold;
  ho.tiles.refresh_ratio = o.tile_refresh;
  ho.engine_nice = o.engine_nice;
  ho.max_updates = o.max_updates;
  ho.sky_dir = o.sky_dir;
  ho.state_dir = o.state_dir;
  ho.journal_compact_after = o.journal_compact_after;
  ho.avatars = o.net.presence;
  return ho;
}

// With --nats: the NatsOrigin the server serves, which publishes what the host makes; null
// without. Throws when the stream holds a newer revision from another origin (one that ran
// without this --state-dir): the gateways are never rolled back.
std::unique_ptr<irradcast::NatsOrigin> start_origin(const Options& o, irradcast::EngineHost& host,
                                                    bool accept_edits) {
  using namespace irradcast;
  if (o.nats.url.empty()) return nullptr;
  NatsOriginOptions no;
  no.url = o.nats.url;
  no.credentials = o.nats.credentials;
  no.accept_edits = accept_edits;
  no.replace_newer = o.nats_replace_newer;
  no.presence = o.net.presence;
  no.presence_every = o.net.presence_every();
  auto origin = std::make_unique<NatsOrigin>(host, no);
  const std::string refusal = origin->check_stream(std::chrono::seconds(10));
  if (!refusal.empty()) throw Error(refusal);
  return origin;
}

// One status line: the engine's progress and the server's traffic.
void log_status(const irradcast::EngineHost& host, const irradcast::Server& server) {
  const irradcast::EngineHostStats es = host.stats();
  char line[192];
  std::snprintf(line, sizeof line, "updates %llu%s (%.2f/s), convergence %.4f, %.2f Mrays/s",
                static_cast<unsigned long long>(es.updates), es.idle ? " (final)" : "",
                es.update_rate, es.convergence, es.rays_per_s * 1e-6);
  irradcast::log::info("status",
                       std::string(line) + ", " + irradcast::tools::traffic_status(server.stats()));
}

int run(const Options& o, const sigset_t& signals) {
  using namespace irradcast;
  const auto token = o.net.begin_serving();
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(o.threads));
  const EngineHostOptions ho = host_options(o);
  EngineHost host(load_lit_scene(o), o.scene, ho);

  ServerOptions so = o.net.server_options(token, "server");
  so.presence_height = o.net.presence_default_height(host.world().bounds.max_extent());
  if (so.presence)
    log::info("server", "presence: avatars " + std::to_string(so.presence_height) +
                            " m tall, the nearest " + std::to_string(so.presence_nearest) +
                            " to each viewer");
  std::unique_ptr<NatsOrigin> origin = start_origin(o, host, !token.first.empty());
  TileSource& source = origin ? static_cast<TileSource&>(*origin) : host;
  Server server(source, so);
  server.start();
  std::unique_ptr<MetricsEndpoint> metrics =
      o.net.start_metrics([&server, &source, &origin](const MetricsEndpoint* endpoint) {
        std::string text = format_metrics(collect_metrics(server, source, endpoint));
        if (origin) text += format_nats_origin_metrics(origin->nats_stats());
        return text;
      });
  host.start();

  // The status line, on its own thread, until a signal arrives.
  std::atomic<bool> done{false};
  std::thread status([&] {
    auto next = std::chrono::steady_clock::now();
    while (!done) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      if (o.net.status_every_s <= 0 || std::chrono::steady_clock::now() < next) continue;
      next += std::chrono::seconds(o.net.status_every_s);
      log_status(host, server);
    }
  });
  int sig = 0;
  while (sigwait(&signals, &sig) == 0 && sig == SIGHUP)
    tools::reload_tls("server", server, metrics.get());
  log::info("server",
            std::string("received ") + (sig == SIGINT ? "SIGINT" : "SIGTERM") + ", shutting down");
  done = true;
  status.join();
  if (metrics) metrics->stop();
  server.stop();
  host.stop();
  if (origin) origin->flush(std::chrono::seconds(2));
  origin.reset();
  const ServerStats ss = server.stats();
  log::info("server", "stopped: " + std::to_string(ss.connections) + " connections, " +
                          std::to_string(ss.bytes_sent) + " bytes sent");
  return 0;
}

}  // namespace

// --list-devices: what the engine could run on (Vulkan devices when there is a driver, and
// Embree, which is always there) and which one --backend auto takes.
int print_devices() {
  std::printf("embree: the CPU (%u threads), always available\n",
              std::thread::hardware_concurrency());
  std::string auto_choice = "embree (no Vulkan GPU)";
  try {
    const std::vector<irradcast::VulkanDeviceInfo> devices = irradcast::list_vulkan_devices();
    if (devices.empty()) std::printf("vulkan: no device\n");
    for (const irradcast::VulkanDeviceInfo& d : devices)
      std::printf("vulkan: %s\n", irradcast::describe(d).c_str());
    const int best = irradcast::auto_vulkan_device(devices);
    if (best >= 0)
      auto_choice = "vulkan device " + std::to_string(best) + " (" +
                    devices[static_cast<std::size_t>(best)].name + ")";
    else if (!devices.empty())
      auto_choice =
          "embree (the Vulkan devices are CPU implementations; --backend vulkan uses them)";
  } catch (const irradcast::Error& e) {
    std::printf("vulkan: not available: %s\n", e.what());
  }
  std::printf("--backend auto: %s\n", auto_choice.c_str());
  return 0;
}

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-server: computes a scene's diffuse irradiance continuously (the GI engine) and "
      "streams it as lightmap tiles to irradcast-view and irradcast-load clients. With a control "
      "token it also takes live scene edits (irradcast-edit, docs/EDITS.md).",
      "irradcast-server"};
  app.option_defaults()->always_capture_default();
  app.add_option("--scene", o.scene,
                 "cornell | rooms:N | sponza (the shared sample data, with a sky and a sun) | "
                 "FILE.gltf | FILE.glb");
  app.add_option("--detail", o.detail, "tessellation of rooms:N")->check(CLI::PositiveNumber);
  app.add_option(
      "--scene-root", o.scene_root,
      "folder a glTF scene may read buffers and images from (default: the scene file's folder)");
  app.add_option("--sky-dir", o.sky_dir,
                 "folder that sky edits may name EXR maps in (default: none, file sky edits are "
                 "refused; docs/EDITS.md)")
      ->check(CLI::ExistingDirectory);
  app.add_option("--state-dir", o.state_dir,
                 "keep every accepted edit in this folder's journal (fsynced before it is "
                 "acknowledged) and replay it when started again on the same scene "
                 "(docs/EDITS.md#durable-edits; default: edits are lost with the process)")
      ->default_str("none");
  app.add_option("--journal-compact-after", o.journal_compact_after,
                 "rewrite the edit journal as one snapshot once it holds this many edits "
                 "(0 = never)");
  o.net.add_to(app);
  o.nats.add_to(app,
                "also publish the scene, its tiles, edits and stats to this NATS server "
                "(nats:// or tls://HOST:PORT, JetStream enabled) for irradcast-gateway, and take "
                "their viewers' cameras and edits (docs/DISTRIBUTION.md)");
  app.add_flag("--nats-replace-newer", o.nats_replace_newer,
               "publish even when the NATS stream holds a newer scene revision from another "
               "origin (its edits are lost for the gateways; without it such an origin exits)");
  app.add_option("--threads", o.threads, "engine worker threads (0 = all cores)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--tile-size", o.tile_size, "tile edge in texels")->check(CLI::Range(4, 1024));
  app.add_option("--tile-threshold", o.tile_threshold,
                 "relative change that gives a tile a new version")
      ->check(CLI::Range(0.0f, 10.0f));
  app.add_option("--engine-nice", o.engine_nice,
                 "nice value of the engine's threads, so the network threads come first "
                 "(0 = same as the process)")
      ->check(CLI::Range(0, 19));
  app.add_option("--tile-refresh", o.tile_refresh,
                 "a tile whose change is within the engine's noise gets a new version once its "
                 "samples grew by R^(1+h), h in [0,1) per tile (1 = every update)")
      ->check(CLI::Range(1.0f, 1000.0f));
  app.add_option("--max-updates", o.max_updates,
                 "stop refining after this many engine updates (0 = never)");
  bool list_devices = false;
  app.add_flag("--list-devices", list_devices,
               "list the compute devices (Vulkan) and exit; the engine runs on Embree (CPU)");
  o.lighting.add_to(app);
  o.engine.add_to(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (list_devices) return print_devices();
  return irradcast::tools::run_service("irradcast-server",
                                       [&o](const sigset_t& signals) { return run(o, signals); });
}

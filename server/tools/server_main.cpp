// irradcast-server: runs the GI engine on a scene continuously and streams its irradiance tiles
// to any number of clients (docs/PROTOCOL.md). Stops cleanly on SIGINT / SIGTERM.
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

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
#include "irradcast/service/net_server.h"
#include "scene_options.h"

namespace {

struct Options {
  std::string scene = "cornell";
  std::string scene_root;
  std::string sky_dir;
  float detail = 1.0f;
  std::string bind = "0.0.0.0";
  int port = 7450;
  int io_threads = 2;
  int threads = 0;
  int tile_size = 32;
  float tile_threshold = 0.01f;
  float tile_refresh = 2.0f;
  int engine_nice = 10;
  std::uint32_t max_updates = 0;
  int idle_timeout_s = 30;
  int status_every_s = 5;
  int metrics_port = -1;     // -1: no metrics endpoint
  int http_port = -1;        // -1: no web port
  std::string metrics_bind;  // empty: --bind
  std::string log_level = "info";
  std::string control_token;
  std::string control_token_file;
  std::string tls_cert, tls_key;
  std::uint32_t max_clients = irradcast::ServerOptions().max_clients;
  std::uint32_t max_clients_per_peer = irradcast::ServerOptions().max_clients_per_peer;
  irradcast::tools::EngineOptions engine;
  irradcast::tools::SceneOptions lighting;
};

// The control token for scene edits (docs/EDITS.md) and where it came from, for the log (the
// token itself is never logged). Empty: the server takes no edits.
std::pair<std::string, std::string> control_token(const Options& o) {
  using irradcast::Error;
  if (!o.control_token.empty() && !o.control_token_file.empty())
    throw Error("give --control-token or --control-token-file, not both");
  if (!o.control_token_file.empty()) {
    std::ifstream f(o.control_token_file);
    if (!f) throw Error("--control-token-file: cannot read '" + o.control_token_file + "'");
    std::string line;
    std::getline(f, line);
    const char* space = " \t\r\n";
    const std::size_t first = line.find_first_not_of(space);
    line = first == std::string::npos
               ? ""
               : line.substr(first, line.find_last_not_of(space) + 1 - first);
    if (line.empty())
      throw Error("--control-token-file: the first line of '" + o.control_token_file +
                  "' is empty (it must hold the token)");
    return {line, "file " + o.control_token_file};
  }
  if (!o.control_token.empty()) return {o.control_token, "--control-token"};
  return {"", ""};
}

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

int run(const Options& o, sigset_t signals) {
  using namespace irradcast;
  log::set_level(log::parse_level(o.log_level));
  Progress::set_enabled(false);
  const auto [token, token_source] = control_token(o);
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(o.threads));
  EngineHostOptions ho;
  ho.engine = o.engine.params();
  ho.backend = o.engine.backend_options();
  ho.atlas = o.engine.atlas();
  ho.tiles.tile_size = o.tile_size;
  ho.tiles.change_threshold = o.tile_threshold;
  ho.tiles.refresh_ratio = o.tile_refresh;
  ho.engine_nice = o.engine_nice;
  ho.max_updates = o.max_updates;
  ho.sky_dir = o.sky_dir;
  if (!token.empty() && token.size() < kMinTokenLength)
    throw Error("the control token from " + token_source + " has " + std::to_string(token.size()) +
                " characters; it needs at least " + std::to_string(kMinTokenLength) +
                " (e.g. head -c 18 /dev/urandom | base64)");
  EngineHost host(load_lit_scene(o), o.scene, ho);

  ServerOptions so;
  so.bind = o.bind;
  so.port = static_cast<std::uint16_t>(o.port);
  if (o.http_port >= 0) so.http_port = static_cast<std::uint16_t>(o.http_port);
  so.io_threads = o.io_threads;
  so.idle_timeout = std::chrono::seconds(o.idle_timeout_s);
  so.control_token = token;
  so.tls_cert = o.tls_cert;
  so.tls_key = o.tls_key;
  so.max_clients = o.max_clients;
  so.max_clients_per_peer = o.max_clients_per_peer;
  const std::uint64_t files = raise_open_file_limit();
  if (files < so.max_clients + 64u)
    log::warn("server", "this process may open " + std::to_string(files) +
                            " files, fewer than --max-clients " + std::to_string(so.max_clients) +
                            " needs (raise the hard limit: ulimit -Hn)");
  log::info("server", token.empty()
                          ? std::string("scene edits: disabled")
                          : "scene edits: enabled (control token from " + token_source + ")");
  Server server(host, so);
  server.start();
  std::unique_ptr<MetricsEndpoint> metrics;
  if (o.metrics_port >= 0) {
    MetricsEndpointOptions mo;
    mo.bind = o.metrics_bind.empty() ? o.bind : o.metrics_bind;
    mo.port = static_cast<std::uint16_t>(o.metrics_port);
    mo.tls_cert = o.tls_cert;
    mo.tls_key = o.tls_key;
    // The body runs on the endpoint's thread, after start(): `metrics` is set by then.
    metrics = std::make_unique<MetricsEndpoint>(
        [&server, &host, &metrics] {
          return format_metrics(collect_metrics(server, host, metrics.get()));
        },
        mo);
    metrics->start();  // logs "metrics on http://ADDR:PORT/metrics"
  }
  host.start();

  // The status line, on its own thread, until a signal arrives.
  std::atomic<bool> done{false};
  std::thread status([&] {
    auto next = std::chrono::steady_clock::now();
    while (!done) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      if (o.status_every_s <= 0 || std::chrono::steady_clock::now() < next) continue;
      next += std::chrono::seconds(o.status_every_s);
      const EngineHostStats es = host.stats();
      const ServerStats ss = server.stats();
      char line[384];
      std::snprintf(line, sizeof line,
                    "updates %llu%s (%.2f/s), convergence %.4f, %.2f Mrays/s, %u clients, "
                    "%.2f MB sent, %llu tiles sent, %llu coalesced, %llu queued (max %llu)",
                    static_cast<unsigned long long>(es.updates), es.idle ? " (final)" : "",
                    es.update_rate, es.convergence, es.rays_per_s * 1e-6, ss.clients,
                    ss.bytes_sent * 1e-6, static_cast<unsigned long long>(ss.tiles_sent),
                    static_cast<unsigned long long>(ss.tiles_coalesced),
                    static_cast<unsigned long long>(ss.queue_depth),
                    static_cast<unsigned long long>(ss.queue_depth_max));
      log::info("status", line);
    }
  });
  int sig = 0;
  sigwait(&signals, &sig);
  log::info("server",
            std::string("received ") + (sig == SIGINT ? "SIGINT" : "SIGTERM") + ", shutting down");
  done = true;
  status.join();
  if (metrics) metrics->stop();
  server.stop();
  host.stop();
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
  app.add_option("--bind", o.bind, "address to listen on");
  app.add_option("--port", o.port, "TCP port (0 = any free port)")->check(CLI::Range(0, 65535));
  app.add_option("--io-threads", o.io_threads, "network threads")->check(CLI::Range(1, 64));
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
  app.add_option("--idle-timeout", o.idle_timeout_s,
                 "seconds without a frame before a client is dropped")
      ->check(CLI::Range(1, 86400));
  app.add_option("--status-every", o.status_every_s, "seconds between status lines (0 = none)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--http-port", o.http_port,
                 "serve the browser viewer at http://ADDR:PORT/ and the protocol over a WebSocket "
                 "at /ws (https and wss with --tls-cert; 0 = any free port; off when not given)")
      ->check(CLI::Range(0, 65535))
      ->default_str("off");
  app.add_option("--metrics-port", o.metrics_port,
                 "serve Prometheus metrics at http://ADDR:PORT/metrics (0 = any free port; off "
                 "when not given)")
      ->check(CLI::Range(0, 65535))
      ->default_str("off");
  app.add_option("--metrics-bind", o.metrics_bind,
                 "address for the metrics endpoint (default: the --bind address)");
  app.add_option("--control-token", o.control_token,
                 "accept live scene edits (irradcast-edit) from clients that give this token "
                 "(visible in the process list: prefer --control-token-file); without a token "
                 "the server takes no edits")
      ->default_str("none");
  app.add_option("--control-token-file", o.control_token_file,
                 "read the control token for scene edits from the first line of this file")
      ->default_str("none");
  app.add_option("--max-clients", o.max_clients,
                 "the most sessions at once, all addresses together; past it a new connection "
                 "gets the error 'the server is full' and is closed")
      ->check(CLI::Range(1u, 1000000u));
  app.add_option("--max-clients-per-peer", o.max_clients_per_peer,
                 "the most sessions from one address (an IPv6 /64) at once; past it a new "
                 "connection is refused (0 = no limit; irradcast-load users on one machine count "
                 "as one address)");
  app.add_option("--tls-cert", o.tls_cert,
                 "serve TLS on the protocol port and the metrics endpoint with this PEM "
                 "certificate chain (with --tls-key; docs/OPERATIONS.md)")
      ->default_str("none");
  app.add_option("--tls-key", o.tls_key, "the PEM private key of --tls-cert")->default_str("none");
  app.add_option("--log-level", o.log_level, "debug | info | warn | error | off");
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
  // Block the stop signals in every thread (threads inherit the mask); main waits for them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  try {
    return run(o, signals);
  } catch (const irradcast::Error& e) {
    std::fprintf(stderr, "irradcast-server: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "irradcast-server: internal error: %s\n", e.what());
    return 2;
  }
}

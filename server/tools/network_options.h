// The network options irradcast-server and irradcast-gateway share (the protocol port, TLS,
// limits, the control token, the metrics endpoint, logging): their CLI, the ServerOptions they
// make, the metrics endpoint with a body function, and main()'s signal and error handling.
#pragma once

#include "irradcast/common/cli.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <pthread.h>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/net_server.h"
#include "irradcast/service/web_origin.h"

namespace irradcast::tools {

// The server's part of a status line: clients and traffic.
inline std::string traffic_status(const ServerStats& ss) {
  char text[192];
  std::snprintf(text, sizeof text,
                "%u clients, %.2f MB sent, %llu tiles sent, %llu coalesced, %llu queued (max %llu)",
                ss.clients, ss.bytes_sent * 1e-6, static_cast<unsigned long long>(ss.tiles_sent),
                static_cast<unsigned long long>(ss.tiles_coalesced),
                static_cast<unsigned long long>(ss.queue_depth),
                static_cast<unsigned long long>(ss.queue_depth_max));
  return text;
}

struct NetworkOptions {
  std::string bind = "0.0.0.0";
  int port = 7450;
  int io_threads = 2;
  int idle_timeout_s = 30;
  int status_every_s = 5;
  int metrics_port = -1;     // -1: no metrics endpoint
  int http_port = -1;        // -1: no web port (browser viewer and WebSocket)
  std::string metrics_bind;  // empty: --bind
  std::string log_level = "info";
  std::string control_token;
  std::string control_token_file;
  std::string tls_cert, tls_key;
  std::vector<std::string> allowed_origins;  // --allowed-origin
  std::vector<std::string> trusted_proxies;  // --trusted-proxy
  std::string forwarded_header = "x-forwarded-for";
  std::string proxy_protocol = "none";
  std::uint32_t max_clients = ServerOptions().max_clients;
  std::uint32_t max_clients_per_peer = ServerOptions().max_clients_per_peer;
  bool presence = false;
  std::uint32_t presence_nearest = ServerOptions().presence_nearest;
  double presence_hz = ServerOptions().presence_hz;
  float presence_height = 0.0f;  // 0: the program's default (presence_default_height)

  void add_to(CLI::App& app) {
    add_ports(app);
    add_proxies(app);
    add_access(app);
    add_presence(app);
  }

  // Ports, threads, timeouts, the web and metrics ports.
  void add_ports(CLI::App& app) {
    app.add_option("--bind", bind, "address to listen on");
    app.add_option("--port", port, "TCP port (0 = any free port)")->check(CLI::Range(0, 65535));
    app.add_option("--io-threads", io_threads, "network threads")->check(CLI::Range(1, 64));
    app.add_option("--idle-timeout", idle_timeout_s,
                   "seconds without a frame before a client is dropped")
        ->check(CLI::Range(1, 86400));
    app.add_option("--status-every", status_every_s, "seconds between status lines (0 = none)")
        ->check(CLI::NonNegativeNumber);
    app.add_option("--http-port", http_port,
                   "serve the browser viewer at http://ADDR:PORT/ and the protocol over a "
                   "WebSocket at /ws (https and wss with --tls-cert; 0 = any free port; off when "
                   "not given)")
        ->check(CLI::Range(0, 65535))
        ->default_str("off");
    app.add_option("--allowed-origin", allowed_origins,
                   "a page origin (scheme://host[:port]) whose scripts may open the web port's "
                   "WebSocket besides pages of this server's own host (repeat or "
                   "comma-separate; docs/OPERATIONS.md)")
        ->delimiter(',');
    app.add_option("--metrics-port", metrics_port,
                   "serve Prometheus metrics at http://ADDR:PORT/metrics (0 = any free port; off "
                   "when not given)")
        ->check(CLI::Range(0, 65535))
        ->default_str("off");
    app.add_option("--metrics-bind", metrics_bind,
                   "address for the metrics endpoint (default: the --bind address)");
    app.add_option("--log-level", log_level, "debug | info | warn | error | off");
  }

  // Reverse proxies: whose client addresses are believed, and how they are told.
  void add_proxies(CLI::App& app) {
    app.add_option("--trusted-proxy", trusted_proxies,
                   "reverse proxies or load balancers (CIDR[,CIDR...], e.g. 10.0.0.0/8) whose "
                   "PROXY protocol v2 header, and on the web port whose --forwarded-header, name "
                   "the client each connection is limited and banned under (docs/OPERATIONS.md "
                   "\"Behind a proxy\"); what other peers send is ignored")
        ->delimiter(',')
        ->check(CLI::Validator(
            [](std::string& cidr) {
              try {
                check_trusted_proxies({cidr});
                return std::string();
              } catch (const Error& e) {
                return std::string(e.what());
              }
            },
            "CIDR"));
    app.add_option("--forwarded-header", forwarded_header,
                   "the header the trusted proxies append their clients' addresses to, on the "
                   "web port (the other one is ignored: a client could write it)")
        ->check(CLI::IsMember({"x-forwarded-for", "forwarded"}, CLI::ignore_case));
    app.add_option("--proxy-protocol", proxy_protocol,
                   "the ports on which every connection from a --trusted-proxy starts with a "
                   "PROXY protocol v2 header (HAProxy's send-proxy-v2; a LOCAL header for its "
                   "health checks): none, protocol, web or both; one without is refused, and "
                   "on other ports no PROXY header is read")
        ->check(CLI::IsMember({"none", "protocol", "web", "both"}, CLI::ignore_case));
  }

  // Who may edit, how many may connect, TLS.
  void add_access(CLI::App& app) {
    app.add_option("--control-token", control_token,
                   "accept live scene edits (irradcast-edit) from clients that give this token "
                   "(visible in the process list: prefer --control-token-file); without a token "
                   "the server takes no edits")
        ->default_str("none");
    app.add_option("--control-token-file", control_token_file,
                   "read the control token for scene edits from the first line of this file")
        ->default_str("none");
    app.add_option("--max-clients", max_clients,
                   "the most sessions at once, all addresses together; past it a new connection "
                   "gets the error 'the server is full' and is closed")
        ->check(CLI::Range(1u, 1000000u));
    app.add_option("--max-clients-per-peer", max_clients_per_peer,
                   "the most sessions from one address (an IPv6 /64) at once; past it a new "
                   "connection is refused (0 = no limit; irradcast-load users on one machine "
                   "count as one address)");
    app.add_option("--tls-cert", tls_cert,
                   "serve TLS on the protocol port and the metrics endpoint with this PEM "
                   "certificate chain (with --tls-key; docs/OPERATIONS.md)")
        ->default_str("none");
    app.add_option("--tls-key", tls_key, "the PEM private key of --tls-cert")->default_str("none");
  }

  // --presence and its settings (docs/DYNAMIC.md#presence).
  void add_presence(CLI::App& app) {
    app.add_flag("--presence", presence,
                 "show each viewer that asks (irradcast-view --presence) to the others as an "
                 "avatar at its camera, lit like the dynamic objects (docs/DYNAMIC.md#presence)");
    app.add_option("--presence-nearest", presence_nearest,
                   "the most avatars a viewer is sent: those nearest its camera")
        ->check(CLI::Range(1u, 256u));
    app.add_option("--presence-hz", presence_hz, "the most avatar updates a viewer gets a second")
        ->check(CLI::Range(0.1, 60.0));
    app.add_option("--presence-height", presence_height,
                   "metres from an avatar's foot to its eye (default: 1.7, or a quarter of the "
                   "scene's largest extent when that is less)")
        ->check(CLI::Range(0.001f, 100.0f));
  }

  // The avatars' height: --presence-height, else 1.7 m, or a quarter of `scene_extent` (metres;
  // 0: unknown) when that is less (a person in the Cornell box would not fit).
  // The time between two avatar sets at --presence-hz (what NATS carries between servers).
  std::chrono::milliseconds presence_every() const {
    return std::chrono::milliseconds(
        std::max<long long>(1, std::llround(1000.0 / std::max(presence_hz, 1e-3))));
  }
  float presence_default_height(float scene_extent) const {
    if (presence_height > 0.0f) return presence_height;
    return scene_extent > 0.0f ? std::min(1.7f, 0.25f * scene_extent) : 1.7f;
  }

  // What a serving program does first: its log level, no progress bars (a service logs
  // lines), and its control token (token()).
  std::pair<std::string, std::string> begin_serving() const {
    log::set_level(log::parse_level(log_level));
    Progress::set_enabled(false);
    return token();
  }

  // The control token for scene edits (docs/EDITS.md) and where it came from, for the log (the
  // token itself is never logged). Empty: no edits.
  std::pair<std::string, std::string> token() const {
    if (!control_token.empty() && !control_token_file.empty())
      throw Error("give --control-token or --control-token-file, not both");
    if (!control_token_file.empty()) {
      std::ifstream f(control_token_file);
      if (!f) throw Error("--control-token-file: cannot read '" + control_token_file + "'");
      std::string line;
      std::getline(f, line);
      const char* space = " \t\r\n";
      const std::size_t first = line.find_first_not_of(space);
      line = first == std::string::npos
                 ? ""
                 : line.substr(first, line.find_last_not_of(space) + 1 - first);
      if (line.empty())
        throw Error("--control-token-file: the first line of '" + control_token_file +
                    "' is empty (it must hold the token)");
      return {line, "file " + control_token_file};
    }
    if (!control_token.empty()) return {control_token, "--control-token"};
    return {"", ""};
  }

  // The server's options with `token`; checks its length and the open-file limit (logs).
  ServerOptions server_options(const std::pair<std::string, std::string>& token,
                               const char* tag) const {
    if (!token.first.empty() && token.first.size() < kMinTokenLength)
      throw Error("the control token from " + token.second + " has " +
                  std::to_string(token.first.size()) + " characters; it needs at least " +
                  std::to_string(kMinTokenLength) + " (e.g. head -c 18 /dev/urandom | base64)");
    ServerOptions so;
    so.bind = bind;
    so.port = static_cast<std::uint16_t>(port);
    if (http_port >= 0) so.http_port = static_cast<std::uint16_t>(http_port);
    so.io_threads = io_threads;
    so.idle_timeout = std::chrono::seconds(idle_timeout_s);
    so.control_token = token.first;
    for (const std::string& origin : allowed_origins) check_origin(origin);
    so.allowed_origins = allowed_origins;
    so.trusted_proxies = trusted_proxies;
    so.forwarded_header = forwarded_header == "forwarded" ? ForwardedHeader::Forwarded
                                                          : ForwardedHeader::XForwardedFor;
    so.proxy_protocol = proxy_protocol == "protocol" || proxy_protocol == "both";
    so.web_proxy_protocol = proxy_protocol == "web" || proxy_protocol == "both";
    if ((so.proxy_protocol || so.web_proxy_protocol) && trusted_proxies.empty())
      throw Error("--proxy-protocol " + proxy_protocol +
                  " needs --trusted-proxy (whose "
                  "connections carry the header)");
    if (!trusted_proxies.empty())
      log::info(tag, "trusted proxies: " + std::to_string(trusted_proxies.size()) +
                         " networks; clients' addresses from " +
                         (so.forwarded_header == ForwardedHeader::Forwarded ? "Forwarded"
                                                                            : "X-Forwarded-For") +
                         " on the web port and PROXY headers on " + proxy_protocol +
                         " (--proxy-protocol)");
    so.tls_cert = tls_cert;
    so.tls_key = tls_key;
    so.max_clients = max_clients;
    so.max_clients_per_peer = max_clients_per_peer;
    so.presence = presence;
    so.presence_nearest = presence_nearest;
    so.presence_hz = presence_hz;
    so.presence_height = presence_default_height(0.0f);
    const std::uint64_t files = raise_open_file_limit();
    if (files < so.max_clients + 64u)
      log::warn(tag, "this process may open " + std::to_string(files) +
                         " files, fewer than --max-clients " + std::to_string(so.max_clients) +
                         " needs (raise the hard limit: ulimit -Hn)");
    log::info(tag, token.first.empty()
                       ? std::string("scene edits: disabled")
                       : "scene edits: enabled (control token from " + token.second + ")");
    return so;
  }

  // The metrics endpoint (started; logs its URL) when --metrics-port was given, else null.
  // `body` gets the endpoint (for its own stats) and runs on the endpoint's thread.
  std::unique_ptr<MetricsEndpoint> start_metrics(
      std::function<std::string(const MetricsEndpoint*)> body) const {
    if (metrics_port < 0) return nullptr;
    MetricsEndpointOptions mo;
    mo.bind = metrics_bind.empty() ? bind : metrics_bind;
    mo.port = static_cast<std::uint16_t>(metrics_port);
    mo.tls_cert = tls_cert;
    mo.tls_key = tls_key;
    auto self = std::make_shared<const MetricsEndpoint*>(nullptr);
    auto metrics = std::make_unique<MetricsEndpoint>(
        [body = std::move(body), self] { return body(*self); }, mo);
    *self = metrics.get();
    metrics->start();  // logs "metrics on http://ADDR:PORT/metrics"
    return metrics;
  }
};

// SIGHUP: --tls-cert and --tls-key loaded again for new connections on every port (a bad file
// keeps the current certificate; both are logged).
inline void reload_tls(const char* component, Server& server, MetricsEndpoint* metrics) {
  log::info(component, "received SIGHUP: reloading the TLS certificate");
  server.reload_tls();
  if (metrics) metrics->reload_tls();
}

// The rest of a service program's main() after its options are parsed: blocks SIGINT, SIGTERM
// and SIGHUP in every thread (threads inherit the mask; `run` waits for them: SIGHUP reloads the
// TLS certificate, reload_tls below), ignores SIGPIPE, and
// turns errors into "TOOL: error: ..." and exit status 1 (2 for internal errors).
inline int run_service(const char* tool, const std::function<int(const sigset_t&)>& run) {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  try {
    return run(signals);
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", tool, e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", tool, e.what());
    return 2;
  }
}

}  // namespace irradcast::tools

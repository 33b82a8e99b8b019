// A minimal HTTP/1.1 endpoint for Prometheus scrapes, on its own port, io_context and thread,
// so that a scrape never waits on the game clients' I/O threads and a bad scrape never touches
// them. `GET /metrics` (or HEAD) answers 200 with the text of a body function (for the server,
// format_metrics(collect_metrics(server, host)), metrics_text.h); another path 404, another
// method 405, a malformed request 400, an oversized request line 414 or headers 431. One request
// per connection: every response says `Connection: close`.
//
// Built to keep answering real scrapers under load (docs/METRICS.md, "Load"): a deep accept
// backlog; up to max_connections open at once, and past that the endpoint drops the oldest
// connection that cannot be a live scrape (already answered, else the oldest with an incomplete
// request) instead of refusing the new one; a deadline for the request head (slowloris) and one
// for the whole connection; a cap on the head's bytes; the body function's text reused for
// cache_for, so a thousand concurrent scrapes cost one collection.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace irradcast {

struct MetricsEndpointOptions {
  std::string bind = "0.0.0.0";
  std::uint16_t port = 9450;  // 0 = any free port (see MetricsEndpoint::port())
  // The request line and headers must have arrived within this time after the connection was
  // accepted, however slowly they trickle in; else the connection is closed without a response.
  std::chrono::milliseconds header_timeout{2000};
  // A connection's whole life: the request, the response, and the wait for the client to close.
  std::chrono::milliseconds timeout{5000};
  // Request line and headers. A longer request line is a 414, longer headers a 431.
  std::size_t max_request_bytes = 8192;
  // Connections open at once (at most a quarter of the process's RLIMIT_NOFILE soft limit at
  // start(), so that the game server keeps its descriptors). A new connection is never refused:
  // with this many open, one is dropped to make room (MetricsEndpointStats::dropped): the oldest
  // already answered, else the oldest whose request is incomplete, else the oldest response
  // being written.
  std::uint32_t max_connections = 1024;
  // The kernel's queue of connections not yet accepted (capped by net.core.somaxconn).
  int listen_backlog = 4096;
  // The body function's text is served again for this long after it was made (0: the function
  // is called for every GET), so concurrent scrapes do not each collect the stats.
  std::chrono::milliseconds cache_for{100};
  // HTTPS: PEM certificate chain and private key (both, or neither for plain HTTP); the same
  // files as the protocol port's --tls-cert and --tls-key. The TLS handshake counts against
  // header_timeout.
  std::string tls_cert, tls_key;
};

struct MetricsEndpointStats {
  std::uint64_t connections = 0;  // accepted
  std::uint64_t open = 0;         // open now
  std::uint64_t dropped = 0;      // closed to make room for a new one (max_connections open)
  std::uint64_t ok = 0;           // 200 responses
  std::uint64_t bad = 0;          // 4xx and 5xx responses
  std::uint64_t timeouts = 0;     // closed by a deadline before a response was sent
  std::uint64_t collections = 0;  // calls of the body function
};

class MetricsEndpoint {
 public:
  // `body` is called on the endpoint's thread for a GET /metrics when the cached text is older
  // than cache_for; it must be thread-safe with respect to whatever it reads. If it throws, the
  // response is a 500 (and nothing is cached).
  using BodyFunction = std::function<std::string()>;
  MetricsEndpoint(BodyFunction body, MetricsEndpointOptions options);
  ~MetricsEndpoint();
  MetricsEndpoint(const MetricsEndpoint&) = delete;
  MetricsEndpoint& operator=(const MetricsEndpoint&) = delete;

  // Binds and starts the thread. Throws irradcast::Error if the address cannot be bound.
  void start();
  // Closes every connection and joins the thread. Idempotent; the endpoint does not restart.
  void stop();
  // Loads its TLS certificate and key again (SIGHUP): new connections get them (false without
  // TLS or when a file is bad, which is logged; the current certificate stays).
  bool reload_tls();
  std::uint16_t port() const;
  // The address to scrape, e.g. "http://127.0.0.1:9450/metrics" ("https://" with TLS).
  std::string url() const;
  // max_connections as applied by start() (the descriptor limit may lower it).
  std::uint32_t max_connections() const;
  MetricsEndpointStats stats() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace irradcast

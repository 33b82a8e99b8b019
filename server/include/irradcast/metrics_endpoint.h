// A minimal HTTP/1.1 endpoint for Prometheus scrapes, on its own port, io_context and thread,
// so that a scrape never waits on the game clients' I/O threads and a bad scrape never touches
// them. `GET /metrics` (or HEAD) answers 200 with the text of a body function (for the server,
// format_metrics(collect_metrics(server, host)), metrics_text.h); another path 404, another
// method 405, a malformed or oversized request 400. One request per connection: every response
// says `Connection: close`. A connection that has not finished within the timeout is closed.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace irradcast {

struct MetricsEndpointOptions {
  std::string bind = "0.0.0.0";
  std::uint16_t port = 9450;  // 0 = any free port (see MetricsEndpoint::port())
  // A connection's whole life: the request must arrive and the response be written within it.
  std::chrono::milliseconds timeout{5000};
  std::size_t max_request_bytes = 8192;  // request line and headers; more is a 400
  std::uint32_t max_connections = 64;    // open at once; more are closed when accepted
};

struct MetricsEndpointStats {
  std::uint64_t connections = 0;  // accepted
  std::uint64_t refused = 0;      // closed at once: max_connections open
  std::uint64_t ok = 0;           // 200 responses
  std::uint64_t bad = 0;          // 4xx and 5xx responses
  std::uint64_t timeouts = 0;     // connections closed by the timeout
};

class MetricsEndpoint {
 public:
  // `body` is called on the endpoint's thread for each GET /metrics; it must be thread-safe with
  // respect to whatever it reads. If it throws, the response is a 500.
  using BodyFunction = std::function<std::string()>;
  MetricsEndpoint(BodyFunction body, MetricsEndpointOptions options);
  ~MetricsEndpoint();
  MetricsEndpoint(const MetricsEndpoint&) = delete;
  MetricsEndpoint& operator=(const MetricsEndpoint&) = delete;

  // Binds and starts the thread. Throws irradcast::Error if the address cannot be bound.
  void start();
  // Closes every connection and joins the thread. Idempotent; the endpoint does not restart.
  void stop();
  std::uint16_t port() const;
  // The address to scrape, e.g. "http://127.0.0.1:9450/metrics".
  std::string url() const;
  MetricsEndpointStats stats() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace irradcast

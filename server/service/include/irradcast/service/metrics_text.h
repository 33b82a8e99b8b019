// The server's metrics in the Prometheus text exposition format (version 0.0.4): what the
// metrics endpoint serves at /metrics. The formatting takes plain structs (a snapshot of
// Server::stats() and EngineHost::stats()) and returns the text, so it is testable without a
// server. Every metric is named irradcast_*, has # HELP and # TYPE lines, counters end in
// _total, and units are seconds and bytes. The list with meanings: docs/METRICS.md.
#pragma once

#include <string>
#include <string_view>

#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/net_server.h"
#include "irradcast/service/tile_source.h"

namespace irradcast {

struct MetricsSnapshot {
  std::string scene;    // the scene id: a label of irradcast_info
  std::string backend;  // the engine's backend and device (TraceBackend::describe()): another
  ServerStats server;
  EngineHostStats engine;
  MetricsEndpointStats endpoint;  // the /metrics endpoint itself (irradcast_metrics_*)
};

// Reads the stats of a running (or stopped) server and engine host, and of the endpoint when one
// is given. Thread-safe; takes the server's session lock and the engine host's stats lock, each
// briefly (the endpoint caches the text, so this runs at most a few times a second).
MetricsSnapshot collect_metrics(const Server& server, const TileSource& host,
                                const MetricsEndpoint* endpoint = nullptr);

// The exposition text: one family per metric, # HELP and # TYPE before its samples, one sample
// per line (`name{label="value",...} value`), "\n" line ends.
std::string format_metrics(const MetricsSnapshot& metrics);

// Appends one unlabelled metric (# HELP, # TYPE and its sample) to `out`: for the families of
// the NATS origin and gateway (nats_origin.h, nats_gateway.h).
void append_metric(std::string& out, std::string_view name, std::string_view type,
                   std::string_view help, double value);

// A label value with \, " and newline escaped (\\, \", \n), as the format requires.
std::string escape_label_value(std::string_view value);
// A sample value in the shortest form that reads back (strtod) to the same double; NaN as NaN,
// infinities as +Inf / -Inf. (Integer counters are written with all their digits.)
std::string format_metric_value(double value);

}  // namespace irradcast

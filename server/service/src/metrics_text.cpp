// The Prometheus text exposition of the server's and the engine's stats (metrics_text.h).
#include "irradcast/service/metrics_text.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace irradcast {

namespace {

using Labels = std::vector<std::pair<std::string, std::string>>;

// Escapes backslashes and newlines (HELP text), and double quotes too for label values.
std::string escape(std::string_view text, bool quotes) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '"' && quotes)
      out += "\\\"";
    else if (c == '\n')
      out += "\\n";
    else
      out += c;
  }
  return out;
}

// Writes families: # HELP and # TYPE once, then the family's samples.
class Writer {
 public:
  void family(std::string_view name, std::string_view type, std::string_view help) {
    name_ = name;
    out_ += "# HELP ";
    out_ += name;
    out_ += ' ';
    out_ += escape(help, false);
    out_ += "\n# TYPE ";
    out_ += name;
    out_ += ' ';
    out_ += type;
    out_ += '\n';
  }
  void sample(const Labels& labels, double value) { line(labels, format_metric_value(value)); }
  void sample(const Labels& labels, std::uint64_t value) { line(labels, std::to_string(value)); }

  // A family with one unlabelled sample.
  void gauge(std::string_view name, std::string_view help, double value) {
    family(name, "gauge", help);
    sample({}, value);
  }
  void gauge(std::string_view name, std::string_view help, std::uint64_t value) {
    family(name, "gauge", help);
    sample({}, value);
  }
  void counter(std::string_view name, std::string_view help, double value) {
    family(name, "counter", help);
    sample({}, value);
  }
  void counter(std::string_view name, std::string_view help, std::uint64_t value) {
    family(name, "counter", help);
    sample({}, value);
  }

  std::string take() { return std::move(out_); }

 private:
  void line(const Labels& labels, const std::string& value) {
    out_ += name_;
    if (!labels.empty()) {
      out_ += '{';
      for (std::size_t i = 0; i < labels.size(); ++i) {
        if (i > 0) out_ += ',';
        out_ += labels[i].first;
        out_ += "=\"";
        out_ += escape_label_value(labels[i].second);
        out_ += '"';
      }
      out_ += '}';
    }
    out_ += ' ';
    out_ += value;
    out_ += '\n';
  }

  std::string out_;
  std::string name_;
};

Labels pass_labels(const EnginePassStats& p) {
  return {{"pass", p.pass}, {"bounce", std::to_string(p.bounce)}};
}

// One family with a sample per engine pass.
template <class Value>
void pass_family(Writer& w, const EngineHostStats& e, std::string_view name, std::string_view type,
                 std::string_view help, Value value) {
  w.family(name, type, help);
  for (const EnginePassStats& p : e.passes) w.sample(pass_labels(p), value(p));
}

void write_clients(Writer& w, const ServerStats& s) {
  w.gauge("irradcast_clients", "Connected clients (sessions).", std::uint64_t{s.clients});
  // Every counter of server_counters.inc, in its order.
#define IRRADCAST_SERVER_COUNTER(name, wire, metric, help) w.counter(metric, help, s.name);
#include "irradcast/service/server_counters.inc"
#undef IRRADCAST_SERVER_COUNTER
  w.gauge("irradcast_partial_frame_bytes", "Bytes of incomplete frames the sessions hold.",
          s.partial_bytes);
  w.family("irradcast_sessions_closed_total", "counter", "Sessions that ended, by reason.");
  for (std::size_t r = 0; r < kCloseReasons; ++r)
    w.sample({{"reason", close_reason_name(static_cast<CloseReason>(r))}}, s.sessions_closed[r]);
}

// Queues and tiles (the traffic counters are in write_clients, from server_counters.inc).
void write_traffic(Writer& w, const ServerStats& s, const EngineHostStats& e) {
  w.gauge("irradcast_queue_depth", "Tiles waiting to be sent, summed over all clients.",
          s.queue_depth);
  w.gauge("irradcast_queue_depth_max", "Tiles waiting for the client with the longest queue.",
          s.queue_depth_max);
  w.gauge("irradcast_tiles", "Tiles of all lightmaps of the scene.", e.tiles);
  w.counter("irradcast_tiles_published_total", "New tile versions the engine published.",
            e.tiles_published);
  w.gauge("irradcast_bytes_per_texel",
          "Mean encoded size of the newest tile payloads (RGB9E5 + zstd), bytes per texel.",
          e.bytes_per_texel);
}

void write_engine(Writer& w, const EngineHostStats& e) {
  w.counter("irradcast_engine_updates_total", "Progressive engine updates completed.", e.updates);
  w.gauge("irradcast_engine_update_rate",
          "Engine updates per second over the last 10 seconds (falls to 0 within 10 s once the "
          "engine stops refining).",
          e.update_rate);
  w.gauge("irradcast_engine_update_seconds", "Wall time of the last engine update.",
          e.last_update_ms * 1e-3);
  w.counter("irradcast_engine_seconds_total", "Wall time spent in engine updates.",
            e.seconds_total);
  w.counter("irradcast_engine_rays_total", "Rays traced by the engine.", e.rays_total);
  w.gauge("irradcast_engine_rays_per_second", "Rays per second of the last engine update.",
          e.rays_per_s);
  w.gauge("irradcast_engine_convergence",
          "Mean relative standard error of the lightmap texels (lower is more converged).",
          e.convergence);
  w.gauge("irradcast_engine_idle",
          "1 when the engine stopped refining (--max-updates reached): the tiles are final.",
          std::uint64_t{e.idle ? 1u : 0u});
  w.gauge("irradcast_engine_texels", "Texels the engine computes.", e.texels);
  w.gauge("irradcast_scene_revision", "Scene edits applied since the scene was loaded.",
          e.revision);
  w.gauge("irradcast_edit_apply_seconds", "Wall time the last scene edit took to apply.",
          e.last_edit_ms / 1e3);
  w.gauge("irradcast_engine_stale_texels",
          "Texels still waiting for new direct light since the last edit (0: caught up).",
          e.stale_texels);
  pass_family(w, e, "irradcast_engine_pass_seconds", "gauge",
              "Wall time of each engine pass in the last update (bounce 0: direct).",
              [](const EnginePassStats& p) { return p.seconds; });
  pass_family(w, e, "irradcast_engine_pass_rays", "gauge",
              "Rays of each engine pass in the last update.",
              [](const EnginePassStats& p) { return p.rays; });
  pass_family(w, e, "irradcast_engine_pass_seconds_total", "counter",
              "Wall time of each engine pass, summed over all updates.",
              [](const EnginePassStats& p) { return p.seconds_total; });
  pass_family(w, e, "irradcast_engine_pass_rays_total", "counter",
              "Rays of each engine pass, summed over all updates.",
              [](const EnginePassStats& p) { return p.rays_total; });
}

// The /metrics endpoint itself.
void write_endpoint(Writer& w, const MetricsEndpointStats& x) {
  w.counter("irradcast_metrics_connections_total", "Connections the metrics endpoint accepted.",
            x.connections);
  w.gauge("irradcast_metrics_connections_open", "Connections open at the metrics endpoint.",
          x.open);
  w.counter("irradcast_metrics_connections_dropped_total",
            "Metrics endpoint connections closed to make room for a new one (max_connections "
            "open): answered ones first, then the oldest with an incomplete request.",
            x.dropped);
  w.counter("irradcast_metrics_connections_timed_out_total",
            "Metrics endpoint connections closed by a deadline (request head or whole "
            "connection) before their response was written.",
            x.timeouts);
  w.counter("irradcast_metrics_scrapes_total", "Metrics endpoint 200 responses.", x.ok);
  w.counter("irradcast_metrics_errors_total", "Metrics endpoint 4xx and 5xx responses.", x.bad);
  w.counter("irradcast_metrics_collections_total",
            "Times the metrics text was made (concurrent scrapes share one).", x.collections);
}

}  // namespace

std::string escape_label_value(std::string_view value) {
  return escape(value, true);
}

std::string format_metric_value(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, value);
  if (ec != std::errc()) return "NaN";  // cannot happen: 64 characters hold any double
  return std::string(buf, end);
}

void append_metric(std::string& out, std::string_view name, std::string_view type,
                   std::string_view help, double value) {
  out.append("# HELP ").append(name).append(" ").append(help).append("\n# TYPE ");
  out.append(name).append(" ").append(type).append("\n").append(name).append(" ");
  out.append(format_metric_value(value)).append("\n");
}

MetricsSnapshot collect_metrics(const Server& server, const TileSource& host,
                                const MetricsEndpoint* endpoint) {
  MetricsSnapshot m;
  if (endpoint) m.endpoint = endpoint->stats();
  m.scene = host.scene_id();
  m.backend = host.backend_name();
  m.server = server.stats();
  m.engine = host.stats();
  return m;
}

std::string format_metrics(const MetricsSnapshot& m) {
  Writer w;
  w.family("irradcast_info", "gauge",
           "Always 1; the labels name the scene being served and the engine's backend.");
  w.sample({{"scene", m.scene}, {"backend", m.backend}}, std::uint64_t{1});
  w.gauge("irradcast_uptime_seconds", "Seconds since the server started.", m.server.uptime_seconds);
  write_clients(w, m.server);
  write_traffic(w, m.server, m.engine);
  write_engine(w, m.engine);
  write_endpoint(w, m.endpoint);
  return w.take();
}

}  // namespace irradcast

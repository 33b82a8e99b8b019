// Server metrics: the Prometheus text formatter, the HTTP endpoint (good and bad requests,
// timeouts), and the numbers it and the Stats frame report for a live engine host and server.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <asio.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>
#include <thread>

#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/metrics_endpoint.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/service/nats_gateway.h"
#include "irradcast/service/nats_origin.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/frame.h"
#include "service_fixture.h"

namespace irradcast::test_metrics {

using asio::ip::tcp;
using namespace std::chrono_literals;

namespace {

// ---------------------------------------------------------------------------------------------
// A strict reader of the text exposition format, for checking what the formatter writes.

using LabelMap = std::map<std::string, std::string>;

struct Sample {
  std::string name;
  LabelMap labels;
  std::string value;  // as written
};

struct Exposition {
  std::map<std::string, std::string> help, type;
  std::vector<Sample> samples;
  std::vector<std::string> errors;  // every rule broken, one line each

  const Sample* find(const std::string& name, const LabelMap& labels = {}) const {
    for (const Sample& s : samples)
      if (s.name == name && s.labels == labels) return &s;
    return nullptr;
  }
  double value(const std::string& name, const LabelMap& labels = {}) const {
    const Sample* s = find(name, labels);
    if (!s) throw std::runtime_error("no sample " + name);
    return std::strtod(s->value.c_str(), nullptr);
  }
  std::vector<const Sample*> family(const std::string& name) const {
    std::vector<const Sample*> out;
    for (const Sample& s : samples)
      if (s.name == name) out.push_back(&s);
    return out;
  }
};

bool valid_value(const std::string& v) {
  if (v == "NaN" || v == "+Inf" || v == "-Inf") return true;
  char* end = nullptr;
  std::strtod(v.c_str(), &end);
  return !v.empty() && end == v.c_str() + v.size();
}

bool metric_name_char(char c, bool first) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' || c == ':' ||
         (!first && c >= '0' && c <= '9');
}
bool valid_metric_name(const std::string& name) {
  if (name.empty()) return false;
  for (std::size_t i = 0; i < name.size(); ++i)
    if (!metric_name_char(name[i], i == 0)) return false;
  return true;
}
bool valid_label_name(const std::string& name) {
  return valid_metric_name(name) && name.find(':') == std::string::npos;
}

// Label pairs `name="value"` separated by commas from text[i], up to and including the closing
// brace; values escape \\, \" and \n. Returns the position after the brace, or npos.
std::size_t parse_labels(const std::string& text, std::size_t i, LabelMap& out) {
  if (i < text.size() && text[i] == '}') return i + 1;
  for (;;) {
    const std::size_t eq = text.find('=', i);
    if (eq == std::string::npos) return std::string::npos;
    const std::string name = text.substr(i, eq - i);
    if (!valid_label_name(name) || out.count(name)) return std::string::npos;
    if (eq + 1 >= text.size() || text[eq + 1] != '"') return std::string::npos;
    std::string value;
    std::size_t j = eq + 2;
    for (;; ++j) {
      if (j >= text.size()) return std::string::npos;
      const char c = text[j];
      if (c == '"') break;
      if (c == '\n') return std::string::npos;
      if (c == '\\') {
        if (++j >= text.size()) return std::string::npos;
        const char e = text[j];
        if (e == '\\')
          value += '\\';
        else if (e == '"')
          value += '"';
        else if (e == 'n')
          value += '\n';
        else
          return std::string::npos;
      } else {
        value += c;
      }
    }
    out[name] = value;
    i = j + 1;
    if (i >= text.size()) return std::string::npos;
    if (text[i] == '}') return i + 1;
    if (text[i] != ',') return std::string::npos;
    ++i;
  }
}

// `name{labels} value` or `name value` (no time stamps).
bool parse_sample(const std::string& line, Sample& s) {
  std::size_t i = 0;
  while (i < line.size() && metric_name_char(line[i], i == 0)) ++i;
  s.name = line.substr(0, i);
  if (s.name.empty() || i >= line.size()) return false;
  if (line[i] == '{') {
    i = parse_labels(line, i + 1, s.labels);
    if (i == std::string::npos || i >= line.size()) return false;
  }
  if (line[i] != ' ') return false;
  s.value = line.substr(i + 1);
  return !s.value.empty() && s.value.find(' ') == std::string::npos;
}

Exposition parse_exposition(const std::string& text) {
  Exposition x;
  if (text.empty() || text.back() != '\n') x.errors.push_back("the text does not end in \\n");
  std::set<std::string> finished;  // families whose samples are over
  std::set<std::string> keys;
  std::string current;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t nl = text.find('\n', pos);
    if (nl == std::string::npos) nl = text.size();
    const std::string line = text.substr(pos, nl - pos);
    pos = nl + 1;
    if (line.rfind("#", 0) == 0) {
      // `# HELP name text` or `# TYPE name type`
      const std::string kind = line.substr(0, 7);
      const std::size_t space = line.find(' ', 7);
      if ((kind != "# HELP " && kind != "# TYPE ") || space == std::string::npos) {
        x.errors.push_back("unexpected comment: " + line);
        continue;
      }
      const std::string name = line.substr(7, space - 7), rest = line.substr(space + 1);
      if (!valid_metric_name(name)) x.errors.push_back("bad name: " + line);
      auto& map = kind == "# HELP " ? x.help : x.type;
      if (map.count(name)) x.errors.push_back("second " + kind + "for " + name);
      if (finished.count(name) || name == current)
        x.errors.push_back(kind + "after the samples of " + name);
      map[name] = rest;
      if (kind == "# TYPE ") {
        if (rest != "counter" && rest != "gauge")
          x.errors.push_back("type " + rest + " of " + name);
        const bool total = name.size() > 6 && name.substr(name.size() - 6) == "_total";
        if ((rest == "counter") != total)
          x.errors.push_back(name + ": counters and only counters end in _total");
      }
      if (name.rfind("irradcast_", 0) != 0) x.errors.push_back(name + " lacks the prefix");
      continue;
    }
    Sample s;
    if (!parse_sample(line, s)) {
      x.errors.push_back("not a sample line: " + line);
      continue;
    }
    if (!valid_value(s.value)) x.errors.push_back("bad value: " + line);
    if (!x.help.count(s.name) || !x.type.count(s.name))
      x.errors.push_back("no HELP and TYPE before " + s.name);
    if (s.name != current) {
      if (finished.count(s.name)) x.errors.push_back("samples of " + s.name + " not together");
      if (!current.empty()) finished.insert(current);
      current = s.name;
    }
    std::string key = s.name;
    for (const auto& [k, v] : s.labels) key += "|" + k + "=" + v;
    if (!keys.insert(key).second) x.errors.push_back("duplicate sample: " + line);
    x.samples.push_back(std::move(s));
  }
  return x;
}

std::string join(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

// ---------------------------------------------------------------------------------------------
// Raw HTTP over loopback.

struct HttpResult {
  std::string raw;  // everything received
  int status = 0;
  std::string head, body;
  bool closed = false;  // the server closed the connection
  std::string header(const std::string& name) const {
    std::size_t p = 0;
    while ((p = head.find("\r\n", p)) != std::string::npos) {
      p += 2;
      if (head.compare(p, name.size() + 1, name + ":") == 0) {
        std::size_t e = head.find("\r\n", p);
        std::string v = head.substr(p + name.size() + 1, e - p - name.size() - 1);
        while (!v.empty() && v.front() == ' ') v.erase(0, 1);
        return v;
      }
    }
    return {};
  }
};

// Reads until the peer closes or `limit` passes.
std::string read_until_closed(asio::io_context& io, tcp::socket& s, std::chrono::milliseconds limit,
                              bool& closed) {
  std::string out;
  std::array<char, 4096> buf{};
  const auto deadline = std::chrono::steady_clock::now() + limit;
  closed = false;
  for (;;) {
    const auto [result, n] =
        test::read_some_before(io, s, asio::buffer(buf), deadline, [&] { s.cancel(); });
    if (result == asio::error::operation_aborted) return out;  // timed out
    out.append(buf.data(), n);
    if (result) {
      closed = true;
      return out;
    }
  }
}

HttpResult parse_http(std::string raw, bool closed) {
  HttpResult r;
  r.raw = std::move(raw);
  r.closed = closed;
  const std::size_t end = r.raw.find("\r\n\r\n");
  if (end == std::string::npos) return r;
  r.head = r.raw.substr(0, end);
  r.body = r.raw.substr(end + 4);
  if (r.head.rfind("HTTP/1.1 ", 0) == 0) r.status = std::atoi(r.head.c_str() + 9);
  return r;
}

// Sends `request` in pieces of `piece` bytes (0: at once) and reads the response to the end.
HttpResult http(std::uint16_t port, const std::string& request, std::size_t piece = 0,
                std::chrono::milliseconds limit = 5000ms) {
  asio::io_context io;
  tcp::socket s(io);
  s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
  s.set_option(tcp::no_delay(true));
  if (piece == 0) piece = request.size();
  for (std::size_t i = 0; i < request.size(); i += piece) {
    asio::write(s, asio::buffer(request.data() + i, std::min(piece, request.size() - i)));
    if (piece < request.size()) std::this_thread::sleep_for(2ms);
  }
  bool closed = false;
  std::string raw = read_until_closed(io, s, limit, closed);
  return parse_http(std::move(raw), closed);
}

HttpResult get(std::uint16_t port, const std::string& path = "/metrics") {
  return http(port, "GET " + path + " HTTP/1.1\r\nHost: localhost\r\nUser-Agent: test\r\n\r\n");
}

// ---------------------------------------------------------------------------------------------
// An in-process engine host and server (service_fixture.h).

EngineHostOptions small_host(float texels_per_scene = 48.0f) {
  return test::host_options(texels_per_scene, 0);
}

ServerOptions loopback() {
  return test::loopback(10000ms);
}

MetricsEndpointOptions local_endpoint(std::chrono::milliseconds timeout = 5000ms) {
  MetricsEndpointOptions o;
  o.bind = "127.0.0.1";
  o.port = 0;
  o.timeout = timeout;
  return o;
}

using test::client_of;
using test::eventually;

// ---------------------------------------------------------------------------------------------
// Many connections at once, all on one io_context in the test's thread.

// Raises the soft descriptor limit to the hard one. Empty when at least `need` descriptors are
// allowed, else why not (for GTEST_SKIP).
std::string descriptors_for(rlim_t need) {
  rlimit lim{};
  if (getrlimit(RLIMIT_NOFILE, &lim) != 0) return "getrlimit(RLIMIT_NOFILE) failed";
  if (lim.rlim_cur < lim.rlim_max) {
    rlimit raised = lim;
    raised.rlim_cur = lim.rlim_max;
    if (setrlimit(RLIMIT_NOFILE, &raised) != 0 && lim.rlim_max >= need) {
      raised.rlim_cur = need;  // a hard limit of "unlimited" cannot be the soft one
      setrlimit(RLIMIT_NOFILE, &raised);
    }
    getrlimit(RLIMIT_NOFILE, &lim);
  }
  if (lim.rlim_cur >= need) return {};
  return "needs " + std::to_string(need) +
         " file descriptors (a thousand client sockets, their server ends, and the endpoint "
         "takes at most a quarter of the limit); RLIMIT_NOFILE allows " +
         std::to_string(lim.rlim_cur) + " (hard limit " + std::to_string(lim.rlim_max) +
         "): raise it with ulimit -Hn";
}

constexpr rlim_t kThousandConnectionsDescriptors = 4096;

struct RawClient {
  explicit RawClient(asio::io_context& io) : socket(io) {}
  tcp::socket socket;
  bool connected = false;
  bool closed = false;  // the server closed (EOF or an error)
  std::string received;
  std::array<char, 4096> buffer{};
};
using RawClients = std::vector<std::unique_ptr<RawClient>>;

// Opens `n` connections at once; returns once each has connected or failed, or `limit` passed.
RawClients connect_all(asio::io_context& io, std::uint16_t port, int n,
                       std::chrono::milliseconds limit = 20000ms) {
  const tcp::endpoint at(asio::ip::make_address("127.0.0.1"), port);
  RawClients clients;
  for (int i = 0; i < n; ++i) {
    clients.push_back(std::make_unique<RawClient>(io));
    RawClient* c = clients.back().get();
    c->socket.async_connect(at, [c](std::error_code ec) { c->connected = !ec; });
  }
  io.restart();
  io.run_for(limit);
  return clients;
}

// Reads until the server closes.
void read_to_end(RawClient* c) {
  c->socket.async_read_some(asio::buffer(c->buffer), [c](std::error_code ec, std::size_t n) {
    c->received.append(c->buffer.data(), n);
    if (ec) {
      if (ec != asio::error::operation_aborted) c->closed = true;
      return;
    }
    read_to_end(c);
  });
}

// Every connected client sends `request` (all at once), then reads its response to the end.
void exchange_all(asio::io_context& io, RawClients& clients, const std::string& request,
                  std::chrono::milliseconds limit = 20000ms) {
  for (auto& client : clients) {
    RawClient* c = client.get();
    if (!c->connected) continue;
    asio::async_write(c->socket, asio::buffer(request), [c](std::error_code ec, std::size_t) {
      if (ec)
        c->closed = true;
      else
        read_to_end(c);
    });
  }
  io.restart();
  io.run_for(limit);
}

// The clients that the server has closed within `wait`.
std::size_t closed_within(asio::io_context& io, RawClients& clients,
                          std::chrono::milliseconds wait) {
  for (auto& c : clients)
    if (c->connected && !c->closed) read_to_end(c.get());
  io.restart();
  io.run_for(wait);
  for (auto& c : clients) {
    std::error_code ignored;
    c->socket.cancel(ignored);
  }
  io.restart();
  io.run();
  std::size_t closed = 0;
  for (auto& c : clients) closed += c->closed ? 1 : 0;
  return closed;
}

// A metrics text of realistic size: the formatter's output for a server with a few clients.
std::string realistic_metrics_text() {
  MetricsSnapshot m;
  m.scene = "rooms:3";
  m.backend = "embree";
  m.server.clients = 3;
  m.engine.passes = {{"direct", 0, 0.001, 1000, 0.009, 9000},
                     {"probes", 1, 0.002, 2000, 0.018, 18000},
                     {"scatter", 1, 0.003, 3000, 0.027, 27000}};
  return format_metrics(m);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// The formatter

TEST(Metrics, FormatterWritesValidExpositionWithTheGivenValues) {
  MetricsSnapshot m;
  m.scene = "odd \"scene\" \\ name\nline two";
  m.backend = "vulkan on \"GPU\" (discrete GPU, Vulkan 1.3.277)";
  ServerStats& s = m.server;
  s.clients = 3;
  s.connections = 17;
  s.clients_refused = 2;
  s.bytes_sent = (1ull << 60) + 1;  // beyond a double's 53 bits: written with every digit
  s.bytes_received = 1234;
  s.frames_received = 56;
  s.tiles_sent = 789;
  s.tile_bytes_sent = 7890;
  s.tiles_coalesced = 12;
  s.scene_bytes_sent = 4567;
  s.errors_sent = 4;
  s.peer_refused = 5;
  s.banned_refused = 6;
  s.accept_errors = 7;
  s.token_failures = 8;
  s.edits_dropped = 9;
  s.log_lines_suppressed = 10;
  s.websocket_sessions = 23;
  s.http_requests = 29;
  s.poses_streamed = 31;
  s.poses_refused = 37;
  s.avatar_frames_sent = 41;
  s.partial_bytes = 11;
  s.queue_depth = 40;
  s.queue_depth_max = 25;
  for (std::size_t r = 0; r < kCloseReasons; ++r) s.sessions_closed[r] = 100 + r;
  s.uptime_seconds = 1.0 / 3.0;
  EngineHostStats& e = m.engine;
  e.updates = 9;
  e.last_update_ms = 12.5;
  e.rays_per_s = 2.5e7;
  e.convergence = 0.0123456789;
  e.idle = true;
  e.tiles_published = 321;
  e.seconds_total = 0.1 + 0.2;
  e.rays_total = 9876543210ull;
  e.update_rate = 7.25;
  e.bytes_per_texel = 2.33;
  e.texels = 118000;
  e.revision = 3;
  e.last_edit_ms = 250.0;
  e.stale_texels = 4321;
  e.tiles = 480;
  e.passes = {{"direct", 0, 0.001, 1000, 0.009, 9000},
              {"probes", 1, 0.002, 2000, 0.018, 18000},
              {"scatter", 1, 0.003, 3000, 0.027, 27000},
              {"probes", 2, 0.004, 4000, 0.036, 36000},
              {"scatter", 2, 5e-320, 5000, 0.045, 45000}};  // a denormal round-trips too
  MetricsEndpointStats& x_stats = m.endpoint;
  x_stats.connections = 1001;
  x_stats.open = 7;
  x_stats.dropped = 11;
  x_stats.timeouts = 13;
  x_stats.ok = 950;
  x_stats.bad = 17;
  x_stats.collections = 19;

  const std::string text = format_metrics(m);
  const Exposition x = parse_exposition(text);
  EXPECT_TRUE(x.errors.empty()) << join(x.errors) << "\n" << text;
  for (const auto& [name, help] : x.help) EXPECT_FALSE(help.empty()) << name;
  EXPECT_EQ(x.help.size(), x.type.size());

  // Every value as given (integers digit for digit, doubles bit for bit).
  std::set<const Sample*> checked;
  auto u = [&](const std::string& name, std::uint64_t want, const LabelMap& labels = {}) {
    const Sample* p = x.find(name, labels);
    ASSERT_NE(p, nullptr) << name;
    checked.insert(p);
    EXPECT_EQ(p->value, std::to_string(want)) << name;
    EXPECT_EQ(x.type.at(name) == "counter", name.ends_with("_total")) << name;
  };
  auto d = [&](const std::string& name, double want, const LabelMap& labels = {}) {
    const Sample* p = x.find(name, labels);
    ASSERT_NE(p, nullptr) << name;
    checked.insert(p);
    EXPECT_EQ(std::strtod(p->value.c_str(), nullptr), want) << name << " = " << p->value;
  };
  u("irradcast_info", 1, {{"scene", m.scene}, {"backend", m.backend}});  // came back unescaped
  d("irradcast_uptime_seconds", s.uptime_seconds);
  u("irradcast_clients", 3);
  u("irradcast_connections_total", 17);
  u("irradcast_clients_refused_total", 2);
  u("irradcast_peer_refused_total", 5);
  u("irradcast_banned_refused_total", 6);
  u("irradcast_accept_errors_total", 7);
  u("irradcast_token_failures_total", 8);
  u("irradcast_edits_dropped_total", 9);
  u("irradcast_log_lines_suppressed_total", 10);
  u("irradcast_websocket_sessions_total", 23);
  u("irradcast_http_requests_total", 29);
  u("irradcast_poses_streamed_total", 31);
  u("irradcast_poses_refused_total", 37);
  u("irradcast_avatar_frames_sent_total", 41);
  u("irradcast_partial_frame_bytes", 11);
  for (std::size_t r = 0; r < kCloseReasons; ++r)
    u("irradcast_sessions_closed_total", 100 + r,
      {{"reason", close_reason_name(static_cast<CloseReason>(r))}});
  EXPECT_EQ(x.family("irradcast_sessions_closed_total").size(), kCloseReasons);
  u("irradcast_bytes_sent_total", (1ull << 60) + 1);
  u("irradcast_tile_bytes_sent_total", 7890);
  u("irradcast_scene_bytes_sent_total", 4567);
  u("irradcast_bytes_received_total", 1234);
  u("irradcast_frames_received_total", 56);
  u("irradcast_errors_sent_total", 4);
  u("irradcast_tiles_sent_total", 789);
  u("irradcast_tiles_coalesced_total", 12);
  u("irradcast_queue_depth", 40);
  u("irradcast_queue_depth_max", 25);
  u("irradcast_tiles", 480);
  u("irradcast_tiles_published_total", 321);
  d("irradcast_bytes_per_texel", 2.33);
  u("irradcast_engine_updates_total", 9);
  d("irradcast_engine_update_rate", 7.25);
  d("irradcast_engine_update_seconds", 12.5e-3);
  d("irradcast_engine_seconds_total", 0.1 + 0.2);
  u("irradcast_engine_rays_total", 9876543210ull);
  d("irradcast_engine_rays_per_second", 2.5e7);
  d("irradcast_engine_convergence", 0.0123456789);
  u("irradcast_engine_idle", 1);
  u("irradcast_engine_texels", 118000);
  u("irradcast_scene_revision", 3);
  d("irradcast_edit_apply_seconds", 0.25);
  u("irradcast_engine_stale_texels", 4321);
  for (const EnginePassStats& p : e.passes) {
    const LabelMap l = {{"pass", p.pass}, {"bounce", std::to_string(p.bounce)}};
    d("irradcast_engine_pass_seconds", p.seconds, l);
    u("irradcast_engine_pass_rays", p.rays, l);
    d("irradcast_engine_pass_seconds_total", p.seconds_total, l);
    u("irradcast_engine_pass_rays_total", p.rays_total, l);
  }
  EXPECT_EQ(x.family("irradcast_engine_pass_seconds").size(), e.passes.size());
  u("irradcast_metrics_connections_total", 1001);
  u("irradcast_metrics_connections_open", 7);
  u("irradcast_metrics_connections_dropped_total", 11);
  u("irradcast_metrics_connections_timed_out_total", 13);
  u("irradcast_metrics_scrapes_total", 950);
  u("irradcast_metrics_errors_total", 17);
  u("irradcast_metrics_collections_total", 19);
  // Nothing else: every sample above was checked.
  EXPECT_EQ(checked.size(), x.samples.size()) << text;
  EXPECT_EQ(x.samples.size(), 49 + kCloseReasons + 4 * e.passes.size());
}

TEST(Metrics, FormatterHandlesAnEmptySnapshotAndSpecialValues) {
  // Before the first update: the pass families have HELP and TYPE and no samples.
  const Exposition x = parse_exposition(format_metrics(MetricsSnapshot{}));
  EXPECT_TRUE(x.errors.empty()) << join(x.errors);
  EXPECT_TRUE(x.family("irradcast_engine_pass_seconds").empty());
  EXPECT_TRUE(x.type.count("irradcast_engine_pass_seconds"));
  EXPECT_EQ(x.value("irradcast_engine_updates_total"), 0.0);

  // The checker catches what it should.
  const std::string head = "# HELP irradcast_a A.\n# TYPE irradcast_a gauge\n";
  EXPECT_TRUE(parse_exposition(head + "irradcast_a{l=\"x\\\"\"} 1\n").errors.empty());
  EXPECT_FALSE(parse_exposition("irradcast_a 1\n").errors.empty());  // no HELP, TYPE
  EXPECT_FALSE(parse_exposition(head + "irradcast_a 1\nirradcast_a 2\n").errors.empty());
  EXPECT_FALSE(parse_exposition(head + "irradcast_a{l=\"x} 1\n").errors.empty());
  EXPECT_FALSE(parse_exposition(head + "irradcast_a{l=\"x\"} one\n").errors.empty());
  EXPECT_FALSE(parse_exposition(head + "irradcast_a 1").errors.empty());  // no final newline
  EXPECT_FALSE(
      parse_exposition("# HELP irradcast_b B.\n# TYPE irradcast_b counter\nirradcast_b 1\n")
          .errors.empty());  // a counter without _total

  EXPECT_EQ(format_metric_value(std::numeric_limits<double>::quiet_NaN()), "NaN");
  EXPECT_EQ(format_metric_value(std::numeric_limits<double>::infinity()), "+Inf");
  EXPECT_EQ(format_metric_value(-std::numeric_limits<double>::infinity()), "-Inf");
  EXPECT_EQ(format_metric_value(0.0), "0");
  EXPECT_EQ(format_metric_value(0.5), "0.5");
  EXPECT_EQ(escape_label_value("a\\b\"c\nd"), "a\\\\b\\\"c\\nd");
  MetricsSnapshot m;
  m.engine.convergence = std::numeric_limits<double>::infinity();
  m.engine.rays_per_s = std::numeric_limits<double>::quiet_NaN();
  const Exposition y = parse_exposition(format_metrics(m));
  EXPECT_TRUE(y.errors.empty()) << join(y.errors);
  EXPECT_EQ(y.find("irradcast_engine_convergence")->value, "+Inf");
  EXPECT_EQ(y.find("irradcast_engine_rays_per_second")->value, "NaN");
}

// ---------------------------------------------------------------------------------------------
// The HTTP endpoint on its own

TEST(Metrics, EndpointAnswersBadRequestsAndKeepsServing) {
  MetricsEndpoint ep([] { return std::string("irradcast_test 1\n"); }, local_endpoint());
  ep.start();
  const std::uint16_t port = ep.port();
  ASSERT_NE(port, 0);
  EXPECT_EQ(ep.url(), "http://127.0.0.1:" + std::to_string(port) + "/metrics");
  auto expect_ok = [&](const HttpResult& r, const std::string& what) {
    EXPECT_EQ(r.status, 200) << what << ": " << r.raw;
    EXPECT_EQ(r.header("Content-Type").rfind("text/plain; version=0.0.4", 0), 0u) << what;
    EXPECT_EQ(r.header("Connection"), "close") << what;
    EXPECT_EQ(r.body, "irradcast_test 1\n") << what;
    EXPECT_EQ(r.header("Content-Length"), std::to_string(r.body.size())) << what;
    EXPECT_TRUE(r.closed) << what;
  };
  expect_ok(get(port), "GET /metrics");
  expect_ok(get(port, "/metrics?name[]=x"), "with a query");
  expect_ok(http(port, "GET /metrics HTTP/1.0\n\n"), "HTTP/1.0 with bare LF");
  expect_ok(http(port, "GET /metrics HTTP/1.1\r\nHost: a\r\n\r\n", 3), "in 3-byte pieces");
  {
    const HttpResult r = http(port, "HEAD /metrics HTTP/1.1\r\nHost: a\r\n\r\n");
    EXPECT_EQ(r.status, 200);
    EXPECT_EQ(r.header("Content-Length"), "17");
    EXPECT_TRUE(r.body.empty());
  }
  struct Bad {
    std::string what, request;
    int status;
  };
  const std::string big(9000, 'a');
  const std::vector<Bad> bad = {
      {"unknown path", "GET /nope HTTP/1.1\r\nHost: a\r\n\r\n", 404},
      {"root", "GET / HTTP/1.1\r\n\r\n", 404},
      {"POST", "POST /metrics HTTP/1.1\r\nHost: a\r\nContent-Length: 5\r\n\r\nhello", 405},
      {"DELETE", "DELETE /metrics HTTP/1.1\r\n\r\n", 405},
      {"garbage bytes", std::string("\x00\x01\x02\xff\xfegarbage\r\n\r\n", 16), 400},
      {"binary after a method", std::string("GET \x01\x02\r\n\r\n", 10), 400},
      {"no version", "GET /metrics\r\n\r\n", 400},
      {"HTTP/2", "GET /metrics HTTP/2.0\r\n\r\n", 400},
      {"absolute target", "GET http://a/metrics HTTP/1.1\r\n\r\n", 400},
      {"header without colon", "GET /metrics HTTP/1.1\r\nHost a\r\n\r\n", 400},
      {"folded header", "GET /metrics HTTP/1.1\r\nX-A: 1\r\n  2\r\n\r\n", 400},
      {"CR inside a line", "GET /metrics HTTP/1.1\r\nX-A: 1\r2\r\n\r\n", 400},
      {"oversized header", "GET /metrics HTTP/1.1\r\nX-Big: " + big + "\r\n\r\n", 431},
      {"oversized, never ending", "GET /metrics HTTP/1.1\r\nX-Big: " + big, 431},
      {"oversized request line", "GET /metrics?" + big + " HTTP/1.1\r\n\r\n", 414},
      {"JSON", "{\"get\": \"/metrics\"}\r\n\r\n", 400},
  };
  for (const Bad& b : bad) {
    const HttpResult r = http(port, b.request);
    EXPECT_EQ(r.status, b.status) << b.what << ": " << r.raw;
    EXPECT_EQ(r.header("Connection"), "close") << b.what;
    EXPECT_TRUE(r.closed) << b.what;
    if (b.status == 405) {
      EXPECT_EQ(r.header("Allow"), "GET, HEAD");
    }
    expect_ok(get(port), "after " + b.what);
  }
  const MetricsEndpointStats st = ep.stats();
  EXPECT_EQ(st.bad, bad.size());
  EXPECT_EQ(st.ok, 5u + bad.size());
  EXPECT_EQ(st.timeouts, 0u);
  ep.stop();
  ep.stop();  // idempotent
}

TEST(Metrics, EndpointClosesIdleConnectionsAfterTheTimeout) {
  MetricsEndpointOptions o = local_endpoint(300ms);
  MetricsEndpoint ep([] { return std::string("irradcast_test 1\n"); }, o);
  ep.start();
  {  // Connects and sends nothing.
    asio::io_context io;
    tcp::socket s(io);
    s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), ep.port()));
    const auto t0 = std::chrono::steady_clock::now();
    bool closed = false;
    EXPECT_EQ(read_until_closed(io, s, 3000ms, closed), "");
    const auto waited = std::chrono::steady_clock::now() - t0;
    EXPECT_TRUE(closed);
    EXPECT_GE(waited, 250ms);
    EXPECT_LT(waited, 2000ms);
  }
  {  // Sends half a request and stops.
    asio::io_context io;
    tcp::socket s(io);
    s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), ep.port()));
    asio::write(s, asio::buffer(std::string("GET /metrics HTTP/1.1\r\nHo")));
    bool closed = false;
    EXPECT_EQ(read_until_closed(io, s, 3000ms, closed), "");
    EXPECT_TRUE(closed);
  }
  EXPECT_EQ(get(ep.port()).status, 200);
  EXPECT_EQ(ep.stats().timeouts, 2u);
  // stop() does not wait for an idle connection's timeout.
  {
    MetricsEndpoint slow([] { return std::string(); }, local_endpoint(60000ms));
    slow.start();
    asio::io_context io;
    tcp::socket s(io);
    s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), slow.port()));
    ASSERT_TRUE(eventually([&] { return slow.stats().connections == 1; }));
    const auto t0 = std::chrono::steady_clock::now();
    slow.stop();
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 1000ms);
  }
}

// Issue 16, item 13: the endpoint answered 64 of 1000 concurrent scrapes (it closed every
// connection past 64 open at once).
TEST(Metrics, EndpointAnswersAThousandConcurrentScrapes) {
  if (const std::string why = descriptors_for(kThousandConnectionsDescriptors); !why.empty())
    GTEST_SKIP() << why;
  const std::string text = realistic_metrics_text();
  std::atomic<int> calls{0};
  MetricsEndpoint ep(
      [&] {
        ++calls;
        return text;
      },
      local_endpoint());
  ep.start();
  ASSERT_GE(ep.max_connections(), 1000u);
  constexpr int kClients = 1000;
  asio::io_context io;
  RawClients clients = connect_all(io, ep.port(), kClients);
  int connected = 0;
  for (const auto& c : clients) connected += c->connected ? 1 : 0;
  ASSERT_EQ(connected, kClients);
  // All connected before any sends: a thousand requests open at once.
  const auto t0 = std::chrono::steady_clock::now();
  exchange_all(io, clients, "GET /metrics HTTP/1.1\r\nHost: localhost\r\nUser-Agent: t\r\n\r\n");
  const auto elapsed = std::chrono::steady_clock::now() - t0;
  int answered = 0;
  for (const auto& c : clients) {
    const HttpResult r = parse_http(c->received, c->closed);
    if (r.status == 200 && r.body == text && r.closed) ++answered;
  }
  EXPECT_EQ(answered, kClients);
  const MetricsEndpointStats st = ep.stats();
  EXPECT_EQ(st.ok, static_cast<std::uint64_t>(kClients));
  EXPECT_EQ(st.dropped, 0u);
  EXPECT_EQ(st.timeouts, 0u);
  // The text was made at most once per cache_for (100 ms), not once per scrape.
  const auto windows = std::chrono::duration_cast<std::chrono::milliseconds>(elapsed) / 100ms;
  EXPECT_LE(calls.load(), 1 + windows) << "in " << elapsed / 1ms << " ms";
  EXPECT_EQ(st.collections, static_cast<std::uint64_t>(calls.load()));
}

// A thousand connections that never finish their request (half a request, or nothing) stay open
// (their deadlines are far away here), and a well-behaved scrape is still answered at once.
TEST(Metrics, EndpointServesAScrapeWhileAThousandConnectionsStall) {
  if (const std::string why = descriptors_for(kThousandConnectionsDescriptors); !why.empty())
    GTEST_SKIP() << why;
  MetricsEndpointOptions o = local_endpoint(60000ms);
  o.header_timeout = 30000ms;
  MetricsEndpoint ep([] { return std::string("irradcast_test 1\n"); }, o);
  ep.start();
  constexpr int kStalled = 1000;
  asio::io_context io;
  RawClients stalled = connect_all(io, ep.port(), kStalled);
  const std::string half = "GET /metrics HTTP/1.1\r\nHo";
  for (std::size_t i = 0; i < stalled.size(); i += 2) {
    ASSERT_TRUE(stalled[i]->connected);
    asio::write(stalled[i]->socket, asio::buffer(half));
  }
  ASSERT_TRUE(eventually([&] { return ep.stats().connections >= kStalled; }));
  const auto t0 = std::chrono::steady_clock::now();
  const HttpResult r = http(ep.port(), "GET /metrics HTTP/1.1\r\nHost: a\r\n\r\n", 0, 2000ms);
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_EQ(r.status, 200) << r.raw;
  EXPECT_EQ(r.body, "irradcast_test 1\n");
  EXPECT_LT(waited, 2000ms);
  // The stalled connections were not touched: none closed, none dropped, none timed out.
  EXPECT_EQ(closed_within(io, stalled, 50ms), 0u);
  const MetricsEndpointStats st = ep.stats();
  EXPECT_EQ(st.dropped, 0u);
  EXPECT_EQ(st.timeouts, 0u);
  EXPECT_TRUE(eventually([&] { return ep.stats().open == kStalled; }));
}

// With max_connections open, a new connection takes the place of the oldest one that cannot be
// a live scrape: an answered one (still open) first, then the oldest incomplete request.
TEST(Metrics, EndpointDropsTheOldestStalledConnectionForANewOne) {
  MetricsEndpointOptions o = local_endpoint(60000ms);
  o.header_timeout = 30000ms;
  o.max_connections = 16;
  MetricsEndpoint ep([] { return std::string("irradcast_test 1\n"); }, o);
  ep.start();
  const tcp::endpoint at(asio::ip::make_address("127.0.0.1"), ep.port());
  asio::io_context io;
  // An answered connection that the client keeps open (the server lingers on it).
  RawClients answered = connect_all(io, ep.port(), 1);
  ASSERT_TRUE(answered[0]->connected);
  asio::write(answered[0]->socket, asio::buffer(std::string("GET /metrics HTTP/1.1\r\n\r\n")));
  ASSERT_TRUE(eventually([&] { return ep.stats().ok == 1; }));
  // 40 stalled ones, connected in order (the kernel's accept queue is first in, first out).
  RawClients stalled;
  for (int i = 0; i < 40; ++i) {
    stalled.push_back(std::make_unique<RawClient>(io));
    stalled.back()->socket.connect(at);
    stalled.back()->connected = true;
  }
  ASSERT_TRUE(eventually([&] { return ep.stats().connections == 41; }));
  // 41 connections, 16 places: the answered one went first, then the 24 oldest stalled ones.
  EXPECT_EQ(ep.stats().dropped, 25u);
  EXPECT_EQ(ep.stats().open, 16u);
  EXPECT_EQ(closed_within(io, answered, 200ms), 1u);
  HttpResult first = parse_http(answered[0]->received, true);
  EXPECT_EQ(first.status, 200);  // it had its response before it was dropped
  const std::size_t closed = closed_within(io, stalled, 200ms);
  EXPECT_EQ(closed, 24u);
  for (std::size_t i = 0; i < stalled.size(); ++i)
    EXPECT_EQ(stalled[i]->closed, i < 24) << "stalled connection " << i;
  // A scraper gets its answer: it takes the place of the oldest stalled connection left.
  EXPECT_EQ(get(ep.port()).status, 200);
  EXPECT_EQ(ep.stats().dropped, 26u);
  EXPECT_EQ(closed_within(io, stalled, 200ms), 25u);
  EXPECT_TRUE(stalled[24]->closed);
  EXPECT_EQ(ep.stats().timeouts, 0u);
}

// Slowloris: the request head must be complete within header_timeout of the connection, however
// steadily its bytes trickle in.
TEST(Metrics, EndpointClosesASlowRequestAtTheHeaderDeadline) {
  MetricsEndpointOptions o = local_endpoint(10000ms);
  o.header_timeout = 300ms;
  MetricsEndpoint ep([] { return std::string("irradcast_test 1\n"); }, o);
  ep.start();
  asio::io_context io;
  tcp::socket s(io);
  s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), ep.port()));
  const auto t0 = std::chrono::steady_clock::now();
  asio::write(s, asio::buffer(std::string("GET /metrics HTTP/1.1\r\n")));
  std::error_code ec;
  for (int i = 0; i < 60 && !ec; ++i) {  // a header line every 50 ms, for up to 3 s
    asio::write(s, asio::buffer("X-Slow-" + std::to_string(i) + ": 1\r\n"), ec);
    std::this_thread::sleep_for(50ms);
  }
  bool closed = false;
  EXPECT_EQ(read_until_closed(io, s, 3000ms, closed), "");  // closed without a response
  EXPECT_TRUE(closed);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 2000ms);
  EXPECT_EQ(ep.stats().timeouts, 1u);
  EXPECT_EQ(ep.stats().ok, 0u);
  EXPECT_EQ(get(ep.port()).status, 200);
}

// An oversized request head: an error status at once, `Connection: close`, and the connection
// closed, also when the client goes on sending.
TEST(Metrics, EndpointAnswersAnOversizedHeadWithAnErrorAndCloses) {
  MetricsEndpoint ep([] { return std::string("irradcast_test 1\n"); }, local_endpoint());
  ep.start();
  std::string many_headers = "GET /metrics HTTP/1.1\r\n";
  for (int i = 0; many_headers.size() < 9000; ++i)
    many_headers += "X-Header-" + std::to_string(i) + ": some value\r\n";
  struct Case {
    std::string what, request;
    int status;
  };
  const std::vector<Case> cases = {
      {"one long header", "GET /metrics HTTP/1.1\r\nX-Big: " + std::string(9000, 'a') + "\r\n\r\n",
       431},
      {"many headers", many_headers + "\r\n", 431},
      {"a long request line", "GET /metrics?" + std::string(9000, 'q') + " HTTP/1.1\r\n\r\n", 414},
  };
  for (const Case& c : cases) {
    const auto t0 = std::chrono::steady_clock::now();
    const HttpResult r = http(ep.port(), c.request, 0, 3000ms);
    EXPECT_EQ(r.status, c.status) << c.what << ": " << r.head;
    EXPECT_EQ(r.header("Connection"), "close") << c.what;
    EXPECT_TRUE(r.closed) << c.what;
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 1500ms) << c.what;
  }
  {  // A client that streams header bytes without end: answered, then closed within the linger.
    asio::io_context io;
    tcp::socket s(io);
    s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), ep.port()));
    asio::write(s, asio::buffer(std::string("GET /metrics HTTP/1.1\r\nX-Endless: ")));
    const std::string chunk(1024, 'z');
    const auto t0 = std::chrono::steady_clock::now();
    std::error_code ec;
    while (!ec && std::chrono::steady_clock::now() - t0 < 5000ms) {
      asio::write(s, asio::buffer(chunk), ec);
      std::this_thread::sleep_for(5ms);
    }
    EXPECT_TRUE(ec) << "the server never closed the connection";
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 3000ms);
    bool closed = false;
    const HttpResult r = parse_http(read_until_closed(io, s, 1000ms, closed), closed);
    // The response may be lost to the reset (the client's unread bytes); the status is checked
    // above. Here the point is that the connection ends.
    if (r.status != 0) {
      EXPECT_EQ(r.status, 431);
    }
  }
  EXPECT_EQ(ep.stats().bad, cases.size() + 1);
  EXPECT_EQ(get(ep.port()).status, 200);
}

// The body function runs at most once per cache_for; 0 calls it for every scrape.
TEST(Metrics, EndpointReusesTheMetricsTextForCacheFor) {
  std::atomic<int> calls{0};
  auto body = [&] { return "irradcast_test " + std::to_string(++calls) + "\n"; };
  MetricsEndpointOptions o = local_endpoint();
  o.cache_for = 500ms;
  MetricsEndpoint cached(body, o);
  cached.start();
  const auto t0 = std::chrono::steady_clock::now();
  const std::string first = get(cached.port()).body, second = get(cached.port()).body;
  if (std::chrono::steady_clock::now() - t0 < 400ms) {
    EXPECT_EQ(first, "irradcast_test 1\n");
    EXPECT_EQ(second, first);
    EXPECT_EQ(cached.stats().collections, 1u);
  }
  std::this_thread::sleep_for(550ms);
  EXPECT_NE(get(cached.port()).body, second);
  cached.stop();
  o.cache_for = 0ms;
  MetricsEndpoint uncached(body, o);
  uncached.start();
  const int before = calls;
  get(uncached.port());
  get(uncached.port());
  EXPECT_EQ(calls, before + 2);
}

TEST(Metrics, EndpointAnswers500WhenTheBodyFunctionThrows) {
  std::atomic<bool> fail{true};
  MetricsEndpoint ep(
      [&] {
        if (fail) throw std::runtime_error("no stats");
        return std::string("irradcast_test 2\n");
      },
      local_endpoint());
  ep.start();
  EXPECT_EQ(get(ep.port()).status, 500);
  fail = false;
  EXPECT_EQ(get(ep.port()).body, "irradcast_test 2\n");
}

TEST(Metrics, EndpointRefusesAnAddressItCannotBind) {
  MetricsEndpointOptions o = local_endpoint();
  o.bind = "not-an-address";
  MetricsEndpoint bad_address([] { return std::string(); }, o);
  EXPECT_THROW(bad_address.start(), Error);
  MetricsEndpoint first([] { return std::string(); }, local_endpoint());
  first.start();
  o = local_endpoint();
  o.port = first.port();
  MetricsEndpoint taken([] { return std::string(); }, o);
  EXPECT_THROW(taken.start(), Error);
}

// ---------------------------------------------------------------------------------------------
// End to end: engine host, server, endpoint, a viewer

TEST(Metrics, EndToEndScrapeMatchesTheServerAndEngine) {
  EngineHost host(make_cornell_box(), "cornell", small_host());
  host.step();
  host.step();
  Server server(host, loopback());
  server.start();
  // Every scrape below must see the state of the moment: no cached text.
  MetricsEndpointOptions mo = local_endpoint();
  mo.cache_for = 0ms;
  const MetricsEndpoint* endpoint = nullptr;
  MetricsEndpoint ep([&] { return format_metrics(collect_metrics(server, host, endpoint)); }, mo);
  endpoint = &ep;
  ep.start();

  ViewClient c(client_of(server, "metrics-viewer"));
  c.connect();
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (!c.all_tiles_received() && std::chrono::steady_clock::now() < deadline) c.poll(50ms);
  ASSERT_TRUE(c.all_tiles_received());
  // The server counts a tile when its write completes; the engine is not running, so the
  // count settles at one per tile.
  ASSERT_TRUE(eventually([&] { return server.stats().tiles_sent >= c.tile_count(); }));

  const HttpResult r = get(ep.port());
  ASSERT_EQ(r.status, 200) << r.raw;
  EXPECT_EQ(r.header("Content-Type"), "text/plain; version=0.0.4; charset=utf-8");
  const Exposition x = parse_exposition(r.body);
  ASSERT_TRUE(x.errors.empty()) << join(x.errors) << r.body;
  const ServerStats ss = server.stats();
  const EngineHostStats es = host.stats();
  EXPECT_EQ(x.value("irradcast_clients"), 1.0);
  EXPECT_GT(x.value("irradcast_tiles_sent_total"), 0.0);
  EXPECT_EQ(x.value("irradcast_tiles_sent_total"), static_cast<double>(ss.tiles_sent));
  EXPECT_EQ(x.value("irradcast_tiles_sent_total"), static_cast<double>(c.tile_count()));
  EXPECT_EQ(x.value("irradcast_tiles"), static_cast<double>(host.tiles().tile_count()));
  EXPECT_EQ(x.value("irradcast_engine_updates_total"), 2.0);
  EXPECT_EQ(es.updates, 2u);
  EXPECT_EQ(x.value("irradcast_connections_total"), 1.0);
  // The endpoint's own counters: this scrape's connection, no 200 before it.
  EXPECT_EQ(x.value("irradcast_metrics_connections_total"), 1.0);
  EXPECT_EQ(x.value("irradcast_metrics_connections_open"), 1.0);
  EXPECT_EQ(x.value("irradcast_metrics_scrapes_total"), 0.0);
  EXPECT_EQ(x.value("irradcast_metrics_connections_dropped_total"), 0.0);
  EXPECT_GT(ss.scene_bytes_sent, c.counters().scene_bytes_downloaded);  // frames > their data
  EXPECT_EQ(x.value("irradcast_scene_bytes_sent_total"), static_cast<double>(ss.scene_bytes_sent));
  EXPECT_GE(x.value("irradcast_bytes_sent_total"), x.value("irradcast_tile_bytes_sent_total") +
                                                       x.value("irradcast_scene_bytes_sent_total"));
  EXPECT_GT(x.value("irradcast_tile_bytes_sent_total"), 0.0);
  EXPECT_EQ(x.value("irradcast_queue_depth"), 0.0);
  EXPECT_EQ(x.value("irradcast_engine_idle"), 0.0);
  EXPECT_GT(x.value("irradcast_engine_update_rate"), 0.0);
  EXPECT_GT(x.value("irradcast_engine_rays_total"), 0.0);
  EXPECT_GT(x.value("irradcast_engine_rays_per_second"), 0.0);
  EXPECT_GT(x.value("irradcast_engine_convergence"), 0.0);
  EXPECT_GT(x.value("irradcast_bytes_per_texel"), 0.0);
  EXPECT_EQ(x.value("irradcast_info", {{"scene", "cornell"}, {"backend", host.backend_name()}}),
            1.0);
  EXPECT_FALSE(host.backend_name().empty());
  // Direct, then probes and scatter per bounce (2 by default).
  ASSERT_EQ(es.passes.size(), 5u);
  ASSERT_EQ(x.family("irradcast_engine_pass_seconds").size(), es.passes.size());
  double pass_sum = 0.0;
  for (const EnginePassStats& p : es.passes) {
    const LabelMap l = {{"pass", p.pass}, {"bounce", std::to_string(p.bounce)}};
    EXPECT_GT(x.value("irradcast_engine_pass_seconds", l), 0.0) << p.pass << p.bounce;
    EXPECT_GT(x.value("irradcast_engine_pass_rays", l), 0.0) << p.pass << p.bounce;
    EXPECT_GE(x.value("irradcast_engine_pass_seconds_total", l),
              x.value("irradcast_engine_pass_seconds", l));
    pass_sum += p.seconds_total;
  }
  EXPECT_LE(pass_sum, es.seconds_total * 1.0001);
  EXPECT_EQ(es.passes[0].pass, "direct");
  EXPECT_EQ(es.passes[1].pass, "probes");
  EXPECT_EQ(es.passes[2].pass, "scatter");
  EXPECT_EQ(es.passes[4].bounce, 2u);

  // The viewer says Bye: the scrape shows no client and a session closed for that reason.
  c.close();
  ASSERT_TRUE(eventually([&] { return server.stats().clients == 0; }));
  const Exposition y = parse_exposition(get(ep.port()).body);
  EXPECT_EQ(y.value("irradcast_clients"), 0.0);
  EXPECT_EQ(y.value("irradcast_metrics_scrapes_total"), 1.0);
  EXPECT_EQ(y.value("irradcast_sessions_closed_total", {{"reason", "bye"}}), 1.0);
  EXPECT_EQ(y.value("irradcast_sessions_closed_total", {{"reason", "idle_timeout"}}), 0.0);
  {  // A frame that does not parse: the session ends for that reason, though the client closes.
    asio::io_context io;
    tcp::socket raw(io);
    raw.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), server.port()));
    std::string junk("\x10\x00\x00\x00", 4);
    for (int i = 0; i < 16; ++i) junk += static_cast<char>(0xF7 ^ (i * 37));
    asio::write(raw, asio::buffer(junk));
    bool closed = false;
    read_until_closed(io, raw, 5000ms, closed);
    EXPECT_TRUE(closed);
  }
  ASSERT_TRUE(eventually([&] { return server.stats().clients == 0; }));
  const Exposition z = parse_exposition(get(ep.port()).body);
  EXPECT_EQ(z.value("irradcast_sessions_closed_total", {{"reason", "bad_frame"}}), 1.0);
  EXPECT_EQ(z.value("irradcast_sessions_closed_total", {{"reason", "disconnect"}}), 0.0);
  EXPECT_EQ(z.value("irradcast_connections_total"), 2.0);
  EXPECT_EQ(z.value("irradcast_errors_sent_total"), 1.0);
  ep.stop();
  server.stop();
}

TEST(Metrics, CoalescedTilesAndQueueDepthAreLive) {
  // Enough tiles that a client capped at 1 byte/s gets only the first burst (64 KiB) and the
  // rest waits in its queue while the engine publishes new versions.
  EngineHost host(make_cornell_box(), "cornell", small_host(128.0f));
  host.step();
  Server server(host, loopback());
  server.start();
  asio::io_context io;
  tcp::socket s(io);
  s.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), server.port()));
  wire::Envelope hello, sub;
  hello.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  hello.mutable_hello()->set_client_name("slow");
  sub.mutable_subscribe()->set_all(true);
  sub.mutable_subscribe()->set_max_bytes_per_s(1);
  asio::write(s, asio::buffer(wire::encode_frame(hello) + wire::encode_frame(sub)));
  ASSERT_TRUE(eventually([&] { return server.stats().queue_depth > 0; }));
  const ServerStats before = server.stats();
  EXPECT_EQ(before.queue_depth_max, before.queue_depth);  // one client: max = sum
  EXPECT_EQ(before.tiles_coalesced, 0u);
  const std::uint64_t first_versions = host.stats().tiles_published;
  // Tiles still waiting get newer versions: coalesced, and counted while the session lasts.
  // (The tile store decides which tiles get a new version after an update; within a few
  // updates most do.)
  for (int i = 0; i < 10 && server.stats().tiles_coalesced == 0; ++i) {
    host.step();
    eventually([&] { return server.stats().tiles_coalesced > 0; }, 200ms);
  }
  const ServerStats during = server.stats();
  EXPECT_GT(during.tiles_coalesced, 0u);
  EXPECT_EQ(during.clients, 1u);
  EXPECT_GT(during.queue_depth, 0u);
  // Each coalesced version is a new version of a tile that was waiting.
  EXPECT_LE(during.tiles_coalesced, host.stats().tiles_published - first_versions);
  // The session ends when the client vanishes.
  std::error_code ignored;
  s.close(ignored);
  ASSERT_TRUE(eventually([&] { return server.stats().clients == 0; }));
  const ServerStats ss = server.stats();
  EXPECT_EQ(ss.queue_depth, 0u);
  EXPECT_EQ(ss.queue_depth_max, 0u);
  EXPECT_EQ(ss.sessions_closed[static_cast<std::size_t>(CloseReason::Disconnect)], 1u);
  server.stop();
}

TEST(Metrics, StatsFrameCarriesTheNewFields) {
  EngineHost host(make_cornell_box(), "cornell", small_host());
  host.step();
  host.step();
  host.step();
  Server server(host, loopback());
  server.start();
  ViewClient c(client_of(server, "stats"));
  c.connect();
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (!c.all_tiles_received() && std::chrono::steady_clock::now() < deadline) c.poll(50ms);
  auto st = c.request_stats(5s);
  ASSERT_TRUE(st.has_value());
  const EngineHostStats es = host.stats();
  ASSERT_EQ(st->pass_times_size(), 5);
  const char* names[] = {"direct", "probes", "scatter", "probes", "scatter"};
  const std::uint32_t bounces[] = {0, 1, 1, 2, 2};
  for (int i = 0; i < st->pass_times_size(); ++i) {
    const wire::PassTime& p = st->pass_times(i);
    EXPECT_EQ(p.pass(), names[i]);
    EXPECT_EQ(p.bounce(), bounces[i]);
    EXPECT_GT(p.ms(), 0.0);
    EXPECT_GT(p.rays(), 0u);
    EXPECT_GE(p.seconds_total(), p.ms() * 1e-3);
    EXPECT_EQ(p.rays_total(), es.passes[static_cast<std::size_t>(i)].rays_total);
  }
  EXPECT_GE(st->update_rate(), 0.0);
  EXPECT_EQ(st->updates(), 3u);
  EXPECT_EQ(st->connections(), 1u);
  EXPECT_EQ(st->clients_refused(), 0u);
  EXPECT_GT(st->scene_bytes_sent(), 0u);
  EXPECT_GT(st->tile_bytes_sent(), 0u);
  EXPECT_EQ(st->tiles_published(), es.tiles_published);
  EXPECT_GT(st->tiles_published(), 0u);
  EXPECT_EQ(st->rays_total(), es.rays_total);
  EXPECT_GT(st->engine_seconds_total(), 0.0);
  EXPECT_EQ(st->tiles(), host.tiles().tile_count());
  EXPECT_EQ(st->texels(), es.texels);
  EXPECT_EQ(st->backend(), host.backend_name());
  EXPECT_GE(st->queue_depth_max(), st->queue_depth());
  EXPECT_GE(st->queue_depth_total(), st->queue_depth_max());
  EXPECT_EQ(st->sessions_closed_size(), static_cast<int>(kCloseReasons));
  EXPECT_EQ(st->sessions_closed(0).reason(), "bye");
  EXPECT_EQ(st->sessions_closed(0).sessions(), 0u);
  EXPECT_EQ(st->sessions_closed(2).reason(), "idle_timeout");
  c.close();
  server.stop();
}

TEST(Metrics, UpdateRateCountsRecentUpdatesOnly) {
  EngineHost host(make_cornell_box(), "cornell", small_host());
  EXPECT_EQ(host.stats().update_rate, 0.0);
  EXPECT_TRUE(host.stats().passes.empty());
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 3; ++i) host.step();
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const EngineHostStats s = host.stats();
  // 3 updates since the first began: at least 3 / elapsed (the stats came later).
  EXPECT_GT(s.update_rate, 0.0);
  EXPECT_LE(s.update_rate, 3.0 / elapsed * 1.01);
  EXPECT_GT(s.update_rate, 3.0 / (elapsed + 1.0));
  EXPECT_EQ(s.updates, 3u);
  EXPECT_GT(s.seconds_total, 0.0);
  EXPECT_LE(s.seconds_total, elapsed);
  EXPECT_GT(s.rays_total, 0u);
  std::uint64_t rays = 0;
  for (const EnginePassStats& p : s.passes) rays += p.rays_total;
  EXPECT_EQ(rays, s.rays_total);
  EXPECT_GT(s.texels, 0u);
  EXPECT_EQ(s.tiles, host.tiles().tile_count());
}

// The NATS families come from their declared lists (nats_origin_stats.inc,
// nats_gateway_stats.inc): every statistic is one metric with its HELP, TYPE and the value it
// holds (each member set to a value of its own here; a bool reads 1).
static void expect_each_declared_metric(
    const std::string& text, const std::vector<std::pair<std::string, double>>& expected) {
  for (const auto& [name, value] : expected) {
    EXPECT_NE(text.find("# HELP " + name + " "), std::string::npos) << name;
    EXPECT_NE(text.find("# TYPE " + name + " "), std::string::npos) << name;
    EXPECT_NE(text.find("\n" + name + " " + format_metric_value(value) + "\n"), std::string::npos)
        << name << " in\n"
        << text;
  }
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'),
            3 * static_cast<std::ptrdiff_t>(expected.size()));
}

TEST(Metrics, TheNatsFamiliesHaveEveryDeclaredStatisticOnce) {
  NatsOriginStats o;
  std::vector<std::pair<std::string, double>> want_o;
  double v = 0.0;
#define IRRADCAST_NATS_ORIGIN_STAT(type, name, kind, metric, help) \
  v += 1.0;                                                        \
  o.name = static_cast<type>(v);                                   \
  want_o.emplace_back(metric, static_cast<double>(o.name));
#include "irradcast/service/nats_origin_stats.inc"
#undef IRRADCAST_NATS_ORIGIN_STAT
  const std::string origin = format_nats_origin_metrics(o);
  expect_each_declared_metric(origin, want_o);

  NatsGatewayStats g;
  std::vector<std::pair<std::string, double>> want_g;
  v = 0.5;
#define IRRADCAST_NATS_GATEWAY_STAT(type, name, kind, metric, help) \
  v += 1.0;                                                         \
  g.name = static_cast<type>(v);                                    \
  want_g.emplace_back(metric, static_cast<double>(g.name));
#include "irradcast/service/nats_gateway_stats.inc"
#undef IRRADCAST_NATS_GATEWAY_STAT
  const std::string gateway = format_nats_gateway_metrics(g);
  expect_each_declared_metric(gateway, want_g);
  // Some that were counted but not shown before the lists.
  for (const char* m :
       {"irradcast_nats_packages_published_total", "irradcast_nats_bad_requests_total",
        "irradcast_nats_poses_published_total"})
    EXPECT_NE(origin.find(m), std::string::npos) << m;
  for (const char* m :
       {"irradcast_gateway_messages_total", "irradcast_gateway_edit_requests_total"})
    EXPECT_NE(gateway.find(m), std::string::npos) << m;
}

}  // namespace irradcast::test_metrics

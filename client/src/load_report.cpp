// LoadReport as text for people and as JSON for scripts and benchmarks, and the statistics it is
// made of (percentiles, version digests).
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "irradcast/client/load_generator.h"

namespace irradcast {

namespace {

std::string fixed(double v, int decimals = 1) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

std::string bytes(double b) {
  if (b >= 1e9) return fixed(b / 1e9, 2) + " GB";
  if (b >= 1e6) return fixed(b / 1e6, 2) + " MB";
  if (b >= 1e3) return fixed(b / 1e3, 1) + " kB";
  return fixed(b, 0) + " B";
}

std::string dist(const Percentiles& p, const std::string& unit, int decimals = 1) {
  if (p.count == 0) return "-";
  return "p50 " + fixed(p.p50, decimals) + unit + "  p95 " + fixed(p.p95, decimals) + unit +
         "  p99 " + fixed(p.p99, decimals) + unit + "  max " + fixed(p.max, decimals) + unit;
}

std::string byte_dist(const Percentiles& p, const std::string& suffix) {
  if (p.count == 0) return "-";
  return "p50 " + bytes(p.p50) + suffix + "  p95 " + bytes(p.p95) + suffix + "  mean " +
         bytes(p.mean) + suffix;
}

nlohmann::json to_json(const Percentiles& p) {
  return {{"count", p.count}, {"p50", p.p50}, {"p95", p.p95},
          {"p99", p.p99},     {"max", p.max}, {"mean", p.mean}};
}

}  // namespace

Percentiles Percentiles::of(std::vector<double> v) {
  Percentiles p;
  p.count = v.size();
  if (v.empty()) return p;
  std::sort(v.begin(), v.end());
  auto rank = [&](double q) {
    const auto i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
    return v[std::clamp<std::size_t>(i, 1, v.size()) - 1];
  };
  p.p50 = rank(0.50);
  p.p95 = rank(0.95);
  p.p99 = rank(0.99);
  p.max = v.back();
  double sum = 0.0;
  for (double x : v) sum += x;
  p.mean = sum / static_cast<double>(v.size());
  return p;
}

std::uint64_t versions_digest(const std::vector<std::uint64_t>& versions) {
  std::uint64_t h = 1469598103934665603ull;
  for (std::uint64_t v : versions)
    for (int b = 0; b < 8; ++b) {
      h ^= (v >> (8 * b)) & 0xffu;
      h *= 1099511628211ull;
    }
  return h;
}

LoadReport LoadReport::of(const LoadOptions& options, double elapsed,
                          std::vector<LoadUserResult> users, std::vector<double> latency,
                          std::vector<double> steady_latency,
                          std::map<std::string, std::uint64_t> errors) {
  LoadReport r;
  r.options = options;
  r.elapsed_s = elapsed;
  r.users = options.users;
  std::vector<double> scene, full, rate, steady, to_full, fps, frame_ms, avatar_rate, avatar_bytes;
  std::uint64_t avatars_listed = 0;
  for (LoadUserResult& res : users) {
    r.connected += res.connected;
    r.failed += !res.failure.empty();
    r.scene_loaded += res.scene_loaded;
    r.full_image += res.full_image;
    if (res.scene_loaded) scene.push_back(res.scene_ms);
    if (res.full_image) {
      full.push_back(res.full_image_ms);
      to_full.push_back(static_cast<double>(res.bytes_to_full_image));
      if (res.seconds_after_full_image > 0.5)
        steady.push_back(static_cast<double>(res.bytes_after_full_image) /
                         res.seconds_after_full_image);
    }
    if (res.connected) rate.push_back(static_cast<double>(res.bytes_received) / elapsed);
    if (options.render && res.connected) {
      fps.push_back(static_cast<double>(res.frames) / elapsed);
      if (res.frames > 0) frame_ms.push_back(res.frame_ms_mean);
    }
    r.tiles_applied += res.tiles_applied;
    r.tiles_live += res.tiles_live;
    r.bytes_received += res.bytes_received;
    r.frames += res.frames;
    r.camera_updates += res.camera_updates;
    if (options.presence && res.connected) {
      avatar_rate.push_back(static_cast<double>(res.avatar_messages) / elapsed);
      avatar_bytes.push_back(static_cast<double>(res.avatar_bytes) / elapsed);
    }
    r.avatar_messages += res.avatar_messages;
    avatars_listed += res.avatars_listed;
    r.connections_lost += res.connections_lost;
    r.reconnects += res.reconnects;
    r.per_user.push_back(std::move(res));
  }
  r.scene_ms = Percentiles::of(std::move(scene));
  r.full_image_ms = Percentiles::of(std::move(full));
  r.tile_latency_ms = Percentiles::of(std::move(latency));
  r.steady_tile_latency_ms = Percentiles::of(std::move(steady_latency));
  r.bytes_per_s = Percentiles::of(std::move(rate));
  r.steady_bytes_per_s = Percentiles::of(std::move(steady));
  r.bytes_to_full_image = Percentiles::of(std::move(to_full));
  r.frames_per_s = Percentiles::of(std::move(fps));
  r.frame_ms = Percentiles::of(std::move(frame_ms));
  r.avatar_messages_per_s = Percentiles::of(std::move(avatar_rate));
  r.avatar_bytes_per_s = Percentiles::of(std::move(avatar_bytes));
  r.avatars_per_message = r.avatar_messages > 0 ? static_cast<double>(avatars_listed) /
                                                      static_cast<double>(r.avatar_messages)
                                                : 0.0;
  r.errors = std::move(errors);
  return r;
}

std::string LoadReport::text() const {
  std::ostringstream s;
  s << "irradcast-load: " << users << (options.render ? " render" : " thin") << " users for "
    << fixed(elapsed_s) << " s against";
  for (const HostPort& server : servers_or(options.servers, options.host, options.port))
    s << " " << server.text();
  if (options.render) s << " (" << options.width << "x" << options.height << ")";
  if (options.decode_per_user) s << " (every user decodes every tile)";
  s << "\n";
  s << "  users             " << connected << " connected, " << failed << " failed, " << full_image
    << " with a full image\n";
  s << "  reconnects        " << reconnects << " (" << connections_lost << " connections lost)\n";
  s << "  scene loaded      " << dist(scene_ms, " ms") << "\n";
  s << "  first full image  " << dist(full_image_ms, " ms") << "\n";
  s << "  tile latency      " << dist(tile_latency_ms, " ms") << "  (" << tiles_live
    << " live tiles of " << tiles_applied << " applied)\n";
  s << "  all users synced  " << dist(steady_tile_latency_ms, " ms") << "  ("
    << steady_tile_latency_ms.count << " tiles)\n";
  s << "  bytes/s per user  " << byte_dist(bytes_per_s, "/s") << "\n";
  s << "  bytes/s steady    " << byte_dist(steady_bytes_per_s, "/s") << "\n";
  s << "  to full image     " << byte_dist(bytes_to_full_image, "") << "\n";
  if (options.render) {
    s << "  frames/s per user " << dist(frames_per_s, "", 2) << "\n";
    s << "  compose per frame " << dist(frame_ms, " ms") << "\n";
  }
  if (options.presence) {
    s << "  avatars/s per user " << dist(avatar_messages_per_s, "", 2) << "  ("
      << fixed(avatars_per_message) << " avatars per message)\n";
    s << "  avatar bytes/s    " << byte_dist(avatar_bytes_per_s, "/s") << "\n";
  }
  s << "  errors            ";
  if (errors.empty()) s << "none";
  bool first = true;
  for (const auto& [kind, n] : errors) {
    s << (first ? "" : ", ") << kind << ": " << n;
    first = false;
  }
  s << "\n";
  if (const auto refused = errors.find("server REFUSED"); refused != errors.end())
    s << "  refused           the server did not admit " << refused->second
      << " connections (too many from this address, or full); every user comes from this host: "
         "start the server with --max-clients-per-peer 0 (or above --users) for a load test\n";
  return s.str();
}

std::string LoadReport::json(bool per_user_details) const {
  nlohmann::json j;
  const std::vector<HostPort> servers = servers_or(options.servers, options.host, options.port);
  std::vector<std::string> addresses;
  for (const HostPort& server : servers) addresses.push_back(server.text());
  j["options"] = {
      {"host", servers[0].host},
      {"port", servers[0].port},
      {"servers", addresses},
      {"users", options.users},
      {"duration_s", options.duration_s},
      {"mode", options.render ? "render" : "thin"},
      {"width", options.width},
      {"height", options.height},
      {"fps", options.fps},
      {"camera_hz", options.camera_hz},
      {"camera_path", options.camera_path},
      {"ramp_s", options.ramp_s},
      {"decode", options.decode_per_user                        ? "per-user"
                 : options.render || options.copy_shared_texels ? "shared, copied"
                                                                : "shared, referenced"}};
  j["elapsed_s"] = elapsed_s;
  j["users"] = {{"total", users},           {"connected", connected},
                {"failed", failed},         {"scene_loaded", scene_loaded},
                {"full_image", full_image}, {"connections_lost", connections_lost},
                {"reconnects", reconnects}};
  j["scene_ms"] = to_json(scene_ms);
  j["full_image_ms"] = to_json(full_image_ms);
  j["tile_latency_ms"] = to_json(tile_latency_ms);
  j["steady_tile_latency_ms"] = to_json(steady_tile_latency_ms);
  j["bytes_per_s_per_user"] = to_json(bytes_per_s);
  j["steady_bytes_per_s_per_user"] = to_json(steady_bytes_per_s);
  j["bytes_to_full_image"] = to_json(bytes_to_full_image);
  j["frames_per_s_per_user"] = to_json(frames_per_s);
  j["compose_ms"] = to_json(frame_ms);
  j["totals"] = {{"tiles_applied", tiles_applied},
                 {"tiles_live", tiles_live},
                 {"bytes_received", bytes_received},
                 {"frames", frames},
                 {"camera_updates", camera_updates}};
  if (options.presence)
    j["avatars"] = {{"messages", avatar_messages},
                    {"per_message", avatars_per_message},
                    {"messages_per_s", to_json(avatar_messages_per_s)},
                    {"bytes_per_s", to_json(avatar_bytes_per_s)}};
  j["errors"] = nlohmann::json::object();
  for (const auto& [kind, n] : errors) j["errors"][kind] = n;
  if (per_user_details) {
    nlohmann::json list = nlohmann::json::array();
    for (const LoadUserResult& u : per_user)
      list.push_back({{"connected", u.connected},
                      {"scene_loaded", u.scene_loaded},
                      {"full_image", u.full_image},
                      {"scene_ms", u.scene_ms},
                      {"full_image_ms", u.full_image_ms},
                      {"bytes_received", u.bytes_received},
                      {"bytes_to_full_image", u.bytes_to_full_image},
                      {"tiles_applied", u.tiles_applied},
                      {"tiles_live", u.tiles_live},
                      {"frames", u.frames},
                      {"connections_lost", u.connections_lost},
                      {"reconnects", u.reconnects},
                      {"tiles_held", u.tiles_held},
                      {"versions_digest", std::to_string(u.versions_digest)},
                      {"failure", u.failure}});
    j["per_user"] = list;
  }
  return j.dump(2);
}

}  // namespace irradcast

// A viewer's connection to irradcast-server: handshake, the scene package (from the cache when
// its hash matches, else downloaded and cached), a subscription, and a tile cache kept current
// as TileUpdates arrive. Composes frames of its own viewpoint with the compositor. Reconnects
// after a lost connection and resumes: the tiles it holds are only sent again when their version
// changed. A connection lost in any phase (connect, handshake, scene download, streaming) is
// retried with capped, jittered exponential back-off (backoff.h) until the deadline; protocol
// errors (a bad frame from the server, another protocol version) are not retried. With several
// server addresses (--connect A,B,...: origins or gateways of the same scene) a refused or lost
// connection moves on to the next address, round after round, and resumes there with the tiles
// held (a server of another tile epoch resends every tile; client_session.h).
// The session's protocol is the ClientSession's (client_session.h; this class sends its camera,
// StatsRequest and Bye itself); this class adds the blocking socket, the scene cache on disk and
// the reconnection policy. Single-threaded: call poll() to make progress.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/client/backoff.h"
#include "irradcast/client/client_passes.h"
#include "irradcast/client/client_session.h"
#include "irradcast/client/client_tls.h"
#include "irradcast/client/host_port.h"
#include "irradcast/client/tile_cache.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

namespace wire {
class BlockingChannel;
}

struct ViewClientOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 7450;
  // The failover list (--connect A,B,...), tried in order from the first; empty: {host, port}.
  std::vector<HostPort> servers;
  std::string name = "irradcast-view";
  std::string cache_dir;  // scene packages by hash; empty = no cache
  wire::TileEncoding encoding = wire::TILE_RGB9E5_ZSTD;
  std::uint64_t max_bytes_per_s = 0;  // 0 = no cap
  // How long connect() and each reconnection keep trying (from their start) when `deadline` is
  // not set.
  std::chrono::milliseconds connect_timeout{10000};
  // When set: connect() and every reconnection keep trying until this time instead (a viewer's
  // --timeout), however long the server is away.
  std::chrono::steady_clock::time_point deadline{};
  std::chrono::milliseconds reply_timeout{10000};  // for Welcome and each scene chunk
  std::chrono::milliseconds ping_interval{5000};   // keeps the server's idle timer happy
  bool reconnect = true;
  BackoffPolicy backoff;           // delays between connection attempts
  std::uint64_t backoff_seed = 0;  // jitter; 0 = a random seed per client
  ClientTls tls;                   // plain TCP unless enabled
  // Dynamic objects get the emitters' direct light traced (shadow rays, dynamic_view.h); false:
  // from the probe volume, as the browser page does (--dynamic-emitters volume).
  bool trace_emitters = true;
  // Presence (irradcast-server --presence; docs/DYNAMIC.md#presence): shown to the other viewers
  // as an avatar at this camera, and drawing theirs (at most `avatars`, the nearest).
  bool presence = false;
  int avatars = 32;
};

struct ViewClientCounters {
  std::uint64_t bytes_received = 0;
  std::uint64_t frames_received = 0;
  std::uint64_t tiles_applied = 0;
  std::uint64_t scene_bytes_downloaded = 0;
  std::uint32_t connections = 0;  // sessions set up (Welcome, scene, Subscribe): 1 + reconnects
  std::uint32_t connections_lost = 0;  // connections that dropped after a session was set up
  std::uint32_t connect_attempts = 0;  // connection attempts, failed ones included
  std::uint32_t failovers = 0;         // moves to the next address of the list after a failure
  bool scene_from_cache = false;
  std::uint64_t errors_received = 0;
  std::uint64_t edits_applied = 0;    // scene edits applied to the viewer's copy of the scene
  std::uint64_t avatar_messages = 0;  // Avatars received (presence)
  std::uint32_t avatars_shown = 0;    // the other viewers' avatars drawn now
};

class ViewClient {
 public:
  explicit ViewClient(ViewClientOptions options);
  ~ViewClient();
  ViewClient(const ViewClient&) = delete;
  ViewClient& operator=(const ViewClient&) = delete;

  // Connects, says Hello, loads the scene and subscribes to every tile, retrying a lost or
  // refused connection with back-off. Throws irradcast::Error when no session is set up before
  // the deadline (or connect_timeout), or on a protocol error.
  void connect();
  // Receives and applies frames for `budget`, pinging as needed; reconnects (if enabled) when the
  // connection drops, which can take until the deadline (then irradcast::Error). Returns the
  // number of tiles applied.
  std::size_t poll(std::chrono::milliseconds budget);
  // Asks for the server's stats and polls until they arrive (or timeout: nullopt).
  std::optional<wire::Stats> request_stats(std::chrono::milliseconds timeout);
  void send_camera(const CameraPose& camera);
  // Says Bye and closes. Idempotent.
  void close();

  // The viewer's frame: the static scene from the lightmaps and the dynamic objects lit by the
  // probe volume (unlit until it arrives; docs/DYNAMIC.md).
  ImageRGB compose(const CameraPose& camera, int width, int height) const;
  // The same frame through the client passes (SSAO, reprojection; client_passes.h). Reset
  // `passes` when static_revision() changes: its history belongs to the old scene.
  ImageRGB compose(const CameraPose& camera, int width, int height, ClientPasses& passes,
                   ClientFrameStats* stats = nullptr) const;
  const Scene& scene() const;
  const World& world() const;
  const Atlas& atlas() const;
  const std::vector<Lightmap>& lightmaps() const { return core_.tiles().lightmaps(); }
  std::uint64_t tile_version(std::uint32_t lightmap, std::uint32_t tx, std::uint32_t ty) const {
    return core_.tiles().version(lightmap, tx, ty);
  }
  // True when every tile has arrived at least once.
  bool all_tiles_received() const { return core_.tiles().all_received(); }
  // The irradiance volume the server sent (epoch 0: none).
  const wire::ReceivedVolume& probe_volume() const { return core_.probe_volume(); }
  std::size_t tile_count() const { return core_.tiles().tile_count(); }
  ViewClientCounters counters() const;
  // The hash of the scene package downloaded (or taken from the cache) at the last connection;
  // edits applied since then do not change it.
  const std::string& scene_hash() const { return core_.scene_hash(); }
  // The revision of the viewer's scene: the package's, plus the edits applied since (every
  // applied SceneEdit the server broadcasts, in order; docs/EDITS.md).
  std::uint64_t scene_revision() const { return core_.revision(); }
  // The server's pose sequence of the last Poses applied (docs/DYNAMIC.md#poses).
  std::uint64_t pose_sequence() const { return core_.pose_sequence(); }
  // Changes with each new scene and each edit of the static scene (not with dynamic moves).
  std::uint64_t static_revision() const { return core_.static_revision(); }
  std::uint64_t session() const { return core_.session(); }
  // The address of the current connection (or of the next attempt).
  const HostPort& server() const { return servers_[current_]; }

 private:
  // Attempts connections (open_connection + handshake) until one sets up a session, moving to
  // the next address after each failure (and first of all when `after_loss`). Sleeps a back-off
  // delay before each round over the list but the first (and before the first too when
  // `after_loss`); throws irradcast::Error at the deadline or on a protocol error.
  void establish(bool after_loss);
  // One TCP connection attempt, bounded by `deadline`; throws ConnectionLost.
  void open_connection(std::chrono::steady_clock::time_point deadline);
  void drop_connection();
  void handshake();
  // After a Welcome for another scene: from the cache on disk, else downloaded (and cached).
  ClientStep load_scene();
  void log_scene(const wire::Welcome& w, bool from_cache) const;
  void send(const wire::Envelope& e);
  void send_all(const ClientStep& step);
  // Next frame within the deadline; false on timeout. Throws ConnectionLost.
  bool read_frame(wire::Envelope& out, std::chrono::steady_clock::time_point deadline);
  // The dynamic objects and the volume that lights them, for compose().
  DynamicView dynamic_view() const;
  // Hands a frame to the protocol core and acts on a server Error or Bye.
  ClientStep feed(const wire::Envelope& e);
  // After ConnectionLost: reconnects (establish) or, without options.reconnect, throws Error.
  void connection_lost(const std::exception& lost);

  ViewClientOptions options_;
  std::vector<HostPort> servers_;            // at least one
  std::size_t current_ = 0;                  // index into servers_
  std::shared_ptr<asio::ssl::context> tls_;  // null: plain TCP
  Backoff backoff_;
  std::unique_ptr<wire::BlockingChannel> net_;  // the connection now, if any
  ClientSession core_;
  // Connection counts; the protocol's counts are the core's.
  std::uint64_t bytes_received_ = 0;  // on the connections before the current one
  std::uint32_t connections_ = 0, connections_lost_ = 0, connect_attempts_ = 0, failovers_ = 0;
  std::chrono::steady_clock::time_point last_ping_{};
};

}  // namespace irradcast

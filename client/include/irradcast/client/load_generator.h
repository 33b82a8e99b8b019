// Simulated users for load tests (irradcast-load): many protocol clients in one process, one
// TCP connection each, all on one Asio io_context. Each user connects, says Hello, downloads
// and checks the scene package, subscribes to every tile, sends CameraUpdates along its camera
// path, and parses, checks and applies every TileUpdate (thin users share the decode of
// byte-identical tiles and keep a reference to it; with decode_per_user each decodes into its
// own lightmaps); in render mode it also composes frames of its view into its own lightmaps. A user
// whose connection drops (reset, EOF, a server Error SERVER_SHUTDOWN, a timed-out handshake or
// download) reconnects with the viewer's back-off policy (backoff.h) until the end of the run and
// resumes as the viewer does (Hello with its scene hash and tile versions); with several servers
// (--connect A,B,...) the users spread their first connection over them and each retry goes to the
// next. The report has the numbers a service owner asks about: who connected, how long the scene
// and the first full image took, tile latency (from the version's time stamp on the server to the
// user's apply), bandwidth, frame rate and errors by kind.
//
// Tile latency compares the server's clock (TileUpdate.server_time_us) with this machine's, so
// it is exact on one machine and needs synchronised clocks (NTP) across machines. Only versions
// the server computed after the user subscribed count (the first download of older tiles is
// "time to first full image" instead).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/client/backoff.h"
#include "irradcast/client/camera_path.h"
#include "irradcast/client/client_tls.h"
#include "irradcast/client/host_port.h"

namespace irradcast {

struct LoadOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 7450;
  // The failover list (--connect A,B,...); empty: {host, port}. User i tries server i mod n
  // first and moves to the next after a refused or lost connection.
  std::vector<HostPort> servers;
  int users = 1;
  double duration_s = 10.0;  // from the start of the run; users then say Bye
  bool render = false;       // compose frames too (else "thin": network + tile decoding)
  // Every user decodes every tile into its own lightmaps. Default: the users share the decode
  // of byte-identical tiles (a real client decodes on its own CPU; N decodes on one load
  // machine would measure the load machine); render users copy the texels into their
  // lightmaps, thin users keep a reference to the shared decode (SharedTexels::Reference).
  bool decode_per_user = false;
  // Thin users copy the shared decode into lightmaps of their own, as render users do (what
  // they did before SharedTexels::Reference; for irradcast-bench-fanout --fresh).
  bool copy_shared_texels = false;
  int width = 320, height = 240;
  double fps = 30.0;        // render mode: frames per second per user at most (0 = no cap)
  double camera_hz = 10.0;  // CameraUpdates per second per user
  std::string camera_path = "orbit";  // "orbit", "random-walk" or a keyframe file
  double ramp_s = 0.0;                // connect the users evenly over this many seconds
  int threads = 0;                    // I/O threads (0 = the machine's cores)
  std::string name = "irradcast-load";
  wire::TileEncoding encoding = wire::TILE_RGB9E5_ZSTD;
  // Delays between connection attempts: connecting and reconnecting are retried until the end
  // of the run.
  BackoffPolicy backoff;
  std::chrono::milliseconds reply_timeout{10000};  // for Welcome and each scene chunk
  std::uint64_t seed = 1;                          // random-walk paths and back-off jitter
  ClientTls tls;                                   // plain TCP unless enabled
  // Presence (irradcast-server --presence): every user is shown as an avatar at its camera,
  // moving along its camera path, and receives the nearest others' Avatars.
  bool presence = false;

  // Throws irradcast::Error naming the first option out of range (run_load calls it first).
  void validate() const;
};

// Distribution of a quantity over users or events.
struct Percentiles {
  std::size_t count = 0;
  double p50 = 0.0, p95 = 0.0, p99 = 0.0, max = 0.0, mean = 0.0;
  static Percentiles of(std::vector<double> values);
};

struct LoadUserResult {
  bool connected = false, scene_loaded = false, full_image = false;
  double scene_ms = 0.0;       // start of the connection to the scene package checked
  double full_image_ms = 0.0;  // start to every tile held (render: the first frame after that)
  std::uint64_t bytes_received = 0;
  std::uint64_t bytes_to_full_image = 0;  // scene included
  std::uint64_t bytes_after_full_image = 0;
  double seconds_after_full_image = 0.0;
  std::uint64_t tiles_applied = 0;
  std::uint64_t tiles_live = 0;    // versions computed after the user subscribed
  std::uint64_t tiles_steady = 0;  // of those, applied once every user had a full image
  std::uint64_t frames = 0;
  double frame_ms_mean = 0.0;
  std::uint64_t camera_updates = 0;
  std::uint64_t avatar_messages = 0, avatars_listed = 0, avatar_bytes = 0;  // presence
  std::uint64_t connections_lost = 0;  // connections that dropped before the end of the run
  std::uint64_t reconnects = 0;        // sessions set up again after a lost connection
  // The tile versions held at the end: how many tiles, and an FNV-1a digest of the version
  // vector in layout order (equal digests = the same versions of every tile).
  std::uint64_t tiles_held = 0;
  std::uint64_t versions_digest = 0;
  std::string failure;  // why the user did not finish ("" when it did)
};

struct LoadProgress {
  double elapsed_s = 0.0;
  int users = 0, connected = 0, scene_loaded = 0, full_image = 0, failed = 0;
  std::uint64_t tiles_applied = 0, bytes_received = 0, frames = 0, errors = 0, reconnects = 0;
  double latency_p99_ms = 0.0;  // of the live tiles applied since the previous progress report
};

struct LoadReport {
  LoadOptions options;
  double elapsed_s = 0.0;
  int users = 0, connected = 0, failed = 0, scene_loaded = 0, full_image = 0;
  Percentiles scene_ms, full_image_ms;
  Percentiles tile_latency_ms;  // every live tile
  // Live tiles applied once every user of the run had its first full image: the steady state,
  // without the initial downloads of users that joined later queued in front.
  Percentiles steady_tile_latency_ms;
  Percentiles bytes_per_s;         // per user, over its whole connection
  Percentiles steady_bytes_per_s;  // per user, after its first full image
  Percentiles bytes_to_full_image;
  Percentiles frames_per_s;  // render mode
  Percentiles frame_ms;      // render mode: compose time per frame, per user mean
  std::uint64_t tiles_applied = 0, tiles_live = 0, bytes_received = 0, frames = 0;
  std::uint64_t camera_updates = 0;
  // Presence: Avatars messages and their bytes per user per second, avatars per message.
  Percentiles avatar_messages_per_s, avatar_bytes_per_s;
  std::uint64_t avatar_messages = 0;
  double avatars_per_message = 0.0;
  std::uint64_t connections_lost = 0, reconnects = 0;  // summed over the users
  std::map<std::string, std::uint64_t> errors;         // by kind
  std::vector<LoadUserResult> per_user;

  // The report of a run from its users' results, the live tile latencies of all users (ms)
  // and the errors by kind.
  static LoadReport of(const LoadOptions& options, double elapsed_s,
                       std::vector<LoadUserResult> users, std::vector<double> tile_latency_ms,
                       std::vector<double> steady_tile_latency_ms,
                       std::map<std::string, std::uint64_t> errors);

  std::string text() const;
  std::string json(bool per_user_details = true) const;
};

// Runs the users to the end of the duration. `on_progress` is called about once a second from
// a helper thread. Throws irradcast::Error for bad options or an unresolvable host; everything
// that goes wrong with a user is in the report.
LoadReport run_load(const LoadOptions& options,
                    const std::function<void(const LoadProgress&)>& on_progress = {});

// A FNV-1a digest of a version vector (what LoadUserResult.versions_digest holds), so a test
// can compare it with the server's tile store.
std::uint64_t versions_digest(const std::vector<std::uint64_t>& versions);

}  // namespace irradcast

// NatsGateway's state, shared by its files: nats_gateway.cpp (the stream's scene state,
// package, tiles, edits and stats; the worker thread; the public API) and nats_gateway_dynamic.cpp
// (the probe volume, the poses and the avatars from the stream).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "irradcast/common/log.h"
#include "irradcast/service/nats_gateway.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast/service/pose_board.h"
#include "irradcast/service/tile_store.h"
#include "irradcast_nats.pb.h"
#include "nats_link.h"
#include "presence_board.h"

namespace irradcast::nats_gateway {

using Clock = std::chrono::steady_clock;
constexpr std::uint32_t kMaxChunks = 1u << 14;      // 8 GiB of package at 512 KiB
constexpr std::size_t kMaxEarlyTiles = 1u << 20;    // tiles before the first state
constexpr std::size_t kMaxEarlyBytes = 256u << 20;  // their payloads
// How far a tile's version may lead the origin's engine updates (its stats lag by up to a
// second's updates).
constexpr std::uint64_t kMaxVersionLead = 1000;
constexpr std::uint32_t kMaxLightmaps = 1u << 20;
constexpr std::size_t kMaxCameras = 4096;
// A NatsPresence with more groups or avatars than an origin publishes is refused whole.
constexpr int kMaxPresenceGroups = 4096;
constexpr std::size_t kMaxPresenceAvatars = 16384;
constexpr auto kCameraKeepalive = std::chrono::seconds(2);
constexpr std::uint32_t kMaxVolumeChunks = 1u << 9;   // 256 MiB at 512 KiB
constexpr std::uint64_t kMaxVolumeBytes = 96u << 20;  // 2^16 probes' layout and SH, with room

}  // namespace irradcast::nats_gateway

namespace irradcast {

struct NatsGateway::Impl {
  using Clock = nats_gateway::Clock;
  explicit Impl(NatsGatewayOptions o)
      : options(std::move(o)), subjects(nats_subjects(options.scene_id)) {}

  NatsGatewayOptions options;
  NatsSubjects subjects;
  const std::uint64_t gateway = [] {
    std::random_device rd;
    return (std::uint64_t{rd()} << 32 | rd()) | 1;
  }();

  nats_link::Listeners listeners;  // the Server's

  mutable std::mutex mutex;  // guards the state below
  mutable std::condition_variable cv;
  bool stopping = false;
  std::unique_ptr<TileStore> store;  // made once, from the first state
  std::vector<std::pair<int, int>> sizes;
  std::shared_ptr<const wire::ScenePackage> package;
  std::uint64_t revision = 0, epoch = 0, origin = 0;
  std::string backend;
  EngineHostStats engine;
  // The origin's engine updates from the stats read since the stream was last (re)subscribed
  // (0: none yet): tiles replayed before the newest stats are not held to stale ones.
  std::uint64_t updates_seen = 0;
  NatsGatewayStats st;
  std::map<std::uint64_t, CameraPose> cameras;
  bool cameras_changed = false;

  // The stream's messages, one at a time (the subscription's thread).
  std::mutex handle_mutex;
  std::optional<wire::NatsSceneState> pending_state;  // waiting for its chunks
  std::map<std::uint32_t, wire::NatsPackageChunk> chunks;
  std::map<std::uint32_t, wire::NatsTile> early_tiles;  // before the first state
  std::size_t early_bytes = 0;
  std::vector<std::uint64_t> tile_origin;          // the origin of each tile's version held
  std::uint64_t reset_origin = 0;                  // a new lineage: its tiles replace what is held
  std::uint64_t last_edit = 0;                     // the newest edit revision forwarded
  std::optional<wire::NatsVolume> pending_volume;  // waiting for its chunks
  std::map<std::uint32_t, wire::NatsVolumeChunk> volume_chunks;
  std::shared_ptr<const ProbeVolumeFrames> volume;  // the newest checked version (mutex)
  PoseBoard poses;                                  // the origin's poses, as they come
  PresenceBoard presence;  // with options.presence: this gateway's avatars and the origin's set
  std::uint64_t avatars_sent = 0;      // the board's local version sent to the origin (mutex)
  Clock::time_point presence_heard{};  // the origin's newest s.presence (mutex)

  std::unique_ptr<nats_link::Connection> conn;
  nats_link::Subscription sub;  // the stream's; worker thread
  std::thread worker;

  void run();
  void subscribe();
  void send_cameras();
  void on_message(natsMsg* msg);
  void handle(const std::string& kind, const std::string& data);
  void on_state(const std::string& data);
  void on_chunk(const std::string& data);
  void try_complete();
  void apply_state(const wire::NatsSceneState& s, std::shared_ptr<const wire::ScenePackage> p);
  void on_tile(wire::NatsTile t);
  bool install(const wire::NatsTile& t);
  void on_edit(const std::string& data);
  void on_stats(const std::string& data);
  void on_volume(const std::string& data);
  void on_volume_chunk(const std::string& data);
  void try_volume();
  void on_poses(const std::string& data);
  void on_presence(const std::string& data);
  void expire_presence(Clock::time_point now);
  void bad(const std::string& what) {
    {
      std::lock_guard lock(mutex);
      ++st.bad_messages;
    }
    log::warn("gateway", "ignored a message from NATS: " + what);
  }
};

}  // namespace irradcast

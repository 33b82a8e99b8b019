// The messages a session builds from the server's state (session_protocol.h decides when): the
// Welcome, the parts of a Stats reply, a TileUpdate; the close reason an Error code means; the
// control token's comparison.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/service/net_server.h"
#include "irradcast/service/tile_source.h"
#include "irradcast/service/tile_store.h"
#include "irradcast/wire/frame.h"
#include "presence_board.h"

namespace irradcast {

// The wall clock in microseconds since the Unix epoch (the *_us fields of messages).
std::uint64_t wall_clock_us();
// Compares a client's token with the server's in time independent of where they differ.
bool same_secret(const std::string& given, const std::string& secret);
// The reason a session ends after sending an Error frame with this code.
CloseReason reason_of(wire::ErrorCode code);

// The Welcome that answers a Hello: the session, the scene package, the lightmaps and tiles, the
// server's limits.
wire::Envelope welcome_message(const TileSource& host, const ServerOptions& options,
                               std::uint64_t session, const wire::ScenePackage& package);
// The engine's and the server's parts of a Stats reply.
void add_engine_stats(const EngineHostStats& es, wire::Stats* s);
void add_server_stats(const ServerStats& ss, wire::Stats* s);
// The inverse of add_engine_stats (a gateway reads the origin's stats from NATS).
EngineHostStats engine_stats_from(const wire::Stats& s);
// A CameraUpdate's pose, or nullopt with the reason in `problem` (a number that is not finite, a
// zero forward direction).
std::optional<CameraPose> camera_pose_of(const wire::CameraUpdate& c, std::string& problem);
// An avatar on the wire (Avatars, NatsCameras, NatsPresence).
void avatar_to_wire(const AvatarState& a, wire::Avatar* w);
// Another server's avatars: those valid_avatar() takes, each id once (the first), at most
// PresenceBoard::kMaxGroupAvatars; `refused` (when given) counts the rest.
std::vector<AvatarState> avatars_from_wire(
    const google::protobuf::RepeatedPtrField<wire::Avatar>& in, std::size_t* refused = nullptr);
// The TileUpdate that carries a snapshot of `tile`.
wire::Envelope tile_update_message(const TileStore::Tile& tile, const TileStore::Snapshot& snap,
                                   wire::TileEncoding encoding);

// The encoded TileUpdate frame of each tile's newest snapshot, per encoding, built once and
// shared by every session that sends it (sessions hold it by pointer until it is written).
// Keyed by the snapshot's payload (a new version, or a gateway's new lineage, has a new one).
// One entry per tile and encoding; any thread (one mutex, frames built outside it).
class TileFrames {
 public:
  std::shared_ptr<const std::string> frame(const TileStore& store, std::uint32_t tile,
                                           const TileStore::Snapshot& snap,
                                           wire::TileEncoding encoding);

 private:
  struct Entry {
    std::shared_ptr<const std::string> payload, frame;
  };
  std::mutex mutex_;
  std::vector<Entry> entries_[2];  // RGB9E5, HALF
};

}  // namespace irradcast

// The client side of the irradcast protocol (docs/PROTOCOL.md) for the viewer and the load users,
// written once and without I/O: fed the frames a server sends, it says what to send back and keeps
// the state a session builds up: the Welcome's session and tile epoch, the scene package
// (downloaded chunk by chunk and checked against the Welcome's hash, or taken from a cache), the
// tile cache and its versions, and the scene's revision as broadcast SceneEdits are applied. A new
// connection resumes with the Hello it makes (the scene hash held and the tile versions). Driven by
// the viewer (ViewClient, blocking) and by each simulated user of the load generator
// (asynchronous), so the load test runs the viewer's protocol code; the drivers send what they add
// themselves (CameraUpdate, StatsRequest, Bye). irradcast-edit (client/tools/edit_session.h:
// Hello, edits, the export) and the browser page (web/src/connection.js) have clients of their own.
//
// Phases: hello() starts AwaitWelcome. A Welcome for the scene held subscribes at once (Streaming);
// one for another scene gives NeedScene, and the driver offers a cached package
// (use_cached_package) or asks for the download (download()). The last chunk, or the cached
// package, subscribes. Bad input throws ClientSessionFailure, whose kind() says what was wrong.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/client/avatars.h"
#include "irradcast/client/tile_cache.h"
#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/wire/probe_volume_message.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

// The scene and what is derived from it; World and RayScene hold pointers into the Scene, so
// they live together at a stable address.
struct ClientScene {
  wire::UnpackedScene unpacked;
  World world;
  std::unique_ptr<RayScene> rays;  // null when the client does not compose frames
  // The dynamic objects' own ray scene (dynamic_view.h); null without dynamic objects or rays.
  std::unique_ptr<RayScene> dynamic_rays;
  // The static scene's emitters, whose direct light the viewer traces onto dynamic objects;
  // null with `dynamic_rays`.
  std::unique_ptr<LightSampler> lights;
  // The other viewers' avatars (avatars.h): nodes [avatar_first, avatar_first + avatar_count)
  // the client added after the package's.
  int avatar_first = -1, avatar_count = 0;

  // Builds `rays` and, when the world has dynamic objects, `dynamic_rays` and `lights`.
  void build_ray_scenes();
};

// Makes the scene of a package (checking it against `hash`); throws irradcast::Error.
using ClientSceneFactory =
    std::function<std::shared_ptr<ClientScene>(const std::string& bytes, const std::string& hash)>;
// The default: unpacks the package (hash checked), adds `avatar_nodes` avatar nodes (0: none;
// add_avatar_nodes), builds the world and its RayScene.
std::shared_ptr<ClientScene> make_client_scene(const std::string& bytes, const std::string& hash,
                                               int avatar_nodes = 0);

// Input the protocol does not allow: kind() is "protocol" (a message out of order or of another
// protocol version), "bad scene" (a chunk or package that does not fit the Welcome) or "bad tile".
class ClientSessionFailure : public Error {
 public:
  ClientSessionFailure(std::string kind, const std::string& what)
      : Error(what), kind_(std::move(kind)) {}
  const std::string& kind() const { return kind_; }

 private:
  std::string kind_;
};

struct ClientSessionOptions {
  std::string name = "irradcast-client";  // Hello.client_name
  wire::TileEncoding encoding = wire::TILE_RGB9E5_ZSTD;
  std::uint64_t max_bytes_per_s = 0;  // 0 = no cap
  // Pings at most this far apart, and a third of the server's idle timeout if that is shorter
  // (but not below min_ping_interval).
  std::chrono::milliseconds ping_interval{5000};
  std::chrono::milliseconds min_ping_interval{0};
  // Apply the SceneEdits the server broadcasts to the scene (the viewer). Off: they are ignored
  // and the scene stays as the package made it (the load test's users share one scene).
  bool follow_edits = true;
  std::string log_tag = "client";  // for the log lines about edits
  // Decode byte-identical tiles once for many sessions of this process (irradcast-load).
  std::shared_ptr<TileDecodeCache> shared_decodes;
  // How the tiles found there are held (Reference: no lightmaps, for users that never compose).
  SharedTexels shared_texels = SharedTexels::Copy;
  // Presence (docs/DYNAMIC.md#presence): subscribe with Subscribe.presence (this viewer is shown
  // to the others at its camera, and gets the nearest others' Avatars).
  bool presence = false;
  // The avatars the default scene factory makes room for (0: none are drawn; with follow_edits).
  int avatar_nodes = 0;
};

struct ClientSessionCounters {
  std::uint64_t frames_received = 0;
  std::uint64_t tiles_applied = 0;
  std::uint64_t scene_bytes_downloaded = 0;
  std::uint64_t errors_received = 0;
  std::uint64_t edits_applied = 0;    // scene edits applied to the client's copy of the scene
  std::uint64_t poses_applied = 0;    // Poses messages applied (docs/DYNAMIC.md#poses)
  std::uint64_t avatar_messages = 0;  // Avatars messages received (docs/DYNAMIC.md#presence)
  std::uint64_t avatars_listed = 0;   // avatars in them, summed
  bool scene_from_cache = false;      // the last scene loaded came from use_cached_package
};

// What a frame (or a step the driver asked for) did.
struct ClientStep {
  enum class Event {
    None,          // nothing for the driver: Pong, a stale tile, an edit, anything newer
    NeedScene,     // a Welcome for a scene not held: use_cached_package() or download()
    Downloading,   // a chunk of the scene package arrived; more are to come
    SessionReady,  // subscribed (`send` holds the Subscribe); scene_loaded when the scene is new
    TileApplied,   // a TileUpdate newer than the version held was decoded
    Stats,         // the server's Stats (last_stats())
    ServerError,   // an Error frame (counted); server_error_is_transient says if it ends this one
    Bye,           // the server's Bye
  };
  Event event = Event::None;
  std::vector<wire::Envelope> send;  // to send, in order
  bool scene_loaded = false;         // SessionReady: a scene package was loaded for it
};

// Microseconds since the Unix epoch: the time stamps of Pings and of TileUpdates.
std::uint64_t wall_time_us();

class ClientSession {
 public:
  enum class Phase { Idle, AwaitWelcome, NeedScene, Downloading, Streaming };

  explicit ClientSession(ClientSessionOptions options, ClientSceneFactory factory = {});

  // A new connection: the Hello to send first (resuming with the scene and tile versions held).
  wire::Envelope hello();
  // The connection is gone; the scene, tiles and versions stay for the next hello().
  void disconnect();
  // One decoded frame from the server. Throws ClientSessionFailure on input the protocol does not
  // allow; the session is then unusable until the next hello().
  ClientStep on_frame(const wire::Envelope& e);
  // After NeedScene: a package from the driver's cache. False when it is damaged or another
  // scene's (`why` says how; the session still needs the scene); else the session is ready.
  bool use_cached_package(const std::string& bytes, ClientStep& step, std::string* why = nullptr);
  // After NeedScene: the SceneRequest that starts the download.
  wire::Envelope download();
  // True once: the broadcast edits cannot be followed (one was missed or does not apply); the
  // current scene comes with a new connection's Welcome.
  bool take_reload();

  static wire::Envelope ping(std::uint64_t nonce, std::uint64_t time_us);

  Phase phase() const { return phase_; }
  bool has_scene() const { return scene_ != nullptr; }
  // Throws irradcast::Error before the first scene.
  const ClientScene& scene() const;
  std::shared_ptr<const ClientScene> scene_ptr() const { return scene_; }
  const wire::Welcome& welcome() const { return welcome_; }
  // The package of the last completed download (for the driver's cache); empty otherwise.
  const std::string& downloaded_package() const { return downloaded_; }
  const TileCache& tiles() const { return tiles_; }
  // The irradiance volume the server sent (epoch 0: none; docs/DYNAMIC.md).
  const wire::ReceivedVolume& probe_volume() const { return volume_; }
  const std::string& scene_hash() const { return scene_hash_; }
  std::uint64_t tile_epoch() const { return tile_epoch_; }
  std::uint64_t revision() const { return revision_; }
  // The server's pose sequence of the last Poses applied (docs/DYNAMIC.md#poses).
  std::uint64_t pose_sequence() const { return pose_sequence_; }
  // The other viewers' avatars shown now (presence; avatars.h).
  int avatars_shown() const { return avatars_.shown(); }
  // Counts the changes to the static scene: a scene installed, or an applied edit that moved,
  // hid or changed static content (edit_changes_static_scene). Edits that only move dynamic
  // objects leave it (a viewer's history stays valid; client_passes.h).
  std::uint64_t static_revision() const { return static_revision_; }
  std::uint64_t session() const { return session_; }
  std::chrono::milliseconds ping_interval() const { return ping_interval_; }
  const std::optional<wire::Stats>& last_stats() const { return last_stats_; }
  void clear_stats() { last_stats_.reset(); }
  const ClientSessionCounters& counters() const { return counters_; }

 private:
  ClientStep on_welcome(const wire::Welcome& w);
  ClientStep on_chunk(const wire::SceneChunk& c);
  ClientStep on_tile(const wire::TileUpdate& t);
  // Takes the scene (from a download or the cache) and subscribes.
  ClientStep install(std::shared_ptr<ClientScene> scene, bool from_cache);
  wire::Envelope subscribe();
  void on_scene_edit(const wire::SceneEdit& m);
  void apply_scene_edit(const wire::SceneEdit& m);
  void on_poses(const wire::Poses& m);
  void on_avatars(const wire::Avatars& m);

  ClientSessionOptions options_;
  ClientSceneFactory factory_;
  Phase phase_ = Phase::Idle;
  wire::Welcome welcome_;
  std::unique_ptr<wire::SceneAssembler> assembler_;
  std::string downloaded_;
  std::shared_ptr<ClientScene> scene_;
  std::string scene_hash_;
  std::uint64_t session_ = 0;
  std::uint64_t tile_epoch_ = 0;
  std::uint64_t revision_ = 0;
  std::uint64_t static_revision_ = 0;
  wire::ReceivedVolume volume_;
  TileCache tiles_;
  std::vector<wire::SceneEdit> pending_edits_;  // arrived while the scene loads
  // Nodes the server posed (docs/DYNAMIC.md#poses), with the pose the scene package gave them.
  std::map<int, NodePoseState> package_poses_;
  std::vector<bool> posable_;  // pose_nodes() of the scene, computed at the first Poses
  std::uint64_t pose_sequence_ = 0;
  AvatarNodes avatars_;  // of scene_
  bool reload_ = false;
  std::chrono::milliseconds ping_interval_;
  std::optional<wire::Stats> last_stats_;
  ClientSessionCounters counters_;
};

}  // namespace irradcast

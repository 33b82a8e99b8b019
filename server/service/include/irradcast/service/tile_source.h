// What a Server serves: the scene package, the tile store with its versions and epoch, the
// scene revision, and the two ways back (scene edits, viewers' cameras), with listeners for new
// tile versions and applied edits. EngineHost implements it with the engine in the process (the
// origin); NatsGateway (nats_gateway.h) with the state an origin publishes to NATS. The Server,
// its sessions, protocol, resume and limits are the same code for both.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/service/pose_board.h"
#include "irradcast/service/tile_store.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

// An edit the engine thread has applied (EngineHost::set_edit_listener).
struct AppliedEdit {
  SceneEdit edit;
  std::uint64_t revision = 0;  // the scene's revision after it (the first edit makes 1)
  std::shared_ptr<const wire::ScenePackage> package;  // the scene package at that revision
  std::uint64_t tile_epoch = 0;                       // EngineHost::tile_epoch() after it
  std::uint64_t applied_us = 0;                       // system clock when the engine had applied it
  double apply_ms = 0.0;  // time to apply (scene, ray scene, G-buffers, engine)
};

// What a host made of an accepted edit (TileSource::submit).
struct EditReceipt {
  std::uint64_t revision = 0;       // the revision it will make (0: it only posed nodes)
  std::uint64_t pose_sequence = 0;  // the pose sequence its pose ops made (0: none)
};

// One engine pass (direct, or a bounce's probe gather or scatter): the last update's time and
// rays, and the totals over every update.
struct EnginePassStats {
  std::string pass;          // "direct", "probes" or "scatter"
  std::uint32_t bounce = 0;  // 0 for direct, k for the k-th indirect bounce
  double seconds = 0.0;      // last update
  std::uint64_t rays = 0;    // last update
  double seconds_total = 0.0;
  std::uint64_t rays_total = 0;
};

struct EngineHostStats {
  std::uint64_t updates = 0;
  double last_update_ms = 0.0;
  double rays_per_s = 0.0;   // of the last update
  double convergence = 1.0;  // mean relative standard error of the texels
  bool idle = false;         // max_updates reached: the lightmaps will not change
  std::uint64_t tiles_published = 0;
  // Passes in the order they run: direct, then per bounce probes (not in unbiased mode, which
  // has no probes) and scatter. Empty before the first update.
  std::vector<EnginePassStats> passes;
  double seconds_total = 0.0;  // time in updates (Engine::update), summed
  std::uint64_t rays_total = 0;
  // Updates per second over the last kUpdateRateWindow: the updates that finished in that
  // window divided by the window (or by the time since the first update began, when that is
  // shorter). Sliding, so it falls to 0 within the window once the engine stops refining.
  double update_rate = 0.0;
  double bytes_per_texel = 0.0;  // TileStore::bytes_per_texel() after the last publish
  std::uint64_t texels = 0;      // texels the engine computes
  std::uint64_t tiles = 0;       // tiles in the tile store
  std::uint64_t revision = 0;    // scene revision (edits applied so far)
  double last_edit_ms = 0.0;     // time the last edit took to apply
  // Texels still waiting for their first estimate since the last edit (0: caught up).
  std::uint64_t stale_texels = 0;
};

// The irradiance volume as sessions send it (docs/DYNAMIC.md): one version's ProbeVolume frame
// with the probes' layout (for a client that has none of this epoch) and without it, each
// encoded once for every session.
struct ProbeVolumeFrames {
  std::uint64_t epoch = 0;
  std::uint64_t version = 0;
  std::shared_ptr<const std::string> with_layout, sh_only;
};

class PresenceBoard;

class TileSource {
 public:
  virtual ~TileSource() = default;

  // Called after each publish with the tiles that got a new version (the engine thread, or the
  // gateway's NATS thread). Null removes the listener.
  using PublishListener = std::function<void(const std::vector<std::uint32_t>&)>;
  virtual void set_listener(PublishListener listener) = 0;
  // Called once per applied edit, before the tiles that show it are published.
  using EditListener = std::function<void(const AppliedEdit&)>;
  virtual void set_edit_listener(EditListener listener) = 0;

  virtual const std::string& scene_id() const = 0;
  // The engine's backend and device ("embree", "vulkan on ..."). Any thread.
  virtual std::string backend_name() const = 0;
  // The scene package at the current revision. Any thread.
  virtual std::shared_ptr<const wire::ScenePackage> package() const = 0;
  // The lineage of tile versions (Welcome.tile_epoch). Any thread.
  virtual std::uint64_t tile_epoch() const = 0;
  // The revision of the scene as applied (0: as loaded). Any thread.
  virtual std::uint64_t revision() const = 0;
  // The tiles; their layout never changes while a Server serves them.
  virtual const TileStore& tiles() const = 0;
  // Validates a scene edit (docs/EDITS.md) and accepts it: its ops that move, show or hide
  // dynamic nodes are posted as poses (docs/DYNAMIC.md#poses; poses() then holds them), the
  // others queued as a revision. `stream`: a streamed pose (irradcast-edit --stream), refused
  // unless every op is a pose op, and past PoseBoard::kStreamRate per node (PoseRateLimited).
  // Throws irradcast::Error with a clear message when it is refused (nothing changes). Any
  // thread.
  virtual EditReceipt submit(const SceneEdit& edit, bool stream) = 0;
  // submit(edit, false).revision.
  std::uint64_t submit_edit(const SceneEdit& edit) { return submit(edit, false).revision; }
  // A viewer's camera (`pose` empty: the viewer left). Any thread.
  virtual void set_camera(std::uint64_t viewer, std::optional<CameraPose> pose) = 0;
  // The engine's stats (a gateway: the origin's, as last published). Any thread.
  virtual EngineHostStats stats() const = 0;
  // The irradiance volume's current version, set before the listener hears of the tiles of the
  // same update; null when there is none (a scene without dynamic nodes; a gateway, for now).
  // Any thread.
  virtual std::shared_ptr<const ProbeVolumeFrames> probe_volume() const { return nullptr; }
  // The dynamic nodes' poses (docs/DYNAMIC.md#poses); null when the scene has no dynamic nodes
  // (or a gateway, for now). Lives as long as the source.
  virtual PoseBoard* poses() { return nullptr; }
  // The avatars shared beyond this server (NATS with --presence: a NatsOrigin or NatsGateway
  // made with presence holds them; docs/DYNAMIC.md#presence); null: a Server with --presence
  // keeps its own. Lives as long as the source.
  virtual PresenceBoard* presence() { return nullptr; }
};

}  // namespace irradcast

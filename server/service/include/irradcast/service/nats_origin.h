// The origin's side of distribution through NATS (docs/DISTRIBUTION.md): wraps an EngineHost as
// the TileSource a Server serves, and publishes what the engine makes to the scene's JetStream
// stream (nats_subjects.h): the scene package (in chunks) and its state, every tile version's
// RGB9E5 payload (the one the tile store encoded), every applied edit, and the engine's stats
// once a second. It answers the gateways' requests: their viewers' cameras (for visible-first
// refinement after edits) and scene edits (which a gateway's session accepted with the control
// token; the token itself never crosses NATS). Publishing runs on its own thread and never blocks
// the engine: the engine's listeners only mark tiles dirty (a tile marked again before it went out
// is published once, at its latest version: counted as coalesced) and queue edits (bounded, oldest
// dropped). On every (re)connection the whole current state is published again, so a NATS server
// that lost its storage is refilled.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "irradcast/service/engine_host.h"
#include "irradcast/service/nats_credentials.h"
#include "irradcast/service/tile_source.h"

namespace irradcast {

struct NatsOriginOptions {
  std::string url;              // nats:// or tls://HOST:PORT
  NatsCredentials credentials;  // who the origin is to NATS, and TLS
  // Take the edits gateways forward on req.edit (the origin has a control token: its own
  // viewers may edit too). The token never crosses NATS: a gateway checks it, and NATS's
  // permissions decide who may publish req.edit (deploy/nats/nats.conf: the gateway user).
  bool accept_edits = false;
  std::chrono::milliseconds stats_every{1000};
  // A gateway's cameras are forgotten after this long without a camera request from it.
  std::chrono::milliseconds camera_expiry{10000};
  std::size_t max_queued_edits = 1024;  // applied edits waiting to be published
  // Gateways whose cameras the origin holds at once (each at most 4096 cameras, forgotten
  // camera_expiry after its last request); a camera request from one more is refused.
  std::size_t max_gateways = 64;
  // Publish even when the stream holds a newer revision from another origin process (its edits
  // are then lost for the gateways). Off: such an origin publishes nothing (docs/DISTRIBUTION.md).
  bool replace_newer = false;
  // --presence (docs/DYNAMIC.md#presence): the gateways' viewers' avatars (NatsCameras.avatars)
  // are shown to this origin's viewers, and every avatar is published to the gateways
  // (s.presence) at most every presence_every while they change and every second regardless. A
  // gateway's avatars go presence_expiry after its last camera request.
  bool presence = false;
  std::chrono::milliseconds presence_every{100};
  std::chrono::milliseconds presence_expiry{5000};
};

// What the origin counts (nats_origin_stats.inc: each member with its metric).
struct NatsOriginStats {
#define IRRADCAST_NATS_ORIGIN_STAT(type, name, kind, metric, help) type name{};
#include "irradcast/service/nats_origin_stats.inc"
#undef IRRADCAST_NATS_ORIGIN_STAT
};

class NatsOrigin final : public TileSource {
 public:
  // Connects (in the background when NATS is not there yet) and starts publishing; hooks the
  // host's listeners (a Server then serves this object, not the host). Throws irradcast::Error
  // on a bad URL.
  NatsOrigin(EngineHost& host, NatsOriginOptions options);
  ~NatsOrigin() override;
  NatsOrigin(const NatsOrigin&) = delete;
  NatsOrigin& operator=(const NatsOrigin&) = delete;

  void set_listener(PublishListener listener) override;
  void set_edit_listener(EditListener listener) override;
  const std::string& scene_id() const override { return host_.scene_id(); }
  std::string backend_name() const override { return host_.backend_name(); }
  std::shared_ptr<const wire::ScenePackage> package() const override { return host_.package(); }
  std::uint64_t tile_epoch() const override { return host_.tile_epoch(); }
  std::uint64_t revision() const override { return host_.revision(); }
  const TileStore& tiles() const override { return host_.tiles(); }
  EditReceipt submit(const SceneEdit& edit, bool stream) override {
    return host_.submit(edit, stream);
  }
  PoseBoard* poses() override { return host_.poses(); }
  std::shared_ptr<const ProbeVolumeFrames> probe_volume() const override {
    return host_.probe_volume();
  }
  void set_camera(std::uint64_t viewer, std::optional<CameraPose> pose) override {
    host_.set_camera(viewer, std::move(pose));
  }
  EngineHostStats stats() const override { return host_.stats(); }
  // With NatsOriginOptions::presence: the avatars of this origin's viewers and the gateways'.
  PresenceBoard* presence() override;

  NatsOriginStats nats_stats() const;
  // Waits until the origin has compared its revision with the stream's (it does on every
  // (re)connection, before it publishes anything) or `limit` passes. Returns the refusal ("" when
  // it may publish, or when NATS did not answer in time: it checks again when it connects).
  // irradcast-server calls it at start and exits with the refusal.
  std::string check_stream(std::chrono::milliseconds limit);
  // Blocks until everything marked so far is published and acknowledged by JetStream, or the
  // limit passes; returns whether it got there (tests, shutdown).
  bool flush(std::chrono::milliseconds limit);

  struct Impl;

 private:
  EngineHost& host_;
  std::unique_ptr<Impl> impl_;
};

// The origin's NATS metrics (irradcast_nats_*) in the Prometheus text format, appended to
// format_metrics()'s text by irradcast-server --nats.
std::string format_nats_origin_metrics(const NatsOriginStats& s);

}  // namespace irradcast

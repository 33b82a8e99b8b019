// A gateway's TileSource (irradcast-gateway, docs/DISTRIBUTION.md): no engine; the tile store,
// scene package, revision, tile epoch and engine stats come from the scene's JetStream stream
// that an origin (NatsOrigin) fills. A Server serves it exactly as it serves an EngineHost.
// The stream keeps the latest message of every subject, so a gateway that starts late, or
// reconnects, reads it from the start (an ordered consumer) and has the current state without
// asking the origin; tile versions are the origin's, so viewers resume across gateways and the
// origin. Viewers' cameras go to the origin (all of this gateway's, every 250 ms while they
// change and every 2 s regardless) and edits (accepted by a session with the control token,
// forwarded without it) through NATS requests. When NATS or the origin goes away the gateway keeps
// serving what it has; on reconnection it reads the stream again and installs what is newer.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "irradcast/service/nats_credentials.h"
#include "irradcast/service/tile_source.h"

namespace irradcast {

struct NatsGatewayOptions {
  std::string url;                                  // nats:// or tls://HOST:PORT
  std::string scene_id = "cornell";                 // the origin's --scene
  NatsCredentials credentials;                      // who the gateway is to NATS, and TLS
  std::chrono::milliseconds request_timeout{3000};  // an edit's answer from the origin
  std::chrono::milliseconds camera_every{250};
  // irradcast-gateway --presence (docs/DYNAMIC.md#presence): this gateway's viewers' avatars go
  // to the origin with the cameras (at most every presence_every while they change), and the
  // origin's set of everybody else's (s.presence) is shown to them; forgotten presence_expiry
  // after the origin's last.
  bool presence = false;
  std::chrono::milliseconds presence_every{100};
  std::chrono::milliseconds presence_expiry{5000};
};

// What the gateway counts (nats_gateway_stats.inc: each member with its metric).
struct NatsGatewayStats {
#define IRRADCAST_NATS_GATEWAY_STAT(type, name, kind, metric, help) type name{};
#include "irradcast/service/nats_gateway_stats.inc"
#undef IRRADCAST_NATS_GATEWAY_STAT
};

class NatsGateway final : public TileSource {
 public:
  // Connects (in the background when NATS is not there yet) and starts reading the stream.
  // Throws irradcast::Error on a bad URL.
  explicit NatsGateway(NatsGatewayOptions options);
  ~NatsGateway() override;
  NatsGateway(const NatsGateway&) = delete;
  NatsGateway& operator=(const NatsGateway&) = delete;

  // Blocks until the first scene package and tile layout have arrived (a Server can be made
  // then), or the limit passes; returns whether they did.
  bool wait_ready(std::chrono::milliseconds limit) const;

  void set_listener(PublishListener listener) override;
  void set_edit_listener(EditListener listener) override;
  const std::string& scene_id() const override;
  std::string backend_name() const override;
  std::shared_ptr<const wire::ScenePackage> package() const override;
  std::uint64_t tile_epoch() const override;
  std::uint64_t revision() const override;
  const TileStore& tiles() const override;  // only once ready
  EditReceipt submit(const SceneEdit& edit, bool stream) override;
  // The origin's probe volume and poses as they come through NATS (docs/DYNAMIC.md). The board
  // is there from the start (empty until the origin posts poses).
  std::shared_ptr<const ProbeVolumeFrames> probe_volume() const override;
  PoseBoard* poses() override;
  // With NatsGatewayOptions::presence: this gateway's viewers' avatars and the origin's others.
  PresenceBoard* presence() override;
  void set_camera(std::uint64_t viewer, std::optional<CameraPose> pose) override;
  EngineHostStats stats() const override;

  NatsGatewayStats nats_stats() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// The gateway's NATS metrics (irradcast_gateway_*) in the Prometheus text format, appended to
// format_metrics()'s text by irradcast-gateway.
std::string format_nats_gateway_metrics(const NatsGatewayStats& s);

}  // namespace irradcast

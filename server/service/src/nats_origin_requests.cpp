// NatsOrigin's request handlers: the gateways' cameras (and with presence their avatars) and
// their scene edits; and the origin's metrics. See nats_origin.h.
#include <string>

#include "irradcast/common/error.h"
#include "irradcast/service/metrics_text.h"
#include "irradcast/wire/edit_message.h"
#include "nats_origin_impl.h"
#include "session_messages.h"

namespace irradcast {

using namespace nats_origin;

void NatsOrigin::Impl::expire_cameras() {
  std::lock_guard lock(camera_mutex);
  const Clock::time_point now = Clock::now();
  for (auto it = gateways.begin(); it != gateways.end();) {
    const auto idle = now - it->second.seen;
    if (options.presence && (idle >= options.presence_expiry || idle >= options.camera_expiry))
      presence.remove_group(it->first);
    if (idle < options.camera_expiry) {
      ++it;
      continue;
    }
    for (std::size_t i = 0; i < it->second.cameras; ++i)
      host.set_camera(kGatewayViewer | ((it->first << 12) + i), std::nullopt);
    it = gateways.erase(it);
  }
}

// A gateway's cameras: they replace the ones it sent before (viewer ids from the gateway's id
// and the camera's position in the list).
void NatsOrigin::Impl::on_cameras(natsConnection* nc, natsMsg* msg) {
  Impl& im = *this;
  wire::NatsCameras m;
  wire::NatsReply r;
  const bool parsed = m.ParseFromString(nats_link::data_of(msg)) && m.gateway() != 0;
  bool full = false;  // this gateway would be one too many
  std::size_t held = 0;
  if (parsed) {
    std::lock_guard lock(im.camera_mutex);
    held = im.gateways.size();
    full = !im.gateways.contains(m.gateway()) && held >= im.options.max_gateways;
  }
  if (!parsed) {
    im.count(&NatsOriginStats::bad_requests);
    r.set_error("cameras: the request does not parse");
    r.set_code(wire::BAD_REQUEST);
  } else if (full) {
    im.count(&NatsOriginStats::gateways_refused);
    r.set_error("cameras: the origin holds the cameras of " + std::to_string(held) +
                " gateways already");
    r.set_code(wire::REFUSED);
  } else {
    im.count(&NatsOriginStats::camera_requests);
    std::lock_guard lock(im.camera_mutex);
    Gateway& g = im.gateways[m.gateway()];
    const std::uint64_t base = kGatewayViewer | (m.gateway() << 12);
    std::size_t n = 0;
    for (int i = 0; i < m.cameras_size() && n < kMaxCamerasPerGateway; ++i) {
      std::string problem;
      if (auto pose = camera_pose_of(m.cameras(i), problem)) im.host.set_camera(base + n++, pose);
    }
    for (std::size_t i = n; i < g.cameras; ++i) im.host.set_camera(base + i, std::nullopt);
    g.cameras = n;
    g.seen = Clock::now();
    if (im.options.presence) {
      std::size_t refused = 0;
      im.presence.set_group(m.gateway(), avatars_from_wire(m.avatars(), &refused));
      if (refused) im.count(&NatsOriginStats::avatars_refused, refused);
    }
  }
  nats_link::reply(nc, msg, r);
  natsMsg_Destroy(msg);
}

// A scene edit from a gateway (its session checked the control token; NATS's permissions decide
// who may publish here), then the host's validation, as a session.
void NatsOrigin::Impl::on_submit(natsConnection* nc, natsMsg* msg) {
  Impl& im = *this;
  wire::SceneEdit m;
  wire::NatsReply r;
  if (!m.ParseFromString(nats_link::data_of(msg))) {
    im.count(&NatsOriginStats::bad_requests);
    r.set_error("scene edit: the request does not parse");
    r.set_code(wire::BAD_REQUEST);
  } else if (const std::string refusal =
                 [&] {
                   std::lock_guard lock(im.mutex);
                   return im.refusal;
                 }();
             !refusal.empty()) {
    // This origin publishes nothing (a newer revision from another origin is in the stream):
    // an edit applied here would reach no gateway's viewers.
    im.count(&NatsOriginStats::edits_refused);
    r.set_error("this origin does not publish: " + refusal);
    r.set_code(wire::REFUSED);
  } else if (!im.options.accept_edits) {
    im.count(&NatsOriginStats::edits_refused);
    r.set_error(
        "the origin takes no edits (start it with --control-token or --control-token-file)");
    r.set_code(wire::PERMISSION_DENIED);
  } else if (!m.token().empty()) {
    // A control token on NATS is a misconfigured or foreign sender: refused, never compared.
    im.count(&NatsOriginStats::edits_refused);
    r.set_error("an edit on NATS carries a token: gateways forward edits without it");
    r.set_code(wire::BAD_REQUEST);
  } else {
    im.count(&NatsOriginStats::edit_requests);
    try {
      const EditReceipt receipt = im.host.submit(wire::from_proto(m), m.stream());
      r.set_revision(receipt.revision);
      r.set_pose_sequence(receipt.pose_sequence);
    } catch (const PoseRateLimited& e) {
      im.count(&NatsOriginStats::edits_refused);
      r.set_error(e.what());
      r.set_code(wire::RATE_LIMITED);
    } catch (const Error& e) {
      im.count(&NatsOriginStats::edits_refused);
      r.set_error(e.what());
      r.set_code(wire::BAD_REQUEST);
    }
  }
  nats_link::reply(nc, msg, r);
  natsMsg_Destroy(msg);
}

std::string format_nats_origin_metrics(const NatsOriginStats& s) {
  std::string out;
#define IRRADCAST_NATS_ORIGIN_STAT(type, name, kind, metric, help) \
  append_metric(out, metric, #kind, help, static_cast<double>(s.name));
#include "irradcast/service/nats_origin_stats.inc"
#undef IRRADCAST_NATS_ORIGIN_STAT
  return out;
}

}  // namespace irradcast

// NatsGateway's handlers of what the origin publishes for dynamic objects and presence: the
// probe volume (chunks reassembled, checked as a client checks it), the poses and the avatars.
// See nats_gateway.h.
#include <cmath>
#include <string>

#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/probe_volume_message.h"
#include "irradcast/wire/scene_package.h"
#include "nats_gateway_impl.h"
#include "session_messages.h"

namespace irradcast {

using namespace nats_gateway;

void NatsGateway::Impl::on_volume(const std::string& data) {
  wire::NatsVolume v;
  if (!v.ParseFromString(data)) return bad("the probe volume's announcement does not parse");
  if (v.hash().empty() && v.chunks() == 0 && v.bytes() == 0) {  // the origin has none
    pending_volume.reset();
    volume_chunks.clear();
    std::lock_guard lock(mutex);
    volume = nullptr;
    return;
  }
  if (v.hash().size() != 32 || v.chunks() == 0 || v.chunks() > kMaxVolumeChunks || v.bytes() == 0 ||
      v.bytes() > kMaxVolumeBytes)
    return bad("the probe volume's announcement is out of range");
  pending_volume = std::move(v);
  try_volume();
}

void NatsGateway::Impl::on_volume_chunk(const std::string& data) {
  wire::NatsVolumeChunk c;
  if (!c.ParseFromString(data) || c.index() >= kMaxVolumeChunks) return bad("a probe volume chunk");
  // Bounded: chunks of older versions are dropped when the held bytes would pass twice a frame.
  std::size_t held = 0;
  for (const auto& [i, k] : volume_chunks) held += i == c.index() ? 0 : k.data().size();
  if (held + c.data().size() > 2 * kMaxVolumeBytes) volume_chunks.clear();
  volume_chunks[c.index()] = std::move(c);
  try_volume();
}

// The announced volume once its chunks are there: the frame checked as a client checks it
// (wire::apply_probe_volume), then served as the origin serves it.
void NatsGateway::Impl::try_volume() {
  if (!pending_volume) return;
  const wire::NatsVolume& v = *pending_volume;
  for (std::uint32_t i = 0; i < v.chunks(); ++i) {
    auto it = volume_chunks.find(i);
    if (it == volume_chunks.end() || it->second.hash() != v.hash()) return;  // not yet
  }
  std::string frame;
  for (std::uint32_t i = 0; i < v.chunks() && frame.size() <= v.bytes(); ++i)
    frame += volume_chunks[i].data();
  const wire::NatsVolume announced = std::move(*pending_volume);
  pending_volume.reset();
  volume_chunks.clear();  // used (or refused) whole; the next version brings its own
  if (frame.size() != announced.bytes() || wire::sha256(frame) != announced.hash())
    return bad("the probe volume's chunks do not make the announced frame");
  wire::FrameDecoder decoder(static_cast<std::size_t>(kMaxVolumeBytes));
  decoder.feed(frame.data(), frame.size());
  wire::Envelope e;
  if (decoder.next(e) != wire::DecodeStatus::Frame || decoder.buffered() != 0 ||
      !e.has_probe_volume() || e.probe_volume().layout().empty() ||
      e.probe_volume().epoch() != announced.epoch() ||
      e.probe_volume().version() != announced.version())
    return bad("the probe volume's frame is not the announced ProbeVolume with its layout");
  wire::ReceivedVolume check;
  wire::apply_probe_volume(e.probe_volume(), check);  // throws on a bad volume: bad()
  auto frames = std::make_shared<ProbeVolumeFrames>();
  frames->epoch = announced.epoch();
  frames->version = announced.version();
  frames->with_layout = std::make_shared<const std::string>(std::move(frame));
  e.mutable_probe_volume()->clear_layout();
  frames->sh_only = std::make_shared<const std::string>(wire::encode_frame(e));
  {
    std::lock_guard lock(mutex);
    volume = std::move(frames);
    ++st.volumes_received;
  }
  listeners.tiles({});  // the sessions look at the volume in the fan-out
}

// The origin's poses: each node whose pose differs from the one held is posted to this
// gateway's board (its sessions get them as from an origin's). Clients check them against the
// scene; here the numbers and the count.
void NatsGateway::Impl::on_poses(const std::string& data) {
  wire::NatsPoses m;
  if (!m.ParseFromString(data)) return bad("the poses do not parse");
  if (m.poses().poses_size() > wire::kMaxWirePoses) return bad("too many poses");
  const std::map<int, NodePoseState> held = poses.snapshot();
  std::map<int, NodePoseState> set;  // the origin's whole set: a node not in it is not posed
  std::vector<std::pair<int, NodePoseState>> changed;
  for (const wire::NodePose& p : m.poses().poses()) {
    if (p.matrix_size() != 16 || p.node() >= (1u << 24)) return bad("a pose is out of range");
    NodePoseState s;
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) {
        const float x = p.matrix(4 * c + r);
        if (!std::isfinite(x)) return bad("a pose is not finite");
        s.local[c][r] = x;
      }
    s.visible = !p.hidden();
    const int node = static_cast<int>(p.node());
    auto it = held.find(node);
    if (it == held.end() || it->second.local != s.local || it->second.visible != s.visible)
      changed.emplace_back(node, s);
    set[node] = s;
  }
  {
    std::lock_guard lock(mutex);
    ++st.poses_received;
  }
  bool gone = false;  // a node the origin no longer poses (an origin restarted without them)
  for (const auto& [node, pose] : held) gone = gone || !set.count(node);
  if (gone)
    poses.replace(set, m.poses().posed_us());
  else if (!changed.empty())
    poses.post(changed, m.poses().posed_us());
}

// The origin's avatars (docs/DYNAMIC.md#presence): every group but this gateway's own replaces
// what the board held of the others. Refused whole when it is larger than an origin publishes or
// its height is no height; avatars that are no place are left out (avatars_refused).
void NatsGateway::Impl::on_presence(const std::string& data) {
  if (!options.presence) return;  // this gateway shows no avatars
  wire::NatsPresence m;
  if (!m.ParseFromString(data)) return bad("the avatars do not parse");
  if (!(m.height() >= 0.0f && m.height() <= 100.0f)) return bad("the avatars' height is no height");
  if (m.groups_size() > kMaxPresenceGroups) return bad("too many avatar groups");
  std::size_t total = 0, refused = 0;
  PresenceBoard::Groups groups;
  for (const wire::NatsAvatarGroup& g : m.groups()) {
    total += static_cast<std::size_t>(g.avatars_size());
    if (total > kMaxPresenceAvatars) return bad("too many avatars");
    if (groups.contains(g.source())) return bad("an avatar group is repeated");
    std::size_t r = 0;
    std::vector<AvatarState> avatars = avatars_from_wire(g.avatars(), &r);
    refused += r;
    if (g.source() != gateway) groups.emplace(g.source(), std::move(avatars));
  }
  presence.replace_groups(std::move(groups));
  presence.set_shared_height(m.height());
  std::lock_guard lock(mutex);
  presence_heard = Clock::now();
  ++st.presence_received;
  st.avatars_refused += refused;
}

// The origin's avatars go presence_expiry after its last set (an origin that stopped, or the
// stale set a new gateway reads from the stream). Worker thread, `mutex` held.
void NatsGateway::Impl::expire_presence(Clock::time_point now) {
  if (!options.presence || presence_heard == Clock::time_point{} ||
      now - presence_heard < options.presence_expiry)
    return;
  presence_heard = {};
  presence.replace_groups({});
  presence.set_shared_height(0.0f);
}

}  // namespace irradcast

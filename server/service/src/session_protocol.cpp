// The protocol side of a client session: frames in, decisions, frames out (no I/O).
#include "session_protocol.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "irradcast/common/error.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/pose_message.h"
#include "session_messages.h"

namespace irradcast {

SessionProtocol::SessionProtocol(SessionContext& context, std::uint64_t id, std::string peer_key,
                                 std::string peer)
    : ctx_(context),
      id_(id),
      peer_key_(std::move(peer_key)),
      peer_(std::move(peer)),
      decoder_(context.hello_frame_cap) {
  const TileStore& tiles = ctx_.host.tiles();
  known_.assign(tiles.tile_count(), 0);
  queue_.resize(tiles.tile_count());
  subscribed_.assign(tiles.lightmap_count(), 0);
}

void SessionProtocol::note(log::Level level, const std::string& message) {
  if (static_cast<int>(level) < static_cast<int>(log::level())) return;
  const auto now = Clock::now();
  const ServerOptions& o = ctx_.options;
  log_tokens_ = std::min(
      o.session_log_burst,
      log_tokens_ + o.session_log_per_s * std::chrono::duration<double>(now - log_refill_).count());
  log_refill_ = now;
  if (log_tokens_ < 1.0) {
    ++log_suppressed_;
    ++ctx_.counters.log_lines_suppressed;
    return;
  }
  log_tokens_ -= 1.0;
  std::string line = "session " + std::to_string(id_) + " (" + peer_ + "): " + message;
  if (log_suppressed_ > 0) {
    line += " [" + std::to_string(log_suppressed_) + " earlier lines of this session suppressed]";
    log_suppressed_ = 0;
  }
  log::write(level, "server", line);
}

// After tiles were queued: publishes the queue depth, and adds the versions coalesced since the
// last call to the server's counter (so that it is live, not counted at the end).
void SessionProtocol::queue_changed() {
  queue_depth_ = queue_.size() + (held_ ? 1 : 0);
  const std::uint64_t c = queue_.coalesced();
  ctx_.counters.tiles_coalesced += c - coalesced_counted_;
  coalesced_counted_ = c;
}

void SessionProtocol::receive(const char* data, std::size_t n) {
  decoder_.feed(data, n);
}

bool SessionProtocol::paused() const {
  return penalty_ || control_.size() >= ctx_.options.max_control_frames / 2;
}

bool SessionProtocol::next_frame(wire::Envelope& env) {
  if (closed_ || closing_ || paused()) return false;
  const wire::DecodeStatus st = decoder_.next(env);
  if (st == wire::DecodeStatus::NeedMore) return false;
  if (st == wire::DecodeStatus::TooLarge) {
    fail(wire::FRAME_TOO_LARGE, decoder_.error());
    return false;
  }
  if (st == wire::DecodeStatus::Malformed) {
    fail(wire::BAD_FRAME, decoder_.error());
    return false;
  }
  ++ctx_.counters.frames_received;
  return true;
}

// A session holding more than 64 KiB of one incomplete frame while the total is over the cap is
// closed; below 64 KiB (any frame that spans two reads) is always allowed, so well-behaved
// clients never meet the cap.
bool SessionProtocol::account_partial(std::size_t transport_held) {
  const auto held = static_cast<std::int64_t>(decoder_.buffered() + transport_held);
  const std::int64_t total = ctx_.counters.partial_bytes += held - partial_counted_;
  partial_counted_ = held;
  if (held > (64 << 10) && total > static_cast<std::int64_t>(ctx_.options.max_partial_bytes)) {
    fail(wire::FRAME_TOO_LARGE,
         "the server holds too many incomplete frames; send smaller frames (" +
             std::to_string(held) + " bytes of one held)");
    return false;
  }
  return true;
}

void SessionProtocol::handle(const wire::Envelope& env) {
  using E = wire::Envelope;
  if (state_ == State::AwaitHello && env.msg_case() != E::kHello) {
    fail(wire::UNEXPECTED_MESSAGE,
         std::string("expected hello as the first frame, got ") + wire::message_name(env));
    return;
  }
  switch (env.msg_case()) {
    case E::kHello:
      on_hello(env.hello());
      break;
    case E::kSceneRequest:
      on_scene_request(env.scene_request());
      break;
    case E::kSubscribe:
      on_subscribe(env.subscribe());
      break;
    case E::kCameraUpdate:
      on_camera(env.camera_update());
      break;
    case E::kSceneEdit:
      on_scene_edit(env.scene_edit());
      break;
    case E::kSceneExportRequest:
      on_scene_export(env.scene_export_request());
      break;
    case E::kStatsRequest:
      send_stats();
      break;
    case E::kPing: {
      wire::Envelope pong;
      pong.mutable_pong()->set_nonce(env.ping().nonce());
      pong.mutable_pong()->set_time_us(env.ping().time_us());
      send(pong);
      break;
    }
    case E::kBye:
      note(log::Level::Debug, "bye: " + log::quote(env.bye().reason()));
      events_.close = CloseReason::Bye;
      break;
    case E::kPong:
      break;
    case E::kError:
      note(log::Level::Info, "reports an error: " + log::quote(env.error().message()));
      break;
    default:
      error(wire::UNEXPECTED_MESSAGE,
            std::string("a client does not send ") + wire::message_name(env));
      break;
  }
}

void SessionProtocol::on_hello(const wire::Hello& h) {
  if (state_ != State::AwaitHello) {
    error(wire::UNEXPECTED_MESSAGE, "hello was already received");
    return;
  }
  if (h.protocol_version() != wire::kProtocolVersion) {
    fail(wire::UNSUPPORTED_VERSION, "protocol version " + std::to_string(h.protocol_version()) +
                                        " is not supported; this server speaks " +
                                        std::to_string(wire::kProtocolVersion));
    return;
  }
  const TileSource& host = ctx_.host;
  const TileStore& tiles = host.tiles();
  // Resume: tiles the client already holds are only sent again when their version changes.
  // Versions only mean something for the same scene package.
  // The package this session serves: the one named in the Welcome (an edit after it is sent
  // to the client as a SceneEdit, which it applies to this package's scene).
  package_ = host.package();
  if (h.cached_scene_hash() == package_->hash && h.known_epoch() == host.tile_epoch())
    for (const wire::TileVersion& k : h.known()) {
      std::int64_t i = tiles.index(k.lightmap(), k.tile_x(), k.tile_y());
      if (i >= 0) known_[static_cast<std::size_t>(i)] = k.version();
    }
  client_name_ = log::quote(h.client_name(), 64);
  events_.welcomed = true;
  decoder_.set_max_frame(ctx_.options.max_frame);
  send(welcome_message(host, ctx_.options, id_, *package_));
  state_ = State::Ready;
  note(log::Level::Info,
       client_name_ + " joined; " + std::to_string(h.known_size()) + " tiles known");
}

void SessionProtocol::on_scene_request(const wire::SceneRequest& r) {
  const std::string& bytes = package_->bytes;
  if (r.offset() > bytes.size()) {
    error(wire::BAD_REQUEST, "scene offset " + std::to_string(r.offset()) +
                                 " is past the end of the " + std::to_string(bytes.size()) +
                                 "-byte package");
    return;
  }
  scene_offset_ = r.offset();
  scene_active_ = true;
}

void SessionProtocol::on_subscribe(const wire::Subscribe& s) {
  const TileStore& tiles = ctx_.host.tiles();
  if (s.encoding() != wire::TILE_RGB9E5_ZSTD && s.encoding() != wire::TILE_HALF_ZSTD &&
      s.encoding() != wire::TILE_RGB9E5_DELTA_ZSTD) {
    error(wire::BAD_REQUEST, "unknown tile encoding " + std::to_string(s.encoding()));
    return;
  }
  std::vector<std::uint8_t> wanted(tiles.lightmap_count(), s.all() ? 1 : 0);
  if (!s.all())
    for (std::uint32_t m : s.lightmaps()) {
      if (m >= wanted.size()) {
        error(wire::BAD_REQUEST, "there is no lightmap " + std::to_string(m) + " (the scene has " +
                                     std::to_string(wanted.size()) + ")");
        return;
      }
      wanted[m] = 1;
    }
  // Deltas need a per-client copy of every tile; this server sends full RGB9E5 instead, which a
  // delta-capable client also accepts.
  encoding_ = s.encoding() == wire::TILE_HALF_ZSTD ? wire::TILE_HALF_ZSTD : wire::TILE_RGB9E5_ZSTD;
  rate_ = static_cast<double>(s.max_bytes_per_s());
  tokens_ = rate_ > 0.0 ? std::max(rate_ * 0.25, 65536.0) : 0.0;
  last_refill_ = Clock::now();
  subscribed_ = wanted;
  streaming_ = true;
  for (std::uint32_t m = 0; m < tiles.lightmap_count(); ++m) {
    if (!subscribed_[m]) continue;
    auto [first, last] = tiles.tiles_of(m);
    for (std::uint32_t t = first; t < last; ++t)
      if (tiles.version(t) > known_[t]) queue_.push(t);
  }
  queue_changed();
  offer_probe_volume();
  poses_due_ = ctx_.host.poses() != nullptr;  // the first Poses: complete
  if (s.presence() && !ctx_.presence) {
    error(wire::BAD_REQUEST, "this server shows no avatars (start it with --presence)");
  } else if (s.presence() && !presence_) {
    presence_ = true;
    if (camera_) ctx_.presence->place(id_, *camera_);
    avatars_ = ctx_.presence->snapshot();  // the first Avatars: those here now
  }
}

void SessionProtocol::poses_changed() {
  if (streaming_ && !closed_) poses_due_ = true;
}

void SessionProtocol::presence_changed(std::shared_ptr<const AvatarSnapshot> avatars) {
  if (presence_ && !closed_) avatars_ = std::move(avatars);
}

// The nearest others' avatars from the newest snapshot; null when they are those sent last.
std::shared_ptr<const std::string> SessionProtocol::next_avatars() {
  const std::shared_ptr<const AvatarSnapshot> all = std::exchange(avatars_, nullptr);
  std::vector<AvatarState> near = nearest_avatars(
      *all, id_, camera_ ? camera_->eye : glm::vec3(0.0f), ctx_.options.presence_nearest);
  const float height = ctx_.presence->height();
  if (avatars_written_ && near == avatars_sent_ && height == height_sent_) return nullptr;
  avatars_written_ = true;
  avatars_sent_ = std::move(near);
  height_sent_ = height;
  wire::Envelope e;
  wire::Avatars* m = e.mutable_avatars();
  m->set_height(height);
  m->set_time_us(wall_clock_us());
  for (const AvatarState& a : avatars_sent_) avatar_to_wire(a, m->add_avatars());
  ++ctx_.counters.avatar_frames_sent;
  return std::make_shared<const std::string>(wire::encode_frame(e));
}

void SessionProtocol::offer_probe_volume() {
  const std::shared_ptr<const ProbeVolumeFrames> v = ctx_.host.probe_volume();
  if (!v || (v->epoch == volume_layout_epoch_ && v->version == volume_version_)) return;
  // The client needs this epoch's layout unless it was written, or waits in the frame replaced.
  const bool layout = v->epoch != volume_layout_epoch_ || volume_frame_has_layout_;
  volume_frame_ = layout ? v->with_layout : v->sh_only;
  volume_frame_has_layout_ = layout;
  volume_layout_epoch_ = v->epoch;
  volume_version_ = v->version;
}

// The viewer's camera: the engine refines what the viewers see first after an edit.
void SessionProtocol::on_camera(const wire::CameraUpdate& c) {
  std::string problem;
  const std::optional<CameraPose> pose = camera_pose_of(c, problem);
  if (!pose) {
    error(wire::BAD_REQUEST, problem);
    return;
  }
  ctx_.host.set_camera(id_, pose);
  camera_ = pose;
  if (presence_) ctx_.presence->place(id_, *pose);
}

// A scene edit: needs the control token; validated by the host (the scene does not change on a
// bad edit); acknowledged to the sender with the revision it will make.
bool SessionProtocol::token_accepted(const std::string& presented) {
  const std::string& token = ctx_.options.control_token;
  if (token.empty()) {
    error(wire::PERMISSION_DENIED,
          "this server takes no edits (start it with --control-token or "
          "--control-token-file)");
    return false;
  }
  if (unattributed_) {
    // Nobody to hold to a wrong token: the proxy's other clients would share its penalty.
    error(wire::PERMISSION_DENIED,
          "a control token is not taken through a trusted proxy that does not name its client "
          "(a PROXY header or X-Forwarded-For; docs/OPERATIONS.md \"Behind a proxy\")");
    return false;
  }
  if (!same_secret(presented, token)) {
    // Answered after a delay that doubles with each failure of the address; nothing else of
    // this session is handled meanwhile. Too many: the address is refused for a while.
    ++ctx_.counters.token_failures;
    const auto [delay, banned] = ctx_.peers.token_failed(peer_key_);
    penalty_ = true;
    events_.penalty = delay;
    events_.banned = banned;
    return false;
  }
  ctx_.peers.token_passed(peer_key_);
  return true;
}

// An export of the live scene (irradcast-edit --export): with the control token, this session's
// scene package becomes the current one, which the client then downloads with SceneRequest.
void SessionProtocol::on_scene_export(const wire::SceneExportRequest& m) {
  if (!token_accepted(m.token())) return;
  if (scene_active_) {
    error(wire::BAD_REQUEST, "an export while the scene package is being sent");
    return;
  }
  package_ = ctx_.host.package();
  note(log::Level::Info, client_name_ + " exports the scene (" +
                             std::to_string(package_->bytes.size()) + "-byte package)");
  wire::Envelope e;
  wire::SceneExport* x = e.mutable_scene_export();
  x->set_request_id(m.request_id());
  x->set_scene_hash(package_->hash);
  x->set_scene_bytes(package_->bytes.size());
  if (PoseBoard* board = ctx_.host.poses()) {  // the package places dynamic nodes as loaded
    std::uint64_t sequence = 0;
    const std::map<int, NodePoseState> poses = board->snapshot(&sequence);
    wire::Poses* p = x->mutable_poses();
    p->set_sequence(sequence);
    p->set_complete(true);
    for (const auto& [node, pose] : poses)
      *p->add_poses() =
          wire::node_pose_to_proto(static_cast<std::uint32_t>(node), pose.local, pose.visible);
  }
  send(e);
}

void SessionProtocol::on_scene_edit(const wire::SceneEdit& m) {
  if (!token_accepted(m.token())) return;
  EditReceipt receipt;
  try {
    receipt = ctx_.host.submit(wire::from_proto(m), m.stream());
  } catch (const PoseRateLimited& e) {
    ++ctx_.counters.poses_refused;
    error(wire::RATE_LIMITED, e.what(), m.request_id(), log::Level::Debug);
    return;
  } catch (const Error& e) {
    if (m.stream()) ++ctx_.counters.poses_refused;
    error(wire::BAD_REQUEST, e.what(), m.request_id());
    return;
  }
  if (m.stream()) {  // never acknowledged: the viewers' Poses show it
    ++ctx_.counters.poses_streamed;
    return;
  }
  note(log::Level::Info,
       client_name_ + " submitted " +
           (receipt.revision ? "edit " + std::to_string(receipt.revision) : std::string("poses")) +
           " (" + std::to_string(m.ops_size()) + " operations)");
  wire::Envelope ack;
  wire::SceneEdit* a = ack.mutable_scene_edit();
  a->set_request_id(m.request_id());
  a->set_revision(receipt.revision);
  a->set_pose_sequence(receipt.pose_sequence);
  a->set_applied(false);
  send(ack);
}

void SessionProtocol::answer_token_failure(bool banned) {
  if (banned) {
    fail(wire::PERMISSION_DENIED,
         "scene edits need the control token; too many wrong tokens: this address is "
         "refused for " +
             std::to_string(ctx_.options.ban_duration.count() / 1000) + " s",
         CloseReason::TokenFailures);
    return;
  }
  error(wire::PERMISSION_DENIED, "scene edits need the control token");
}

void SessionProtocol::send_stats() {
  const EngineHostStats es = ctx_.host.stats();
  const ServerStats ss = ctx_.server_stats();
  wire::Envelope e;
  wire::Stats* s = e.mutable_stats();
  add_server_stats(ss, s);
  add_engine_stats(es, s);
  s->set_queue_depth(queue_.size() + (held_ ? 1 : 0));
  s->set_uptime_ms(static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - ctx_.counters.started)
          .count()));
  s->set_backend(ctx_.host.backend_name());
  send(e);
}

void SessionProtocol::tiles_changed(const std::vector<std::uint32_t>& tiles) {
  if (closed_ || !streaming_) return;
  const TileStore& store = ctx_.host.tiles();
  for (std::uint32_t t : tiles)
    if (subscribed_[store.tile(t).lightmap]) queue_.push(t);
  queue_changed();
  offer_probe_volume();
}

// Broadcasts wait in their own bounded queue (not with the replies, whose bound drops the
// client): past max_pending_edits the oldest are dropped, and the client, seeing the revision
// gap, loads the current scene package. Somebody else's burst of edits never drops a viewer.
void SessionProtocol::edit_applied(std::shared_ptr<const std::string> frame) {
  if (closed_ || closing_ || state_ != State::Ready) return;
  edits_.push_back(std::move(frame));
  while (edits_.size() > ctx_.options.max_pending_edits) {
    edits_.pop_front();
    ++ctx_.counters.edits_dropped;
  }
}

void SessionProtocol::hello_timed_out(bool handshaking) {
  if (closed_ || state_ != State::AwaitHello) return;
  const std::string text =
      "no hello within " + std::to_string(ctx_.options.hello_timeout.count()) + " ms";
  if (handshaking) {
    // Still in the TLS handshake or a proxy's PROXY header: no frame can be sent.
    note(log::Level::Info, "closed: " + text + " (TLS handshake or PROXY header not completed)");
    events_.close = CloseReason::HelloTimeout;
    return;
  }
  fail(wire::IDLE_TIMEOUT, text, CloseReason::HelloTimeout);
}

void SessionProtocol::idle_timed_out() {
  if (closed_) return;
  fail(wire::IDLE_TIMEOUT,
       "no frame for " + std::to_string(ctx_.options.idle_timeout.count()) + " ms");
}

void SessionProtocol::error(wire::ErrorCode code, const std::string& message,
                            std::uint64_t request_id, log::Level level) {
  note(level, "error sent: " + log::quote(message, 200));
  ++ctx_.counters.errors_sent;
  wire::Envelope e = wire::make_error(code, message);
  e.mutable_error()->set_request_id(request_id);
  send(e);
}

void SessionProtocol::fail(wire::ErrorCode code, const std::string& message, CloseReason reason) {
  if (closed_ || closing_) return;
  note(log::Level::Info, "closed: " + log::quote(message, 200));
  ++ctx_.counters.errors_sent;
  control_.push_back(wire::encode_frame(wire::make_error(code, message)));
  closing_ = true;
  close_reason_ = reason;
  events_.closing = true;
}

void SessionProtocol::send_frame(std::string frame) {
  if (closed_ || closing_) return;
  if (control_.size() >= ctx_.options.max_control_frames) {
    fail(wire::BAD_REQUEST,
         "the client does not read its replies (" + std::to_string(control_.size()) + " queued)",
         CloseReason::SlowClient);
    return;
  }
  control_.push_back(std::move(frame));
}

// Control frames first, then edit broadcasts, then the scene package, then tiles (within the
// byte-rate cap).
SessionWrite SessionProtocol::next_write(Clock::time_point now) {
  using Kind = SessionWrite::Kind;
  if (closed_) return {};
  if (!control_.empty()) {
    auto frame = std::make_shared<const std::string>(std::move(control_.front()));
    control_.pop_front();
    return {Kind::Control, std::move(frame)};
  }
  if (!edits_.empty() && !closing_) {
    auto frame = std::move(edits_.front());
    edits_.pop_front();
    return {Kind::Edit, std::move(frame)};
  }
  if (closing_) return {Kind::Close, nullptr};  // the reason fail() gave stands
  if (poses_due_) {
    poses_due_ = false;
    // The newest pose of every node moved since the last frame: coalesced, never a queue.
    if (PoseBoard* board = ctx_.host.poses()) {
      const PoseBoard::Frame f = board->frame_since(poses_seen_, !poses_complete_);
      poses_complete_ = true;
      poses_seen_ = f.sequence;
      if (f.frame) return {Kind::Edit, f.frame};
    }
  }
  if (avatars_)
    if (auto frame = next_avatars()) return {Kind::Edit, std::move(frame)};
  if (volume_frame_) {
    volume_frame_has_layout_ = false;
    return {Kind::Control, std::exchange(volume_frame_, nullptr)};
  }
  if (scene_active_) return {Kind::Scene, std::make_shared<const std::string>(next_scene_chunk())};
  if (streaming_) return next_tile(now);
  return {};
}

std::string SessionProtocol::next_scene_chunk() {
  const wire::ScenePackage& pkg = *package_;
  const std::size_t n =
      std::min<std::size_t>(ctx_.options.scene_chunk_bytes, pkg.bytes.size() - scene_offset_);
  wire::Envelope e;
  wire::SceneChunk* c = e.mutable_scene_chunk();
  c->set_scene_hash(pkg.hash);
  c->set_offset(scene_offset_);
  c->set_total(pkg.bytes.size());
  c->set_data(pkg.bytes.substr(scene_offset_, n));
  scene_offset_ += n;
  if (scene_offset_ >= pkg.bytes.size()) scene_active_ = false;
  return wire::encode_frame(e);
}

// The next tile frame, or None when there is none, or Wait when the rate cap says wait.
SessionWrite SessionProtocol::next_tile(Clock::time_point now) {
  const TileStore& store = ctx_.host.tiles();
  while (!held_) {
    std::uint32_t t = 0;
    if (!queue_.pop(t)) {
      queue_depth_ = 0;
      return {};
    }
    TileStore::Snapshot snap = store.snapshot(t, encoding_);
    if (snap.version == 0 || snap.version <= known_[t]) continue;  // nothing new
    held_frame_ = ctx_.frames ? ctx_.frames->frame(store, t, snap, encoding_)
                              : std::make_shared<const std::string>(wire::encode_frame(
                                    tile_update_message(store.tile(t), snap, encoding_)));
    held_ = true;
    known_[t] = snap.version;
  }
  queue_depth_ = queue_.size() + 1;
  if (rate_ > 0.0) {
    tokens_ = std::min(tokens_ + rate_ * std::chrono::duration<double>(now - last_refill_).count(),
                       std::max(rate_ * 0.25, 65536.0));
    last_refill_ = now;
    const double need = static_cast<double>(held_frame_->size());
    if (tokens_ < need) {
      const double wait_s = (need - tokens_) / rate_;
      return {SessionWrite::Kind::Wait, nullptr,
              std::chrono::microseconds(static_cast<std::int64_t>(std::ceil(wait_s * 1e6)))};
    }
    tokens_ -= need;
  }
  held_ = false;
  return {SessionWrite::Kind::Tile, std::move(held_frame_)};
}

std::string SessionProtocol::move_peer(const std::string& key, const std::string& peer,
                                       bool trusted) {
  const PeerTable::Admission admission = ctx_.peers.move(peer_key_, key, trusted);
  switch (admission) {
    case PeerTable::Admission::Ok:
      peer_key_ = key;
      peer_ = peer;
      break;
    case PeerTable::Admission::Banned:
      ++ctx_.counters.banned_refused;
      break;
    default:
      ++ctx_.counters.peer_refused;
      break;
  }
  return ctx_.peers.refusal(admission);
}

void SessionProtocol::close(CloseReason reason) {
  if (closed_) return;
  closed_ = true;
  if (!close_reason_) close_reason_ = reason;
  ctx_.counters.partial_bytes -= partial_counted_;
  partial_counted_ = 0;
  ctx_.peers.release(peer_key_);
  ctx_.host.set_camera(id_, std::nullopt);
  if (presence_) ctx_.presence->remove(id_);
  queue_changed();
  ++ctx_.counters.sessions_closed[static_cast<std::size_t>(*close_reason_)];
  queue_depth_ = 0;
  log::debug("server", "session " + std::to_string(id_) + " ended (" +
                           close_reason_name(*close_reason_) + ")");
}

}  // namespace irradcast

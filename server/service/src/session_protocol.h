// The protocol side of one client session (docs/PROTOCOL.md), without I/O: it is fed the bytes a
// client sent, decodes and handles its frames (Hello and resume, scene requests, subscriptions,
// cameras, edits and their control token, stats, ping), keeps what the client is owed (replies,
// edit broadcasts, the scene package, tiles within the byte-rate cap) and says which frame to
// write next. It decides every limit and every reason to close; the connection that drives it
// (session.h) only moves bytes and runs the timers the protocol asks for (SessionEvents).
// Not thread-safe: the connection calls it on its strand (queue_depth() excepted).
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "irradcast/common/log.h"
#include "irradcast/service/net_server.h"
#include "irradcast/service/send_queue.h"
#include "irradcast/service/tile_source.h"
#include "irradcast/wire/frame.h"
#include "peer_table.h"
#include "presence_board.h"
#include "session_messages.h"

namespace irradcast {

// The server's counters (ServerStats, server_counters.inc), which sessions add to from any I/O
// thread.
struct ServerCounters {
  std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();
#define IRRADCAST_SERVER_COUNTER(name, wire, metric, help) std::atomic<std::uint64_t> name{0};
#include "irradcast/service/server_counters.inc"
#undef IRRADCAST_SERVER_COUNTER
  std::atomic<std::int64_t> partial_bytes{0};  // incomplete frames in every session's decoder
  std::array<std::atomic<std::uint64_t>, kCloseReasons> sessions_closed{};
};

// What a session's protocol uses of the server around it; outlives every session.
struct SessionContext {
  TileSource& host;
  const ServerOptions& options;
  ServerCounters& counters;
  PeerTable& peers;
  std::function<ServerStats()> server_stats;  // for a StatsRequest
  std::size_t hello_frame_cap = 0;            // the decoder's cap before Hello
  TileFrames* frames = nullptr;               // shared tile frames (null: each session builds)
  PresenceBoard* presence = nullptr;          // ServerOptions::presence (null: off)
};

// What the connection must do after a call into the protocol (SessionProtocol::take_events()).
struct SessionEvents {
  bool welcomed = false;  // Hello accepted: stop the hello timer
  bool closing = false;   // an Error that ends the session is queued: start the 2 s grace timer
  std::optional<CloseReason> close;  // close the connection now
  // A wrong token: answer (SessionProtocol::answer_token_failure) after this delay, reading
  // nothing meanwhile.
  std::optional<std::chrono::milliseconds> penalty;
  bool banned = false;  // with penalty: the answer closes the session
};

// The next thing to write (SessionProtocol::next_write).
struct SessionWrite {
  enum class Kind { None, Close, Wait, Control, Edit, Scene, Tile };
  Kind kind = Kind::None;
  std::shared_ptr<const std::string> frame;  // Control, Edit, Scene, Tile
  std::chrono::microseconds wait{0};         // Wait: the tile rate cap frees enough bytes then
};

class SessionProtocol {
 public:
  using Clock = std::chrono::steady_clock;

  // id: the session number (Welcome.session); peer_key: the address admit() counted it under;
  // peer: "address:port" for log lines.
  SessionProtocol(SessionContext& context, std::uint64_t id, std::string peer_key,
                  std::string peer);

  // Input: bytes the client sent; then next_frame() and handle() for each frame.
  void receive(const char* data, std::size_t n);
  // The next frame to handle; false when there is none to handle now (more bytes needed, the
  // session is closing or paused). A frame too large or malformed fails the session.
  bool next_frame(wire::Envelope& env);
  void handle(const wire::Envelope& env);
  // Adds the incomplete frame held to the server's total; false: too much held, the session
  // failed (FRAME_TOO_LARGE).
  // `transport_held`: bytes of an incomplete message the transport holds below the frame
  // decoder (the WebSocket layer's unfinished message), counted with the decoder's.
  bool account_partial(std::size_t transport_held = 0);
  // Reading waits: a wrong token's answer is delayed, or the replies pile up.
  bool paused() const;

  // The engine thread's news (posted to the session's strand).
  void tiles_changed(const std::vector<std::uint32_t>& tiles);
  // Queues the host's irradiance volume when it is newer than what this client has (after
  // Subscribe): the newest replaces one still waiting, with its layout while the client has
  // none of its epoch.
  void offer_probe_volume();
  void edit_applied(std::shared_ptr<const std::string> frame);
  // The host's poses changed (docs/DYNAMIC.md#poses): after Subscribe, the next write sends the
  // newest pose of every node moved since the last Poses this client got.
  void poses_changed();
  // The avatars moved (presence_board.h): with Subscribe.presence, the next write sends the
  // nearest others' when they differ from those sent last.
  void presence_changed(std::shared_ptr<const AvatarSnapshot> avatars);

  // The connection's timers and state.
  void penalty_ended() { penalty_ = false; }
  void answer_token_failure(bool banned);
  void hello_timed_out(bool handshaking);
  void idle_timed_out();
  void shutdown() { fail(wire::SERVER_SHUTDOWN, "the server is shutting down"); }
  // The transport under the frames failed (a WebSocket message that is malformed, text or too
  // large): the same Error and close as a bad frame on TCP.
  void transport_failed(wire::ErrorCode code, const std::string& message) { fail(code, message); }

  // The client's own address, learnt from a trusted proxy (a PROXY header, X-Forwarded-For): the
  // session is counted, limited and banned under `key` from now on, and logged as `peer`. Empty
  // when admitted; else why not (counted like a refused connection; the session stays as it
  // was, for the caller to close).
  std::string move_peer(const std::string& key, const std::string& peer, bool trusted = false);
  // The session is counted under a trusted proxy's address, not its client's: it may not present
  // a control token (a wrong one would penalise the proxy's other clients).
  void set_unattributed(bool unattributed) { unattributed_ = unattributed; }

  // The client may not have a session (move_peer's refusal): Error REFUSED, then close.
  void refuse(const std::string& message) { fail(wire::REFUSED, message, CloseReason::Disconnect); }

  // Output: what to write next; `now` drives the tile byte-rate cap.
  SessionWrite next_write(Clock::time_point now);
  SessionEvents take_events() { return std::exchange(events_, SessionEvents{}); }

  // The connection closed (reason counts unless a failure gave one before): releases what the
  // session held of the server and counts it. Idempotent.
  void close(CloseReason reason);
  bool closed() const { return closed_; }
  bool closing() const { return closing_; }
  bool awaiting_hello() const { return state_ == State::AwaitHello; }
  std::uint64_t id() const { return id_; }
  // Tiles waiting; any thread.
  std::size_t queue_depth() const { return queue_depth_.load(); }

  // A log line this session causes, within its budget (ServerOptions::session_log_burst and
  // session_log_per_s); lines over it are counted, and the next line says how many.
  void note(log::Level level, const std::string& message);

 private:
  enum class State { AwaitHello, Ready };

  void on_hello(const wire::Hello& h);
  void on_scene_request(const wire::SceneRequest& r);
  void on_subscribe(const wire::Subscribe& s);
  void on_camera(const wire::CameraUpdate& c);
  void on_scene_edit(const wire::SceneEdit& m);
  void on_scene_export(const wire::SceneExportRequest& m);
  // Whether `presented` is the control token; when not, the error (no token configured) or the
  // delayed answer of a wrong token is under way.
  bool token_accepted(const std::string& presented);
  void send_stats();
  void queue_changed();
  // A reply or notice (answering request `request_id`, 0: none); the connection stays open.
  void error(wire::ErrorCode code, const std::string& message, std::uint64_t request_id = 0,
             log::Level level = log::Level::Info);
  // An Error frame, then close once it is written (or after a grace period).
  void fail(wire::ErrorCode code, const std::string& message) {
    fail(code, message, reason_of(code));
  }
  void fail(wire::ErrorCode code, const std::string& message, CloseReason reason);
  void send(const wire::Envelope& e) { send_frame(wire::encode_frame(e)); }
  void send_frame(std::string frame);
  std::string next_scene_chunk();
  std::shared_ptr<const std::string> next_avatars();
  SessionWrite next_tile(Clock::time_point now);

  SessionContext& ctx_;
  std::uint64_t id_;
  std::string peer_key_;       // what admit() counted this session under
  bool unattributed_ = false;  // a trusted proxy's, with no client named
  std::string peer_, client_name_;
  wire::FrameDecoder decoder_;
  SessionEvents events_;
  State state_ = State::AwaitHello;
  bool closed_ = false, closing_ = false;
  std::optional<CloseReason> close_reason_;
  bool penalty_ = false;              // a wrong token's answer is being delayed
  std::int64_t partial_counted_ = 0;  // of the server's partial_bytes
  double log_tokens_ = 1e9;           // clamped to the burst at the first line
  Clock::time_point log_refill_ = Clock::now();
  std::uint64_t log_suppressed_ = 0;
  std::deque<std::string> control_;
  std::deque<std::shared_ptr<const std::string>> edits_;  // broadcasts not yet written
  std::shared_ptr<const std::string> volume_frame_;       // the probe volume, not yet written
  bool poses_due_ = false;                         // a Poses frame may be owed (poses_changed)
  bool poses_complete_ = false;                    // the first, complete Poses was written
  std::uint64_t poses_seen_ = 0;                   // the pose sequence the client stands at
  bool presence_ = false;                          // Subscribe.presence on a --presence server
  std::optional<CameraPose> camera_;               // the last CameraUpdate
  std::shared_ptr<const AvatarSnapshot> avatars_;  // newer than those sent, not yet written
  std::vector<AvatarState> avatars_sent_;
  float height_sent_ = 0.0f;
  bool avatars_written_ = false;  // an Avatars frame was written (the first goes out if empty)
  bool volume_frame_has_layout_ = false;
  std::uint64_t volume_layout_epoch_ = 0, volume_version_ = 0;  // queued or written
  std::shared_ptr<const wire::ScenePackage> package_;           // set by Hello
  bool scene_active_ = false;
  std::uint64_t scene_offset_ = 0;
  bool streaming_ = false;
  std::vector<std::uint8_t> subscribed_;
  std::vector<std::uint64_t> known_;  // newest version the client has (or has been sent)
  SendQueue queue_;
  std::uint64_t coalesced_counted_ = 0;  // of queue_.coalesced(), added to the server's counter
  std::atomic<std::size_t> queue_depth_{0};
  wire::TileEncoding encoding_ = wire::TILE_RGB9E5_ZSTD;
  bool held_ = false;  // a tile frame waiting for the rate cap
  std::shared_ptr<const std::string> held_frame_;
  double rate_ = 0.0, tokens_ = 0.0;
  Clock::time_point last_refill_ = Clock::now();
};

}  // namespace irradcast

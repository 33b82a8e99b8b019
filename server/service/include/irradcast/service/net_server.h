// The network server: accepts TCP connections and runs one session per client (the protocol of
// docs/PROTOCOL.md) on a small pool of Asio I/O threads. It serves the scene package and the
// tiles of a TileSource (an EngineHost, or a NATS gateway); the engine runs on its own thread and
// only tells the server which tiles got new versions. A session's memory is bounded: at most one
// queue entry per tile and a capped number of control frames, so a slow or stuck client never makes
// the server buffer without bound or stall the others.
#pragma once

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/service/forwarded_header.h"
#include "irradcast/service/tile_source.h"

namespace irradcast {

struct ServerOptions {
  std::string bind = "0.0.0.0";
  std::uint16_t port = 7450;  // 0 = any free port (see Server::port())
  // The web port (docs/PROTOCOL.md, "WebSocket"): the viewer page at / and the protocol over a
  // WebSocket at /ws, on the same address, with TLS when the protocol port has it. None: no web
  // port; 0: any free port (Server::http_port()).
  std::optional<std::uint16_t> http_port;
  int io_threads = 2;
  std::size_t max_frame = 16u << 20;              // largest frame accepted after Hello
  std::chrono::milliseconds idle_timeout{30000};  // close after this long without a frame
  std::size_t scene_chunk_bytes = 256u << 10;     // SceneChunk payload size
  std::size_t max_control_frames = 256;           // queued replies before a client is dropped
  // The most sessions at once, all peers together; past it a new connection gets
  // Error{INTERNAL, "the server is full"} and is closed.
  std::uint32_t max_clients = 4096;
  // The secret a client must put in SceneEdit.token to edit the scene (docs/EDITS.md). Empty:
  // this server takes no edits (every SceneEdit gets Error PERMISSION_DENIED). At least
  // kMinTokenLength characters.
  std::string control_token;
  // The web port: pages of these origins (scheme://host[:port]) may open /ws besides the
  // server's own host (--allowed-origin; docs/OPERATIONS.md "The web port").
  std::vector<std::string> allowed_origins;
  // Reverse proxies and load balancers (CIDRs: "10.0.0.0/8", "192.0.2.7", "fd00::/8") whose word
  // on who their clients are is taken (--trusted-proxy; docs/OPERATIONS.md "Behind a proxy"): a
  // PROXY protocol v2 header on either port, and on the web port `forwarded_header`. A session
  // is then counted, limited and banned under its client's address; a trusted peer itself has no
  // per-address limit. Empty: every peer is its own client.
  std::vector<std::string> trusted_proxies;
  ForwardedHeader forwarded_header = ForwardedHeader::XForwardedFor;
  // Every connection from a trusted proxy to the protocol port (proxy_protocol) or the web port
  // (web_proxy_protocol) starts with a PROXY protocol v2 header (--proxy-protocol); one without
  // is refused. Off: no PROXY header is read on that port (a trusted peer's bytes are its own).
  bool proxy_protocol = false;
  bool web_proxy_protocol = false;

  // Hostile clients (docs/OPERATIONS.md).
  // TLS on the protocol port: PEM certificate chain and private key (both or neither).
  std::string tls_cert, tls_key;
  // Frames before Hello: at most this many bytes, plus 32 per tile of the scene (the `known`
  // list of a resuming client).
  std::size_t max_hello_frame = 4096;
  // A connection that has not completed its (TLS handshake and) Hello within this is closed.
  std::chrono::milliseconds hello_timeout{5000};
  // All sessions' incomplete frames together; a session holding more than 64 KiB of an
  // incomplete frame when the total is above this is closed (Error FRAME_TOO_LARGE).
  std::size_t max_partial_bytes = 64u << 20;
  // A session whose writes make no progress for this long is closed as a slow client (0: no
  // watch).
  std::chrono::milliseconds write_stall_timeout{10000};
  // SO_SNDBUF of each client socket, which bounds the kernel memory a client that does not read
  // can hold (0: the kernel's autotuning, up to net.ipv4.tcp_wmem's maximum).
  int socket_send_buffer = 0;
  // Sessions per peer address (an IPv6 peer's /64); 0 = no limit.
  std::uint32_t max_clients_per_peer = 64;
  // Edit broadcasts waiting for one client; past it the oldest are dropped (the client sees
  // the revision gap and loads the current scene package, docs/PROTOCOL.md).
  std::size_t max_pending_edits = 64;
  // Wrong control tokens: each answer is delayed (token_failure_delay, doubling per failure of
  // the address); after max_token_failures the connection is closed and the address refused
  // for ban_duration.
  std::uint32_t max_token_failures = 5;
  std::chrono::milliseconds token_failure_delay{250};
  std::chrono::milliseconds ban_duration{60000};
  // Log lines one session may cause: a burst, then so many per second (the rest are counted).
  double session_log_burst = 20.0;
  double session_log_per_s = 1.0;

  // Presence (--presence, docs/DYNAMIC.md#presence): a viewer that subscribes with
  // Subscribe.presence is shown to the others as an avatar at its camera, and is sent the
  // presence_nearest avatars nearest its camera, at most presence_hz times a second. Off: such a
  // Subscribe gets Error{BAD_REQUEST} (the rest of it stands).
  bool presence = false;
  std::uint32_t presence_nearest = 32;
  double presence_hz = 10.0;
  float presence_height = 1.7f;  // metres from an avatar's foot to its eye (Avatars.height)
};

inline constexpr std::size_t kMinTokenLength = 16;

// Why a session ended (ServerStats::sessions_closed).
enum class CloseReason : std::uint8_t {
  Bye,                 // the client said Bye
  Disconnect,          // the client closed the connection, or a read or write failed
  IdleTimeout,         // no frame for the idle timeout
  BadFrame,            // a frame that does not parse
  FrameTooLarge,       // a frame above the size cap
  UnsupportedVersion,  // Hello with another protocol version
  UnexpectedMessage,   // a first frame other than Hello
  SlowClient,          // the client did not read its replies
  Shutdown,            // the server stopped
  Internal,            // a failure inside the server
  HelloTimeout,        // no (TLS handshake and) Hello within ServerOptions::hello_timeout
  TokenFailures,       // too many wrong control tokens
  Tls,                 // the TLS handshake failed
};
inline constexpr std::size_t kCloseReasons = 13;
// "bye", "disconnect", "idle_timeout", "bad_frame", "frame_too_large", "unsupported_version",
// "unexpected_message", "slow_client", "shutdown", "internal", "hello_timeout",
// "token_failures", "tls".
const char* close_reason_name(CloseReason reason);

// Throws irradcast::Error naming an entry of ServerOptions::trusted_proxies that is not an IPv4 or
// IPv6 network (the Server's constructor throws the same).
void check_trusted_proxies(const std::vector<std::string>& cidrs);

// Raises this process's soft limit of open files to its hard limit (each client holds one);
// returns the limit now in force.
std::uint64_t raise_open_file_limit();

// Counters count since the server was created (server_counters.inc); the rest is the state at
// the time of the call.
struct ServerStats {
#define IRRADCAST_SERVER_COUNTER(name, wire, metric, help) std::uint64_t name = 0;
#include "irradcast/service/server_counters.inc"
#undef IRRADCAST_SERVER_COUNTER
  std::uint32_t clients = 0;
  std::uint64_t partial_bytes = 0;    // incomplete frames held now, all sessions
  std::uint64_t queue_depth = 0;      // tiles waiting, all clients
  std::uint64_t queue_depth_max = 0;  // tiles waiting for the client with the longest queue
  std::array<std::uint64_t, kCloseReasons> sessions_closed{};  // by CloseReason
  double uptime_seconds = 0.0;
};

class Server {
 public:
  Server(TileSource& host, ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds and starts the I/O threads. Throws irradcast::Error if the address cannot be bound.
  void start();
  // Tells every client (Error SERVER_SHUTDOWN), closes every connection, joins the threads.
  // Idempotent.
  void stop();
  // Loads --tls-cert/--tls-key again (SIGHUP): new connections on both ports get the new
  // certificate, open ones keep theirs. False (logged) without TLS, or when a file is bad: the
  // current certificate stays.
  bool reload_tls();
  std::uint16_t port() const;
  // The web port; 0 when ServerOptions::http_port is not set.
  std::uint16_t http_port() const;
  ServerStats stats() const;

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace irradcast

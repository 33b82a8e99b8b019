// The network server: accepts TCP connections and runs one session per client (the protocol of
// docs/PROTOCOL.md) on a small pool of Asio I/O threads. It serves the scene package and the
// tiles of an EngineHost; the engine runs on its own thread and only tells the server which
// tiles got new versions. A session's memory is bounded: at most one queue entry per tile and a
// capped number of control frames, so a slow or stuck client never makes the server buffer
// without bound or stall the others.
#pragma once

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "irradcast/engine_host.h"

namespace irradcast {

struct ServerOptions {
  std::string bind = "0.0.0.0";
  std::uint16_t port = 7450;  // 0 = any free port (see Server::port())
  int io_threads = 2;
  std::size_t max_frame = 16u << 20;              // largest frame accepted from a client
  std::chrono::milliseconds idle_timeout{30000};  // close after this long without a frame
  std::size_t scene_chunk_bytes = 256u << 10;     // SceneChunk payload size
  std::size_t max_control_frames = 256;           // queued replies before a client is dropped
  std::uint32_t max_clients = 4096;
  // The secret a client must put in SceneEdit.token to edit the scene (docs/EDITS.md). Empty:
  // this server takes no edits (every SceneEdit gets Error PERMISSION_DENIED).
  std::string control_token;
};

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
};
inline constexpr std::size_t kCloseReasons = 10;
// "bye", "disconnect", "idle_timeout", "bad_frame", "frame_too_large", "unsupported_version",
// "unexpected_message", "slow_client", "shutdown", "internal".
const char* close_reason_name(CloseReason reason);

// Counters count since the server was created; the rest is the state at the time of the call.
struct ServerStats {
  std::uint32_t clients = 0;
  std::uint64_t connections = 0;      // accepted so far (refused ones included)
  std::uint64_t clients_refused = 0;  // accepted and closed at once: max_clients reached
  std::uint64_t bytes_sent = 0;       // every frame
  std::uint64_t bytes_received = 0;
  std::uint64_t frames_received = 0;
  std::uint64_t tiles_sent = 0;
  std::uint64_t tile_bytes_sent = 0;   // TileUpdate frames
  std::uint64_t tiles_coalesced = 0;   // versions replaced while waiting (counted as they happen)
  std::uint64_t scene_bytes_sent = 0;  // SceneChunk frames
  std::uint64_t errors_sent = 0;
  std::uint64_t queue_depth = 0;      // tiles waiting, all clients
  std::uint64_t queue_depth_max = 0;  // tiles waiting for the client with the longest queue
  std::array<std::uint64_t, kCloseReasons> sessions_closed{};  // by CloseReason
  double uptime_seconds = 0.0;
};

class Server {
 public:
  Server(EngineHost& host, ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds and starts the I/O threads. Throws irradcast::Error if the address cannot be bound.
  void start();
  // Tells every client (Error SERVER_SHUTDOWN), closes every connection, joins the threads.
  // Idempotent.
  void stop();
  std::uint16_t port() const;
  ServerStats stats() const;

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace irradcast

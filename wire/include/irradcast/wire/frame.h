// Framing of the wire protocol: every frame is a 4-byte little-endian length N and N bytes of one
// serialized Envelope (proto/irradcast.proto, package irradcast.wire). docs/PROTOCOL.md has the
// messages and the session state machine.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "irradcast.pb.h"  // generated from proto/irradcast.proto

namespace irradcast::wire {

constexpr std::uint32_t kProtocolVersion = 1;
constexpr std::size_t kDefaultMaxFrame = 16u << 20;  // 16 MiB: largest Envelope accepted
constexpr std::size_t kFrameHeaderBytes = 4;
// The server closes a connection that sent no frame for this long (Welcome.idle_timeout_ms).
constexpr std::uint32_t kDefaultIdleTimeoutMs = 30000;

// Welcome.capabilities (docs/PROTOCOL.md, "Capabilities").
inline constexpr const char* kCapTilesRgb9e5 = "tiles.rgb9e5";
inline constexpr const char* kCapTilesHalf = "tiles.half";
inline constexpr const char* kCapTilesDelta = "tiles.delta";
inline constexpr const char* kCapResume = "resume";
inline constexpr const char* kCapStats = "stats";

// 4-byte little-endian length + serialized Envelope. Throws irradcast::Error if the serialized
// Envelope is larger than max_frame (a peer with that cap would drop the connection) or than
// 2 GiB - 1 (protobuf's limit).
std::string encode_frame(const Envelope& e, std::size_t max_frame = kDefaultMaxFrame);

enum class DecodeStatus { Frame, NeedMore, TooLarge, Malformed };
const char* to_string(DecodeStatus s);

// Incremental decoder for a byte stream: feed() appends bytes; next() extracts one frame.
//
// Unknown message types: an Envelope that parses but has no known oneof case set (a newer peer's
// message, or an empty Envelope) is returned as DecodeStatus::Frame with
// out.msg_case() == Envelope::MSG_NOT_SET; the stream stays usable, the receiver answers
// Error{UNEXPECTED_MESSAGE} and goes on. Only bytes that do not parse as an Envelope are
// Malformed.
class FrameDecoder {
 public:
  // max_frame: the largest payload accepted (clamped to 2 GiB - 1, protobuf's limit).
  explicit FrameDecoder(std::size_t max_frame = kDefaultMaxFrame);

  void feed(const void* data, std::size_t n);

  // Frame: `out` holds the next envelope. NeedMore: wait for bytes. TooLarge: the announced
  // length exceeds max_frame (stream unusable). Malformed: the payload does not parse as an
  // Envelope (stream unusable). After TooLarge or Malformed every further call returns the same
  // status. error() explains the last failure in one line.
  DecodeStatus next(Envelope& out);

  const std::string& error() const { return error_; }
  // A new cap for frames not yet decoded (the server raises it once a client said Hello).
  void set_max_frame(std::size_t max_frame);
  std::size_t buffered() const { return buffer_.size() - start_; }
  std::size_t max_frame() const { return max_frame_; }
  // Frames decoded so far.
  std::uint64_t frames() const { return frames_; }

 private:
  std::size_t max_frame_;
  std::string buffer_;
  std::size_t start_ = 0;                         // first unread byte of buffer_
  DecodeStatus failed_ = DecodeStatus::NeedMore;  // TooLarge / Malformed once the stream broke
  std::string error_;
  std::uint64_t frames_ = 0;
};

// Name of the message an Envelope carries ("hello", "tile_update", ...; "unknown" if none set).
const char* message_name(const Envelope& e);

// Convenience builders
Envelope make_error(ErrorCode code, const std::string& message);
Envelope make_bye(const std::string& reason);

}  // namespace irradcast::wire

#include "irradcast/wire/frame.h"

#include <algorithm>
#include <limits>

#include "irradcast/common/error.h"

namespace irradcast::wire {
namespace {

void put_u32le(char* p, std::uint32_t v) {
  p[0] = static_cast<char>(v & 0xFF);
  p[1] = static_cast<char>((v >> 8) & 0xFF);
  p[2] = static_cast<char>((v >> 16) & 0xFF);
  p[3] = static_cast<char>((v >> 24) & 0xFF);
}

std::uint32_t get_u32le(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return static_cast<std::uint32_t>(b[0]) | (static_cast<std::uint32_t>(b[1]) << 8) |
         (static_cast<std::uint32_t>(b[2]) << 16) | (static_cast<std::uint32_t>(b[3]) << 24);
}

}  // namespace

std::string encode_frame(const Envelope& e, std::size_t max_frame) {
  const std::size_t size = e.ByteSizeLong();
  if (size > max_frame || size > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw irradcast::Error("cannot send a " + std::string(message_name(e)) + " frame of " +
                           std::to_string(size) + " bytes: the limit is " +
                           std::to_string(max_frame) + " bytes");
  std::string out(kFrameHeaderBytes + size, '\0');
  put_u32le(out.data(), static_cast<std::uint32_t>(size));
  if (size > 0 && !e.SerializeToArray(out.data() + kFrameHeaderBytes, static_cast<int>(size)))
    throw irradcast::Error("cannot serialize a " + std::string(message_name(e)) + " frame");
  return out;
}

const char* to_string(DecodeStatus s) {
  switch (s) {
    case DecodeStatus::Frame:
      return "frame";
    case DecodeStatus::NeedMore:
      return "need more bytes";
    case DecodeStatus::TooLarge:
      return "frame too large";
    case DecodeStatus::Malformed:
      return "malformed frame";
  }
  return "unknown status";
}

// protobuf parses at most INT_MAX bytes at once: larger caps are clamped.
FrameDecoder::FrameDecoder(std::size_t max_frame)
    : max_frame_(std::min<std::size_t>(max_frame, std::numeric_limits<int>::max())) {}

void FrameDecoder::set_max_frame(std::size_t max_frame) {
  max_frame_ = std::min<std::size_t>(max_frame, std::numeric_limits<int>::max());
}

void FrameDecoder::feed(const void* data, std::size_t n) {
  if (n == 0 || failed_ != DecodeStatus::NeedMore) return;  // a broken stream keeps no bytes
  // Drop consumed bytes before growing, so the buffer holds at most one partial frame plus
  // what was fed since the last next().
  if (start_ > 0 && (start_ >= buffer_.size() / 2 || start_ >= (1u << 16))) {
    buffer_.erase(0, start_);
    start_ = 0;
  }
  buffer_.append(static_cast<const char*>(data), n);
}

DecodeStatus FrameDecoder::next(Envelope& out) {
  if (failed_ != DecodeStatus::NeedMore) return failed_;
  const std::size_t avail = buffered();
  if (avail < kFrameHeaderBytes) return DecodeStatus::NeedMore;
  const std::uint32_t len = get_u32le(buffer_.data() + start_);
  if (len > max_frame_) {
    error_ = "frame of " + std::to_string(len) + " bytes exceeds the limit of " +
             std::to_string(max_frame_) + " bytes";
    failed_ = DecodeStatus::TooLarge;
    buffer_.clear();
    start_ = 0;
    return failed_;
  }
  if (avail - kFrameHeaderBytes < len) return DecodeStatus::NeedMore;
  const char* payload = buffer_.data() + start_ + kFrameHeaderBytes;
  if (!out.ParseFromArray(payload, static_cast<int>(len))) {
    error_ = "frame " + std::to_string(frames_ + 1) + " (" + std::to_string(len) +
             " bytes) does not parse as an Envelope";
    failed_ = DecodeStatus::Malformed;
    buffer_.clear();
    start_ = 0;
    return failed_;
  }
  start_ += kFrameHeaderBytes + len;
  if (start_ == buffer_.size()) {
    buffer_.clear();
    start_ = 0;
  }
  ++frames_;
  return DecodeStatus::Frame;
}

const char* message_name(const Envelope& e) {
  switch (e.msg_case()) {
    case Envelope::kHello:
      return "hello";
    case Envelope::kWelcome:
      return "welcome";
    case Envelope::kSceneRequest:
      return "scene_request";
    case Envelope::kSceneChunk:
      return "scene_chunk";
    case Envelope::kSubscribe:
      return "subscribe";
    case Envelope::kCameraUpdate:
      return "camera_update";
    case Envelope::kTileUpdate:
      return "tile_update";
    case Envelope::kStatsRequest:
      return "stats_request";
    case Envelope::kStats:
      return "stats";
    case Envelope::kPing:
      return "ping";
    case Envelope::kPong:
      return "pong";
    case Envelope::kError:
      return "error";
    case Envelope::kPoses:
      return "poses";
    case Envelope::kAvatars:
      return "avatars";
    case Envelope::kBye:
      return "bye";
    case Envelope::kSceneEdit:
      return "scene_edit";
    case Envelope::kSceneExportRequest:
      return "scene_export_request";
    case Envelope::kSceneExport:
      return "scene_export";
    case Envelope::kProbeVolume:
      return "probe_volume";
    case Envelope::MSG_NOT_SET:
      break;
  }
  return "unknown";
}

Envelope make_error(ErrorCode code, const std::string& message) {
  Envelope e;
  Error* err = e.mutable_error();
  err->set_code(code);
  err->set_message(message);
  return e;
}

Envelope make_bye(const std::string& reason) {
  Envelope e;
  e.mutable_bye()->set_reason(reason);
  return e;
}

}  // namespace irradcast::wire

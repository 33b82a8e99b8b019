// NatsOrigin's state, shared by its files: nats_origin.cpp (the publisher thread and the public
// API) and nats_origin_requests.cpp (the gateways' camera and edit requests, the metrics).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/service/nats_origin.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast_nats.pb.h"
#include "nats_link.h"
#include "presence_board.h"

namespace irradcast::nats_origin {

using Clock = std::chrono::steady_clock;
constexpr std::size_t kMaxCamerasPerGateway = 4096;
constexpr std::uint64_t kGatewayViewer = std::uint64_t{1} << 63;  // above every session id
// s.presence: at least once a second while presence is on (a gateway forgets the avatars 5 s
// after the last), and at most this many avatars (about 30 bytes each: within NATS's 1 MiB).
constexpr auto kPresenceKeepalive = std::chrono::seconds(1);
constexpr std::size_t kMaxPublishedAvatars = 16384;

inline std::uint64_t random_id() {
  std::random_device rd;
  return (std::uint64_t{rd()} << 32 | rd()) | 1;
}

}  // namespace irradcast::nats_origin

namespace irradcast {

struct NatsOrigin::Impl {
  using Clock = nats_origin::Clock;
  Impl(EngineHost& h, NatsOriginOptions o)
      : host(h), options(std::move(o)), subjects(nats_subjects(h.scene_id())) {}

  EngineHost& host;
  NatsOriginOptions options;
  NatsSubjects subjects;
  const std::uint64_t origin = nats_origin::random_id();

  nats_link::Listeners listeners;  // the Server's

  mutable std::mutex mutex;  // guards what follows, to `conn`
  std::condition_variable cv;
  bool stopping = false;
  bool idle = false;  // the last round published everything marked before it
  std::vector<std::uint8_t> dirty;
  std::vector<std::uint32_t> dirty_list;
  std::deque<AppliedEdit> edits;
  NatsOriginStats st;

  std::mutex camera_mutex;
  struct Gateway {
    std::size_t cameras = 0;
    Clock::time_point seen;
  };
  PresenceBoard presence;  // with options.presence
  std::map<std::uint64_t, Gateway> gateways;

  std::unique_ptr<nats_link::Connection> conn;
  nats_link::Subscription camera_sub, edit_sub;
  std::thread worker;

  bool stream_checked = false;  // a stream check got an answer (mutex)
  std::string refusal;          // why this origin publishes nothing (mutex); "" = it may

  // Worker thread only.
  std::uint64_t published_generation = 0;
  const wire::ScenePackage* last_package = nullptr;
  std::optional<AppliedEdit> last_edit;  // the newest edit published
  Clock::time_point next_stats{};
  Clock::time_point next_check{};
  std::shared_ptr<const ProbeVolumeFrames> published_volume;  // the newest volume published
  std::uint64_t published_poses = 0;                          // the pose sequence published
  Clock::time_point poses_published_at{};
  std::uint64_t published_presence = ~std::uint64_t{0};  // the board version published
  Clock::time_point presence_published_at{};

  // The host's poses changed (mutex): published at most every kPoseEvery.
  static constexpr auto kPoseEvery = std::chrono::milliseconds(16);
  bool poses_dirty = false;
  int pose_listener = 0;

  void on_tiles(const std::vector<std::uint32_t>& tiles);
  void on_edit(const AppliedEdit& applied);
  void run();
  bool round(bool full, const std::vector<std::uint32_t>& tiles, std::deque<AppliedEdit>& eds,
             bool poses);
  bool publish_volume(bool full);
  bool publish_poses(bool full);
  bool publish_presence(bool full);
  bool ensure_stream();
  bool stream_allows(std::uint64_t revision);
  bool stream_intact();
  bool publish(const std::string& subject, const google::protobuf::MessageLite& m);
  bool publish_package(const wire::ScenePackage& package, std::uint64_t revision,
                       std::uint64_t epoch);
  bool publish_tile(std::uint32_t index);
  bool publish_everything(std::deque<AppliedEdit>& eds);
  bool publish_edits(std::deque<AppliedEdit>& eds);
  bool publish_edit(const AppliedEdit& a, bool names_package);
  bool publish_stats();
  void expire_cameras();
  void count(std::uint64_t NatsOriginStats::*field, std::uint64_t n = 1) {
    std::lock_guard lock(mutex);
    st.*field += n;
  }
  void on_cameras(natsConnection* nc, natsMsg* msg);
  void on_submit(natsConnection* nc, natsMsg* msg);
};

}  // namespace irradcast

// The poses of dynamic nodes as a server holds and sends them (docs/DYNAMIC.md#poses): the newest
// local transform and visibility of every node a pose moved, a sequence that grows by one per
// accepted pose edit, each node's rate for streamed poses, and the Poses frames sessions write,
// encoded once for all the sessions that stand at the same sequence. A slow session is sent the
// newest poses of the nodes that moved since its last frame: never a queue. Thread-safe.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/scene_edit.h"

namespace irradcast {

// A streamed pose past its node's rate (wire::RATE_LIMITED): dropped, nothing changed.
struct PoseRateLimited : Error {
  using Error::Error;
};

class PoseBoard {
 public:
  using Clock = std::chrono::steady_clock;
  // Streamed poses per second per node, and the burst a node may send above it (network jitter
  // bunches poses sent evenly).
  static constexpr double kStreamRate = 60.0;
  static constexpr double kStreamBurst = 10.0;
  // Sessions at distinct sequences whose frames are kept encoded.
  static constexpr std::size_t kCachedFrames = 64;

  // Whether a streamed pose that moves `nodes` may pass at `now`: when every node has a token,
  // one is taken from each and nullopt returned; else nothing is taken and the first node over
  // its rate is returned.
  std::optional<int> admit_stream(const std::vector<int>& nodes, Clock::time_point now);

  // Records the newest poses of some nodes as one step of the sequence (returned), accepted at
  // `posed_us` (system clock), then calls the listener (outside the lock).
  std::uint64_t post(const std::vector<std::pair<int, NodePoseState>>& poses,
                     std::uint64_t posed_us);
  // The whole set of posed nodes becomes `poses` (a gateway's copy of its origin's, which may
  // have restarted without some): one step of the sequence, and every session's next frame is
  // complete (a client puts the nodes it no longer lists back where the package places them).
  std::uint64_t replace(const std::map<int, NodePoseState>& poses, std::uint64_t posed_us);
  // At start (no listener is called): the poses saved before, at their sequence.
  void restore(std::map<int, NodePoseState> poses, std::uint64_t sequence);
  // Called after every post, on the posting thread (the server's fan-out, a NATS origin's
  // publisher). Returns an id for remove_listener.
  int add_listener(std::function<void()> listener);
  void remove_listener(int id);

  std::uint64_t sequence() const;
  // Every posed node's newest pose, and the sequence they stand at.
  std::map<int, NodePoseState> snapshot(std::uint64_t* sequence = nullptr) const;

  struct Frame {
    std::shared_ptr<const std::string> frame;  // an encoded Poses frame; null: nothing to send
    std::uint64_t sequence = 0;                // what the client stands at once it has it
  };
  // For a client that stands at `since`: the poses of the nodes moved after it; `complete`: every
  // posed node (the first frame of a session, sent even when no node is posed, and the frame of
  // a client from before the last replace()).
  Frame frame_since(std::uint64_t since, bool complete) const;

 private:
  struct Entry {
    NodePoseState pose;
    std::uint64_t sequence = 0;  // of the post that set it
  };
  struct Bucket {
    double tokens = kStreamBurst;
    Clock::time_point refilled{};
  };
  mutable std::mutex mutex_;
  std::map<int, Entry> entries_;
  std::map<int, Bucket> buckets_;
  std::uint64_t sequence_ = 0;
  std::uint64_t replaced_ = 0;  // the sequence of the last replace(): older clients get it whole
  std::uint64_t posed_us_ = 0;
  std::map<int, std::function<void()>> listeners_;
  int next_listener_ = 1;
  // Frames encoded at the current sequence, by (since, complete).
  mutable std::map<std::pair<std::uint64_t, bool>, std::shared_ptr<const std::string>> frames_;
};

}  // namespace irradcast

#include "irradcast/service/pose_board.h"

#include <algorithm>

#include "irradcast.pb.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"

namespace irradcast {

std::optional<int> PoseBoard::admit_stream(const std::vector<int>& nodes, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  for (int n : nodes) {
    auto [it, fresh] = buckets_.try_emplace(n);
    Bucket& b = it->second;
    if (fresh) b.refilled = now;
    const double elapsed = std::chrono::duration<double>(now - b.refilled).count();
    b.tokens = std::min(kStreamBurst, b.tokens + std::max(elapsed, 0.0) * kStreamRate);
    b.refilled = std::max(now, b.refilled);
    if (b.tokens < 1.0) return n;
  }
  for (int n : nodes) buckets_[n].tokens -= 1.0;
  return std::nullopt;
}

std::uint64_t PoseBoard::post(const std::vector<std::pair<int, NodePoseState>>& poses,
                              std::uint64_t posed_us) {
  std::vector<std::function<void()>> listeners;
  std::uint64_t sequence = 0;
  {
    std::lock_guard lock(mutex_);
    sequence = ++sequence_;
    for (const auto& [node, pose] : poses) entries_[node] = Entry{pose, sequence};
    posed_us_ = posed_us;
    frames_.clear();
    for (const auto& [id, l] : listeners_) listeners.push_back(l);
  }
  for (const auto& l : listeners) l();
  return sequence;
}

std::uint64_t PoseBoard::replace(const std::map<int, NodePoseState>& poses,
                                 std::uint64_t posed_us) {
  std::vector<std::function<void()>> listeners;
  std::uint64_t sequence = 0;
  {
    std::lock_guard lock(mutex_);
    sequence = ++sequence_;
    entries_.clear();
    for (const auto& [node, pose] : poses) entries_[node] = Entry{pose, sequence};
    replaced_ = sequence;
    posed_us_ = posed_us;
    frames_.clear();
    for (const auto& [id, l] : listeners_) listeners.push_back(l);
  }
  for (const auto& l : listeners) l();
  return sequence;
}

void PoseBoard::restore(std::map<int, NodePoseState> poses, std::uint64_t sequence) {
  std::lock_guard lock(mutex_);
  entries_.clear();
  for (const auto& [node, pose] : poses) entries_[node] = Entry{pose, sequence};
  sequence_ = sequence;
  frames_.clear();
}

int PoseBoard::add_listener(std::function<void()> listener) {
  std::lock_guard lock(mutex_);
  listeners_.emplace(next_listener_, std::move(listener));
  return next_listener_++;
}

void PoseBoard::remove_listener(int id) {
  std::lock_guard lock(mutex_);
  listeners_.erase(id);
}

std::uint64_t PoseBoard::sequence() const {
  std::lock_guard lock(mutex_);
  return sequence_;
}

std::map<int, NodePoseState> PoseBoard::snapshot(std::uint64_t* sequence) const {
  std::lock_guard lock(mutex_);
  std::map<int, NodePoseState> out;
  for (const auto& [node, e] : entries_) out.emplace(node, e.pose);
  if (sequence) *sequence = sequence_;
  return out;
}

PoseBoard::Frame PoseBoard::frame_since(std::uint64_t since, bool complete) const {
  std::lock_guard lock(mutex_);
  Frame f;
  f.sequence = sequence_;
  if (since < replaced_) complete = true;  // nodes may have gone: only a complete frame says so
  if (!complete && since >= sequence_) return f;
  const auto key = std::make_pair(complete ? 0 : since, complete);
  if (auto it = frames_.find(key); it != frames_.end()) {
    f.frame = it->second;
    return f;
  }
  wire::Envelope e;
  wire::Poses* m = e.mutable_poses();
  m->set_sequence(sequence_);
  m->set_complete(complete);
  m->set_posed_us(posed_us_);
  for (const auto& [node, entry] : entries_)
    if (complete || entry.sequence > since)
      *m->add_poses() = wire::node_pose_to_proto(static_cast<std::uint32_t>(node), entry.pose.local,
                                                 entry.pose.visible);
  f.frame = std::make_shared<const std::string>(wire::encode_frame(e));
  if (frames_.size() < kCachedFrames) frames_.emplace(key, f.frame);
  return f;
}

}  // namespace irradcast

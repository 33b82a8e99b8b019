// Where the viewers that show themselves stand (presence_board.h).
#include "presence_board.h"

#include <algorithm>
#include <cmath>

namespace irradcast {

void PresenceBoard::place(std::uint64_t id, const CameraPose& camera) {
  const glm::vec3 e = camera.eye;
  if (!(std::abs(e.x) <= kMaxCoordinate && std::abs(e.y) <= kMaxCoordinate &&
        std::abs(e.z) <= kMaxCoordinate)) {
    remove(id);
    return;
  }
  // Level heading; looking straight up or down keeps +Z.
  const glm::vec2 level(camera.forward.x, camera.forward.z);
  const float heading = glm::dot(level, level) > 1e-12f ? std::atan2(level.x, level.y) : 0.0f;
  const AvatarState a{id, e, heading};
  std::lock_guard lock(mutex_);
  auto [it, added] = avatars_.try_emplace(id, a);
  if (!added && it->second == a) return;
  it->second = a;
  changed_ = true;
}

void PresenceBoard::remove(std::uint64_t id) {
  std::lock_guard lock(mutex_);
  if (avatars_.erase(id) > 0) changed_ = true;
}

std::shared_ptr<const AvatarSnapshot> PresenceBoard::take_changed() {
  std::lock_guard lock(mutex_);
  if (!changed_) return nullptr;
  changed_ = false;
  return snapshot_locked();
}

std::shared_ptr<const AvatarSnapshot> PresenceBoard::snapshot() const {
  std::lock_guard lock(mutex_);
  return snapshot_locked();
}

std::shared_ptr<const AvatarSnapshot> PresenceBoard::snapshot_locked() const {
  auto snapshot = std::make_shared<AvatarSnapshot>();
  snapshot->reserve(avatars_.size());
  for (const auto& [id, a] : avatars_) snapshot->push_back(a);
  return snapshot;
}

std::size_t PresenceBoard::size() const {
  std::lock_guard lock(mutex_);
  return avatars_.size();
}

std::vector<AvatarState> nearest_avatars(const AvatarSnapshot& all, std::uint64_t self,
                                         glm::vec3 eye, std::size_t k) {
  struct Near {
    double d2;
    const AvatarState* a;
    bool operator<(const Near& o) const { return d2 != o.d2 ? d2 < o.d2 : a->id < o.a->id; }
  };
  std::vector<Near> near;
  near.reserve(all.size());
  for (const AvatarState& a : all) {
    if (a.id == self) continue;
    const glm::dvec3 d = glm::dvec3(a.eye) - glm::dvec3(eye);
    near.push_back({glm::dot(d, d), &a});
  }
  const std::size_t n = std::min(k, near.size());
  std::partial_sort(near.begin(), near.begin() + static_cast<std::ptrdiff_t>(n), near.end());
  std::vector<AvatarState> out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) out.push_back(*near[i].a);
  return out;
}

}  // namespace irradcast

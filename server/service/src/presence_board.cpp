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
  touch();
  ++local_version_;
}

void PresenceBoard::remove(std::uint64_t id) {
  std::lock_guard lock(mutex_);
  if (avatars_.erase(id) > 0) {
    touch();
    ++local_version_;
  }
}

void PresenceBoard::set_group(std::uint64_t source, std::vector<AvatarState> avatars) {
  std::lock_guard lock(mutex_);
  set_group_locked(source, std::move(avatars));
}

void PresenceBoard::set_group_locked(std::uint64_t source, std::vector<AvatarState> avatars) {
  if (avatars.empty()) {
    if (groups_.erase(source) > 0) touch();
    return;
  }
  std::map<std::uint64_t, AvatarState>& held = groups_[source];
  std::map<std::uint64_t, AvatarState> next;
  for (const AvatarState& a : avatars) {
    if (next.size() >= kMaxGroupAvatars) break;
    if (!valid_avatar(a) || next.contains(a.id)) continue;
    const auto was = held.find(a.id);
    AvatarState shown = a;
    shown.id = was != held.end() ? was->second.id : next_group_id_++;
    next.emplace(a.id, shown);
  }
  if (next != held) touch();
  held = std::move(next);
  if (held.empty()) groups_.erase(source);
}

void PresenceBoard::remove_group(std::uint64_t source) {
  std::lock_guard lock(mutex_);
  if (groups_.erase(source) > 0) touch();
}

void PresenceBoard::replace_groups(Groups groups) {
  std::lock_guard lock(mutex_);
  for (auto it = groups_.begin(); it != groups_.end();) {
    if (groups.contains(it->first)) {
      ++it;
    } else {
      it = groups_.erase(it);
      touch();
    }
  }
  for (auto& [source, avatars] : groups) set_group_locked(source, std::move(avatars));
}

PresenceBoard::Groups PresenceBoard::groups() const {
  std::lock_guard lock(mutex_);
  Groups out;
  for (const auto& [source, avatars] : groups_) {
    std::vector<AvatarState>& list = out[source];
    for (const auto& [id, a] : avatars) {
      list.push_back(a);
      list.back().id = id;  // the source's own
    }
  }
  return out;
}

std::vector<AvatarState> PresenceBoard::local(std::uint64_t* version) const {
  std::lock_guard lock(mutex_);
  if (version) *version = local_version_;
  std::vector<AvatarState> out;
  out.reserve(avatars_.size());
  for (const auto& [id, a] : avatars_) out.push_back(a);
  return out;
}

std::uint64_t PresenceBoard::local_version() const {
  std::lock_guard lock(mutex_);
  return local_version_;
}

void PresenceBoard::set_height(float metres) {
  std::lock_guard lock(mutex_);
  if (height_ == metres) return;
  height_ = metres;
  touch();
}

void PresenceBoard::set_shared_height(float metres) {
  std::lock_guard lock(mutex_);
  if (shared_height_ == metres) return;
  shared_height_ = metres;
  touch();
}

std::uint64_t PresenceBoard::version() const {
  std::lock_guard lock(mutex_);
  return version_;
}

float PresenceBoard::height() const {
  std::lock_guard lock(mutex_);
  return shared_height_ > 0.0f ? shared_height_ : height_;
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
  for (const auto& [source, avatars] : groups_)
    for (const auto& [id, a] : avatars) snapshot->push_back(a);
  return snapshot;
}

std::size_t PresenceBoard::size() const {
  std::lock_guard lock(mutex_);
  std::size_t n = avatars_.size();
  for (const auto& [source, avatars] : groups_) n += avatars.size();
  return n;
}

bool valid_avatar(const AvatarState& a) {
  const float m = PresenceBoard::kMaxCoordinate;
  return a.id != 0 && std::abs(a.eye.x) <= m && std::abs(a.eye.y) <= m && std::abs(a.eye.z) <= m &&
         std::isfinite(a.heading);
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

// Presence (irradcast-server --presence, docs/DYNAMIC.md#presence): where the viewers that show
// themselves stand, as avatars. Each session places its own avatar from its CameraUpdates and
// takes it away when it ends; the server takes a snapshot at most ServerOptions::presence_hz
// times a second when any avatar moved and hands it to every session, which sends its client
// the nearest others (nearest_avatars). A snapshot is shared, never copied per session: a slow
// client is sent the newest set, never a queue. Thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/world.h"

namespace irradcast {

struct AvatarState {
  std::uint64_t id = 0;  // the viewer's session
  glm::vec3 eye{0.0f};
  float heading = 0.0f;  // radians about +Y, from +Z towards +X
  bool operator==(const AvatarState&) const = default;
};

// The avatars at one time.
using AvatarSnapshot = std::vector<AvatarState>;

class PresenceBoard {
 public:
  // Coordinates beyond this (metres) are no place for an avatar: one there is not shown.
  static constexpr float kMaxCoordinate = 1e7f;

  // Session `id`'s avatar at `camera` (a finite pose, as camera_pose_of() checks): where it
  // stands, turned to where it looks. Replaces its earlier place.
  void place(std::uint64_t id, const CameraPose& camera);
  // Session `id` shows no avatar any more (it ended, or its camera left the world).
  void remove(std::uint64_t id);
  // The avatars now, when any was placed or removed since the last call; else null.
  std::shared_ptr<const AvatarSnapshot> take_changed();
  // The avatars now (a session that just subscribed).
  std::shared_ptr<const AvatarSnapshot> snapshot() const;
  std::size_t size() const;

 private:
  std::shared_ptr<const AvatarSnapshot> snapshot_locked() const;

  mutable std::mutex mutex_;
  std::map<std::uint64_t, AvatarState> avatars_;
  bool changed_ = false;
};

// The at most `k` avatars of `all` nearest to `eye`, `self` left out, nearest first (equal
// distances: the lower id first).
std::vector<AvatarState> nearest_avatars(const AvatarSnapshot& all, std::uint64_t self,
                                         glm::vec3 eye, std::size_t k);

}  // namespace irradcast

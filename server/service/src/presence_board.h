// Presence (irradcast-server --presence, docs/DYNAMIC.md#presence): where the viewers that show
// themselves stand, as avatars. Each session places its own avatar from its CameraUpdates and
// takes it away when it ends; the server takes a snapshot at most ServerOptions::presence_hz
// times a second when any avatar moved and hands it to every session, which sends its client
// the nearest others (nearest_avatars). A snapshot is shared, never copied per session: a slow
// client is sent the newest set, never a queue. Thread-safe.
//
// Across NATS (docs/DYNAMIC.md#presence) the board also holds other servers' avatars in groups,
// one per source: at the origin each gateway's (from its camera requests), at a gateway all the
// others (the origin's NatsPresence, its own group left out). Their ids are the sources' own, so
// the board gives each (source, id) an id of its own, above every session id, kept while it
// stays listed.
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

  // The avatars of one source beyond this server, at most this many (the rest are not shown).
  static constexpr std::size_t kMaxGroupAvatars = 4096;
  // The ids the board gives other servers' avatars start here: session ids count from 1 (at a
  // thousand connections a second they reach it in 35 years), and an id below 2^42 is at most 6
  // bytes on the wire (2^62 took 9: 13 % more bytes per Avatars message through a gateway).
  static constexpr std::uint64_t kFirstGroupId = std::uint64_t{1} << 40;
  using Groups = std::map<std::uint64_t, std::vector<AvatarState>>;

  // Session `id`'s avatar at `camera` (a finite pose, as camera_pose_of() checks): where it
  // stands, turned to where it looks. Replaces its earlier place.
  void place(std::uint64_t id, const CameraPose& camera);
  // Session `id` shows no avatar any more (it ended, or its camera left the world).
  void remove(std::uint64_t id);

  // Source `source`'s avatars (valid_avatar() each, ids distinct, at most kMaxGroupAvatars):
  // they replace the ones it had.
  void set_group(std::uint64_t source, std::vector<AvatarState> avatars);
  // Source `source` shows none any more.
  void remove_group(std::uint64_t source);
  // All the groups at once: those not named go.
  void replace_groups(Groups groups);
  // The groups with the sources' own ids (what the origin publishes).
  Groups groups() const;
  // This server's own viewers' avatars, with their session ids; `version` (when given) gets a
  // count that moves whenever they change.
  std::vector<AvatarState> local(std::uint64_t* version = nullptr) const;
  std::uint64_t local_version() const;

  // The avatars' height (Avatars.height, metres): the one another server decides
  // (set_shared_height > 0: a gateway shows its origin's), else this server's own.
  void set_height(float metres);
  void set_shared_height(float metres);  // 0: none
  float height() const;

  // The avatars now, when any was placed or removed since the last call (or the height
  // changed); else null.
  std::shared_ptr<const AvatarSnapshot> take_changed();
  // The avatars now (a session that just subscribed).
  std::shared_ptr<const AvatarSnapshot> snapshot() const;
  std::size_t size() const;
  // Moves whenever anything changes (the origin publishes when it moved).
  std::uint64_t version() const;

 private:
  std::shared_ptr<const AvatarSnapshot> snapshot_locked() const;
  void set_group_locked(std::uint64_t source, std::vector<AvatarState> avatars);
  void touch() {
    changed_ = true;
    ++version_;
  }

  mutable std::mutex mutex_;
  std::map<std::uint64_t, AvatarState> avatars_;  // this server's sessions'
  std::uint64_t local_version_ = 0;
  // Other servers' avatars: by source, then by the source's id, with the board's own id.
  std::map<std::uint64_t, std::map<std::uint64_t, AvatarState>> groups_;
  std::uint64_t next_group_id_ = kFirstGroupId;
  float height_ = 0.0f, shared_height_ = 0.0f;
  bool changed_ = false;
  std::uint64_t version_ = 0;
};

// Whether `a` may be shown: an id other than 0, an eye within kMaxCoordinate and a finite
// heading. What another server sends is checked with it.
bool valid_avatar(const AvatarState& a);

// The at most `k` avatars of `all` nearest to `eye`, `self` left out, nearest first (equal
// distances: the lower id first).
std::vector<AvatarState> nearest_avatars(const AvatarSnapshot& all, std::uint64_t self,
                                         glm::vec3 eye, std::size_t k);

}  // namespace irradcast

// Presence on a viewer's side (docs/DYNAMIC.md#presence): the other viewers' avatars, which the
// server lists in Avatars messages, drawn as dynamic objects lit by the probe volume. The scene
// gets a fixed number of avatar nodes when it is loaded (dynamic, hidden, the built-in capsule);
// each Avatars message becomes a pose edit of those nodes, and an avatar keeps its node while it
// stays listed (so that the viewer's history sees it move, not jump between nodes).
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

// The avatar's capsule, in units of its height (foot to eye), its eye at the node's origin.
inline constexpr float kAvatarRadius = 0.16f;
inline constexpr float kAvatarTop = 0.08f;  // the capsule's top above the eye
// The avatars' colour (linear), one material for all.
inline constexpr float kAvatarAlbedo[3] = {0.62f, 0.55f, 0.45f};

// Appends `count` avatar nodes to the scene (roots, dynamic, hidden; one capsule mesh and one
// material shared) and, for their objects, empty lightmap layouts to the atlas (they get no
// texels, like every dynamic object). Returns the first node's index. Throws irradcast::Error on
// a count outside 1..256.
int add_avatar_nodes(wire::UnpackedScene& unpacked, int count);

// Which node shows which avatar.
class AvatarNodes {
 public:
  AvatarNodes() = default;
  AvatarNodes(int first_node, int count);

  int count() const { return static_cast<int>(ids_.size()); }
  // The edit that shows the avatars of `m` and hides the nodes of those gone. An avatar whose
  // numbers are not finite, whose eye lies outside `bounds` grown by its largest extent on every
  // side, or that repeats an id, is not shown; past count(), the farthest are left out. Throws
  // irradcast::Error on a height that is not finite and within (0, 100] metres.
  SceneEdit place(const wire::Avatars& m, const Bounds& bounds);
  // The avatars shown after the last place().
  int shown() const;

 private:
  int first_ = -1;
  std::vector<std::uint64_t> ids_;  // per node: the avatar shown (0: none; session ids start at 1)
};

}  // namespace irradcast

// The other viewers' avatars on a viewer (avatars.h).
#include "irradcast/client/avatars.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include <glm/gtc/matrix_transform.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/shapes.h"

namespace irradcast {

int add_avatar_nodes(wire::UnpackedScene& unpacked, int count) {
  if (count < 1 || count > 256)
    throw Error("avatars: " + std::to_string(count) + " nodes (need 1..256)");
  Scene& s = unpacked.scene;
  Material m;
  m.name = "irradcast avatar";
  m.base_color = glm::vec3(kAvatarAlbedo[0], kAvatarAlbedo[1], kAvatarAlbedo[2]);
  s.materials.push_back(m);
  // Foot at -1, top at kAvatarTop: the cylinder between the hemispheres' centres.
  const float length = 1.0f + kAvatarTop - 2.0f * kAvatarRadius;
  Mesh mesh = capsule("irradcast avatar", kAvatarRadius, length, 12, 24,
                      static_cast<std::uint32_t>(s.materials.size() - 1));
  const float centre = 0.5f * (kAvatarTop - 1.0f);
  for (glm::vec3& p : mesh.positions) p.y += centre;
  s.meshes.push_back(std::move(mesh));
  const int first = static_cast<int>(s.nodes.size());
  for (int i = 0; i < count; ++i) {
    Node n;
    n.name = "irradcast avatar " + std::to_string(i);
    n.mesh = static_cast<int>(s.meshes.size() - 1);
    n.visible = false;
    n.dynamic = true;
    s.add_node(std::move(n));
  }
  unpacked.atlas.objects.resize(s.objects().size());  // the new objects: no lightmap
  return first;
}

AvatarNodes::AvatarNodes(int first_node, int count)
    : first_(first_node), ids_(static_cast<std::size_t>(std::max(count, 0)), 0) {}

int AvatarNodes::shown() const {
  return static_cast<int>(std::count_if(ids_.begin(), ids_.end(), [](auto id) { return id != 0; }));
}

SceneEdit AvatarNodes::place(const wire::Avatars& m, const Bounds& bounds) {
  const float height = m.height();
  if (!std::isfinite(height) || !(height > 0.0f) || height > 100.0f)
    throw Error("avatars: a height of " + std::to_string(height) + " m (need (0, 100])");
  const glm::vec3 grow(bounds.empty() ? 0.0f : bounds.max_extent());
  const glm::vec3 lo = bounds.lo - grow, hi = bounds.hi + grow;
  // The avatars to show, in the server's order (nearest first), at most one per node.
  std::vector<const wire::Avatar*> wanted;
  std::set<std::uint64_t> seen;
  for (const wire::Avatar& a : m.avatars()) {
    if (wanted.size() == ids_.size()) break;
    const glm::vec3 e(a.eye().x(), a.eye().y(), a.eye().z());
    const bool inside =
        glm::all(glm::greaterThanEqual(e, lo)) && glm::all(glm::lessThanEqual(e, hi));
    if (a.id() == 0 || !inside || !std::isfinite(a.heading()) || !seen.insert(a.id()).second)
      continue;  // NaN eyes fail `inside`
    wanted.push_back(&a);
  }
  // Those still listed keep their node; the others' nodes are free for the new ones.
  std::vector<std::uint64_t> next(ids_.size(), 0);
  std::vector<const wire::Avatar*> at(ids_.size(), nullptr);
  std::vector<const wire::Avatar*> fresh;
  for (const wire::Avatar* a : wanted) {
    const auto it = std::find(ids_.begin(), ids_.end(), a->id());
    if (it == ids_.end()) {
      fresh.push_back(a);
      continue;
    }
    const auto i = static_cast<std::size_t>(it - ids_.begin());
    next[i] = a->id();
    at[i] = a;
  }
  std::size_t free_node = 0;
  for (const wire::Avatar* a : fresh) {
    while (next[free_node] != 0) ++free_node;
    next[free_node] = a->id();
    at[free_node] = a;
  }
  SceneEdit edit;
  for (std::size_t i = 0; i < ids_.size(); ++i) {
    EditOp op;
    op.target = "#" + std::to_string(first_ + static_cast<int>(i));
    if (at[i]) {
      const wire::Avatar& a = *at[i];
      op.kind = EditOp::Kind::SetTransform;
      op.matrix =
          glm::translate(glm::mat4(1.0f), glm::vec3(a.eye().x(), a.eye().y(), a.eye().z())) *
          glm::rotate(glm::mat4(1.0f), a.heading(), glm::vec3(0.0f, 1.0f, 0.0f)) *
          glm::scale(glm::mat4(1.0f), glm::vec3(height));
      edit.ops.push_back(op);
    }
    if ((at[i] != nullptr) != (ids_[i] != 0)) {  // shown now and not before, or the reverse
      op.kind = at[i] ? EditOp::Kind::Show : EditOp::Kind::Hide;
      edit.ops.push_back(op);
    }
  }
  ids_ = std::move(next);
  return edit;
}

}  // namespace irradcast

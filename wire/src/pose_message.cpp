#include "irradcast/wire/pose_message.h"

#include <cmath>
#include <string>
#include <vector>

#include "irradcast/common/error.h"

namespace irradcast::wire {

NodePose node_pose_to_proto(std::uint32_t node, const glm::mat4& local, bool visible) {
  NodePose p;
  p.set_node(node);
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) p.add_matrix(local[c][r]);
  p.set_hidden(!visible);
  return p;
}

irradcast::SceneEdit pose_edit(const Poses& m, const Scene& scene,
                               const std::vector<bool>& posable) {
  if (m.poses_size() > kMaxWirePoses)
    throw irradcast::Error("poses: " + std::to_string(m.poses_size()) +
                           " poses in one message (at most " + std::to_string(kMaxWirePoses) + ")");
  irradcast::SceneEdit edit;
  edit.ops.reserve(2 * static_cast<std::size_t>(m.poses_size()));
  for (int i = 0; i < m.poses_size(); ++i) {
    const NodePose& p = m.poses(i);
    const std::string where = "poses: pose " + std::to_string(i + 1);
    if (p.node() >= scene.nodes.size())
      throw irradcast::Error(where + " names node " + std::to_string(p.node()) + " of a scene of " +
                             std::to_string(scene.nodes.size()) + " nodes");
    if (p.matrix_size() != 16)
      throw irradcast::Error(where + " has " + std::to_string(p.matrix_size()) +
                             " matrix values (16 expected)");
    if (p.node() >= posable.size() || !posable[p.node()])
      throw irradcast::Error(where + " moves node '" + scene.nodes[p.node()].name +
                             "', which is not dynamic (a pose moves dynamic nodes only)");
    irradcast::EditOp op;
    op.kind = irradcast::EditOp::Kind::SetTransform;
    op.target = "#" + std::to_string(p.node());
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) {
        op.matrix[c][r] = p.matrix(4 * c + r);
        if (!std::isfinite(op.matrix[c][r]))
          throw irradcast::Error(where + " has a matrix value that is not finite");
      }
    edit.ops.push_back(op);
    op.kind = p.hidden() ? irradcast::EditOp::Kind::Hide : irradcast::EditOp::Kind::Show;
    op.matrix = glm::mat4(1.0f);
    edit.ops.push_back(op);
  }
  return edit;
}

}  // namespace irradcast::wire

// Poses on the wire (docs/DYNAMIC.md#poses): a dynamic node's local transform and visibility as
// NodePose, and the Poses a client receives turned into the absolute edit ops it applies to its
// copy of the scene.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast.pb.h"
#include "irradcast/common/scene_edit.h"

namespace irradcast::wire {

// The most poses one Poses message may hold (a client refuses more).
inline constexpr int kMaxWirePoses = 1 << 16;

NodePose node_pose_to_proto(std::uint32_t node, const glm::mat4& local, bool visible);

// The absolute edit that gives each node of `m` its pose in `scene`: a transform op and a show
// or hide op per node, targets by index ("#3"). Throws irradcast::Error with a clear message on a
// node index out of range or a node that is not a pose node of `scene` (is_pose_op), a matrix
// that is not 16 finite numbers, or more than kMaxWirePoses poses. The rest is checked when the
// edit is applied (apply_edit: affine, invertible, within bounds).
// `posable`: pose_nodes(scene), which its holder computes once.
irradcast::SceneEdit pose_edit(const Poses& m, const Scene& scene,
                               const std::vector<bool>& posable);

}  // namespace irradcast::wire

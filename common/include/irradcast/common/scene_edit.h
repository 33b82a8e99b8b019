// Live scene edits (docs/EDITS.md): a list of operations applied to a Scene together. The
// server validates an edit against its scene, applies it between engine updates and sends it to
// every viewer, which applies the same edit to its own copy (so its primary rays see the moved
// geometry). An edit that names an unknown target or carries a non-finite number is refused as a
// whole: the scene does not change.
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/scene.h"

namespace irradcast {

struct EditOp {
  enum class Kind {
    Move,              // node: translate by `vector` (in the parent's frame)
    Rotate,            // node: rotate by `value` degrees about axis `vector` through its origin
    Scale,             // node: scale by `vector` about its origin (in its own frame)
    SetTransform,      // node: local transform = `matrix`
    Show,              // node (and its subtree): visible
    Hide,              // node (and its subtree): hidden
    LightColor,        // punctual light: colour = `vector` (linear RGB)
    LightIntensity,    // punctual light: intensity = `value`
    MaterialAlbedo,    // material: base colour factor = `vector`
    MaterialEmission,  // material: emissive factor = `vector`, emissive strength = `value`
    Sky,               // the sky: the parts `sky_parts` names (colour, strength, map file)
  };
  // The parts of the sky a Sky op sets.
  enum SkyPart : unsigned {
    kSkyColor = 1,     // constant radiance = `vector` (drops the map)
    kSkyStrength = 2,  // strength = `value`
    kSkyFile = 4,      // map = `sky_map`, read from the file `target` (in the server's sky folder)
  };
  Kind kind = Kind::Move;
  // A node, light or material, by name, or by index as "#3".
  std::string target;
  glm::vec3 vector{0.0f};
  float value = 0.0f;
  glm::mat4 matrix{1.0f};
  unsigned sky_parts = 0;  // Sky: SkyPart bits
  // Sky with kSkyFile: the map. Only a server reads the file (from its --sky-dir, before it
  // accepts the edit); viewers get the map with the edit (wire: at most 1024 x 512).
  std::shared_ptr<const ImageRGB> sky_map;
};

struct SceneEdit {
  std::vector<EditOp> ops;
};

// What an applied edit changed, for the engine's invalidation.
struct EditEffect {
  std::vector<int> nodes;      // nodes whose local transform or visibility changed
  std::vector<int> lights;     // punctual lights whose colour or intensity changed
  std::vector<int> materials;  // materials whose albedo or emission changed
  bool sky = false;            // the sky changed (it lights everything that sees out)
  bool empty() const { return nodes.empty() && lights.empty() && materials.empty() && !sky; }
};

// The lowercase names used on the command line and in JSON ("move", "rotate", "scale",
// "transform", "show", "hide", "light_color", "light_intensity", "albedo", "emission", "sky").
const char* edit_kind_name(EditOp::Kind kind);
// Throws irradcast::Error naming the valid kinds.
EditOp::Kind parse_edit_kind(std::string_view name);
// What an op of this kind names as its target, also its target's JSON key: "node", "light",
// "material" or "sky".
const char* edit_target_name(EditOp::Kind kind);

// Throws irradcast::Error with a message that names the operation (by position and kind) and
// what is wrong: an empty edit, an unknown target, a non-finite number, a zero rotation axis or
// scale factor, a matrix that is not affine or not invertible, a negative intensity or colour, a
// sky op with no part or with both a colour and a file, or a file whose map was not loaded.
// The transforms the edit leads to are checked too, ops composed in order: each node's local
// transform within +-1e9 after every op, and (a parent's scale multiplying its children's) the
// world transforms below a moved node finite, their objects' vertices within +-1e18 in world
// space and their triangle areas finite.
void validate_edit(const Scene& scene, const SceneEdit& edit);
// The checks of validate_edit that look at each op on its own (targets, numbers, matrices, sky
// parts), not the transforms they lead to: `scene` needs its nodes, lights and materials only.
// The edit journal checks a snapshot with it before it writes it.
void validate_edit_ops(const Scene& scene, const SceneEdit& edit);
// Whether the edit can change the static scene (what the engine lights): false only when every
// op moves, shows or hides a node whose subtree holds no static mesh or light (a dynamic node,
// or a rig of dynamic children; Node::dynamic, docs/DYNAMIC.md), which costs the engine nothing.
// Ops whose target does not resolve count as static. A light, material or sky op always does
// (even on a material only dynamic objects use).
bool edit_changes_static_scene(const Scene& scene, const SceneEdit& edit);
// A node's pose: its local transform and whether it is visible (docs/DYNAMIC.md#poses).
struct NodePoseState {
  glm::mat4 local{1.0f};
  bool visible = true;
};

// A pose op (docs/DYNAMIC.md#moving-them-poses): one that moves, shows or hides a node whose
// subtree holds no static mesh or light (a dynamic node, or a rig of them). A server keeps such
// ops out of the revisioned edits: they go to the viewers as the node's new pose.
// Per node: whether a pose op may move it, in one pass over the hierarchy (a node no root reaches
// counts as static). Edits never change it (they move and hide nodes, not reparent them), so a
// holder of a scene computes it once.
std::vector<bool> pose_nodes(const Scene& scene);
// The node a pose op moves (-1: not a pose op); `posable` is pose_nodes(scene).
int pose_node(const Scene& scene, const std::vector<bool>& posable, const EditOp& op);
bool is_pose_op(const Scene& scene, const EditOp& op);
// The edit's pose ops and its other ops, each in the edit's order. The two parts are
// independent: a pose op changes a node no other op of the edit can see through.
std::pair<SceneEdit, SceneEdit> split_poses(const Scene& scene, const std::vector<bool>& posable,
                                            const SceneEdit& edit);
// Validates, then applies every operation in order. On an invalid edit it throws and the scene
// is unchanged.
EditEffect apply_edit(Scene& scene, const SceneEdit& edit);

// The edit that takes a scene in the state of `from` to the state of `to`: absolute operations
// (transform, show or hide, light colour and intensity, albedo, emission, sky) for every node,
// light and material whose editable state differs, targets by index ("#3"), the sky last. Both
// must be the same scene (the same counts of nodes, lights and materials: throws
// irradcast::Error otherwise); only the editable state is read, so `from` may lack meshes and
// textures. Empty when nothing differs. The edit journal's snapshot (docs/EDITS.md).
SceneEdit state_edit(const Scene& from, const Scene& to);

// The JSON form (docs/EDITS.md): an object {"ops": [op, ...]} or a single op object, where an op
// is {"op": "move", "node": "tall_block", "by": [x, y, z]} and so on; a sky op has no target:
// {"op": "sky", "color": [r, g, b]}, {"op": "sky", "file": "dusk.exr", "strength": 2}, any of
// "color" or "file" (not both) and "strength". Throws irradcast::Error
// on bad JSON or a bad op (with the op's position).
SceneEdit parse_edit_json(std::string_view text);
std::string edit_to_json(const SceneEdit& edit);
// A script: a JSON array of steps, each an edit with an optional "after_ms" delay before it is
// sent, or one edit. Used by irradcast-edit --script and the edit benchmark.
struct EditStep {
  double after_ms = 0.0;
  SceneEdit edit;
};
std::vector<EditStep> parse_edit_script(std::string_view text);

}  // namespace irradcast

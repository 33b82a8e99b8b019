#include "irradcast/common/scene_edit.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <map>
#include <utility>

#include <glm/gtc/matrix_transform.hpp>

#include "irradcast/common/error.h"

namespace irradcast {
namespace {

using Kind = EditOp::Kind;

struct KindName {
  Kind kind;
  const char* name;
};
constexpr KindName kKinds[] = {
    {Kind::Move, "move"},
    {Kind::Rotate, "rotate"},
    {Kind::Scale, "scale"},
    {Kind::SetTransform, "transform"},
    {Kind::Show, "show"},
    {Kind::Hide, "hide"},
    {Kind::LightColor, "light_color"},
    {Kind::LightIntensity, "light_intensity"},
    {Kind::MaterialAlbedo, "albedo"},
    {Kind::MaterialEmission, "emission"},
    {Kind::Sky, "sky"},
};

enum class Target { Node, Light, Material, Sky };

Target target_of(Kind k) {
  switch (k) {
    case Kind::LightColor:
    case Kind::LightIntensity:
      return Target::Light;
    case Kind::MaterialAlbedo:
    case Kind::MaterialEmission:
      return Target::Material;
    case Kind::Sky:
      return Target::Sky;
    default:
      return Target::Node;
  }
}

const char* target_name(Target t) {
  return t == Target::Node    ? "node"
         : t == Target::Light ? "light"
         : t == Target::Sky   ? "sky"
                              : "material";
}

// Index of the named item, or of "#N"; -1 if none.
template <typename T>
int find(const std::vector<T>& items, const std::string& target) {
  if (target.size() > 1 && target[0] == '#') {
    const std::string digits = target.substr(1);
    if (!std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; }) ||
        digits.size() > 9)
      return -1;
    const long i = std::strtol(digits.c_str(), nullptr, 10);
    return i < static_cast<long>(items.size()) ? static_cast<int>(i) : -1;
  }
  for (std::size_t i = 0; i < items.size(); ++i)
    if (items[i].name == target) return static_cast<int>(i);
  return -1;
}

bool finite(glm::vec3 v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// The op's node, light or material (0 for the sky, the scene's only one).
int resolve(const Scene& scene, const EditOp& op, const std::string& where) {
  const Target t = target_of(op.kind);
  if (t == Target::Sky) return 0;
  if (op.target.empty()) throw Error(where + ": no " + target_name(t) + " named");
  const int i = t == Target::Node    ? find(scene.nodes, op.target)
                : t == Target::Light ? find(scene.lights, op.target)
                                     : find(scene.materials, op.target);
  if (i < 0) {
    const std::size_t count = t == Target::Node    ? scene.nodes.size()
                              : t == Target::Light ? scene.lights.size()
                                                   : scene.materials.size();
    throw Error(where + ": the scene has no " + target_name(t) + " '" + op.target + "' (it has " +
                std::to_string(count) + " " + target_name(t) + "s; name one or give #index)");
  }
  return i;
}

// A Sky op's parts (its numbers are finite and within +-1e6 already).
void check_sky_op(const EditOp& op, const std::string& where) {
  constexpr unsigned kAll = EditOp::kSkyColor | EditOp::kSkyStrength | EditOp::kSkyFile;
  const unsigned parts = op.sky_parts;
  if (parts == 0 || (parts & ~kAll) != 0)
    throw Error(where + ": set the sky's colour, strength or file (parts " + std::to_string(parts) +
                ")");
  if ((parts & EditOp::kSkyColor) && (parts & EditOp::kSkyFile))
    throw Error(where + ": a sky colour and a sky file together (a colour replaces the map)");
  if ((parts & EditOp::kSkyColor) && glm::any(glm::lessThan(op.vector, glm::vec3(0.0f))))
    throw Error(where + ": a sky colour component is negative");
  if ((parts & EditOp::kSkyStrength) && op.value < 0.0f)
    throw Error(where + ": the sky strength is negative");
  if (!(parts & EditOp::kSkyFile)) return;
  if (op.target.empty()) throw Error(where + ": no sky file named");
  if (!op.sky_map)
    throw Error(where + ": the sky file '" + op.target +
                "' was not read (a server reads sky files from its --sky-dir)");
  Sky probe;  // the map's checks: size, finite and non-negative texels
  probe.map = *op.sky_map;
  validate_sky(probe, where + " (sky file '" + op.target + "')");
  if (probe.map.pixels.empty()) throw Error(where + ": the sky file '" + op.target + "' is empty");
}

void check_op(const Scene& scene, const EditOp& op, const std::string& where) {
  resolve(scene, op, where);
  if (!finite(op.vector) || !std::isfinite(op.value))
    throw Error(where + ": a number is not finite (NaN or infinity)");
  // Bounds that keep every coordinate finite however many edits follow one another.
  constexpr float kLimit = 1e6f;
  if (glm::any(glm::greaterThan(glm::abs(op.vector), glm::vec3(kLimit))) ||
      std::abs(op.value) > kLimit)
    throw Error(where + ": a number is beyond +-1e6");
  if (op.kind == Kind::Scale && glm::any(glm::lessThan(glm::abs(op.vector), glm::vec3(1e-3f))))
    throw Error(where + ": a scale factor below 1e-3 in magnitude; use hide instead");
  switch (op.kind) {
    case Kind::Rotate:
      if (!(glm::length(op.vector) > 0.0f))
        throw Error(where + ": the rotation axis is zero (give a direction and degrees)");
      break;
    case Kind::Scale:
      if (op.vector.x == 0.0f || op.vector.y == 0.0f || op.vector.z == 0.0f)
        throw Error(where + ": a scale factor of 0 flattens the object; use hide instead");
      break;
    case Kind::SetTransform: {
      for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
          if (!std::isfinite(op.matrix[c][r]))
            throw Error(where + ": the matrix has a non-finite entry (NaN or infinity)");
      if (op.matrix[0][3] != 0.0f || op.matrix[1][3] != 0.0f || op.matrix[2][3] != 0.0f ||
          op.matrix[3][3] != 1.0f)
        throw Error(where + ": the matrix is not affine (its last row must be 0 0 0 1)");
      if (!(std::abs(glm::determinant(glm::mat3(op.matrix))) > 1e-12f))
        throw Error(where + ": the matrix is not invertible");
      break;
    }
    case Kind::LightColor:
    case Kind::MaterialAlbedo:
      if (glm::any(glm::lessThan(op.vector, glm::vec3(0.0f))))
        throw Error(where + ": a colour component is negative");
      break;
    case Kind::LightIntensity:
      if (op.value < 0.0f) throw Error(where + ": the intensity is negative");
      break;
    case Kind::MaterialEmission:
      if (glm::any(glm::lessThan(op.vector, glm::vec3(0.0f))) || op.value < 0.0f)
        throw Error(where + ": the emission colour or strength is negative");
      break;
    case Kind::Sky:
      check_sky_op(op, where);
      break;
    default:
      break;
  }
}

bool changes_transform(Kind k) {
  return k == Kind::Move || k == Kind::Rotate || k == Kind::Scale || k == Kind::SetTransform;
}

// A node's local transform after a Move, Rotate, Scale or SetTransform op (validated).
glm::mat4 transformed(const glm::mat4& local, const EditOp& op) {
  switch (op.kind) {
    case Kind::Move:
      return glm::translate(glm::mat4(1.0f), op.vector) * local;
    case Kind::Rotate: {
      const glm::vec3 origin(local[3]);
      const glm::mat4 r =
          glm::rotate(glm::mat4(1.0f), glm::radians(op.value), glm::normalize(op.vector));
      return glm::translate(glm::mat4(1.0f), origin) * r *
             glm::translate(glm::mat4(1.0f), -origin) * local;
    }
    case Kind::Scale:
      return local * glm::scale(glm::mat4(1.0f), op.vector);
    case Kind::SetTransform:
      return op.matrix;
    default:
      return local;
  }
}

// Bounds that keep every coordinate finite however many edits follow one another.
constexpr float kMaxTransformEntry = 1e9f;

bool within(const glm::mat4& m, float limit) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      if (!(std::abs(m[c][r]) < limit)) return false;  // NaN fails too
  return true;
}

// The world-space result of the new local transforms: every node under a moved one keeps a
// finite world transform, and every triangle of the objects there keeps corners within
// +-kMaxCoordinate and a finite area (a parent's scale multiplies its children's).
void check_world(const Scene& scene, const std::map<int, glm::mat4>& locals) {
  const std::size_t count = scene.nodes.size();
  auto local = [&](std::size_t n) -> const glm::mat4& {
    auto it = locals.find(static_cast<int>(n));
    return it == locals.end() ? scene.nodes[n].local : it->second;
  };
  // World transforms from the roots (iteratively, as Scene::world_matrices); `moved`: the node
  // or one of its ancestors has a new local transform.
  std::vector<glm::mat4> world(count, glm::mat4(1.0f));
  std::vector<std::uint8_t> moved(count, 0), done(count, 0);
  std::vector<std::pair<int, int>> stack;  // (node, parent or -1)
  for (int r : scene.roots) stack.emplace_back(r, -1);
  while (!stack.empty()) {
    const auto [n, parent] = stack.back();
    stack.pop_back();
    const std::size_t i = static_cast<std::size_t>(n);
    if (i >= count || done[i]) continue;
    done[i] = 1;
    const std::size_t p = static_cast<std::size_t>(parent);
    world[i] = parent < 0 ? local(i) : world[p] * local(i);
    moved[i] = (parent >= 0 && moved[p]) || locals.count(n) > 0;
    for (int c : scene.nodes[i].children) stack.emplace_back(c, n);
  }
  for (std::size_t n = 0; n < count; ++n) {
    if (!moved[n]) continue;
    std::string name = scene.nodes[n].name.substr(0, 60);
    for (char& c : name)
      if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
    const std::string what = "node " + std::to_string(n) + (name.empty() ? "" : " '" + name + "'");
    if (!within(world[n], std::numeric_limits<float>::infinity()))
      throw Error("scene edit: " + what + " would get a world transform that is not finite");
    const int m = scene.nodes[n].mesh;
    if (m < 0 || static_cast<std::size_t>(m) >= scene.meshes.size()) continue;
    const Mesh& mesh = scene.meshes[static_cast<std::size_t>(m)];
    std::vector<glm::vec3> p(mesh.positions.size());
    for (std::size_t v = 0; v < p.size(); ++v) {
      p[v] = glm::vec3(world[n] * glm::vec4(mesh.positions[v], 1.0f));
      if (!(glm::all(glm::lessThanEqual(glm::abs(p[v]), glm::vec3(kMaxCoordinate)))))
        throw Error("scene edit: " + what +
                    " would place a vertex beyond +-1e18 or at infinity in world space");
    }
    for (const glm::uvec3& t : mesh.triangles) {
      if (t.x >= p.size() || t.y >= p.size() || t.z >= p.size()) continue;
      const float area = 0.5f * glm::length(glm::cross(p[t.y] - p[t.x], p[t.z] - p[t.x]));
      if (!std::isfinite(area))
        throw Error("scene edit: " + what + " would give a triangle an infinite area");
    }
  }
}

void add_unique(std::vector<int>& v, int i) {
  if (std::find(v.begin(), v.end(), i) == v.end()) v.push_back(i);
}

}  // namespace

const char* edit_kind_name(EditOp::Kind kind) {
  for (const KindName& k : kKinds)
    if (k.kind == kind) return k.name;
  return "?";
}

EditOp::Kind parse_edit_kind(std::string_view name) {
  for (const KindName& k : kKinds)
    if (name == k.name) return k.kind;
  std::string all;
  for (const KindName& k : kKinds) all += std::string(all.empty() ? "" : ", ") + k.name;
  throw Error("unknown edit operation '" + std::string(name) + "' (expected one of " + all + ")");
}

const char* edit_target_name(EditOp::Kind kind) {
  return target_name(target_of(kind));
}

void validate_edit_ops(const Scene& scene, const SceneEdit& edit) {
  for (std::size_t i = 0; i < edit.ops.size(); ++i)
    check_op(scene, edit.ops[i],
             "edit op " + std::to_string(i + 1) + " (" + edit_kind_name(edit.ops[i].kind) + ")");
}

std::vector<bool> pose_nodes(const Scene& scene) {
  // One pass: each node's own static content, then children's folded into parents, deepest
  // first (breadth-first order from the parentless nodes, reversed). A node no root reaches
  // (a cycle) counts as static.
  const std::vector<bool> dynamic = scene.dynamic_nodes();
  const std::size_t n = scene.nodes.size();
  std::vector<bool> holds(n, false), reached(n, false);
  std::vector<int> order;
  order.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Node& node = scene.nodes[i];
    holds[i] = !dynamic[i] && (node.mesh >= 0 || node.light >= 0);
    if (node.parent < 0) {
      reached[i] = true;
      order.push_back(static_cast<int>(i));
    }
  }
  for (std::size_t k = 0; k < order.size(); ++k)
    for (int c : scene.nodes[static_cast<std::size_t>(order[k])].children)
      if (c >= 0 && static_cast<std::size_t>(c) < n && !reached[static_cast<std::size_t>(c)]) {
        reached[static_cast<std::size_t>(c)] = true;
        order.push_back(c);
      }
  for (auto it = order.rbegin(); it != order.rend(); ++it) {
    const auto i = static_cast<std::size_t>(*it);
    const int parent = scene.nodes[i].parent;
    if (holds[i] && parent >= 0 && static_cast<std::size_t>(parent) < n)
      holds[static_cast<std::size_t>(parent)] = true;
  }
  std::vector<bool> out(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = reached[i] && !holds[i];
  return out;
}

int pose_node(const Scene& scene, const std::vector<bool>& posable, const EditOp& op) {
  if (target_of(op.kind) != Target::Node) return -1;
  const int n = find(scene.nodes, op.target);
  return n >= 0 && static_cast<std::size_t>(n) < posable.size() && posable[n] ? n : -1;
}

bool edit_changes_static_scene(const Scene& scene, const SceneEdit& edit) {
  const std::vector<bool> posable = pose_nodes(scene);
  for (const EditOp& op : edit.ops)
    if (pose_node(scene, posable, op) < 0) return true;
  return false;
}

bool is_pose_op(const Scene& scene, const EditOp& op) {
  return pose_node(scene, pose_nodes(scene), op) >= 0;
}

std::pair<SceneEdit, SceneEdit> split_poses(const Scene& scene, const std::vector<bool>& posable,
                                            const SceneEdit& edit) {
  std::pair<SceneEdit, SceneEdit> parts;
  for (const EditOp& op : edit.ops)
    (pose_node(scene, posable, op) >= 0 ? parts.first : parts.second).ops.push_back(op);
  return parts;
}

void validate_edit(const Scene& scene, const SceneEdit& edit) {
  if (edit.ops.empty()) throw Error("scene edit: no operations");
  // Each op on its own, then the transforms it leads to: the ops of an edit compose (13 scales
  // by 1000 of one node, each fine alone, reach infinity together), so each node's transform is
  // followed through the edit and checked after every op, then the world-space result.
  std::map<int, glm::mat4> locals;  // nodes whose local transform the edit changes: the result
  for (std::size_t i = 0; i < edit.ops.size(); ++i) {
    const EditOp& op = edit.ops[i];
    const std::string where =
        "edit op " + std::to_string(i + 1) + " (" + edit_kind_name(op.kind) + ")";
    check_op(scene, op, where);
    if (!changes_transform(op.kind)) continue;
    const int n = resolve(scene, op, where);
    auto it = locals.find(n);
    const glm::mat4 next = transformed(
        it == locals.end() ? scene.nodes[static_cast<std::size_t>(n)].local : it->second, op);
    if (!within(next, kMaxTransformEntry))
      throw Error(where + ": the node's transform would leave +-1e9");
    locals[n] = next;
  }
  if (!locals.empty()) check_world(scene, locals);
}

namespace {

void apply_sky(Sky& sky, const EditOp& op) {
  if (op.sky_parts & EditOp::kSkyColor) {
    sky.color = op.vector;
    sky.map = ImageRGB{};
    sky.source.clear();
  }
  if (op.sky_parts & EditOp::kSkyFile) {
    sky.map = *op.sky_map;
    sky.source = op.target;
  }
  if (op.sky_parts & EditOp::kSkyStrength) sky.strength = op.value;
}

// Applies one op to its resolved target i and returns the effect list that records it.
std::vector<int>& apply_op(Scene& scene, const EditOp& op, int i, EditEffect& effect) {
  switch (op.kind) {
    case Kind::Move:
    case Kind::Rotate:
    case Kind::Scale:
    case Kind::SetTransform:
      scene.nodes[i].local = transformed(scene.nodes[i].local, op);
      return effect.nodes;
    case Kind::Show:
    case Kind::Hide:
      scene.nodes[i].visible = op.kind == Kind::Show;
      return effect.nodes;
    case Kind::LightColor:
      scene.lights[i].color = op.vector;
      return effect.lights;
    case Kind::LightIntensity:
      scene.lights[i].intensity = op.value;
      return effect.lights;
    case Kind::MaterialAlbedo:
      scene.materials[i].base_color = op.vector;
      return effect.materials;
    case Kind::MaterialEmission:
      scene.materials[i].emissive = op.vector;
      scene.materials[i].emissive_strength = op.value;
      return effect.materials;
    case Kind::Sky:
      break;  // apply_edit applies it
  }
  throw Error("edit: unknown op kind");
}

}  // namespace

EditEffect apply_edit(Scene& scene, const SceneEdit& edit) {
  validate_edit(scene, edit);
  EditEffect effect;
  for (const EditOp& op : edit.ops) {
    if (op.kind == Kind::Sky) {
      apply_sky(scene.sky, op);
      effect.sky = true;
      continue;
    }
    const int i = resolve(scene, op, "");
    add_unique(apply_op(scene, op, i, effect), i);
  }
  return effect;
}

SceneEdit state_edit(const Scene& from, const Scene& to) {
  if (from.nodes.size() != to.nodes.size() || from.lights.size() != to.lights.size() ||
      from.materials.size() != to.materials.size())
    throw Error("state edit: the two scenes differ in their nodes, lights or materials");
  SceneEdit edit;
  auto add = [&edit](Kind kind, std::size_t i) -> EditOp& {
    EditOp& op = edit.ops.emplace_back();
    op.kind = kind;
    op.target = "#" + std::to_string(i);
    return op;
  };
  for (std::size_t i = 0; i < to.nodes.size(); ++i) {
    const Node& a = from.nodes[i];
    const Node& b = to.nodes[i];
    if (a.local != b.local) add(Kind::SetTransform, i).matrix = b.local;
    if (a.visible != b.visible) add(b.visible ? Kind::Show : Kind::Hide, i);
  }
  for (std::size_t i = 0; i < to.lights.size(); ++i) {
    const Light& a = from.lights[i];
    const Light& b = to.lights[i];
    if (a.color != b.color) add(Kind::LightColor, i).vector = b.color;
    if (a.intensity != b.intensity) add(Kind::LightIntensity, i).value = b.intensity;
  }
  for (std::size_t i = 0; i < to.materials.size(); ++i) {
    const Material& a = from.materials[i];
    const Material& b = to.materials[i];
    if (a.base_color != b.base_color) add(Kind::MaterialAlbedo, i).vector = b.base_color;
    if (a.emissive != b.emissive || a.emissive_strength != b.emissive_strength) {
      EditOp& op = add(Kind::MaterialEmission, i);
      op.vector = b.emissive;
      op.value = b.emissive_strength;
    }
  }
  const Sky& a = from.sky;
  const Sky& b = to.sky;
  const bool same_map = a.map.width == b.map.width && a.map.height == b.map.height &&
                        a.map.pixels == b.map.pixels && a.source == b.source;
  if (a.color != b.color || a.strength != b.strength || !same_map) {
    EditOp op;
    op.kind = Kind::Sky;
    op.value = b.strength;
    op.sky_parts = EditOp::kSkyStrength;
    if (b.map.width > 0) {
      op.sky_parts |= EditOp::kSkyFile;
      op.target = b.source.empty() ? "sky map" : b.source;  // a file op names its map
      op.sky_map = std::make_shared<const ImageRGB>(b.map);
    } else {
      op.sky_parts |= EditOp::kSkyColor;
      op.vector = b.color;
    }
    edit.ops.push_back(std::move(op));
  }
  return edit;
}

}  // namespace irradcast

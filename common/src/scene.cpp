#include "irradcast/common/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <type_traits>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"

namespace irradcast {
namespace {

bool usable_point(glm::vec3 p) {
  return std::abs(p.x) <= kMaxCoordinate && std::abs(p.y) <= kMaxCoordinate &&
         std::abs(p.z) <= kMaxCoordinate;  // false for NaN too
}

// A name from the scene for a one-line message: control characters replaced, length capped.
std::string printable(const std::string& name) {
  std::string out = name.substr(0, 40);
  for (char& c : out)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}

bool finite_matrix(const glm::mat4& m) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      if (!std::isfinite(m[c][r])) return false;
  return usable_point(glm::vec3(m[3]));
}

}  // namespace

const std::array<float, 256>& srgb_to_linear_table() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      float c = static_cast<float>(i) / 255.0f;
      t[i] = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
    return t;
  }();
  return table;
}

bool usable_triangle(glm::vec3 a, glm::vec3 b, glm::vec3 c) {
  if (!usable_point(a) || !usable_point(b) || !usable_point(c)) return false;
  const float area = 0.5f * glm::length(glm::cross(b - a, c - a));
  return area > 0.0f && std::isfinite(area);
}

glm::vec4 Texture::sample_srgb(glm::vec2 uv) const {
  if (width <= 0 || height <= 0) return glm::vec4(1.0f);
  const auto& lut = srgb_to_linear_table();
  float x = uv.x * static_cast<float>(width) - 0.5f;
  float y = uv.y * static_cast<float>(height) - 0.5f;
  float fx = std::floor(x), fy = std::floor(y);
  float ax = x - fx, ay = y - fy;
  // Wrapped once per axis; the next texel wraps to 0 past the edge (two divisions, not eight).
  auto wrap = [](long i, int n) { return static_cast<int>(((i % n) + n) % n); };
  const int x0 = wrap(static_cast<long>(fx), width), y0 = wrap(static_cast<long>(fy), height);
  const int x1 = x0 + 1 == width ? 0 : x0 + 1, y1 = y0 + 1 == height ? 0 : y0 + 1;
  auto fetch = [&](int i, int j) {
    const std::uint8_t* p = &rgba8[4 * (static_cast<std::size_t>(j) * width + i)];
    return glm::vec4(lut[p[0]], lut[p[1]], lut[p[2]], static_cast<float>(p[3]) / 255.0f);
  };
  glm::vec4 a = glm::mix(fetch(x0, y0), fetch(x1, y0), ax);
  glm::vec4 b = glm::mix(fetch(x0, y1), fetch(x1, y1), ax);
  return glm::mix(a, b, ay);
}

int Scene::add_node(Node node) {
  int index = static_cast<int>(nodes.size());
  int parent = node.parent;
  nodes.push_back(std::move(node));
  if (parent >= 0)
    nodes[parent].children.push_back(index);
  else
    roots.push_back(index);
  return index;
}

std::vector<glm::mat4> Scene::world_matrices() const {
  std::vector<glm::mat4> world(nodes.size(), glm::mat4(1.0f));
  std::vector<bool> done(nodes.size(), false);
  // Depth-first from the roots; a node not reachable from a root keeps its parent chain product.
  std::vector<std::pair<int, glm::mat4>> stack;
  for (int r : roots) stack.emplace_back(r, glm::mat4(1.0f));
  while (!stack.empty()) {
    auto [n, parent] = stack.back();
    stack.pop_back();
    if (done[n]) continue;  // guards against cycles in malformed hierarchies
    done[n] = true;
    world[n] = parent * nodes[n].local;
    for (int c : nodes[n].children) stack.emplace_back(c, world[n]);
  }
  return world;
}

namespace {

// A per-node flag handed down from the roots: flag(parent's value, node) for each node reached
// (false for nodes no root reaches; cycles are cut).
template <class Flag>
std::vector<bool> inherited(const Scene& s, bool root_value, Flag flag) {
  std::vector<bool> value(s.nodes.size(), false);
  std::vector<bool> done(s.nodes.size(), false);
  std::vector<std::pair<int, bool>> stack;
  for (int r : s.roots) stack.emplace_back(r, root_value);
  while (!stack.empty()) {
    auto [n, parent] = stack.back();
    stack.pop_back();
    if (done[n]) continue;
    done[n] = true;
    value[n] = flag(parent, s.nodes[n]);
    for (int c : s.nodes[n].children) stack.emplace_back(c, value[n]);
  }
  return value;
}

}  // namespace

std::vector<bool> Scene::visible_nodes() const {
  return inherited(*this, true, [](bool parent, const Node& n) { return parent && n.visible; });
}

std::vector<bool> Scene::dynamic_nodes() const {
  return inherited(*this, false, [](bool parent, const Node& n) { return parent || n.dynamic; });
}

std::vector<Object> Scene::objects() const {
  std::vector<Object> out;
  // Only nodes reachable from the roots are part of the scene.
  std::vector<bool> reachable(nodes.size(), false);
  std::vector<int> stack(roots.begin(), roots.end());
  while (!stack.empty()) {
    int n = stack.back();
    stack.pop_back();
    if (reachable[n]) continue;
    reachable[n] = true;
    for (int c : nodes[n].children) stack.push_back(c);
  }
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i) {
    if (!reachable[i] || nodes[i].mesh < 0) continue;
    const Node& node = nodes[i];
    std::string name = node.name.empty() ? meshes[node.mesh].name : node.name;
    if (name.empty()) name = "object" + std::to_string(out.size());
    out.push_back(Object{name, i, node.mesh});
  }
  return out;
}

int Scene::first_camera_node() const {
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i)
    if (nodes[i].camera >= 0) return i;
  return -1;
}

std::size_t Scene::triangle_count() const {
  std::size_t n = 0;
  for (const Object& o : objects()) n += meshes[o.mesh].triangle_count();
  return n;
}

namespace {

// Which of the mesh's triangles are usable (indices in range, usable_triangle()) in the mesh and
// wherever a node in `placed` puts it. Sets *bad_vertex if some vertex is not a usable point.
std::vector<bool> usable_triangles(const Mesh& mesh, const std::vector<int>& placed,
                                   const std::vector<glm::mat4>& world, bool* bad_vertex) {
  const std::size_t nv = mesh.positions.size(), nt = mesh.triangles.size();
  std::vector<bool> keep(nt, true);
  auto check = [&](const std::vector<glm::vec3>& p) {
    for (const glm::vec3& v : p) *bad_vertex = *bad_vertex || !usable_point(v);
    for (std::size_t t = 0; t < nt; ++t) {
      const glm::uvec3& i = mesh.triangles[t];
      if (keep[t] && !(i.x < nv && i.y < nv && i.z < nv && usable_triangle(p[i.x], p[i.y], p[i.z])))
        keep[t] = false;
    }
  };
  check(mesh.positions);
  std::vector<glm::vec3> wp(nv);
  const glm::mat4* last = nullptr;
  for (int node : placed) {
    const glm::mat4& mat = world[static_cast<std::size_t>(node)];
    if (last && *last == mat) continue;
    last = &mat;
    for (std::size_t v = 0; v < nv; ++v)
      wp[v] = glm::vec3(mat * glm::vec4(mesh.positions[v], 1.0f));
    check(wp);
  }
  return keep;
}

// Keeps the triangles marked in `keep` and the vertices they use (in first-use order).
void compact_mesh(Mesh& mesh, const std::vector<bool>& keep) {
  const std::size_t nv = mesh.positions.size(), nt = mesh.triangles.size();
  std::vector<std::uint32_t> remap(nv, ~0u);
  std::vector<glm::uvec3> triangles;
  std::vector<std::uint32_t> materials;
  std::uint32_t next = 0;
  for (std::size_t t = 0; t < nt; ++t) {
    if (!keep[t]) continue;
    glm::uvec3 tri = mesh.triangles[t];
    for (int k = 0; k < 3; ++k) {
      if (remap[tri[k]] == ~0u) remap[tri[k]] = next++;
      tri[k] = remap[tri[k]];
    }
    triangles.push_back(tri);
    if (t < mesh.triangle_material.size()) materials.push_back(mesh.triangle_material[t]);
  }
  auto compact = [&](auto& values) {
    if (values.size() != nv) return;
    std::remove_reference_t<decltype(values)> out(next);
    for (std::size_t v = 0; v < nv; ++v)
      if (remap[v] != ~0u) out[remap[v]] = values[v];
    values = std::move(out);
  };
  compact(mesh.normals);
  compact(mesh.uv0);
  compact(mesh.uv1);
  compact(mesh.positions);
  mesh.triangles = std::move(triangles);
  mesh.triangle_material = std::move(materials);
}

// Removes the lights and cameras of nodes whose world transform is not finite (with a warning).
void drop_unplaced_lights_and_cameras(Scene& scene, const std::vector<glm::mat4>& world,
                                      const std::string& label) {
  std::size_t lights = 0, cameras = 0;
  for (std::size_t n = 0; n < scene.nodes.size(); ++n) {
    Node& node = scene.nodes[n];
    if ((node.light < 0 && node.camera < 0) || finite_matrix(world[n])) continue;
    lights += node.light >= 0;
    cameras += node.camera >= 0;
    node.light = -1;
    node.camera = -1;
  }
  if (lights + cameras > 0)
    log::warn("scene", label + ": dropped " + std::to_string(lights) + " lights and " +
                           std::to_string(cameras) +
                           " cameras on nodes whose world transform is not finite");
}

}  // namespace

std::size_t drop_degenerate_triangles(Scene& scene, const std::string& label) {
  const std::vector<glm::mat4> world = scene.world_matrices();
  const std::vector<Object> objects = scene.objects();
  std::vector<std::vector<int>> placed(scene.meshes.size());  // nodes placing each mesh
  for (const Object& o : objects) placed[static_cast<std::size_t>(o.mesh)].push_back(o.node);

  std::size_t dropped = 0, total = 0, meshes_hit = 0;
  std::string which;
  for (std::size_t m = 0; m < scene.meshes.size(); ++m) {
    Mesh& mesh = scene.meshes[m];
    if (placed[m].empty()) continue;  // not in the world
    const std::size_t nt = mesh.triangles.size();
    total += nt;
    bool bad_vertex = false;
    const std::vector<bool> keep = usable_triangles(mesh, placed[m], world, &bad_vertex);
    const std::size_t kept = static_cast<std::size_t>(std::count(keep.begin(), keep.end(), true));
    if (kept == nt && !bad_vertex) continue;
    // Keep the triangles that are usable everywhere and the vertices they use.
    compact_mesh(mesh, keep);
    if (mesh.triangles.empty())
      for (int node : placed[m]) scene.nodes[static_cast<std::size_t>(node)].mesh = -1;
    if (kept == nt) continue;  // only unused vertices went
    dropped += nt - kept;
    if (++meshes_hit <= 4)
      which += std::string(which.empty() ? "" : ", ") + "mesh " + std::to_string(m) +
               (mesh.name.empty() ? "" : " \"" + printable(mesh.name) + "\"") + " " +
               std::to_string(nt - kept) + " of " + std::to_string(nt);
  }

  drop_unplaced_lights_and_cameras(scene, world, label);
  if (dropped == 0) return 0;
  log::warn("scene", label + ": dropped " + std::to_string(dropped) + " of " +
                         std::to_string(total) +
                         " triangles with zero area or corners that are not finite (in the "
                         "mesh or where a node places it), from " +
                         std::to_string(meshes_hit) + (meshes_hit == 1 ? " mesh (" : " meshes (") +
                         which + (meshes_hit > 4 ? ", ...)" : ")"));
  if (scene.objects().empty())
    throw Error(label + ": the scene has no triangles with area after dropping " +
                std::to_string(dropped) + " degenerate or non-finite ones");
  return dropped;
}

}  // namespace irradcast

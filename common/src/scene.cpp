#include "irradcast/scene.h"

#include <array>
#include <cmath>

namespace irradcast {
namespace {

const std::array<float, 256>& srgb_table() {
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

}  // namespace

glm::vec4 Texture::sample_srgb(glm::vec2 uv) const {
  if (width <= 0 || height <= 0) return glm::vec4(1.0f);
  const auto& lut = srgb_table();
  float x = uv.x * static_cast<float>(width) - 0.5f;
  float y = uv.y * static_cast<float>(height) - 0.5f;
  float fx = std::floor(x), fy = std::floor(y);
  float ax = x - fx, ay = y - fy;
  auto wrap = [](long i, int n) { return static_cast<int>(((i % n) + n) % n); };
  auto fetch = [&](long i, long j) {
    const std::uint8_t* p =
        &rgba8[4 * (static_cast<std::size_t>(wrap(j, height)) * width + wrap(i, width))];
    return glm::vec4(lut[p[0]], lut[p[1]], lut[p[2]], static_cast<float>(p[3]) / 255.0f);
  };
  long ix = static_cast<long>(fx), iy = static_cast<long>(fy);
  glm::vec4 a = glm::mix(fetch(ix, iy), fetch(ix + 1, iy), ax);
  glm::vec4 b = glm::mix(fetch(ix, iy + 1), fetch(ix + 1, iy + 1), ax);
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

std::vector<bool> Scene::visible_nodes() const {
  std::vector<bool> visible(nodes.size(), false);
  std::vector<bool> done(nodes.size(), false);
  std::vector<std::pair<int, bool>> stack;
  for (int r : roots) stack.emplace_back(r, true);
  while (!stack.empty()) {
    auto [n, parent] = stack.back();
    stack.pop_back();
    if (done[n]) continue;
    done[n] = true;
    visible[n] = parent && nodes[n].visible;
    for (int c : nodes[n].children) stack.emplace_back(c, visible[n]);
  }
  return visible;
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

}  // namespace irradcast

// The light hierarchy (light_tree.h), after pbrt-v4's BVHLightSampler and LightBounds: the
// build's bucketed split by the orientation-aware cost, the importance, and the walk.
#include "irradcast/common/light_tree.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>

#include "irradcast/common/lights.h"
#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

using Node = LightTree::Node;

float safe_sqrt(float v) {
  return std::sqrt(std::max(v, 0.0f));
}
float safe_acos(float v) {
  return std::acos(std::clamp(v, -1.0f, 1.0f));
}

// cos(max(0, a - b)) and sin(max(0, a - b)) of two angles given by their sines and cosines.
float cos_sub_clamped(float sin_a, float cos_a, float sin_b, float cos_b) {
  return cos_a > cos_b ? 1.0f : cos_a * cos_b + sin_a * sin_b;
}
float sin_sub_clamped(float sin_a, float cos_a, float sin_b, float cos_b) {
  return cos_a > cos_b ? 0.0f : sin_a * cos_b - cos_a * sin_b;
}

// v turned by `angle` about the unit axis k (Rodrigues).
glm::vec3 rotate(glm::vec3 v, glm::vec3 k, float angle) {
  const float c = std::cos(angle), s = std::sin(angle);
  return v * c + glm::cross(k, v) * s + k * glm::dot(k, v) * (1.0f - c);
}

// The smallest cone (of those pbrt-v4's DirectionCone::Union makes) holding both.
void merge_cones(glm::vec3 wa, float cos_a, glm::vec3 wb, float cos_b, glm::vec3& w, float& cos_o) {
  const float theta_a = safe_acos(cos_a), theta_b = safe_acos(cos_b);
  const float theta_d = safe_acos(glm::dot(wa, wb));
  if (std::min(theta_d + theta_b, kPi) <= theta_a) {
    w = wa;
    cos_o = cos_a;
    return;
  }
  if (std::min(theta_d + theta_a, kPi) <= theta_b) {
    w = wb;
    cos_o = cos_b;
    return;
  }
  const float theta_o = 0.5f * (theta_a + theta_d + theta_b);
  const glm::vec3 axis = glm::cross(wa, wb);
  const float len = glm::length(axis);
  if (theta_o >= kPi || !(len > 1e-12f)) {
    w = wa;
    cos_o = -1.0f;  // every direction
    return;
  }
  w = glm::normalize(rotate(wa, axis / len, theta_o - theta_a));
  cos_o = std::cos(theta_o);
}

Node merge(const Node& a, const Node& b) {
  if (a.phi == 0.0f) return b;
  if (b.phi == 0.0f) return a;
  Node m;
  m.lo = glm::min(a.lo, b.lo);
  m.hi = glm::max(a.hi, b.hi);
  m.phi = a.phi + b.phi;
  m.two_sided = a.two_sided || b.two_sided;
  merge_cones(a.w, a.cos_o, b.w, b.cos_o, m.w, m.cos_o);
  return m;
}

float surface_area(const Node& b) {
  const glm::vec3 d = b.hi - b.lo;
  return 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
}

// pbrt-v4's EvaluateCost: power x the solid angle the cone of normals (widened by the emission's
// 90 degrees) sweeps x the surface area, the split axis's thinness weighted.
float split_cost(const Node& b, glm::vec3 diagonal, int dim) {
  if (b.phi == 0.0f) return 0.0f;
  const float theta_o = safe_acos(b.cos_o), theta_e = 0.5f * kPi;
  const float theta_w = std::min(theta_o + theta_e, kPi);
  const float sin_o = std::sin(theta_o);
  const float m_omega = 2.0f * kPi * (1.0f - b.cos_o) +
                        0.5f * kPi *
                            (2.0f * theta_w * sin_o - std::cos(theta_o - 2.0f * theta_w) -
                             2.0f * theta_o * sin_o + b.cos_o);
  const float longest = std::max({diagonal.x, diagonal.y, diagonal.z});
  const float kr = diagonal[dim] > 0.0f ? longest / diagonal[dim] : 1.0f;
  return b.phi * m_omega * kr * surface_area(b);
}

constexpr int kBuckets = 12;
constexpr int kTrailBits = 64;

}  // namespace

LightTree::Cone LightTree::cone(const Node& node) {
  Cone c;
  c.centre = 0.5f * (node.lo + node.hi);
  c.radius = 0.5f * glm::length(node.hi - node.lo);
  c.w = node.w;
  c.phi = node.phi;
  c.cos_o = node.cos_o;
  c.sin_o = safe_sqrt(1.0f - node.cos_o * node.cos_o);
  c.two_sided = node.two_sided;
  return c;
}

float LightTree::importance(const Node& node, glm::vec3 p, glm::vec3 n) {
  return importance(cone(node), p, n);
}

float LightTree::importance(const Cone& node, glm::vec3 p, glm::vec3 n) {
  if (!(node.phi > 0.0f)) return 0.0f;
  const glm::vec3 pc = node.centre;
  const float radius = node.radius;
  const float dist2 = glm::dot(p - pc, p - pc);
  const float d2 = std::max(dist2, radius);
  // Inside the bounds' sphere every direction is possible: power over distance only.
  if (!(dist2 > radius * radius)) return node.phi / std::max(d2, 1e-12f);
  const glm::vec3 wi = (p - pc) / std::sqrt(dist2);  // from the lights towards p
  // The bounds as seen from p: a cone of half-angle b about -wi.
  const float sin2_b = radius * radius / dist2;
  const float cos_b = safe_sqrt(1.0f - sin2_b), sin_b = safe_sqrt(sin2_b);
  // The smallest angle between an emission direction and a direction towards p.
  float cos_w = glm::dot(node.w, wi);
  if (node.two_sided) cos_w = std::fabs(cos_w);
  const float sin_w = safe_sqrt(1.0f - cos_w * cos_w);
  const float sin_o = node.sin_o;
  const float cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, node.cos_o);
  const float sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, node.cos_o);
  const float cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
  if (!(cos_p > 0.0f)) return 0.0f;  // every light faces away from p (cos_e = cos 90 degrees)
  // The smallest angle between p's normal and a direction towards the lights: p receives only
  // from in front of its tangent plane.
  const float cos_i = -glm::dot(n, wi);
  const float sin_i = safe_sqrt(1.0f - cos_i * cos_i);
  const float cos_pi = cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
  if (!(cos_pi > 0.0f)) return 0.0f;
  return node.phi * cos_p * cos_pi / d2;
}

LightTree::LightTree(const std::vector<EmissiveTriangle>& triangles,
                     const std::vector<float>& power) {
  std::vector<Node> leaves(triangles.size());
  std::vector<std::uint32_t> lights;
  trail_.assign(triangles.size(), ~std::uint64_t{0});
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    const EmissiveTriangle& t = triangles[i];
    Node& l = leaves[i];
    const glm::vec3 a = t.p0, b = t.p0 + t.e1, c = t.p0 + t.e2;
    l.lo = glm::min(a, glm::min(b, c));
    l.hi = glm::max(a, glm::max(b, c));
    l.w = t.normal;
    l.cos_o = 1.0f;
    l.two_sided = t.double_sided;
    l.phi = i < power.size() && power[i] > 0.0f && std::isfinite(power[i]) ? power[i] : 0.0f;
    l.leaf = true;
    l.index = static_cast<std::uint32_t>(i);
    if (l.phi > 0.0f) lights.push_back(static_cast<std::uint32_t>(i));
  }
  if (lights.empty()) return;
  max_depth_ = std::max(0, kTrailBits - 1 - static_cast<int>(std::bit_width(lights.size())));
  nodes_.reserve(2 * lights.size());
  build(lights, 0, lights.size(), 0, leaves);
  // Each triangle's trail, from a walk over the finished tree.
  struct Step {
    std::uint32_t node;
    std::uint64_t trail;
    int depth;
  };
  std::vector<Step> stack{{0, 0, 0}};
  while (!stack.empty()) {
    const Step s = stack.back();
    stack.pop_back();
    const Node& nd = nodes_[s.node];
    if (nd.leaf) {
      trail_[nd.index] = s.trail;
      continue;
    }
    stack.push_back({s.node + 1, s.trail, s.depth + 1});
    stack.push_back({nd.index, s.trail | (std::uint64_t{1} << s.depth), s.depth + 1});
  }
  cones_.reserve(nodes_.size());
  for (const Node& nd : nodes_) cones_.push_back(cone(nd));
}

std::uint32_t LightTree::build(std::vector<std::uint32_t>& lights, std::size_t begin,
                               std::size_t end, int depth, const std::vector<Node>& leaves) {
  const auto at = static_cast<std::uint32_t>(nodes_.size());
  if (end - begin == 1) {
    nodes_.push_back(leaves[lights[begin]]);
    return at;
  }
  Node all;
  glm::vec3 clo(std::numeric_limits<float>::infinity()), chi(-clo);
  for (std::size_t k = begin; k < end; ++k) {
    const Node& l = leaves[lights[k]];
    all = merge(all, l);
    const glm::vec3 c = 0.5f * (l.lo + l.hi);
    clo = glm::min(clo, c);
    chi = glm::max(chi, c);
  }
  const glm::vec3 diagonal = all.hi - all.lo;
  // The cheapest split between buckets of the centroids along any axis (pbrt-v4's buildBVH).
  float best_cost = std::numeric_limits<float>::infinity();
  int best_dim = -1, best_bucket = -1;
  auto bucket_of = [&](const Node& l, int dim) {
    const float c = 0.5f * (l.lo[dim] + l.hi[dim]);
    const int b = static_cast<int>(kBuckets * ((c - clo[dim]) / (chi[dim] - clo[dim])));
    return std::clamp(b, 0, kBuckets - 1);
  };
  // Trails are 64 bits: past max_depth_ the splits halve by count, which ends every branch
  // within the bits left.
  if (depth < max_depth_)
    for (int dim = 0; dim < 3; ++dim) {
      if (!(chi[dim] > clo[dim])) continue;
      std::array<Node, kBuckets> bucket{};
      for (std::size_t k = begin; k < end; ++k) {
        const Node& l = leaves[lights[k]];
        Node& b = bucket[static_cast<std::size_t>(bucket_of(l, dim))];
        b = merge(b, l);
      }
      for (int split = 0; split + 1 < kBuckets; ++split) {
        Node below, above;
        for (int b = 0; b <= split; ++b) below = merge(below, bucket[static_cast<std::size_t>(b)]);
        for (int b = split + 1; b < kBuckets; ++b)
          above = merge(above, bucket[static_cast<std::size_t>(b)]);
        if (below.phi == 0.0f || above.phi == 0.0f) continue;
        const float cost = split_cost(below, diagonal, dim) + split_cost(above, diagonal, dim);
        if (cost < best_cost) {
          best_cost = cost;
          best_dim = dim;
          best_bucket = split;
        }
      }
    }
  std::size_t mid;
  if (best_dim >= 0) {
    const auto split_at = std::partition(
        lights.begin() + static_cast<std::ptrdiff_t>(begin),
        lights.begin() + static_cast<std::ptrdiff_t>(end),
        [&](std::uint32_t i) { return bucket_of(leaves[i], best_dim) <= best_bucket; });
    mid = static_cast<std::size_t>(split_at - lights.begin());
  } else {
    mid = (begin + end) / 2;  // the centroids coincide (or the tree is deep): halves by count
  }
  if (mid == begin || mid == end) mid = (begin + end) / 2;
  nodes_.push_back(all);
  nodes_[at].leaf = false;
  build(lights, begin, mid, depth + 1, leaves);
  const std::uint32_t second = build(lights, mid, end, depth + 1, leaves);
  nodes_[at].index = second;
  return at;
}

namespace {

// The walks, with the node importances from `imp(node index)`: LightTree's at one point, or an
// At's remembered ones (the same values, so the same picks and probabilities).
template <class Importance>
bool sample_walk(const std::vector<Node>& nodes, Importance&& imp, float u, std::uint32_t& index,
                 float& pmf) {
  if (nodes.empty()) return false;
  std::uint32_t at = 0;
  float prob = 1.0f;
  while (!nodes[at].leaf) {
    const std::uint32_t child[2] = {at + 1, nodes[at].index};
    const float c0 = imp(child[0]), c1 = imp(child[1]);
    const float sum = c0 + c1;
    if (!(sum > 0.0f)) return false;
    const float p0 = c0 / sum;
    // Pick a child and stretch u over its share, so that one number serves the whole walk.
    if (u < p0) {
      u = std::min(u / p0, 0x1.fffffep-1f);
      prob *= p0;
      at = child[0];
    } else {
      u = std::min((u - p0) / (1.0f - p0), 0x1.fffffep-1f);
      prob *= 1.0f - p0;
      at = child[1];
    }
  }
  if (at == 0 && !(imp(0) > 0.0f)) return false;
  if (!(prob > 0.0f)) return false;
  index = nodes[at].index;
  pmf = prob;
  return true;
}

template <class Importance>
float pmf_walk(const std::vector<Node>& nodes, const std::vector<std::uint64_t>& trails,
               Importance&& imp, std::uint32_t index) {
  if (nodes.empty() || index >= trails.size() || trails[index] == ~std::uint64_t{0}) return 0.0f;
  std::uint32_t at = 0;
  std::uint64_t trail = trails[index];
  float prob = 1.0f;
  while (!nodes[at].leaf) {
    const std::uint32_t child[2] = {at + 1, nodes[at].index};
    const float c0 = imp(child[0]), c1 = imp(child[1]);
    const float sum = c0 + c1;
    if (!(sum > 0.0f)) return 0.0f;
    const int second = static_cast<int>(trail & 1u);
    prob *= (second ? c1 : c0) / sum;
    at = child[second];
    trail >>= 1;
  }
  if (at == 0) return imp(0) > 0.0f ? 1.0f : 0.0f;
  return prob;
}

}  // namespace

bool LightTree::sample(glm::vec3 p, glm::vec3 n, float u, std::uint32_t& index, float& pmf) const {
  return sample_walk(
      nodes_, [&](std::uint32_t k) { return importance(cones_[k], p, n); }, u, index, pmf);
}

float LightTree::pmf(glm::vec3 p, glm::vec3 n, std::uint32_t index) const {
  return pmf_walk(
      nodes_, trail_, [&](std::uint32_t k) { return importance(cones_[k], p, n); }, index);
}

LightTree::At::At(const LightTree& tree, glm::vec3 p, glm::vec3 n) : tree_(&tree), p_(p), n_(n) {
  std::fill(std::begin(key_), std::end(key_), ~std::uint32_t{0});
}

float LightTree::At::importance(std::uint32_t node) {
  const std::uint32_t slot = node % kSlots;
  if (key_[slot] != node) {
    key_[slot] = node;
    value_[slot] = LightTree::importance(tree_->cones_[node], p_, n_);
  }
  return value_[slot];
}

bool LightTree::At::sample(float u, std::uint32_t& index, float& pmf) {
  return sample_walk(
      tree_->nodes_, [&](std::uint32_t k) { return importance(k); }, u, index, pmf);
}

float LightTree::At::pmf(std::uint32_t index) {
  return pmf_walk(
      tree_->nodes_, tree_->trail_, [&](std::uint32_t k) { return importance(k); }, index);
}

}  // namespace irradcast

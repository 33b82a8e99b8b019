// A light hierarchy over the emissive triangles (pbrt-v4's BVHLightSampler): each node bounds
// its lights' positions, their total power and the cone of their normals, and a point picks a
// light by walking from the root, taking each child with probability proportional to its
// importance at that point (power, distance, orientation towards the point, and whether it can
// lie in front of the point's tangent plane). A light that can light the point always has a
// probability above zero, so an estimate divided by that probability is unbiased; lights far
// away, behind walls' backs or facing away are picked seldom or never. LightSampler uses it for
// scenes with more emissive triangles than its per-texel list holds (LightSampler::kMaxFront).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

namespace irradcast {

struct EmissiveTriangle;

class LightTree {
 public:
  // One node: the bounds of its lights, their power, the cone of their emission directions
  // (axis w, half-angle cos_o; each light emits within a further cos_e = cos 90 degrees of it),
  // and either two children or one light.
  struct Node {
    glm::vec3 lo{0.0f}, hi{0.0f};
    glm::vec3 w{0.0f, 0.0f, 1.0f};
    float phi = 0.0f;
    float cos_o = 1.0f;
    bool two_sided = false;
    bool leaf = false;
    std::uint32_t index = 0;  // leaf: the emissive triangle; inner: the second child (the first
                              // follows the node)
  };

  LightTree() = default;
  // `power` per triangle (its pick weight by power); triangles of zero power are left out.
  LightTree(const std::vector<EmissiveTriangle>& triangles, const std::vector<float>& power);

  bool empty() const { return nodes_.empty(); }
  const std::vector<Node>& nodes() const { return nodes_; }
  // A triangle for the point p with unit normal n (it receives light from its front only), with
  // u uniform in [0, 1): false when no light can reach p; else `index` and its probability.
  bool sample(glm::vec3 p, glm::vec3 n, float u, std::uint32_t& index, float& pmf) const;
  // The probability that sample() picks triangle `index` at (p, n).
  float pmf(glm::vec3 p, glm::vec3 n, std::uint32_t index) const;

  // The hierarchy at one point: sample() and pmf() as the tree's, bit for bit, remembering the
  // importance of the nodes it has walked (a small table by node index), so that the samples of
  // one texel evaluate the levels their walks share once. Lives on the stack, per point.
  class At {
   public:
    At(const LightTree& tree, glm::vec3 p, glm::vec3 n);
    bool sample(float u, std::uint32_t& index, float& pmf);
    float pmf(std::uint32_t index);

   private:
    float importance(std::uint32_t node);
    static constexpr std::uint32_t kSlots = 128;
    const LightTree* tree_;
    glm::vec3 p_, n_;
    std::uint32_t key_[kSlots];
    float value_[kSlots];
  };
  // A node's importance at (p, n): zero only where none of its lights can light p.
  static float importance(const Node& node, glm::vec3 p, glm::vec3 n);

 private:
  // A node as importance() reads it, its bounds' centre and radius and the sine of its cone's
  // angle computed once (the same values it would compute from the node each time).
  struct Cone {
    glm::vec3 centre{0.0f};
    float radius = 0.0f;
    glm::vec3 w{0.0f, 0.0f, 1.0f};
    float phi = 0.0f;
    float cos_o = 1.0f, sin_o = 0.0f;
    bool two_sided = false;
  };
  static Cone cone(const Node& node);
  static float importance(const Cone& node, glm::vec3 p, glm::vec3 n);

  std::uint32_t build(std::vector<std::uint32_t>& lights, std::size_t begin, std::size_t end,
                      int depth, const std::vector<Node>& leaves);
  std::vector<Node> nodes_;
  std::vector<Cone> cones_;           // per node
  int max_depth_ = 0;                 // the deepest level split by cost
  std::vector<std::uint64_t> trail_;  // per triangle: its path from the root (bit d: second
                                      // child at depth d); ~0 for a triangle left out
};

}  // namespace irradcast

// Instant radiosity / instant global illumination (seeds 003 and 000; docs/METHODS.md): light
// paths from the lights (emitters, punctual lights, the sky) leave virtual point lights (VPLs)
// where they hit surfaces, and every texel gathers the VPLs with shadow rays. Bounce k is the light
// of the VPLs k hits from a light.
//   - Quasi-random paths: a scrambled Halton sequence picks the light, the point, the direction
//     and each bounce's direction (seed 003 section 8.3.5, Keller's instant radiosity).
//   - A pool of EngineParams::vpl_paths paths in strided temporal sets, one gathered per update
//     (seed 000 Algorithm 4); once each set has been gathered the pool is shot again with the
//     next Halton points, so the running means converge.
//   - Interleaved sampling: within the set a texel gathers the subset of its lightmap position
//     modulo vpl_interleave, and a filter over that neighbourhood that stops at discontinuities
//     (normals, off-plane neighbours) rebuilds the whole set (seed 003 section 8.3.8, seed 000's
//     normal-based discontinuity buffer).
//   - Clamping: the geometry term's 1/d^2 is bounded at d = vpl_clamp x the scene size, so a
//     VPL next to a texel cannot light it without bound (the bias of instant radiosity).
//   - Scene edits (seed 000 Algorithms 2 and 3): VPLs on or from a changed region, or occluded
//     from their parent, are invalid with their descendants and are shot again from their parent,
//     round robin, at most vpl_replace per update.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indirect_method.h"

namespace irradcast {

struct VirtualPointLight {
  glm::vec3 position{0.0f};
  glm::vec3 normal{0.0f, 0.0f, 1.0f};  // facing the side the light came from
  glm::vec3 power{0.0f};               // incident flux x albedo / pi (per path; / paths in use)
  bool valid = false;                  // false: not shot yet, the path ended, or invalidated
};

class VplMethod final : public IndirectMethod {
 public:
  VplMethod(const EngineParams& params, const World& world, const RayScene& rays,
            const LightSampler& lights);

  std::string name() const override { return "vpl"; }
  PassResult prepare(const PassInput& in) override;
  BounceResult bounce(const PassInput& in, const RadianceField& prev,
                      std::vector<glm::vec3>& out) override;
  void scene_changed(const SceneChange& change, const Lap& lap) override;
  std::string summary() const override;

  // The pool: path p's VPL of bounce k (1..K) is vpls()[p * K + k - 1].
  const std::vector<VirtualPointLight>& vpls() const { return vpls_; }
  std::size_t invalid() const;

 private:
  // bounce()'s two steps: the VPLs' light at each texel, then the discontinuity filter.
  std::uint64_t gather(const PassInput& in, int k, std::vector<glm::vec3>& raw) const;
  void filter(const PassInput& in, const std::vector<glm::vec3>& raw,
              std::vector<glm::vec3>& out) const;
  struct PathStart {
    glm::vec3 origin{0.0f};  // the point on the light (the first VPL's parent)
    bool live = false;
  };
  // Where a path leaves emitter e (picked with probability pdf): its first ray and flux.
  struct PathOrigin {
    glm::vec3 origin{0.0f}, direction{0.0f, 0.0f, -1.0f}, flux{0.0f};
    const WorldLight* point = nullptr;  // a point or spot light (its range window applies)
  };
  void build_emitters();
  PathOrigin emit(std::size_t e, float pdf, float side_u, glm::vec2 up, glm::vec2 ud) const;
  // Traces path `p` with Halton index `index` and fills its VPLs; returns the rays traced.
  std::uint64_t shoot(std::size_t p, std::uint64_t index);
  float dim(std::uint64_t index, int d) const;
  void build_texel_map(const PassInput& in);

  const EngineParams params_;
  const World* world_;
  const RayScene* rays_;
  const LightSampler* lights_;
  int depth_ = 1;  // VPLs per path = indirect bounces
  // Emitters: area triangles (by LightSampler index), punctual lights and the sky (last, when
  // there is one), picked by power.
  std::vector<float> emitter_cdf_, emitter_pdf_;
  std::size_t area_count_ = 0;
  std::vector<float> shifts_;  // Cranley-Patterson rotation per Halton dimension
  std::vector<VirtualPointLight> vpls_;
  std::vector<PathStart> starts_;
  std::vector<std::uint64_t> path_index_;  // Halton index each path was shot with
  // Per path: 0, or 1 + the first bounce an edit invalidated (shot again by prepare()).
  std::vector<std::uint8_t> pending_;
  std::uint64_t cycle_ = 0;         // pools shot so far
  int set_ = -1;                    // temporal set of this update
  std::size_t replace_cursor_ = 0;  // round-robin position of the replacement scan
  std::size_t replaced_ = 0;        // VPLs shot again since the last edit
  // Per object: lightmap texel -> index in the engine's texels (-1: none), for the filter.
  std::vector<std::vector<std::int32_t>> texel_index_;
  std::uint64_t map_generation_ = ~0ull;
};

}  // namespace irradcast

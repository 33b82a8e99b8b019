// The irradiance cache (seed 004, after Ward 1988 and Ward & Heckbert 1992; docs/METHODS.md):
// the indirect light is computed at sparse records and interpolated everywhere else.
//   - A record's irradiance comes from many stratified cosine-weighted hemisphere rays
//     (ic_rays x 4 ic_rays per update), whose hits read the previous bounce's lightmaps.
//   - Its radius R is the harmonic mean distance of its rays, clamped to
//     [ic_min_radius, ic_max_radius] x the scene size.
//   - Records are placed where no existing record has Ward weight
//     w = 1 / (|p - p_k| / R_k + sqrt(1 - n . n_k)) above 1 / a (a = ic_accuracy), over the
//     texels in a shuffled order, splatting each new record over its whole zone of influence
//     (seed 004's splatting-based detection, so no traversal order matters).
//   - Every update re-estimates every record with new rays, with its rotational and
//     translational gradients, and splats the records into the lightmap texels:
//     E(p) = sum_k w_k (E_k + (n_k x n) . grad_r E_k + (p - p_k) . grad_t E_k) / sum_k w_k over
//     the records with w_k > 1 / a (and not in front of p) that p sees: a visibility ray per
//     (texel, record) pair, paid once per placement, keeps records from lighting texels
//     behind a wall (Ward's cache has no such test and leaks through thin walls).
//   - A scene edit drops the records within their radius of a changed region; the next update
//     places new ones where texels are no longer covered.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "indirect_method.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

struct IrradianceRecord {
  glm::vec3 position{0.0f};
  glm::vec3 normal{0.0f, 0.0f, 1.0f};
  glm::vec3 geo_normal{0.0f, 0.0f, 1.0f};
  float radius = 1.0f;  // R_k, world units
};

// One update's estimate at a record: irradiance and its gradients (one vector per channel).
struct RecordEstimate {
  glm::vec3 irradiance{0.0f};
  glm::vec3 rotation[3];
  glm::vec3 translation[3];
};

// Estimates the irradiance at (p, n, ng) from `theta` x 4 `theta` stratified cosine-weighted
// rays whose hits read `prev`, with Ward & Heckbert's rotational and translational gradients;
// *harmonic (optional) gets the rays' harmonic mean distance (infinity if all miss).
RecordEstimate estimate_record(const RayScene& rays, const RadianceField* prev, glm::vec3 p,
                               glm::vec3 n, glm::vec3 ng, int theta, Rng& rng,
                               float* harmonic = nullptr);

class IrradianceCache final : public IndirectMethod {
 public:
  IrradianceCache(const EngineParams& params, const World& world, const RayScene& rays);

  std::string name() const override { return "irradiance-cache"; }
  PassResult prepare(const PassInput& in) override;
  BounceResult bounce(const PassInput& in, const RadianceField& prev,
                      std::vector<glm::vec3>& out) override;
  void scene_changed(const SceneChange& change, const Lap& lap) override;
  std::string summary() const override;

  const std::vector<IrradianceRecord>& records() const { return records_; }

 private:
  // Drops the records near a changed region (placed again by the next prepare()).
  void drop_records(const SceneChange& change);
  // Ward weight of record k at (p, n), 0 if it may not contribute (below 1/a or in front).
  float weight(const IrradianceRecord& r, glm::vec3 p, glm::vec3 n) const;
  bool visible(const IrradianceRecord& r, glm::vec3 p, glm::vec3 ng) const;
  // Sum of the weights of the records (from `first_record` on) that may contribute at p and
  // that p sees.
  float coverage(glm::vec3 p, glm::vec3 n, glm::vec3 ng, std::size_t first_record = 0) const;
  void build_splats(const PassInput& in);
  void insert(std::uint32_t record);
  glm::ivec3 cell_of(glm::vec3 p) const;
  const std::vector<std::uint32_t>& cell_records(glm::vec3 p) const;

  const EngineParams params_;
  const World* world_;
  const RayScene* rays_;
  std::vector<IrradianceRecord> records_;
  bool place_ = true;  // texels may be uncovered: place records in the next prepare()
  // A uniform grid over the scene bounds: per cell, the records whose zone of influence
  // (radius a R_k) overlaps it.
  glm::ivec3 dims_{1};
  float cell_ = 1.0f;
  std::vector<std::vector<std::uint32_t>> grid_;
  std::size_t placed_last_ = 0;
  // Per texel (engine order) the records it uses and their weights: splat_offsets_[i] ..
  // splat_offsets_[i + 1] in splat_.
  std::vector<std::uint32_t> splat_offsets_;
  std::vector<std::pair<std::uint32_t, float>> splat_;
  std::uint64_t splat_generation_ = ~0ull;
};

}  // namespace irradcast

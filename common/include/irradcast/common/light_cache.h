// Which area lights light each region of the scene, learned from the direct pass's own shadow
// rays, and a light pick that uses it: a one-sample mixture of the light hierarchy (light_tree.h)
// and the region's learned table. The hierarchy picks by power, distance and orientation and
// cannot see walls; the table holds the lights whose samples came back unoccluded from that
// region, weighted by what they brought. Mixing keeps the estimate unbiased (every light the
// hierarchy can pick keeps a probability above zero, and the pick's probability is the mixture's
// exactly) while most shadow rays go to lights that are seen.
//
// A region is a cube of the grid over the scene's bounds and the one of six axis directions
// nearest the surface normal (so the two faces of a wall learn apart). Learning sums each
// light's sampled irradiance (the estimate's weight, its luminance) per region in fixed point,
// so the sums and the tables do not depend on the order in which threads add them: the same
// seed gives the same lightmaps on any number of cores. Each learn() lets the old sums fade by an
// eighth before adding the new ones, so a region follows a scene that changes (a door closed);
// an edit starts the cache anew (EmbreeBackend::scene_changed).
#pragma once

#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/common/light_tree.h"

namespace irradcast {

struct Bounds;

class LightCache {
 public:
  // Lights per region's table (the most valuable; the rest are left to the hierarchy).
  static constexpr int kMaxLights = 32;
  // Regions along the scene's largest extent.
  static constexpr int kRegionsAcross = 24;
  // The mixture's share of picks by the hierarchy, where a region has a table (measured:
  // docs/bench/engine.md, "Many lights").
  static constexpr float kTreeShare = 0.25f;
  // The fixed point's one: a weight of `unit` (the constructor's) sums as this.
  static constexpr float kFixedOne = 1048576.0f;

  // One region's table: its lights in decreasing weight, and their cumulative weights.
  struct Table {
    int count = 0;
    float total = 0.0f;
    std::uint32_t light[kMaxLights];
    float cdf[kMaxLights];
    // The probability that the table picks `index` (0 when it is not in the table).
    float pmf(std::uint32_t index) const;
  };

  // One thread's samples of a pass: per region and light, the summed weight.
  class Record {
   public:
    explicit Record(float unit = 1.0f) : scale_(kFixedOne / unit) {}
    // A sample of `light` from `region` that brought `luminance` (its weight's luminance).
    void add(std::uint64_t region, std::uint32_t light, float luminance);
    bool empty() const { return entries_.empty(); }

   private:
    friend class LightCache;
    struct Entry {
      std::uint64_t region;
      std::uint32_t light;
      std::uint64_t sum;
    };
    std::vector<Entry> entries_;
    float scale_;
  };

  LightCache() = default;
  // A grid over `bounds` for `lights` emissive triangles; `unit`: a typical irradiance (the fixed
  // point's scale, say the brightest light's emitted radiance).
  LightCache(const Bounds& bounds, std::size_t lights, float unit);

  bool valid() const { return lights_ > 0; }
  std::size_t lights() const { return lights_; }
  float unit() const { return unit_; }
  // The region of the point p with unit normal n.
  std::uint64_t region(glm::vec3 p, glm::vec3 n) const;
  // Its table; null where nothing has been learned.
  const Table* find(std::uint64_t region) const;
  std::size_t regions() const { return tables_.size(); }

  // Adds the records' sums to the regions' (after fading those), and rebuilds the tables.
  void learn(std::vector<Record*> records);
  void clear();

  // A light for p (unit normal n), u uniform in [0, 1): by the hierarchy alone without a table;
  // with one, by the hierarchy for u below kTreeShare, else by the table. `pmf`: the probability
  // of picking `index` either way. false: no light picked (none can light p).
  static bool pick(const LightTree& tree, const Table* table, glm::vec3 p, glm::vec3 n, float u,
                   std::uint32_t& index, float& pmf);

 private:
  glm::vec3 origin_{0.0f};
  float inv_cell_ = 1.0f;
  std::size_t lights_ = 0;
  float unit_ = 1.0f;
  // Per region: each light's summed weight (fixed point), sorted by light.
  std::unordered_map<std::uint64_t, std::vector<std::pair<std::uint32_t, std::uint64_t>>> sums_;
  std::unordered_map<std::uint64_t, Table> tables_;
};

}  // namespace irradcast

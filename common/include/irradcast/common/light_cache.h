// Which area lights light each region of the scene, learned from the direct pass's own shadow
// rays, and a light pick that uses it: a one-sample mixture of the light hierarchy (light_tree.h)
// and the region's learned table. The hierarchy picks by power, distance and orientation and
// cannot see walls; the table weighs each light by what one of its samples brought the region on
// average, shadowed (the mean of its emitted irradiance over the shadow rays traced toward it,
// zero for an occluded one): an estimate of the light's irradiance there, its visibility
// included, that does not depend on how often the light was picked. Mixing keeps the estimate
// unbiased (every light the hierarchy can pick keeps a probability above zero, and the pick's
// probability is the mixture's exactly) while most shadow rays go to lights that are seen.
//
// A region is a cube of the grid over the scene's bounds, the one of six axis directions
// nearest the surface normal (so the two faces of a wall learn apart) and the surface's object
// (so the floors on either side of a wall do). Learning sums, per region and light, the samples'
// luminance in fixed point and counts them, so the sums and the tables do not depend on the order
// in which threads add them: the same seed gives the same lightmaps on any number of cores. Each
// learn() lets the old sums and counts fade by an eighth before adding the new ones, so a region
// follows a scene that changes (a door closed); an edit starts the cache anew
// (EmbreeBackend::scene_changed).
//
// Where no light reaches, every shadow ray ends occluded whatever the pick; the direct pass spends
// fewer samples there (samples_in). That test is kept on patches, cubes up to kPatchSplit times
// finer than a region's (the same normal direction and object): a region's table is better learned
// from many texels, but a region that light reaches in part (a floor with a table on it, a wall
// behind a couch) holds texels no light reaches (on rooms:6, before the patches, 6.5 % of the
// texels in regions with a table saw no light and traced 15 % of the shadow rays, all occluded). A
// patch from which many rays and no light came back is dark.
#pragma once

#include <algorithm>
#include <cstdint>
#include <unordered_map>
#include <unordered_set>
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
  // Patches (of the dark test) along a region's edge, at most: fewer where a patch would be under
  // kMinPatchEdge metres (a small scene's regions are small: rooms:2's 34 cm would give 8.5 cm
  // patches, about two texels at 16 texels a metre, which take several updates to gather
  // kDarkRays rays; docs/bench/engine.md, "Dark patches").
  static constexpr int kPatchSplit = 4;
  static constexpr float kMinPatchEdge = 0.25f;
  // The mixture's share of picks by the hierarchy, where a region has a table (measured:
  // docs/bench/engine.md, "Many lights").
  static constexpr float kTreeShare = 0.25f;
  // The fewest emissive triangles for which the engine's direct pass learns tables: more than
  // one rooms:N ceiling panel (8 triangles), so that cornell and rooms:1 pick as before.
  static constexpr std::size_t kLearnFrom = 9;
  // A texel that picks among the lights in front of it uses its region's table only where at
  // most this share of the region's rays brought light: where every light is seen (the inside of
  // a lamp, a furnace), a table only reshuffles the pick by power, and where an emitter touches
  // the receiver it thins the pick of the nearby light whose rare close samples carry much of
  // its light, so that a few updates read dark (EngineFurnace, all faces emitting: the direct pass
  // 6 % low after four updates).
  static constexpr float kFrontLitShare = 0.75f;
  // A patch is dark once this many of its shadow rays (faded as the sums are) brought nothing:
  // the direct pass then takes an eighth of its samples there (samples_in).
  static constexpr std::uint64_t kDarkRays = 32;
  // The fixed point's one: a luminance of `unit` (the constructor's) sums as this (2^32: a light
  // 10^6 times dimmer than the brightest, seen at a thousandth of its radiance, still counts).
  static constexpr float kFixedOne = 4294967296.0f;

  // One region's table: its lights in decreasing weight and their cumulative weights, and the
  // weight of the lights seen there but left out (`rest`): the table's picks that land on it are
  // the hierarchy's, so a region seeing more than kMaxLights lights loses none of them.
  struct Table {
    int count = 0;
    float total = 0.0f;  // the kept lights' weights and rest
    float rest = 0.0f;
    std::uint32_t light[kMaxLights];
    float cdf[kMaxLights];
    // The probability that the table picks `index` itself (0 when it is not in the table).
    float pmf(std::uint32_t index) const;
    // The share of the table's picks that go to the hierarchy (rest / total).
    float rest_share() const { return rest / total; }
    // The mean over the lights the region's rays went toward of the share of each one's rays
    // that brought light (independent of how often each was picked).
    float lit_share = 1.0f;
  };

  // One thread's samples of a pass: per region and light, the summed luminance and the count.
  class Record {
   public:
    explicit Record(float unit = 1.0f)
        : scale_(kFixedOne / (unit > 0.0f && unit < 3.4e38f ? unit : 1.0f)) {}
    // A shadow ray traced from `region` toward `light`: `luminance`, the luminance of what it
    // brought (the light's emitted irradiance, not divided by the pick's probability; 0 when
    // it was occluded).
    void add(std::uint64_t region, std::uint32_t light, float luminance);
    // A texel's shadow rays toward area lights in `patch`: `rays` traced, `lit` of them brought
    // light (the dark test's counts).
    void add_patch(std::uint64_t patch, std::uint32_t rays, std::uint32_t lit);
    bool empty() const { return entries_.empty() && patches_.empty(); }

   private:
    friend class LightCache;
    struct Entry {  // 32 bytes
      std::uint64_t region;
      std::uint64_t sum;
      std::uint64_t count;
      std::uint32_t light;
      std::uint32_t lit;  // rays that brought light (saturating: at most 2^32 - 1)
    };
    // Every kCompactAt entries (or twice the distinct pairs, when more), the entries of the same
    // region and light are merged: a record holds about its distinct pairs, not one entry per
    // sample (the sums are integers, so merging early changes no table).
    static constexpr std::size_t kCompactAt = std::size_t{1} << 15;
    struct PatchEntry {
      std::uint64_t patch, rays, lit;
    };
    void compact();
    std::vector<Entry> entries_;
    std::vector<PatchEntry> patches_;  // texels of the same patch in a row merged
    std::size_t compact_at_ = kCompactAt;
    float scale_;
  };

  LightCache() = default;
  // A grid over `bounds` for `lights` emissive triangles; `unit`: a typical irradiance (the fixed
  // point's scale, say the brightest light's emitted radiance).
  LightCache(const Bounds& bounds, std::size_t lights, float unit);

  bool valid() const { return lights_ > 0; }
  std::size_t lights() const { return lights_; }
  float unit() const { return unit_; }
  // The region of the point p with unit normal n on `object`: its grid cube, its normal's
  // direction and its object (so the floors of two rooms learn apart where a wall runs through
  // a cube). A 64-bit hash of the three: two regions that collide share a table, which costs
  // efficiency, not correctness (a pick's probability is that of the table it used).
  std::uint64_t region(glm::vec3 p, glm::vec3 n, std::uint32_t object = 0) const;
  // The point's patch: as region(), on a grid kPatchSplit times finer, or as many times as keeps
  // its edge at least kMinPatchEdge (1 to kPatchSplit).
  std::uint64_t patch(glm::vec3 p, glm::vec3 n, std::uint32_t object = 0) const;
  // Its table; null where nothing has been learned.
  const Table* find(std::uint64_t region) const;
  // The table a texel's pick mixes with: find(region), but none for a texel that picks among the
  // lights in front of it (`front_list`) where more than kFrontLitShare of the region's rays
  // brought light.
  const Table* table_for(std::uint64_t region, bool front_list) const {
    const Table* t = find(region);
    return t != nullptr && front_list && t->lit_share > kFrontLitShare ? nullptr : t;
  }
  std::size_t regions() const { return tables_.size(); }
  // Whether no light has been seen from the patch in kDarkRays rays (none since they faded).
  bool dark(std::uint64_t patch) const { return dark_.contains(patch); }
  // The samples to take in a patch: `samples`, or in a dark one an eighth of them (at least
  // one): every texel still samples every light the hierarchy can pick, so its estimate stays
  // unbiased, and where light does come back the patch stops being dark at the next learn().
  int samples_in(std::uint64_t patch, int samples) const {
    return dark(patch) ? std::max(1, samples / 8) : samples;
  }

  // Adds the records' sums to the regions' (after fading those), and rebuilds the tables.
  void learn(std::vector<Record*> records);
  void clear();

  // A light for the hierarchy's point (`tree`: p, unit normal n), u uniform in [0, 1): by the
  // hierarchy alone without a table;
  // with one, by the hierarchy for u below kTreeShare, else by the table (whose `rest` defers to
  // the hierarchy). `pmf`: the probability of picking `index` by all those ways together,
  // (kTreeShare + (1 - kTreeShare) rest_share) p_hierarchy + (1 - kTreeShare) p_table. false: no
  // light picked (none can light p).
  static bool pick(LightTree::At& tree, const Table* table, float u, std::uint32_t& index,
                   float& pmf) {
    return mix(tree, table, u, index, pmf);
  }
  // pick() with another sampler of every light that can light p in the hierarchy's place (the
  // engine's per-texel list of the lights in front, LightSampler::FrontLights): `d` has
  // sample(u, index, pmf) and pmf(index), and must give every light that can light p a
  // probability above zero.
  template <class Defensive>
  static bool mix(Defensive& d, const Table* table, float u, std::uint32_t& index, float& pmf) {
    if (table == nullptr) return d.sample(u, index, pmf);
    constexpr float a = kTreeShare;
    // The sampler's share of all picks: its own and the table's rest.
    const float by_d = a + (1.0f - a) * table->rest_share();
    const float v = u < a ? 0.0f : std::min((u - a) / (1.0f - a), 0x1.fffffep-1f) * table->total;
    const float kept = table->cdf[table->count - 1];
    if (u < a || v >= kept) {
      // The sampler: u stretched over its part, or over the table's rest.
      const float w = u < a ? u / a : (v - kept) / table->rest;
      float pd;
      if (!d.sample(std::min(w, 0x1.fffffep-1f), index, pd)) return false;
      pmf = by_d * pd + (1.0f - a) * table->pmf(index);
      return true;
    }
    int k = 0;
    while (k + 1 < table->count && table->cdf[k] <= v) ++k;
    index = table->light[k];
    pmf = by_d * d.pmf(index) + (1.0f - a) * table->pmf(index);
    return pmf > 0.0f;
  }

 private:
  std::uint64_t key(glm::vec3 p, glm::vec3 n, std::uint32_t object, float inv_cell) const;
  void learn_patches(const std::vector<Record*>& records);

  glm::vec3 origin_{0.0f};
  float inv_cell_ = 1.0f;   // regions per metre
  float inv_patch_ = 1.0f;  // patches per metre (patch())
  std::size_t lights_ = 0;
  float unit_ = 1.0f;
  // Per region: each light's summed luminance (fixed point) and count of samples, by light.
  // 24 bytes. `lit` saturates at 2^32 - 1 (about 537 M lit rays a pass from one region to
  // one light, with the fade); the sum and the count, which make the mean, do not.
  struct Sum {
    std::uint64_t sum, count;
    std::uint32_t light, lit;
  };
  std::unordered_map<std::uint64_t, std::vector<Sum>> sums_;
  std::unordered_map<std::uint64_t, Table> tables_;
  // Per patch: its rays and those that brought light (in units of 2^-16, light_cache.cpp), faded
  // as the sums are; the dark ones.
  struct PatchSum {
    std::uint64_t rays, lit;
  };
  std::unordered_map<std::uint64_t, PatchSum> patch_sums_;
  std::unordered_set<std::uint64_t> dark_;
};

}  // namespace irradcast

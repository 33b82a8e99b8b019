#include "irradcast/common/light_cache.h"

#include <algorithm>
#include <cmath>

#include "irradcast/common/sampling.h"
#include "irradcast/common/world.h"

namespace irradcast {
namespace {

constexpr int kAxisBits = 20;  // per grid coordinate in a region's key
constexpr std::uint64_t kAxisMax = (std::uint64_t{1} << kAxisBits) - 1;
constexpr float kMaxSample = 4503599627370496.0f;  // 2^52: one sample's largest fixed point
// Record::add looks this far back for an entry of the same region and light (a thread's texels
// come in runs of one radiance cell, so few regions and lights at a time).
constexpr std::size_t kCoalesce = 64;
// Each learn() keeps 1 - 2^-kForget of the old sums (7/8: a light no longer seen fades out
// over tens of passes).
constexpr int kForget = 3;
// A patch's lit rays count 2^kLitShift each, so that one of them keeps the patch from being dark
// for about 80 passes (as a light's fixed-point sum keeps it in a region's table) rather than
// the next pass only.
constexpr int kLitShift = 16;
// 1 / LightCache::kMinPatchEdge.
constexpr float kMinPatchInv = 1.0f / LightCache::kMinPatchEdge;

// x less its 2^-kForget part, rounded up, so that every count reaches 0 (and its entry goes)
// once nothing adds to it.
std::uint64_t fade(std::uint64_t x) {
  constexpr std::uint64_t kMask = (std::uint64_t{1} << kForget) - 1;
  return x - (x >> kForget) - ((x & kMask) != 0 ? 1 : 0);
}

std::uint64_t saturating_add(std::uint64_t a, std::uint64_t b) {
  return a > ~b ? ~std::uint64_t{0} : a + b;
}

std::uint32_t saturating_add32(std::uint32_t a, std::uint64_t b) {
  return static_cast<std::uint32_t>(
      std::min<std::uint64_t>(a + std::min<std::uint64_t>(b, ~0u), ~0u));
}

// The direction of the normal's largest component: 0..5 (+x, -x, +y, -y, +z, -z).
std::uint64_t direction_of(glm::vec3 n) {
  const glm::vec3 a = glm::abs(n);
  const int axis = a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
  return static_cast<std::uint64_t>(2 * axis + (n[axis] < 0.0f ? 1 : 0));
}

// Sorts v by `less`, then merges each run of elements that are the `same` into its first
// (`merge`); returns how many are left.
template <class T, class Less, class Same, class Merge>
std::size_t merge_runs(std::vector<T>& v, Less less, Same same, Merge merge) {
  std::sort(v.begin(), v.end(), less);
  std::size_t out = 0;
  for (std::size_t k = 0; k < v.size(); ++k) {
    if (out > 0 && same(v[out - 1], v[k]))
      merge(v[out - 1], v[k]);
    else
      v[out++] = v[k];
  }
  v.resize(out);
  return out;
}

}  // namespace

float LightCache::Table::pmf(std::uint32_t index) const {
  for (int k = 0; k < count; ++k)
    if (light[k] == index) return (cdf[k] - (k > 0 ? cdf[k - 1] : 0.0f)) / total;
  return 0.0f;
}

void LightCache::Record::add(std::uint64_t region, std::uint32_t light, float luminance) {
  const float x = luminance * scale_;  // rounded; occluded (0) and NaN to 0
  const auto q =
      x > 0.0f ? static_cast<std::uint64_t>(std::min(x, kMaxSample) + 0.5f) : std::uint64_t{0};
  const std::size_t n = entries_.size();
  for (std::size_t k = n; k > 0 && n - k < kCoalesce; --k) {
    Entry& e = entries_[k - 1];
    if (e.region == region && e.light == light) {
      e.sum = saturating_add(e.sum, q);
      ++e.count;
      e.lit = saturating_add32(e.lit, q > 0 ? 1u : 0u);
      return;
    }
  }
  entries_.push_back({region, q, 1, light, q > 0 ? 1u : 0u});
  if (entries_.size() >= compact_at_) compact();
}

void LightCache::Record::add_patch(std::uint64_t patch, std::uint32_t rays, std::uint32_t lit) {
  if (rays == 0) return;
  if (!patches_.empty() && patches_.back().patch == patch) {
    patches_.back().rays += rays;
    patches_.back().lit += lit;
    return;
  }
  patches_.push_back({patch, rays, lit});
  if (patches_.size() >= compact_at_) compact();
}

void LightCache::Record::compact() {
  const std::size_t out = merge_runs(
      entries_,
      [](const Entry& a, const Entry& b) {
        return a.region != b.region ? a.region < b.region : a.light < b.light;
      },
      [](const Entry& a, const Entry& b) { return a.region == b.region && a.light == b.light; },
      [](Entry& m, const Entry& e) {
        m.sum = saturating_add(m.sum, e.sum);
        m.count += e.count;
        m.lit = saturating_add32(m.lit, e.lit);
      });
  const std::size_t patches = merge_runs(
      patches_, [](const PatchEntry& a, const PatchEntry& b) { return a.patch < b.patch; },
      [](const PatchEntry& a, const PatchEntry& b) { return a.patch == b.patch; },
      [](PatchEntry& m, const PatchEntry& e) {
        m.rays += e.rays;
        m.lit += e.lit;
      });
  compact_at_ = std::max(kCompactAt, 2 * std::max(out, patches));
}

LightCache::LightCache(const Bounds& bounds, std::size_t lights, float unit)
    : origin_(bounds.lo),
      inv_cell_(static_cast<float>(kRegionsAcross) / std::max(bounds.max_extent(), 1e-20f)),
      // kPatchSplit patches along a region's edge, fewer where they would be under
      // kMinPatchEdge.
      inv_patch_(inv_cell_ * std::clamp(std::floor(kMinPatchInv / inv_cell_), 1.0f,
                                        static_cast<float>(kPatchSplit))),
      lights_(lights),
      unit_(unit > 0.0f && std::isfinite(unit) ? unit : 1.0f) {}

std::uint64_t LightCache::region(glm::vec3 p, glm::vec3 n, std::uint32_t object) const {
  return key(p, n, object, inv_cell_);
}

std::uint64_t LightCache::patch(glm::vec3 p, glm::vec3 n, std::uint32_t object) const {
  return key(p, n, object, inv_patch_);
}

std::uint64_t LightCache::key(glm::vec3 p, glm::vec3 n, std::uint32_t object,
                              float inv_cell) const {
  const glm::vec3 g = (p - origin_) * inv_cell;
  auto axis = [](float v) {  // NaN and below 0 to 0
    return v > 0.0f ? static_cast<std::uint64_t>(std::min(v, static_cast<float>(kAxisMax))) : 0;
  };
  const std::uint64_t cube =
      (((axis(g.x) << kAxisBits | axis(g.y)) << kAxisBits | axis(g.z)) << 3) | direction_of(n);
  return mix64(cube) ^ (std::uint64_t{object} * 0x9E3779B97F4A7C15ull);
}

const LightCache::Table* LightCache::find(std::uint64_t region) const {
  const auto it = tables_.find(region);
  return it == tables_.end() ? nullptr : &it->second;
}

void LightCache::clear() {
  sums_.clear();
  tables_.clear();
  patch_sums_.clear();
  dark_.clear();
}

void LightCache::learn_patches(const std::vector<Record*>& records) {
  // Faded as the sums are, the new counts added; a patch with enough rays and none lit is dark.
  for (auto it = patch_sums_.begin(); it != patch_sums_.end();) {
    it->second.rays = fade(it->second.rays);
    it->second.lit = fade(it->second.lit);
    it = it->second.rays == 0 ? patch_sums_.erase(it) : std::next(it);
  }
  for (const Record* r : records)
    for (const Record::PatchEntry& e : r->patches_) {
      PatchSum& sum = patch_sums_[e.patch];
      sum.rays = saturating_add(sum.rays, e.rays);
      sum.lit = saturating_add(sum.lit, e.lit << kLitShift);
    }
  dark_.clear();
  for (const auto& [patch, sum] : patch_sums_)
    if (sum.lit == 0 && sum.rays >= kDarkRays) dark_.insert(patch);
}

void LightCache::learn(std::vector<Record*> records) {
  // The old sums and counts mostly kept (kForget), then the new ones added: integers, so the
  // order of records and entries does not change them.
  for (auto it = sums_.begin(); it != sums_.end();) {
    auto& sums = it->second;
    for (Sum& s : sums) {
      s.sum = fade(s.sum);
      s.count = fade(s.count);
      s.lit = static_cast<std::uint32_t>(std::min<std::uint64_t>(fade(s.lit), s.count));
    }
    std::erase_if(sums, [](const Sum& s) { return s.count == 0; });
    it = sums.empty() ? sums_.erase(it) : std::next(it);
  }
  for (Record* r : records)
    for (const Record::Entry& e : r->entries_) {
      if (e.light >= lights_) continue;
      auto& sums = sums_[e.region];
      const auto at = std::lower_bound(sums.begin(), sums.end(), e.light,
                                       [](const Sum& s, std::uint32_t l) { return s.light < l; });
      if (at != sums.end() && at->light == e.light) {
        at->sum = saturating_add(at->sum, e.sum);
        at->count = saturating_add(at->count, e.count);
        at->lit = saturating_add32(at->lit, e.lit);
      } else {
        sums.insert(at, {e.sum, e.count, e.light, e.lit});
      }
    }
  learn_patches(records);
  // Each region's table: its kMaxLights lights of the largest mean (ties by index).
  tables_.clear();
  tables_.reserve(sums_.size());
  std::vector<std::pair<double, std::uint32_t>> order;
  for (const auto& [region, sums] : sums_) {
    order.clear();
    // The lit share as the mean over the region's lights of the share of each one's rays that
    // brought light: what a pick that ignores the table would see, however often the table
    // picked each light (the share of all rays would grow with the table's skill, until the
    // table switched itself off: table_for()).
    double lit_rates = 0.0;
    std::size_t sampled = 0;
    for (const Sum& s : sums) {
      if (s.count > 0) {
        lit_rates += std::min(1.0, static_cast<double>(s.lit) / static_cast<double>(s.count));
        ++sampled;
      }
      if (s.sum > 0)
        order.push_back({static_cast<double>(s.sum) / static_cast<double>(s.count), s.light});
    }
    if (order.empty()) continue;
    const std::size_t keep = std::min<std::size_t>(order.size(), kMaxLights);
    std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(keep), order.end(),
                      [](const auto& a, const auto& b) {
                        return a.first != b.first ? a.first > b.first : a.second < b.second;
                      });
    Table t;
    float total = 0.0f;
    for (std::size_t k = 0; k < keep; ++k) {
      total += static_cast<float>(order[k].first);
      t.light[t.count] = order[k].second;
      t.cdf[t.count++] = total;
    }
    double rest = 0.0;
    for (std::size_t k = keep; k < order.size(); ++k) rest += order[k].first;
    t.rest = static_cast<float>(rest);
    t.total = total + t.rest;
    t.lit_share = sampled > 0 ? static_cast<float>(lit_rates / static_cast<double>(sampled)) : 1.0f;
    if (t.count > 0 && total > 0.0f) tables_.emplace(region, t);
  }
}

}  // namespace irradcast

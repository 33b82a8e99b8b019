// DilationPlan: the gap fill worked out once from the texel kinds, applied per bounce. Held
// against a plain statement of the rule (each ring fills every empty texel next to a filled one
// with the mean of its filled 8-neighbours, first + mean difference, read row by row), written
// here as a scan of the whole map per ring: the plan must give the same bits.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "dilation_plan.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/prepared_scene.h"

namespace irradcast::test_dilation_plan {

namespace {

std::vector<glm::vec3> fill_by_scans(std::vector<glm::vec3> v, int w, int h,
                                     const std::vector<TexelKind>& kind, int rings) {
  std::vector<std::uint8_t> filled(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) filled[i] = holds_estimate(kind[i]);
  for (int ring = 0; rings < 0 || ring < rings; ++ring) {
    std::vector<std::uint8_t> now = filled;
    bool any = false;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (filled[static_cast<std::size_t>(y) * w + x]) continue;
        glm::vec3 first(0.0f), diff(0.0f);
        int count = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
            const std::size_t j = static_cast<std::size_t>(ny) * w + nx;
            if (!filled[j]) continue;
            if (count++ == 0)
              first = v[j];
            else
              diff += v[j] - first;
          }
        if (count == 0) continue;
        v[static_cast<std::size_t>(y) * w + x] =
            count > 1 ? first + diff / static_cast<float>(count) : first;
        now[static_cast<std::size_t>(y) * w + x] = 1;
        any = true;
      }
    filled.swap(now);
    if (!any) break;
  }
  return v;
}

bool same_bits(const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
}

}  // namespace

TEST(DilationPlan, GivesTheBitsOfTheRuleOnRandomMaps) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> value(0.0f, 10.0f);
  for (int trial = 0; trial < 40; ++trial) {
    const int w = 1 + static_cast<int>(rng() % 40), h = 1 + static_cast<int>(rng() % 40);
    const float density = (trial % 4 + 1) * 0.08f;  // sparse to dense valid texels
    std::vector<TexelKind> kind(static_cast<std::size_t>(w) * h);
    std::vector<glm::vec3> v(kind.size());
    for (std::size_t i = 0; i < kind.size(); ++i) {
      const float u = std::uniform_real_distribution<float>(0.0f, 1.0f)(rng);
      kind[i] = u < density                 ? TexelKind::Covered
                : u < density * 1.5f        ? TexelKind::Conservative
                : u < density * 1.5f + 0.1f ? TexelKind::Hidden
                                            : TexelKind::Empty;
      v[i] = glm::vec3(value(rng), value(rng), value(rng));
    }
    for (int rings : {-1, 0, 1, 3}) {
      const DilationPlan plan(w, h, kind, rings);
      std::vector<glm::vec3> applied = v;
      plan.apply(applied);
      EXPECT_TRUE(same_bits(applied, fill_by_scans(v, w, h, kind, rings)))
          << w << "x" << h << " rings " << rings << " trial " << trial;
      // dilate() is the plan made for the call.
      std::vector<glm::vec3> dilated = v;
      dilate(dilated, w, h, kind, rings);
      EXPECT_TRUE(same_bits(applied, dilated));
    }
  }
}

TEST(DilationPlan, ListsEachFilledTexelOnceRingByRing) {
  // cornell's G-buffers: every empty texel that some valid one reaches is a target once, in
  // rings of growing distance, and its sources were filled before its ring.
  Progress::set_enabled(false);
  PreparedSceneOptions o;
  o.atlas.texels_per_scene = 48.0f;
  const PreparedScene p = PreparedScene::build(make_cornell_box(), o);
  for (const TexelGBuffer& g : p.gbuffers()) {
    const DilationPlan plan(g.width, g.height, g.kind);
    std::vector<int> ring_of(g.size(), -1);
    for (std::size_t i = 0; i < g.size(); ++i)
      if (g.valid(i)) ring_of[i] = 0;
    for (std::size_t r = 0; r < plan.rings(); ++r)
      for (std::uint32_t k = plan.ring_begin(r); k < plan.ring_end(r); ++k) {
        const std::uint32_t i = plan.target()[k];
        ASSERT_EQ(ring_of[i], -1) << "texel " << i << " listed twice";
        ASSERT_NE(plan.sources()[k], 0) << "texel " << i << " without a source";
        const int x = static_cast<int>(i % g.width), y = static_cast<int>(i / g.width);
        int b = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            if (dx == 0 && dy == 0) continue;
            if (plan.sources()[k] >> b++ & 1u) {
              const int s = ring_of[static_cast<std::size_t>(y + dy) * g.width + (x + dx)];
              ASSERT_GE(s, 0);
              ASSERT_LE(s, static_cast<int>(r));
            }
          }
        ring_of[i] = static_cast<int>(r) + 1;
      }
    for (std::size_t i = 0; i < g.size(); ++i) EXPECT_GE(ring_of[i], 0) << i;  // all reached
  }
}

TEST(DilationPlan, RefusesValuesOfAnotherSize) {
  const std::vector<TexelKind> kind(12, TexelKind::Covered);
  EXPECT_THROW(DilationPlan(3, 5, kind), Error);
  const DilationPlan plan(3, 4, kind);
  std::vector<glm::vec3> v(11);
  EXPECT_THROW(plan.apply(v), Error);
}

}  // namespace irradcast::test_dilation_plan

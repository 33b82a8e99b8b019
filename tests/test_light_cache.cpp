// The learned light tables (light_cache.h): a region is a grid cube, a normal direction (the two
// faces of a wall learn apart) and an object (the floors either side of it do); the tables do not
// depend on the order in which samples are added (the same seed, the same lightmaps on any number
// of threads); the mixture of the light hierarchy and a table picks each light exactly as often
// as the probability it returns; and in the engine's direct pass on a building of 72 emissive
// triangles, learning keeps the mean and brings most texels closer to the truth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "engine_setup.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/light_cache.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/sampling.h"
#include "scene_builders.h"

namespace irradcast::test_light_cache {

namespace {

Bounds box(glm::vec3 lo, glm::vec3 hi) {
  Bounds b;
  b.extend(lo);
  b.extend(hi);
  return b;
}

// `count` small triangles scattered over a 10 m box, facing every way, some double sided.
std::vector<EmissiveTriangle> triangles(int count, std::uint64_t seed) {
  std::vector<EmissiveTriangle> out;
  Rng rng(seed);
  for (int k = 0; k < count; ++k) {
    EmissiveTriangle t;
    t.p0 = glm::vec3(rng.next_float(), rng.next_float(), rng.next_float()) * 10.0f;
    t.e1 = glm::vec3(rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f);
    t.e2 = glm::vec3(rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f);
    const glm::vec3 c = glm::cross(t.e1, t.e2);
    t.area = 0.5f * glm::length(c);
    t.normal = glm::normalize(c);
    t.double_sided = k % 7 == 0;
    out.push_back(t);
  }
  return out;
}

bool same_table(const LightCache::Table& a, const LightCache::Table& b) {
  return a.count == b.count && a.total == b.total &&
         std::memcmp(a.light, b.light, sizeof(a.light[0]) * a.count) == 0 &&
         std::memcmp(a.cdf, b.cdf, sizeof(a.cdf[0]) * a.count) == 0;
}

}  // namespace

TEST(LightCache, RegionsAreGridCubesNormalDirectionsAndObjects) {
  const LightCache c(box(glm::vec3(0.0f), glm::vec3(24.0f)), 10, 1.0f);  // 1 m regions
  const glm::vec3 up(0, 1, 0), east(1, 0, 0);
  EXPECT_EQ(c.region({3.2f, 1.5f, 7.7f}, up), c.region({3.9f, 1.1f, 7.1f}, up));
  EXPECT_NE(c.region({3.2f, 1.5f, 7.7f}, up), c.region({4.2f, 1.5f, 7.7f}, up));
  // The two faces of a wall: the same cube, opposite normals.
  EXPECT_NE(c.region({5.0f, 1.0f, 2.0f}, east), c.region({5.0f, 1.0f, 2.0f}, -east));
  // The normal's largest component decides; points outside the bounds clamp to the edge cubes.
  EXPECT_EQ(c.region({2.5f, 2.5f, 2.5f}, glm::normalize(glm::vec3(0.2f, 0.9f, 0.3f))),
            c.region({2.5f, 2.5f, 2.5f}, up));
  EXPECT_EQ(c.region({-5.0f, 0.5f, 0.5f}, up), c.region({0.5f, 0.5f, 0.5f}, up));
  // Two objects in one cube (the floors either side of a wall) learn apart.
  EXPECT_EQ(c.region({3.2f, 0.0f, 7.7f}, up, 5), c.region({3.9f, 0.0f, 7.1f}, up, 5));
  EXPECT_NE(c.region({3.2f, 0.0f, 7.7f}, up, 5), c.region({3.9f, 0.0f, 7.1f}, up, 6));
  // NaN positions fall in a region (the grid's first cube) rather than anywhere undefined.
  const float nan = std::nanf("");
  EXPECT_EQ(c.region({nan, 0.5f, 0.5f}, up), c.region({0.5f, 0.5f, 0.5f}, up));
}

// The dark test's patches: a region's cube split kPatchSplit ways along each axis. Where light
// reaches part of a region (its table learns from the lit part), a patch no light reaches
// becomes dark once kDarkRays of its rays brought nothing, takes an eighth of the samples, and
// stops being dark at the first learn() after one of its rays brings light.
TEST(LightCache, PatchesNoLightReachesAreDarkInsideALitRegion) {
  const LightCache c(box(glm::vec3(0.0f), glm::vec3(24.0f)), 10, 1.0f);  // 1 m regions
  const glm::vec3 up(0, 1, 0);
  const float patch = 1.0f / LightCache::kPatchSplit;
  const glm::vec3 lit_p(3.01f, 0.5f, 7.01f), shade_p = lit_p + glm::vec3(0.5f, 0.0f, 0.5f);
  ASSERT_EQ(c.region(lit_p, up, 2), c.region(shade_p, up, 2));
  EXPECT_NE(c.patch(lit_p, up, 2), c.patch(shade_p, up, 2));
  EXPECT_EQ(c.patch(lit_p, up, 2), c.patch(lit_p + glm::vec3(0.9f * patch, 0, 0), up, 2));
  EXPECT_NE(c.patch(lit_p, up, 2), c.patch(lit_p, up, 3));
  EXPECT_NE(c.patch(lit_p, up, 2), c.patch(lit_p, -up, 2));
  // A small scene's regions (an 8 m box: 33 cm) are not split under kMinPatchEdge: its patches
  // are its regions; a 16 m box's 67 cm regions split in two.
  const LightCache small(box(glm::vec3(0.0f), glm::vec3(8.0f)), 10, 1.0f);
  const glm::vec3 q(1.01f, 0.5f, 1.01f), q_quarter = q + glm::vec3(0.3f / 4.0f, 0.0f, 0.0f);
  ASSERT_EQ(small.region(q, up), small.region(q_quarter, up));
  EXPECT_EQ(small.patch(q, up), small.patch(q_quarter, up));
  const LightCache middle(box(glm::vec3(0.0f), glm::vec3(16.0f)), 10, 1.0f);
  const glm::vec3 m(2.01f, 0.5f, 2.01f);
  ASSERT_EQ(middle.region(m, up), middle.region(m + glm::vec3(0.6f, 0, 0), up));
  EXPECT_EQ(middle.patch(m, up), middle.patch(m + glm::vec3(0.3f, 0, 0), up));
  EXPECT_NE(middle.patch(m, up), middle.patch(m + glm::vec3(0.6f, 0, 0), up));

  LightCache cache(box(glm::vec3(0.0f), glm::vec3(24.0f)), 10, 1.0f);
  const std::uint64_t region = cache.region(lit_p, up, 2);
  const std::uint64_t lit = cache.patch(lit_p, up, 2), shade = cache.patch(shade_p, up, 2);
  // One learn() of 8 texels a patch, 8 rays each: light 3 seen from one patch, nothing from the
  // other.
  auto pass = [&](int shade_lit) {
    LightCache::Record r(cache.unit());
    for (int texel = 0; texel < 8; ++texel) {
      for (int ray = 0; ray < 8; ++ray) r.add(region, 3, ray % 2 == 0 ? 1.0f : 0.0f);
      r.add_patch(lit, 8, 4);
      for (int ray = 0; ray < 8; ++ray) r.add(region, 3, 0.0f);
      r.add_patch(shade, 8, texel == 0 ? static_cast<std::uint32_t>(shade_lit) : 0u);
    }
    cache.learn({&r});
  };
  static_assert(LightCache::kDarkRays <= 64);
  pass(0);  // 64 rays from the shaded patch, none lit
  ASSERT_NE(cache.find(region), nullptr) << "the region learned light 3";
  EXPECT_TRUE(cache.dark(shade));
  EXPECT_FALSE(cache.dark(lit));
  EXPECT_EQ(cache.samples_in(shade, 64), 8);
  EXPECT_EQ(cache.samples_in(shade, 4), 1);
  EXPECT_EQ(cache.samples_in(lit, 64), 64);
  pass(1);  // one ray brought light: no longer dark, for as long as that ray counts
  EXPECT_FALSE(cache.dark(shade));
  for (int k = 0; k < 3; ++k) pass(0);
  EXPECT_FALSE(cache.dark(shade)) << "a lit ray fades out slowly";
  cache.clear();
  EXPECT_FALSE(cache.dark(shade));
}

TEST(LightCache, TablesDoNotDependOnTheOrderOfTheSamples) {
  const Bounds b = box(glm::vec3(0.0f), glm::vec3(10.0f));
  LightCache one(b, 50, 2.0f), other(b, 50, 2.0f);
  struct Sample {
    std::uint64_t region;
    std::uint32_t light;
    float value;
  };
  std::vector<Sample> samples;
  Rng rng(5);
  // About 3,000 samples in each of 27 regions: the one record below merges its entries on the way
  // (past Record::kCompactAt, 32 k; few of its 80 k samples find their pair among the last 64
  // entries), the three records of about 27 k samples each do not.
  for (int k = 0; k < 80000; ++k) {
    const glm::vec3 p(rng.next_float(), rng.next_float(), rng.next_float());
    samples.push_back({one.region(p, glm::vec3(0, 1, 0)),
                       static_cast<std::uint32_t>(rng.next_float() * 50.0f),
                       std::exp(8.0f * rng.next_float() - 4.0f)});
  }
  for (int round = 0; round < 2; ++round) {
    // In order into one record, against reversed and dealt over three records.
    LightCache::Record a(one.unit());
    for (const Sample& s : samples) a.add(s.region, s.light, s.value);
    LightCache::Record r[3] = {LightCache::Record(other.unit()), LightCache::Record(other.unit()),
                               LightCache::Record(other.unit())};
    for (std::size_t k = samples.size(); k-- > 0;)
      r[k % 3].add(samples[k].region, samples[k].light, samples[k].value);
    one.learn({&a});
    other.learn({&r[2], &r[0], &r[1]});
    std::reverse(samples.begin(), samples.end());
  }
  ASSERT_GT(one.regions(), 20u);
  ASSERT_EQ(one.regions(), other.regions());
  int full = 0;
  for (const Sample& s : samples) {
    const LightCache::Table* x = one.find(s.region);
    const LightCache::Table* y = other.find(s.region);
    ASSERT_NE(x, nullptr);
    ASSERT_NE(y, nullptr);
    EXPECT_TRUE(same_table(*x, *y));
    full += x->count == LightCache::kMaxLights;
    EXPECT_GE(x->pmf(x->light[0]), x->pmf(x->light[x->count - 1])) << "heaviest first";
  }
  EXPECT_GT(full, 0) << "some regions saw more lights than a table holds";
}

// The gate of the front lists' mixture (table_for) follows how much of each light the region
// sees, not how well its table already picks: a region whose rays mostly went, by its table, to
// the one light it sees keeps the table (the share of all its rays that brought light, 100 of
// 115, would have turned it off), and a region that sees every light unoccluded (a furnace)
// loses it.
TEST(LightCache, TheFrontListsGateDoesNotFollowTheTablesOwnPicks) {
  const Bounds b = box(glm::vec3(0.0f), glm::vec3(10.0f));
  LightCache cache(b, 4, 1.0f);
  const std::uint64_t room = cache.region(glm::vec3(1.0f), glm::vec3(0, 1, 0));
  const std::uint64_t furnace = cache.region(glm::vec3(9.0f), glm::vec3(0, 1, 0));
  ASSERT_NE(room, furnace);
  LightCache::Record r(cache.unit());
  for (int k = 0; k < 100; ++k) r.add(room, 0, 1.0f);  // the light it sees, picked by the table
  for (std::uint32_t light = 1; light < 4; ++light)
    for (int k = 0; k < 5; ++k) r.add(room, light, 0.0f);  // the others, behind walls
  for (std::uint32_t light = 0; light < 4; ++light)
    for (int k = 0; k < 20; ++k) r.add(furnace, light, 1.0f);
  cache.learn({&r});
  ASSERT_NE(cache.find(room), nullptr);
  ASSERT_NE(cache.find(furnace), nullptr);
  EXPECT_NEAR(cache.find(room)->lit_share, 0.25f, 1e-6f);
  EXPECT_EQ(cache.table_for(room, true), cache.find(room));
  EXPECT_FLOAT_EQ(cache.find(furnace)->lit_share, 1.0f);
  EXPECT_EQ(cache.table_for(furnace, true), nullptr);
  EXPECT_EQ(cache.table_for(furnace, false), cache.find(furnace));  // the hierarchy's mixture
}

// At points all over the lights' box, with a table of a few of the lights (some the hierarchy
// never picks there), or of more than a table keeps: each light is picked as often as the
// probability the pick returns for it, which is the mixture's. The probabilities sum to at most
// one: the hierarchy's part of the picks fails where a subtree can light nothing at the point (its
// share of the sum is missing then, and the pick returns false as often).
TEST(LightCache, TheMixturePicksEachLightAsOftenAsItsProbability) {
  const std::vector<EmissiveTriangle> t = triangles(300, 11);
  std::vector<float> power;
  for (const EmissiveTriangle& e : t) power.push_back(e.area * (e.double_sided ? 2.0f : 1.0f));
  const LightTree tree(t, power);
  const Bounds b = box(glm::vec3(0.0f), glm::vec3(10.0f));
  Rng rng(3);
  for (int point = 0; point < 6; ++point) {
    const glm::vec3 p = glm::vec3(rng.next_float(), rng.next_float(), rng.next_float()) * 10.0f;
    const glm::vec3 n = glm::normalize(
        glm::vec3(rng.next_float() - 0.5f, rng.next_float() - 0.5f, rng.next_float() - 0.5f));
    LightCache cache(b, t.size(), 1.0f);
    LightCache::Record r(cache.unit());
    // 12 lights at 3 points, 40 at the others (more than a table keeps: the rest is the
    // hierarchy's).
    const int seen = point < 3 ? 12 : 40;
    for (int k = 0; k < seen; ++k)
      r.add(cache.region(p, n), static_cast<std::uint32_t>(k * 23 % 300), 1.0f + k);
    cache.learn({&r});
    const LightCache::Table* table = cache.find(cache.region(p, n));
    ASSERT_NE(table, nullptr);
    ASSERT_EQ(table->count, std::min(seen, LightCache::kMaxLights));
    EXPECT_EQ(table->rest > 0.0f, seen > LightCache::kMaxLights);
    const double a = LightCache::kTreeShare;
    const double by_tree = a + (1.0 - a) * table->rest_share();
    std::vector<double> expected(t.size());
    double sum = 0.0;
    for (std::uint32_t i = 0; i < t.size(); ++i) {
      expected[i] = by_tree * tree.pmf(p, n, i) + (1.0 - a) * table->pmf(i);
      sum += expected[i];
    }
    EXPECT_LE(sum, 1.0 + 1e-4);
    EXPECT_GE(sum, 1.0 - by_tree - 1e-4);
    std::vector<int> hits(t.size(), 0);
    int failed = 0;
    constexpr int kPicks = 200000;
    LightTree::At at(tree, p, n);  // one point's walks, shared by all its picks
    for (int k = 0; k < kPicks; ++k) {
      std::uint32_t i;
      float pmf;
      const float u = (static_cast<float>(k) + rng.next_float()) / kPicks;
      if (!LightCache::pick(at, table, u, i, pmf)) {
        ++failed;
        // Only the hierarchy's picks can fail: its own, and the table's rest.
        const double kept = a + (1.0 - a) * (1.0 - table->rest_share());
        ASSERT_TRUE(u < a || u >= kept - 1e-6) << "u " << u;
        continue;
      }
      ASSERT_LT(i, t.size());
      ASSERT_GT(expected[i], 0.0);
      ASSERT_NEAR(pmf / expected[i], 1.0, 1e-4) << "light " << i;
      ++hits[i];
    }
    EXPECT_NEAR(failed, (1.0 - sum) * kPicks, 5.0 * std::sqrt((1.0 - sum) * kPicks) + 2.0);
    for (std::uint32_t i = 0; i < t.size(); ++i) {
      const double mean = expected[i] * kPicks;
      EXPECT_NEAR(hits[i], mean, 5.0 * std::sqrt(mean) + 2.0) << "light " << i;
    }
  }
}

// The engine's direct sample among the lights in front of a texel, mixed with a table
// (LightCache::mix with the front list by power): the same mean as the front list alone. Inside
// the furnace's closed box (12 emissive triangles, every one visible from every point) with
// tables that favour some lights, leave some out and name one behind the point.
TEST(LightCache, TheFrontListsMixtureKeepsTheMean) {
  const test::EngineSetup s(test::closed_box(glm::vec3(0.5f), glm::vec3(1.0f)), 8.0f);
  const LightSampler& l = s.lights;
  ASSERT_EQ(l.emissive_triangles().size(), 12u);
  const Bounds b = s.world.bounds;
  const struct {
    glm::vec3 p, n;
  } points[] = {{{0.1f, -1.0f, 0.3f}, {0, 1, 0}},
                {{-0.7f, 0.2f, 1.0f}, {0, 0, -1}},
                {{0.95f, 0.9f, -0.2f}, {-1, 0, 0}}};
  for (const auto& pt : points) {
    LightSampler::FrontLights front;
    ASSERT_TRUE(l.front_lights(pt.p, pt.n, front));
    LightCache cache(b, 12, 1.0f);
    LightCache::Record r(cache.unit());
    for (std::uint32_t k = 0; k < 12; k += 2) r.add(cache.region(pt.p, pt.n), k, 1.0f + 3.0f * k);
    cache.learn({&r});
    const LightCache::Table* table = cache.find(cache.region(pt.p, pt.n));
    ASSERT_NE(table, nullptr);
    double mean[2] = {0.0, 0.0};
    constexpr int kSamples = 400000;
    for (int way = 0; way < 2; ++way) {
      Rng rng(9);
      for (int k = 0; k < kSamples; ++k) {
        const glm::vec3 u((static_cast<float>(k) + rng.next_float()) / kSamples, rng.next_2d());
        LightSampler::ShadowSample smp;
        glm::vec3 w(0.0f);
        if (l.direct_sample(s.rays, &front, pt.p, pt.n, pt.n, u, smp, w, way ? table : nullptr))
          mean[way] += (w.x + w.y + w.z) / kSamples;
      }
    }
    // The pass's own way: 8 stratified samples a call (LightSampler::direct_samples).
    double batched = 0.0;
    Rng rng(5);
    constexpr int kCalls = kSamples / 8;
    for (int c = 0; c < kCalls; ++c) {
      LightSampler::ShadowSample smp[8];
      glm::vec3 w[8];
      bool lit[8];
      l.direct_samples(s.rays, &front, pt.p, pt.n, pt.n, rng, 0, 8, 8, smp, w, lit, table);
      for (int k = 0; k < 8; ++k)
        if (lit[k]) batched += (w[k].x + w[k].y + w[k].z) / kSamples;
    }
    EXPECT_NEAR(batched / mean[0], 1.0, 0.01) << "point " << pt.p.x << "," << pt.p.y;
    EXPECT_GT(mean[0], 1.0);
    EXPECT_NEAR(mean[1] / mean[0], 1.0, 0.01) << "point " << pt.p.x << "," << pt.p.y;
  }
}

namespace {

// The Embree backend learning light tables or not, keeping every direct pass's output.
class RecordingDirect final : public test::EmbreeForwarder {
 public:
  RecordingDirect(const RayScene& rays, const LightSampler& lights, bool learn)
      : EmbreeForwarder(rays, lights) {
    inner.set_learn_lights(learn);
  }
  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override {
    const PassResult r = inner.direct(in, out);
    outputs.push_back(out);
    position = in.texels.position;
    normal = in.texels.normal;
    geo_normal.resize(in.texels.size());
    for (std::size_t i = 0; i < in.texels.size(); ++i)
      geo_normal[i] = in.texels.geo_normal(in.world, i);
    return r;
  }
  std::vector<std::vector<glm::vec3>> outputs;
  std::vector<glm::vec3> position, normal, geo_normal;  // the texels' (the last pass's)
};

// Per texel, the mean luminance of passes from..end.
std::vector<double> mean_of(const std::vector<std::vector<glm::vec3>>& passes, std::size_t from) {
  std::vector<double> mean(passes[from].size(), 0.0);
  const double k = static_cast<double>(passes.size() - from);
  for (std::size_t u = from; u < passes.size(); ++u)
    for (std::size_t i = 0; i < mean.size(); ++i) mean[i] += luminance(passes[u][i]) / k;
  return mean;
}

}  // namespace

// rooms:6:lit at low detail (72 emissive triangles, over LightSampler::kMaxFront; ceiling
// panels only, no light within centimetres of a surface): the direct pass with learned tables
// against the hierarchy alone, 2 passes to learn and 12 compared, both against the truth at every
// 16th texel (the sum over every light of 8 x 8 stratified samples of it). Over those texels both
// means are within 2 % of the truth (unbiased), and the learned tables bring most texels closer
// to it (at the same samples; irradcast-bench-lights measures the error at the same time).
TEST(LightCache, LearningKeepsTheDirectPassUnbiasedAndLowersItsError) {
  RoomsOptions ro;
  ro.n = 6;
  ro.detail = 0.5f;
  ro.every_room_lit = true;
  const test::EngineSetup s(make_rooms(ro), 48.0f);
  ASSERT_GT(s.lights.emissive_triangles().size(), std::size_t{LightSampler::kMaxFront});
  ASSERT_FALSE(s.lights.tree().empty());
  EngineParams p;
  p.indirect_bounces = 0;
  auto learned = std::make_unique<RecordingDirect>(s.rays, s.lights, true);
  auto tree = std::make_unique<RecordingDirect>(s.rays, s.lights, false);
  const RecordingDirect& l = *learned;
  const RecordingDirect& t = *tree;
  auto e1 = s.engine(p, std::move(learned));
  auto e2 = s.engine(p, std::move(tree));
  constexpr int kLearn = 2, kPasses = 14;
  for (int u = 0; u < kPasses; ++u) {
    e1->update();
    e2->update();
  }
  const std::vector<double> ml = mean_of(l.outputs, kLearn), mt = mean_of(t.outputs, kLearn);
  const std::size_t lights = s.lights.emissive_triangles().size();
  double truth_sum = 0.0, sum_l = 0.0, sum_t = 0.0, err_l = 0.0, err_t = 0.0;
  std::size_t compared = 0, lit = 0, closer = 0;
  for (std::size_t i = 0; i < ml.size(); i += 16) {
    double truth = 0.0;
    for (std::size_t k = 0; k < lights; ++k)
      for (int q = 0; q < 64; ++q) {
        const glm::vec2 u((static_cast<float>(q % 8) + 0.5f) / 8.0f,
                          (static_cast<float>(q / 8) + 0.5f) / 8.0f);
        truth += luminance(s.lights.triangle_irradiance(s.rays, k, l.position[i], l.normal[i],
                                                        l.geo_normal[i], u)) /
                 64.0;
      }
    truth_sum += truth;
    sum_l += ml[i];
    sum_t += mt[i];
    err_l += (ml[i] - truth) * (ml[i] - truth);
    err_t += (mt[i] - truth) * (mt[i] - truth);
    ++compared;
    if (truth > 0.0) {
      ++lit;
      closer += std::fabs(ml[i] - truth) < std::fabs(mt[i] - truth);
    }
  }
  RecordProperty("mean_learned_over_truth", std::to_string(sum_l / truth_sum));
  RecordProperty("mean_tree_over_truth", std::to_string(sum_t / truth_sum));
  RecordProperty("squared_error_tree_over_learned", std::to_string(err_t / err_l));
  RecordProperty("texels_closer_learned", std::to_string(static_cast<double>(closer) / lit));
  ASSERT_GT(compared, 300u);
  ASSERT_GT(truth_sum, 0.0);
  EXPECT_NEAR(sum_l / truth_sum, 1.0, 0.02);
  EXPECT_NEAR(sum_t / truth_sum, 1.0, 0.02);
  // Seeds 1-7: the learned mean is the closer to the truth at 57-61 % of the lit texels (half,
  // within 2 % either way, if learning did nothing). The summed squared error is 0.95-1.44 times
  // lower: a few texels decide it, so it is only required not to be much higher (a heavy-tailed
  // learning signal, the weight over the pick's probability, gave 0.35).
  EXPECT_GT(static_cast<double>(closer) / static_cast<double>(lit), 0.54)
      << "the learned tables should bring most texels closer to the truth";
  EXPECT_GT(err_t / err_l, 0.8) << "the learned tables should not raise the error";
}

}  // namespace irradcast::test_light_cache

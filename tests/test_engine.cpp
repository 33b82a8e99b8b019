#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "embree_backend.h"
#include "engine_setup.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/engine.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/reference_lightmaps.h"
#include "irradcast/engine/texel_validity.h"
#include "scene_builders.h"

namespace irradcast::test_engine {

using test::EngineSetup;
using test::mean_valid;

class EngineFurnace : public ::testing::TestWithParam<std::tuple<float, float>> {};

// Closed room, every surface emitting Le with albedo rho, 1 direct + K indirect bounces: the
// irradiance everywhere is pi Le (1 - rho^(K+1)) / (1 - rho).
TEST_P(EngineFurnace, LightmapsConvergeToTheAnalyticIrradiance) {
  auto [rho, range] = GetParam();
  const float le = 1.0f;
  EngineSetup s(test::closed_box(glm::vec3(rho), glm::vec3(le)), 24.0f);
  EngineParams p;
  p.tracing_range = range;
  p.indirect_bounces = 2;
  auto engine = s.engine(p);
  for (int u = 0; u < 4; ++u) engine->update();
  double measured = mean_valid(s, engine->lightmaps());
  double expected = kPi * le * (1.0 - std::pow(rho, 3.0)) / (1.0 - rho);
  RecordProperty("relative_error", std::to_string(measured / expected - 1.0));
  EXPECT_NEAR(measured, expected, 0.02 * expected) << "rho " << rho << " range " << range;
}

INSTANTIATE_TEST_SUITE_P(Engine, EngineFurnace,
                         ::testing::Values(std::make_tuple(0.5f, 0.3f), std::make_tuple(0.8f, 0.3f),
                                           std::make_tuple(0.5f, INFINITY),
                                           std::make_tuple(0.8f, INFINITY)));

TEST(Engine, FixedSeedGivesBitIdenticalLightmaps) {
  EngineSetup s(make_cornell_box(), 32.0f);
  EngineParams p;
  p.seed = 11;
  auto a = s.engine(p), b = s.engine(p);
  a->update();
  a->update();
  b->update();
  b->update();
  auto la = a->lightmaps(), lb = b->lightmaps();
  ASSERT_EQ(la.size(), lb.size());
  for (std::size_t o = 0; o < la.size(); ++o) EXPECT_EQ(la[o].texels, lb[o].texels) << o;
  p.seed = 12;
  auto c = s.engine(p);
  c->update();
  c->update();
  EXPECT_NE(c->lightmaps()[0].texels, la[0].texels);
}

// Random numbers are drawn per texel (seed, texel, update, pass), never per thread or per work
// unit, so the dispatch order changes the memory access pattern but not one bit of the result.
TEST(Engine, PerCellAndPerObjectDispatchGiveTheSameLightmaps) {
  EngineSetup s(make_cornell_box(), 32.0f);
  EngineParams cell, object;
  cell.dispatch = Dispatch::PerCell;
  object.dispatch = Dispatch::PerObject;
  auto a = s.engine(cell), b = s.engine(object);
  for (int u = 0; u < 2; ++u) {
    a->update();
    b->update();
  }
  auto la = a->lightmaps(), lb = b->lightmaps();
  ASSERT_EQ(la.size(), lb.size());
  std::size_t texels = 0;
  for (std::size_t o = 0; o < la.size(); ++o) {
    EXPECT_EQ(la[o].texels, lb[o].texels) << "object " << o;
    texels += la[o].texels.size();
  }
  EXPECT_GT(texels, 1000u);
}

// The composed Cornell view against the reference path tracer at the same bounce count.
// Bound: relative MSE below 0.01 at 16 updates. Justification: at this lightmap density
// (64 texels across the box) the lightmaps carry residual Monte Carlo noise of a few percent per
// texel, which alone gives a relative MSE of about 1e-3; the reference's own noise at 1024 spp
// adds about 1e-3; the biased mode's probe approximation adds a few 1e-3 near corners. And the
// error must fall as updates accumulate.
class EngineCornell : public ::testing::TestWithParam<float> {};

TEST_P(EngineCornell, ComposedViewMatchesTheReferenceAndImprovesWithSamples) {
  const float range = GetParam();
  EngineSetup s(make_cornell_box(), 64.0f);
  const test::ReferenceView view(s);
  EngineParams p;
  p.tracing_range = range;
  auto engine = s.engine(p);
  const auto [first, last] = view.after_1_and_16_updates(*engine);
  EXPECT_LT(last, 0.01);
  EXPECT_LT(last, 0.7 * first) << "error must fall as samples accumulate";
  EXPECT_LT(engine->mean_relative_error(), 0.1);
}

INSTANTIATE_TEST_SUITE_P(Engine, EngineCornell, ::testing::Values(0.3f, INFINITY));

TEST(Engine, ProbesInsideGeometryAreMovedOut) {
  // A solid block straddling the centre of the only cell: its probe starts inside it.
  Scene s = test::closed_box(glm::vec3(0.5f), glm::vec3(0.0f));
  std::uint32_t white = test::add_material(s, glm::vec3(0.5f));
  const glm::vec3 lo(-0.3f), hi(0.3f);
  test::add_block(s, "block", lo, hi, white);
  EngineSetup setup(std::move(s), 16.0f);
  EngineParams p;
  p.cell_size = 1.0f;  // one cell, its probe at the centre of the block
  auto moved = setup.engine(p);
  ASSERT_EQ(moved->probes().count(), 1u);
  EXPECT_EQ(moved->probe_stats().relocated, 1u);
  glm::vec3 q = moved->probes().position[0];
  bool inside = glm::all(glm::greaterThan(q, lo)) && glm::all(glm::lessThan(q, hi));
  EXPECT_FALSE(inside) << q.x << "," << q.y << "," << q.z;
  // And out in the open, far from both the block and the box's walls (at +-1): the farthest any
  // spot gets from both is 0.44 (on a diagonal); the coarse-to-fine search finds 0.37 (the 9 x 9
  // x 9 lattice it replaced, 0.325 at best).
  const float to_block = glm::length(glm::max(glm::abs(q) - hi, glm::vec3(0.0f)));
  const float to_wall = 1.0f - std::max({std::abs(q.x), std::abs(q.y), std::abs(q.z)});
  std::printf("relocated probe at %.4f %.4f %.4f: %.4f from the block, %.4f from a wall\n", q.x,
              q.y, q.z, to_block, to_wall);
  EXPECT_GE(std::min(to_block, to_wall), 0.3f);
  p.relocate_probes = false;
  auto kept = setup.engine(p);
  EXPECT_EQ(kept->probe_stats().relocated, 0u);
  EXPECT_EQ(kept->probes().position[0], glm::vec3(0.0f));
}

// Probe leaks (seed 001, section 4.3.2): at a tracing range of 0.05 almost every hemisphere ray
// of the scatter pass ends at a probe, and probes interpolated across a wall carry the lit
// neighbour's light into an unlit room (light leaks), while probes inside slabs carry darkness
// (dark leaks). rooms:2 lights rooms (1,0) and (0,1); rooms (0,0) and (1,1) get their light only
// through the doorways. The texels of each unlit room are grouped by object (walls, floor,
// ceiling, each piece of furniture), and each group's mean irradiance is compared with the mean
// of reference lightmaps over the same texels. Cells are 0.125 of the scene (one probe per 2 m,
// i.e. 2 per room per axis): a range this short needs cells of a comparable size (with 0.25
// cells the probe approximation alone is off by 30-50% in the dim rooms, leaks or not).
// Bounds, with relocation and visibility: each unlit room's mean within 10% of the reference and
// the texel-weighted mean absolute error of its groups below 12% of the mean (measured: 3%
// and 8.5%, and 6%). Group means average hundreds of texels, so Monte Carlo noise adds about 1% to
// either. Without the fixes the same measures must show the seed's leaks (measured: walls shared
// with a lit room at 2.6x the reference, group error 38%), so the test tells the two apart.
namespace {
struct LeakErrors {
  double room[2][2] = {};     // engine room mean / reference room mean - 1
  double group_error = 0.0;   // sum |engine - reference| over groups / sum reference
  double shared_walls = 0.0;  // engine / reference on the walls owned by the lit rooms
};

LeakErrors leak_errors(const EngineSetup& s, const std::vector<Lightmap>& engine,
                       const std::vector<Lightmap>& reference) {
  LeakErrors out;
  double room_e[2][2] = {}, room_r[2][2] = {};
  double abs_sum = 0.0, ref_sum = 0.0, wall_e = 0.0, wall_r = 0.0;
  for (std::size_t o = 0; o < engine.size(); ++o) {
    double e[2][2] = {}, r[2][2] = {};
    for (std::size_t t = 0; t < engine[o].texels.size(); ++t) {
      if (!s.gbuffers[o].valid(t)) continue;
      const glm::vec3 q = s.gbuffers[o].position(s.world.objects[o], t);
      if (q.y < -0.05f || q.y > 2.85f) continue;  // the building's outside
      const int i = static_cast<int>(std::floor(q.x / 4.0f));
      const int j = static_cast<int>(std::floor(q.z / 4.0f));
      if (i < 0 || i > 1 || j < 0 || j > 1 || (i + j) % 2 != 0) continue;  // unlit rooms only
      e[i][j] += luminance(engine[o].texels[t]);
      r[i][j] += luminance(reference[o].texels[t]);
    }
    const std::string name = s.scene.objects()[s.world.objects[o].object].name;
    const bool lit_walls = name == "room_1_0_walls" || name == "room_0_1_walls";
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        room_e[i][j] += e[i][j];
        room_r[i][j] += r[i][j];
        abs_sum += std::abs(e[i][j] - r[i][j]);
        ref_sum += r[i][j];
        if (lit_walls) {
          wall_e += e[i][j];
          wall_r += r[i][j];
        }
      }
  }
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      out.room[i][j] = room_r[i][j] > 0.0 ? room_e[i][j] / room_r[i][j] - 1.0 : 0.0;
  out.group_error = abs_sum / ref_sum;
  out.shared_walls = wall_e / wall_r;
  return out;
}
}  // namespace

TEST(Engine, ShortTracingRangeDoesNotLeakLightThroughWalls) {
  EngineSetup s(make_rooms(RoomsOptions{}), 40.0f);
  auto has_node = [&](const std::string& name) {
    return std::any_of(s.scene.nodes.begin(), s.scene.nodes.end(),
                       [&](const Node& n) { return n.name == name; });
  };
  ASSERT_TRUE(has_node("light_1_0") && has_node("light_0_1"));
  ASSERT_FALSE(has_node("light_0_0") || has_node("light_1_1"));
  EXPECT_GT(s.hidden, 0u) << "rooms:2 has wall faces buried in pillars and slabs";
  PathTracer tracer(s.world, s.rays, s.lights, PathTracerOptions{2, true, 5});
  const auto reference = reference_lightmaps(s.world, tracer, s.gbuffers, 96);

  EngineParams p;
  p.tracing_range = 0.05f;
  p.cell_size = 0.125f;
  auto fixed = s.engine(p);
  p.relocate_probes = false;
  p.probe_visibility = false;
  auto seed = s.engine(p);
  for (int u = 0; u < 6; ++u) {
    fixed->update();
    seed->update();
  }
  const LeakErrors with_fix = leak_errors(s, fixed->lightmaps(), reference);
  const LeakErrors without = leak_errors(s, seed->lightmaps(), reference);
  RecordProperty("group_error", std::to_string(with_fix.group_error));
  RecordProperty("group_error_seed", std::to_string(without.group_error));
  RecordProperty("shared_walls_ratio", std::to_string(with_fix.shared_walls));
  RecordProperty("shared_walls_ratio_seed", std::to_string(without.shared_walls));
  for (auto [i, j] : {std::pair{0, 0}, std::pair{1, 1}})
    EXPECT_LT(std::abs(with_fix.room[i][j]), 0.10) << "unlit room " << i << "," << j;
  EXPECT_LT(with_fix.group_error, 0.12);
  EXPECT_NEAR(with_fix.shared_walls, 1.0, 0.15) << "walls shared with the lit rooms";
  // The seed's behaviour on the same scene: the walls shared with the lit rooms glow.
  EXPECT_GT(without.shared_walls, 1.5);
  EXPECT_GT(without.group_error, 0.25);
}

TEST(Engine, RejectsBadParameters) {
  EngineSetup s(make_cornell_box(), 16.0f);
  EngineParams p;
  p.cell_size = 0.0f;
  EXPECT_THROW(s.engine(p), Error);
  p = EngineParams{};
  p.indirect_samples = 0;
  EXPECT_THROW(s.engine(p), Error);
  EXPECT_THROW(parse_tracing_range("far"), Error);
  EXPECT_TRUE(parse_tracing_range("inf").infinite());
  EXPECT_EQ(parse_tracing_range("3m"), Length::in_metres(3.0f));
  EXPECT_THROW(parse_dispatch("triangle"), Error);
}

}  // namespace irradcast::test_engine

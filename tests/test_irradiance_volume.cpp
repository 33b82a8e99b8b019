// The irradiance volume (common/irradiance_volume.h, engine/irradiance_volume_builder.h): its SH
// L2 against closed forms, the octahedral map, the probes' placement out of geometry, the whole
// pipeline in a furnace (a closed box of uniform radiance, whose irradiance is pi L everywhere)
// and light that must not leak through a wall.
#include <gtest/gtest.h>

#include <zstd.h>

#include <cmath>

#include "engine_setup.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/irradiance_volume.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/irradiance_volume_builder.h"
#include "irradcast/wire/probe_volume_message.h"
#include "scene_builders.h"

namespace irradcast::test_irradiance_volume {

namespace {

// The irradiance coefficients of radiance L(d), projected with n spherical Fibonacci directions.
template <class Radiance>
ShIrradiance project(Radiance radiance, int n = 4096) {
  ShIrradiance e{};
  for (int k = 0; k < n; ++k) {
    const float z = 1.0f - (2.0f * float(k) + 1.0f) / float(n);
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    const glm::vec3 d(r * std::cos(2.39996323f * float(k)), r * std::sin(2.39996323f * float(k)),
                      z);
    const auto y = sh_basis(d);
    for (int c = 0; c < kShCoefficients; ++c) e[c] += (4.0f * kPi / float(n)) * y[c] * radiance(d);
  }
  for (int c = 0; c < kShCoefficients; ++c) e[c] *= kShCosineBand[c == 0 ? 0 : c < 4 ? 1 : 2];
  return e;
}

const glm::vec3 kNormals[] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                              {0, -1, 0}, {0, 0, 1},  glm::normalize(glm::vec3(1, -2, 3))};

}  // namespace

TEST(SphericalHarmonics, ConstantRadianceGivesPiLEverywhere) {
  const ShIrradiance e = project([](glm::vec3) { return glm::vec3(0.5f, 1.0f, 2.0f); });
  for (const glm::vec3& n : kNormals) {
    const glm::vec3 got = sh_irradiance(e, n);
    EXPECT_NEAR(got.x, kPi * 0.5f, 1e-3f);
    EXPECT_NEAR(got.y, kPi * 1.0f, 2e-3f);
    EXPECT_NEAR(got.z, kPi * 2.0f, 4e-3f);
  }
}

// A cosine-shaped radiance (L = max(0, d.y)) lies in bands 0-2 almost wholly: its irradiance
// has closed forms: E(+y) = 2 pi / 3, E(-y) = 0, E(+x) = (int sin^3)(int cos sin) = 4/3 x 1/2.
TEST(SphericalHarmonics, CosineLobeMatchesItsClosedForm) {
  const ShIrradiance e = project([](glm::vec3 d) { return glm::vec3(std::max(0.0f, d.y)); });
  EXPECT_NEAR(sh_irradiance(e, {0, 1, 0}).x, 2.0f * kPi / 3.0f, 0.05f);
  EXPECT_NEAR(sh_irradiance(e, {0, -1, 0}).x, 0.0f, 0.05f);
  EXPECT_NEAR(sh_irradiance(e, {1, 0, 0}).x, 2.0f / 3.0f, 0.05f);
}

TEST(OctahedralMap, RoundTrips) {
  for (int k = 0; k < 500; ++k) {
    const float z = 1.0f - (2.0f * k + 1.0f) / 500.0f, r = std::sqrt(1.0f - z * z);
    const glm::vec3 d(r * std::cos(2.4f * k), r * std::sin(2.4f * k), z);
    const glm::vec2 uv = octahedral_encode(d);
    ASSERT_GE(uv.x, 0.0f);
    ASSERT_LE(uv.x, 1.0f);
    const glm::vec3 back = octahedral_decode(uv);
    EXPECT_NEAR(glm::dot(back, d), 1.0f, 1e-5f) << k;
  }
}

TEST(IrradianceVolume, GridCoversTheBoundsAtTheSpacing) {
  Bounds b;
  b.extend({-1, -1, -1});
  b.extend({3, 1, 1});
  IrradianceVolumeOptions o;
  o.spacing = 0.5f;
  const VolumeGrid g = probe_grid_for(b, o);
  EXPECT_EQ(g.counts, glm::ivec3(8, 4, 4));
  EXPECT_FLOAT_EQ(g.spacing, 0.5f);
  EXPECT_NEAR(g.position({0, 0, 0}).x, -0.75f, 1e-5f);
  EXPECT_NEAR(g.position({7, 3, 3}).x, 2.75f, 1e-5f);
  o.spacing = 0.0f;
  o.spacing_fraction = 0.25f;  // of the largest extent, 4: 1 unit
  EXPECT_EQ(probe_grid_for(b, o).counts, glm::ivec3(4, 2, 2));
  o.max_probes = 4;
  EXPECT_LE(probe_grid_for(b, o).probe_count(), 4u);
  o.spacing = -1.0f;
  o.spacing_fraction = std::nanf("");
  EXPECT_THROW(probe_grid_for(b, o), Error);
}

// A furnace: a closed box of albedo a and emission Le is filled with radiance L = Le / (1 - a);
// given lightmaps of that solution (E = pi L on every wall), the volume gives pi L everywhere
// inside, for every normal.
TEST(IrradianceVolume, FurnaceGivesPiLEverywhere) {
  const float a = 0.6f, le = 0.4f, l = le / (1.0f - a);
  test::EngineSetup setup(test::closed_box(glm::vec3(a), glm::vec3(le)), 24.0f);
  std::vector<Lightmap> maps;
  for (const ObjectLightmap& o : setup.atlas.objects)
    maps.emplace_back(o.width, o.height, glm::vec3(kPi * l));
  IrradianceVolumeOptions opt;
  opt.spacing_fraction = 0.25f;
  IrradianceVolumeBuilder builder(setup.world, setup.rays, setup.atlas, opt);
  EXPECT_EQ(builder.switched_off(), 0u);
  for (int r = 0; r < 2; ++r) builder.refine(maps);
  const IrradianceVolume& v = builder.volume();
  for (const glm::vec3& p :
       {glm::vec3(0.0f), glm::vec3(0.7f, -0.6f, 0.3f), glm::vec3(-0.95f, 0.9f, 0.9f)})
    for (const glm::vec3& n : kNormals) {
      const glm::vec3 e = v.irradiance(p, n);
      EXPECT_NEAR(e.x / (kPi * l), 1.0f, 0.02f) << p.x << " " << n.x << n.y << n.z;
    }
}

// Probes inside solid blocks are moved out or switched off: no active probe is inside anything.
TEST(IrradianceVolume, ProbesLeaveGeometry) {
  Scene s = test::closed_box(glm::vec3(0.5f), glm::vec3(0.0f));
  const std::uint32_t white = test::add_material(s, glm::vec3(0.7f));
  test::add_block(s, "block", {-0.55f, -1.0f, -0.55f}, {0.55f, 0.3f, 0.55f}, white);
  test::EngineSetup setup(s, 24.0f);
  IrradianceVolumeOptions opt;
  opt.spacing_fraction = 0.125f;
  IrradianceVolumeBuilder builder(setup.world, setup.rays, setup.atlas, opt);
  EXPECT_GT(builder.switched_off(), 0u);
  const IrradianceVolume& v = builder.volume();
  int active = 0;
  for (std::size_t i = 0; i < v.probe_count(); ++i) {
    if (!v.active[i]) continue;
    ++active;
    const glm::vec3 p = v.probe_position(i);
    const bool inside_block = std::fabs(p.x) < 0.55f && std::fabs(p.z) < 0.55f && p.y < 0.3f;
    EXPECT_FALSE(inside_block) << i << " at " << p.x << "," << p.y << "," << p.z;
    EXPECT_LE(std::fabs(v.offsets[i].x), 0.45f * v.grid.spacing + 1e-5f);
  }
  EXPECT_GT(active, 300);
}

// Two closed rooms side by side, one lit by an emissive ceiling, one dark: the volume must not
// carry the lit room's light through the wall into the dark one.
TEST(IrradianceVolume, NoLightThroughAWall) {
  Scene s;
  const std::uint32_t wall = test::add_material(s, glm::vec3(0.7f));
  const std::uint32_t lamp = test::add_material(s, glm::vec3(0.7f), glm::vec3(8.0f));
  // Room A: x in [-2, 0], room B: x in [0, 2] (the wall at x = 0 is one-sided per room: two
  // quads back to back, 1 mm apart).
  for (int room = 0; room < 2; ++room) {
    const float x0 = room == 0 ? -2.0f : 0.0005f, x1 = room == 0 ? -0.0005f : 2.0f;
    Scene box = test::closed_box(glm::vec3(0.7f), glm::vec3(0.0f));
    for (std::size_t m = 0; m < box.meshes.size(); ++m) {
      Mesh mesh = box.meshes[m];
      for (glm::vec3& p : mesh.positions) p.x = x0 + (p.x + 1.0f) * 0.5f * (x1 - x0);
      const bool ceiling = box.meshes[m].name == "y+";
      for (std::uint32_t& t : mesh.triangle_material) t = room == 0 && ceiling ? lamp : wall;
      mesh.name += room == 0 ? "_a" : "_b";
      s.meshes.push_back(mesh);
      Node node;
      node.name = mesh.name;
      node.mesh = static_cast<int>(s.meshes.size() - 1);
      s.add_node(node);
    }
  }
  test::EngineSetup setup(s, 24.0f);
  // Lightmaps: the lit room's walls bright, the dark room's dark (what the engine would find).
  std::vector<Lightmap> maps;
  for (std::size_t o = 0; o < setup.atlas.objects.size(); ++o) {
    const bool lit = setup.world.objects[o].positions[0].x < 0.0f;
    maps.emplace_back(setup.atlas.objects[o].width, setup.atlas.objects[o].height,
                      glm::vec3(lit ? 10.0f : 0.0f));
  }
  IrradianceVolumeOptions opt;
  opt.spacing = 0.5f;  // probes 0.25 from the wall on both sides
  IrradianceVolumeBuilder builder(setup.world, setup.rays, setup.atlas, opt);
  for (int r = 0; r < 2; ++r) builder.refine(maps);
  const IrradianceVolume& v = builder.volume();
  // Next to the wall in the dark room, facing it and facing away.
  for (const glm::vec3& n : {glm::vec3(-1, 0, 0), glm::vec3(1, 0, 0), glm::vec3(0, 1, 0)}) {
    const glm::vec3 dark = v.irradiance({0.1f, 0.0f, 0.0f}, n);
    const glm::vec3 lit = v.irradiance({-0.1f, 0.0f, 0.0f}, n);
    EXPECT_GT(lit.x, 5.0f);
    EXPECT_LT(dark.x, 0.02f * lit.x) << "normal " << n.x << "," << n.y;
  }
}

// Against the truth: in the Cornell box lit by the engine's converged lightmaps, the volume's
// irradiance at points in the open (6 normals each) against the path tracer's at the same point
// and normal, with one bounce more (the volume reads the lightmaps' radiance at its hits):
// the mean within 5 %, the relative MSE (sum of squared errors over sum of squares) at most 0.02.
TEST(IrradianceVolume, CornellBoxAgainstThePathTracer) {
  test::EngineSetup setup(make_cornell_box(), 48.0f);
  EngineParams params;
  auto engine = setup.engine(params);
  for (int u = 0; u < 12; ++u) engine->update();
  const std::vector<Lightmap> maps = engine->lightmaps();
  IrradianceVolumeBuilder builder(setup.world, setup.rays, setup.atlas);
  for (int r = 0; r < 8; ++r) builder.refine(maps);
  const IrradianceVolume& v = builder.volume();
  PathTracer truth(setup.world, setup.rays, setup.lights,
                   PathTracerOptions{params.indirect_bounces + 1, true, 7});
  const Bounds& b = setup.world.bounds;
  double sum_volume = 0.0, sum_truth = 0.0, worst = 0.0, squared_error = 0.0, squared = 0.0;
  int count = 0;
  for (const glm::vec3& f : {glm::vec3(0.5f, 0.5f, 0.5f), glm::vec3(0.3f, 0.7f, 0.6f),
                             glm::vec3(0.75f, 0.3f, 0.4f), glm::vec3(0.25f, 0.5f, 0.3f)}) {
    const glm::vec3 p = b.lo + f * b.extent();
    for (const glm::vec3& n : kNormals) {
      Rng rng(11, static_cast<std::uint64_t>(count));
      glm::dvec3 e(0.0);
      const int samples = 6000;
      for (int s = 0; s < samples; ++s)
        e += glm::dvec3(truth.irradiance(p, n, n, params.indirect_bounces + 1, rng));
      const double expected = luminance(glm::vec3(e / double(samples)));
      const double got = luminance(v.irradiance(p, n));
      sum_volume += got;
      sum_truth += expected;
      worst = std::max(worst, std::fabs(got - expected) / expected);
      squared_error += (got - expected) * (got - expected);
      squared += expected * expected;
      ++count;
    }
  }
  // SH L2 rings: beside a bright ceiling light the dim directions are off by a few tenths of the
  // light's irradiance (up to 42 % of their own here), which the relative MSE weighs as the
  // eye does, by brightness.
  const double rel_mse = squared_error / squared;
  std::printf("volume against the path tracer: mean ratio %.4f, relative MSE %.4f, worst %.3f\n",
              sum_volume / sum_truth, rel_mse, worst);
  EXPECT_NEAR(sum_volume / sum_truth, 1.0, 0.05);
  EXPECT_LT(rel_mse, 0.02);
}

// The ProbeVolume message: a round trip within binary16, and hostile messages refused whole.
TEST(ProbeVolumeMessage, RoundTripAndBadMessages) {
  test::EngineSetup setup(make_cornell_box(), 32.0f);
  std::vector<Lightmap> maps;
  for (const ObjectLightmap& o : setup.atlas.objects)
    maps.emplace_back(o.width, o.height, glm::vec3(1.0f));
  IrradianceVolumeBuilder builder(setup.world, setup.rays, setup.atlas);
  builder.refine(maps);
  const IrradianceVolume& v = builder.volume();
  const wire::ProbeVolume full = wire::probe_volume_to_proto(v, 3, 7, true);
  const wire::ProbeVolume sh = wire::probe_volume_to_proto(v, 3, 8, false);
  std::printf("probe volume: %zu probes, %zu bytes with the layout, %zu bytes of SH per version\n",
              v.probe_count(), full.ByteSizeLong(), sh.ByteSizeLong());
  wire::ReceivedVolume got;
  EXPECT_FALSE(wire::apply_probe_volume(sh, got));  // no layout of epoch 3 yet: ignored
  ASSERT_TRUE(wire::apply_probe_volume(full, got));
  EXPECT_TRUE(wire::apply_probe_volume(sh, got));
  EXPECT_EQ(got.epoch, 3u);
  EXPECT_EQ(got.version, 8u);
  ASSERT_EQ(got.volume.probe_count(), v.probe_count());
  // The emitters' part travels apart (the Cornell box's light), and both arrive.
  EXPECT_FALSE(full.emitted().empty());
  for (const glm::vec3& p : {glm::vec3(0.0f), v.grid.position({1, 2, 3})})
    for (const glm::vec3& n : kNormals)
      for (const bool with_emitted : {true, false}) {
        const float a = luminance(v.irradiance(p, n, with_emitted)),
                    b = luminance(got.volume.irradiance(p, n, with_emitted));
        EXPECT_NEAR(b, a, 0.01f * a + 1e-4f);
      }
  const glm::vec3 below_light = v.grid.position(v.grid.counts / 2);
  EXPECT_GT(luminance(got.volume.irradiance(below_light, {0, 1, 0})),
            2.0f * luminance(got.volume.irradiance(below_light, {0, 1, 0}, false)));
  {  // Without the field (a scene without emitters) the emitters' part is zero.
    wire::ProbeVolume none = full;
    none.clear_emitted();
    wire::ReceivedVolume dark;
    ASSERT_TRUE(wire::apply_probe_volume(none, dark));
    EXPECT_EQ(dark.volume.irradiance(below_light, {0, 1, 0}),
              dark.volume.irradiance(below_light, {0, 1, 0}, false));
  }
  const wire::ReceivedVolume before = got;
  const auto refused = [&](wire::ProbeVolume m, const char* what) {
    EXPECT_THROW(wire::apply_probe_volume(m, got), Error) << what;
    EXPECT_EQ(got.version, before.version) << what;
  };
  wire::ProbeVolume m = full;
  m.set_counts(0, 0);
  refused(m, "a count of 0");
  m = full;
  m.set_counts(0, 1u << 20);
  refused(m, "too many probes");
  m = full;
  m.set_spacing(std::nanf(""));
  refused(m, "a spacing that is not a number");
  m = full;
  m.set_sh(m.sh().substr(0, m.sh().size() / 2));
  refused(m, "cut SH data");
  m = full;
  m.set_layout("not zstd");
  refused(m, "a layout that is not zstd");
  m = full;
  m.clear_origin();
  refused(m, "no origin");
  m = full;
  m.set_origin(0, 3e38f);
  refused(m, "a grid whose probes lie past any finite coordinate");
  // binary16 infinity or NaN in the SH: refused, not evaluated to NaN.
  std::string nan_sh;
  for (std::size_t i = 0; i < v.probe_count() * kShCoefficients * 3; ++i) nan_sh += "\x00\x7e";
  std::string z(ZSTD_compressBound(nan_sh.size()), '\0');
  z.resize(ZSTD_compress(z.data(), z.size(), nan_sh.data(), nan_sh.size(), 1));
  m = full;
  m.set_sh(z);
  refused(m, "NaN coefficients");
  m = full;
  m.set_emitted(z);
  refused(m, "NaN coefficients of the emitters");
  m = full;
  m.set_emitted(m.emitted().substr(0, m.emitted().size() / 2));
  refused(m, "cut SH data of the emitters");
}

// Distance moments survive binary16 at any scale: a probe grid of 1 km spacing keeps its
// visibility (a mean square in metres would clip at 65504 past 256 m).
TEST(ProbeVolumeMessage, MomentsKeepTheirPrecisionAtAnyScale) {
  VolumeGrid g;
  g.counts = {2, 2, 2};
  g.spacing = 1000.0f;
  IrradianceVolume v;
  v.reset(g);
  v.depth[3] = glm::vec2(800.0f, 800.0f * 800.0f + 5000.0f);
  wire::ReceivedVolume got;
  ASSERT_TRUE(wire::apply_probe_volume(wire::probe_volume_to_proto(v, 1, 1, true), got));
  for (std::size_t t : {std::size_t{0}, std::size_t{3}}) {
    EXPECT_NEAR(got.volume.depth[t].x, v.depth[t].x, 1e-3f * v.depth[t].x) << t;
    EXPECT_NEAR(got.volume.depth[t].y, v.depth[t].y, 2e-3f * v.depth[t].y) << t;
  }
}

}  // namespace irradcast::test_irradiance_volume

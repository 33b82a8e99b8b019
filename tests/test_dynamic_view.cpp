// Dynamic objects in the viewers' frames (common/dynamic_view.h, docs/DYNAMIC.md "Drawing
// them"): their own ray scene, drawn where nearer than the static scene, lit by the probe volume;
// against the path tracer with the object visible to camera rays only; no light through a wall;
// SSAO sees them and reprojection does not ghost them.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <mutex>

#include "engine_setup.h"
#include "irradcast/client/client_passes.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/dynamic_view.h"
#include "irradcast/common/error.h"
#include "irradcast/common/shapes.h"
#include "irradcast/engine/irradiance_volume_builder.h"
#include "scene_builders.h"
#include "testdata.h"

namespace irradcast::test_dynamic_view {

namespace {

// `scene` with a dynamic sphere "ball" of radius r at `at` (its own white material, or a checker
// texture of two colours).
Scene with_ball(Scene s, glm::vec3 at, float r, bool textured = false) {
  std::uint32_t mat = test::add_material(s, glm::vec3(0.8f));
  if (textured) {
    Texture t;
    t.name = "checker";
    t.width = t.height = 64;
    for (int y = 0; y < t.height; ++y)
      for (int x = 0; x < t.width; ++x) {
        const bool odd = ((x / 8) + (y / 8)) % 2 == 1;
        const std::uint8_t rgb[3] = {odd ? std::uint8_t(230) : std::uint8_t(40),
                                     odd ? std::uint8_t(180) : std::uint8_t(90),
                                     odd ? std::uint8_t(60) : std::uint8_t(200)};
        t.rgba8.insert(t.rgba8.end(), {rgb[0], rgb[1], rgb[2], 255});
      }
    s.textures.push_back(std::move(t));
    s.materials[mat].base_color = glm::vec3(1.0f);
    s.materials[mat].base_color_texture = static_cast<int>(s.textures.size() - 1);
  }
  s.meshes.push_back(uv_sphere("ball", r, 24, 48, mat));
  Node n;
  n.name = "ball";
  n.mesh = static_cast<int>(s.meshes.size() - 1);
  n.local[3] = glm::vec4(at, 1.0f);
  n.dynamic = true;
  s.add_node(std::move(n));
  return s;
}

// trace_dynamic's pixels, collected.
std::vector<DynamicPixel> pixels_of(const World& world, const RayScene& rays,
                                    const DynamicView& view, const CameraPose& cam, int w, int h) {
  std::vector<DynamicPixel> out;
  std::mutex m;
  trace_dynamic(world, rays, view, cam, w, h, [&](const DynamicPixel& p) {
    const std::lock_guard<std::mutex> g(m);
    out.push_back(p);
  });
  return out;
}

// A scene lit by the engine's converged lightmaps, with its dynamic objects' ray scene and the
// probe volume refined from those lightmaps (a server's volume after 32 updates).
struct Lit {
  Lit(Scene s, float texels, int updates, IrradianceVolumeOptions vo = {}, int refines = 32)
      : setup(std::move(s), texels), dynamic(setup.world, true, RaySceneContent::Dynamic) {
    auto engine = setup.engine(params);
    for (int u = 0; u < updates; ++u) engine->update();
    maps = engine->lightmaps();
    volume = std::make_unique<IrradianceVolumeBuilder>(setup.world, setup.rays, setup.atlas, vo);
    for (int r = 0; r < refines; ++r) volume->refine(maps);
  }
  // As irradcast-view draws them (tracing the emitters' direct light), or with
  // `trace_emitters` false as the browser page does (the volume's emitters' part instead).
  DynamicView view(bool trace_emitters = true) const {
    return {&dynamic, &volume->volume(), trace_emitters ? &setup.lights : nullptr};
  }
  ImageRGB compose(const CameraPose& cam, int w, int h, bool trace_emitters = true) const {
    const DynamicView v = view(trace_emitters);
    return irradcast::compose(setup.world, setup.rays, setup.atlas, maps, cam, w, h, nullptr, &v);
  }
  EngineParams params;
  test::EngineSetup setup;
  RayScene dynamic;
  std::vector<Lightmap> maps;
  std::unique_ptr<IrradianceVolumeBuilder> volume;
};

// The viewer's pixels of the dynamic objects against the path tracer's (camera rays only see
// them; one bounce more, as the volume reads the lightmaps' radiance at its hits).
struct Against {
  double rel_mse = 0.0;  // as compare(): per channel d^2 / (r^2 + 0.01), averaged
  double mean_ratio = 0.0;
  std::size_t pixels = 0;
};
Against against_path_tracer(const Lit& lit, const CameraPose& cam, int w, int h, int spp,
                            bool trace_emitters = true) {
  const std::vector<DynamicPixel> px =
      pixels_of(lit.setup.world, lit.setup.rays, lit.view(), cam, w, h);
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
  for (const DynamicPixel& p : px) mask[p.index] = 1;
  const ImageRGB view = lit.compose(cam, w, h, trace_emitters);
  PathTracerOptions po{lit.params.indirect_bounces + 1, true, 5};
  po.camera_only = &lit.dynamic;
  const ImageRGB ref = PathTracer(lit.setup.world, lit.setup.rays, lit.setup.lights, po)
                           .render(cam, w, h, spp, {}, nullptr, &mask);
  Against a;
  double rel = 0.0, sum_v = 0.0, sum_r = 0.0;
  for (const DynamicPixel& p : px)
    for (int c = 0; c < 3; ++c) {
      const double x = view.pixels[p.index][c], r = ref.pixels[p.index][c];
      rel += (x - r) * (x - r) / (r * r + 0.01);
      sum_v += x;
      sum_r += r;
    }
  a.pixels = px.size();
  a.rel_mse = rel / std::max(1.0, 3.0 * static_cast<double>(px.size()));
  a.mean_ratio = sum_r > 0.0 ? sum_v / sum_r : 0.0;
  return a;
}

CameraPose looking(glm::vec3 eye, glm::vec3 target, float yfov = 0.69f) {
  CameraPose c;
  c.eye = eye;
  c.forward = glm::normalize(target - eye);
  c.up = glm::vec3(0, 1, 0);
  c.yfov = yfov;
  return c;
}

}  // namespace

TEST(DynamicView, TheDynamicSceneHoldsOnlyTheDynamicObjects) {
  const Scene s = with_ball(make_cornell_box(), {0.2f, 0.3f, 0.15f}, 0.08f);
  const World w = World::build(s);
  const RayScene stat(w), dyn(w, false, RaySceneContent::Dynamic);
  EXPECT_TRUE(dyn.editable());  // a move refits the object's BVH
  Ray down;  // from above the ball, straight down: the ball first, then the floor
  down.origin = {0.2f, 0.5f, 0.15f};
  down.direction = {0.0f, -1.0f, 0.0f};
  const Hit hd = dyn.intersect(down), hs = stat.intersect(down);
  ASSERT_TRUE(hd.valid());
  ASSERT_TRUE(hs.valid());
  EXPECT_TRUE(w.objects[static_cast<std::size_t>(hd.object)].dynamic);
  EXPECT_FALSE(w.objects[static_cast<std::size_t>(hs.object)].dynamic);
  EXPECT_NEAR(hd.t, 0.5f - 0.3f - 0.08f, 1e-3f);
  Ray side = down;  // misses the ball
  side.origin.x = 0.45f;
  EXPECT_FALSE(dyn.intersect(side).valid());
}

// Drawn where nearer than the static scene, hidden behind it; every other pixel is the static
// scene's, bit for bit; without a volume only the emission shows (black here).
TEST(DynamicView, DrawnInFrontHiddenBehindAndNothingElseChanges) {
  Scene s = with_ball(make_cornell_box(), {0.2f, 0.3f, 0.15f}, 0.08f);
  test::EngineSetup setup(s, 24.0f);
  std::vector<Lightmap> maps;
  for (const ObjectLightmap& o : setup.atlas.objects)
    maps.emplace_back(o.width, o.height, glm::vec3(1.0f));
  const RayScene dyn(setup.world, true, RaySceneContent::Dynamic);
  const CameraPose cam = default_camera(setup.scene, setup.world);
  constexpr int kW = 64, kH = 64;
  const ImageRGB plain = compose(setup.world, setup.rays, setup.atlas, maps, cam, kW, kH);
  const DynamicView unlit{&dyn, nullptr};
  const ImageRGB with =
      compose(setup.world, setup.rays, setup.atlas, maps, cam, kW, kH, nullptr, &unlit);
  const std::vector<DynamicPixel> px = pixels_of(setup.world, setup.rays, unlit, cam, kW, kH);
  ASSERT_GT(px.size(), 50u);
  std::vector<std::uint8_t> ball(plain.pixels.size(), 0);
  for (const DynamicPixel& p : px) {
    ball[p.index] = 1;
    EXPECT_EQ(with.pixels[p.index], glm::vec3(0.0f));  // no volume yet, no emission
    EXPECT_GT(p.depth, 0.5f);
    // On the sphere: its position 8 cm from the centre, its normal the outward radius.
    EXPECT_NEAR(glm::length(p.position - glm::vec3(0.2f, 0.3f, 0.15f)), 0.08f, 1e-3f);
    EXPECT_GT(glm::dot(p.normal, glm::normalize(p.position - glm::vec3(0.2f, 0.3f, 0.15f))), 0.98f);
  }
  for (std::size_t i = 0; i < plain.pixels.size(); ++i)
    if (!ball[i]) {
      ASSERT_EQ(with.pixels[i], plain.pixels[i]) << "pixel " << i;
    }

  // Moved behind the tall block from the camera (inside its footprint, below its top): a move
  // refits the dynamic scene, and the ball is no longer drawn.
  std::size_t ball_node = 0;
  for (std::size_t n = 0; n < s.nodes.size(); ++n)
    if (s.nodes[n].name == "ball") ball_node = n;
  World w = World::build(s);
  const RayScene stat(w);
  RayScene moving(w, true, RaySceneContent::Dynamic);
  const DynamicView view{&moving, nullptr};
  EXPECT_EQ(pixels_of(w, stat, view, cam, kW, kH).size(), px.size());
  s.nodes[ball_node].local[3] = glm::vec4(0.37f, 0.15f, 0.40f, 1.0f);
  const std::vector<int> changed = w.update(s);
  ASSERT_EQ(changed.size(), 1u);
  moving.update(changed);
  EXPECT_TRUE(pixels_of(w, stat, view, cam, kW, kH).empty());
  // Back in the open and hidden by an edit: not drawn either.
  s.nodes[ball_node].local[3] = glm::vec4(0.2f, 0.3f, 0.15f, 1.0f);
  s.nodes[ball_node].visible = false;
  moving.update(w.update(s));
  EXPECT_TRUE(pixels_of(w, stat, view, cam, kW, kH).empty());
  s.nodes[ball_node].visible = true;
  moving.update(w.update(s));
  EXPECT_EQ(pixels_of(w, stat, view, cam, kW, kH).size(), px.size());
}

// Part 5: the sphere at three places in the Cornell box, and a textured one, against the path
// tracer over the sphere's pixels: relative MSE <= 0.02 and the mean within 5 %, as irradcast-view
// draws them (the emitters' direct light traced). As the browser page draws them, from the volume
// alone, the sphere on the floor against the red wall (1 cm from the floor, 3 mm from the wall)
// reads 7 % dark (the probes see the light and the wall over a wide view: docs/DYNAMIC.md), held
// at 10 %, the others at 5 %.
TEST(DynamicView, CornellSphereAgainstThePathTracer) {
  constexpr int kW = 96, kH = 96;
  struct Case {
    glm::vec3 at;
    bool textured;
    const char* what;
    double page_bound;
  };
  const Case cases[] = {{{0.20f, 0.30f, 0.15f}, false, "above the short block", 0.05},
                        {{0.47f, 0.09f, 0.15f}, false, "on the floor by the red wall", 0.10},
                        {{0.40f, 0.45f, 0.20f}, false, "under the ceiling", 0.05},
                        {{0.20f, 0.30f, 0.15f}, true, "textured, above the short block", 0.05}};
  for (const Case& c : cases) {
    const Lit lit(with_ball(make_cornell_box(), c.at, 0.08f, c.textured), 48.0f, 12);
    const CameraPose cam = default_camera(lit.setup.scene, lit.setup.world);
    const Against a = against_path_tracer(lit, cam, kW, kH, 512);
    const Against page = against_path_tracer(lit, cam, kW, kH, 512, false);
    std::printf(
        "sphere %s: %zu pixels, relative MSE %.4f, mean ratio %.4f (from the volume alone: %.4f, "
        "%.4f)\n",
        c.what, a.pixels, a.rel_mse, a.mean_ratio, page.rel_mse, page.mean_ratio);
    RecordProperty(std::string("rel_mse ") + c.what, std::to_string(a.rel_mse));
    EXPECT_GT(a.pixels, 200u) << c.what;
    EXPECT_LE(a.rel_mse, 0.02) << c.what;
    EXPECT_NEAR(a.mean_ratio, 1.0, 0.05) << c.what;
    EXPECT_LE(page.rel_mse, 0.02) << c.what;
    EXPECT_NEAR(page.mean_ratio, 1.0, c.page_bound) << c.what;
  }
}

// Part 5: a sphere in a dark room of rooms:2, near the wall it shares with a lit room and away
// from the doorway, gets the light the path tracer finds there (what the doorway lets in), not
// the lit room's through the wall.
TEST(DynamicView, NoLightThroughTheWallOfRooms) {
  RoomsOptions ro;
  ro.n = 2;
  ro.detail = 0.5f;
  // Room 0_0 is dark and 1_0 lit (seed 1); their wall is at x = 4, the doorway at z 1.5..2.5.
  const Lit lit(with_ball(make_rooms(ro), {3.6f, 1.3f, 0.8f}, 0.2f), 3.0f, 12);
  const CameraPose cam = looking({2.2f, 1.5f, 0.9f}, {3.6f, 1.3f, 0.8f});
  const Against dark = against_path_tracer(lit, cam, 64, 64, 256);
  // The same sphere in the lit room, as far from the wall on the other side.
  const Lit bright(with_ball(make_rooms(ro), {4.4f, 1.3f, 0.8f}, 0.2f), 3.0f, 12);
  const CameraPose cam_b = looking({5.8f, 1.5f, 0.9f}, {4.4f, 1.3f, 0.8f});
  const ImageRGB lit_view = bright.compose(cam_b, 64, 64);
  const ImageRGB dark_view = lit.compose(cam, 64, 64);
  double dark_mean = 0.0, lit_mean = 0.0;
  std::size_t dark_n = 0, lit_n = 0;
  for (const DynamicPixel& p :
       pixels_of(lit.setup.world, lit.setup.rays, lit.view(), cam, 64, 64)) {
    dark_mean += luminance(dark_view.pixels[p.index]);
    ++dark_n;
  }
  for (const DynamicPixel& p :
       pixels_of(bright.setup.world, bright.setup.rays, bright.view(), cam_b, 64, 64)) {
    lit_mean += luminance(lit_view.pixels[p.index]);
    ++lit_n;
  }
  ASSERT_GT(dark_n, 100u);
  ASSERT_GT(lit_n, 100u);
  dark_mean /= static_cast<double>(dark_n);
  lit_mean /= static_cast<double>(lit_n);
  std::printf(
      "rooms:2 sphere by the wall: dark side %.5f (path tracer ratio %.3f, relative MSE "
      "%.4f), lit side %.5f\n",
      dark_mean, dark.mean_ratio, dark.rel_mse, lit_mean);
  EXPECT_LT(dark_mean, 0.1 * lit_mean);
  EXPECT_LT(dark.mean_ratio, 1.25);  // not brighter than the truth: nothing through the wall
  EXPECT_GT(dark.mean_ratio, 0.4);   // and not black: the doorway's light is there
}

// SSAO sees a dynamic object (a contact shadow on the floor beside it), and when it moves away
// the reprojection cache forgets what it covered and shadowed: the next frame's SSAO there is
// that of a viewer without history, not the old shadow.
TEST(DynamicView, SsaoSeesThemAndReprojectionDoesNotGhost) {
  Scene s = with_ball(make_cornell_box(), {0.42f, 0.06f, 0.15f}, 0.06f);
  const test::EngineSetup setup(s, 24.0f);
  std::vector<Lightmap> maps;
  for (const ObjectLightmap& o : setup.atlas.objects)
    maps.emplace_back(o.width, o.height, glm::vec3(1.0f));
  World w = World::build(s);
  const RayScene stat(w);
  RayScene dyn(w, true, RaySceneContent::Dynamic);
  const DynamicView view{&dyn, nullptr};
  // Looking down at the floor beside the ball.
  const CameraPose cam = looking({0.30f, 0.35f, -0.05f}, {0.42f, 0.0f, 0.15f}, 0.9f);
  constexpr int kW = 96, kH = 96;
  ClientPassOptions po;
  po.ssao = true;
  po.reproject = true;
  po.ssao_params.radius = 0.15f;  // 8 cm: the size of the ball
  ClientPasses passes(po);
  // The floor pixels just outside the ball's footprint (under its overhang).
  const FrameGBuffer g = trace_frame(w, stat, setup.atlas, maps, cam, kW, kH, &view);
  std::vector<std::size_t> ring;
  for (std::size_t i = 0; i < g.size(); ++i) {
    if (!g.hit(i) || g.position[i].y > 1e-3f) continue;
    const float d = glm::length(glm::vec2(g.position[i].x - 0.42f, g.position[i].z - 0.15f));
    if (d > 0.062f && d < 0.075f) ring.push_back(i);
  }
  ASSERT_GT(ring.size(), 30u);
  const auto mean_at = [&](const std::vector<float>& v) {
    double sum = 0.0;
    for (std::size_t i : ring) sum += v[i];
    return sum / static_cast<double>(ring.size());
  };
  for (int f = 0; f < 8; ++f)
    passes.compose(w, stat, setup.atlas, maps, cam, kW, kH, nullptr, &view);
  const double shadowed = mean_at(passes.visibility());
  // Without the ball, the same pixels are open.
  ClientPasses bare(po);
  bare.compose(w, stat, setup.atlas, maps, cam, kW, kH);
  const double open = mean_at(bare.visibility());
  std::printf("SSAO beside the ball %.3f, without it %.3f\n", shadowed, open);
  EXPECT_LT(shadowed, open - 0.03);  // a contact shadow

  // Turned in place (its box unchanged): what it covers is still computed again.
  std::size_t ball = 0;
  for (std::size_t n = 0; n < s.nodes.size(); ++n)
    if (s.nodes[n].name == "ball") ball = n;
  const glm::vec4 at = s.nodes[ball].local[3];
  s.nodes[ball].local =
      glm::mat4(glm::vec4(-1, 0, 0, 0), glm::vec4(0, 1, 0, 0), glm::vec4(0, 0, -1, 0), at);
  dyn.update(w.update(s));
  ClientFrameStats turned;
  passes.compose(w, stat, setup.atlas, maps, cam, kW, kH, &turned, &view);
  EXPECT_GT(turned.forgotten, ring.size());

  // The ball moves away: the next frame has no ghost of its shadow.
  std::size_t ball_node = 0;
  for (std::size_t n = 0; n < s.nodes.size(); ++n)
    if (s.nodes[n].name == "ball") ball_node = n;
  s.nodes[ball_node].local[3] = glm::vec4(0.42f, 0.40f, 0.45f, 1.0f);
  dyn.update(w.update(s));
  ClientFrameStats st;
  passes.compose(w, stat, setup.atlas, maps, cam, kW, kH, &st, &view);
  const double after = mean_at(passes.visibility());
  ClientPasses fresh(po);
  fresh.compose(w, stat, setup.atlas, maps, cam, kW, kH, nullptr, &view);
  const double truth = mean_at(fresh.visibility());
  std::printf(
      "after the move: %.3f (a viewer without history %.3f), %zu history pixels forgotten\n", after,
      truth, st.forgotten);
  EXPECT_GT(st.forgotten, ring.size());
  EXPECT_NEAR(after, truth, 0.01);  // the old shadow would be open - 0.03 or darker
}

// Part 5 in the sky-lit Sponza: a sphere on the floor of the atrium and a textured one in the
// shade of the side gallery, against the path tracer (the sun's direct light traced by the viewer,
// the rest from the volume at the default 1 m spacing; lightmaps at 160 texels per scene).
// Measured 2026-12-07 (mean ratios, atrium / gallery): 0.950 / 0.966 at the default cells and
// range (1 m, 1.2 m here); 0.957 / 0.999 from the unbiased mode's lightmaps (16 updates), so the
// atrium's 4-5 % is the volume's own (its probes in the sunlit atrium), held at 6 %; with the
// cells and range of before (0.25, 0.3 of the scene: 8.7 m cells) 1.019 / 1.128, the engine's
// bias in the shade (issue 33 part 5) then hiding the volume's in the atrium. The gallery is held
// at 5 %.
TEST(DynamicView, SponzaSpheresAgainstThePathTracer) {
  IRRADCAST_NEED_TESTDATA();
  ::setenv("IRRADCAST_TESTDATA", test::testdata_dir().c_str(), 1);
  struct Case {
    glm::vec3 at;
    bool textured;
    CameraPose cam;
    const char* what;
    double mean_bound;
  };
  const Case cases[] = {{{-6.0f, 0.8f, 0.0f},
                         false,
                         looking({-11.0f, 1.8f, 0.5f}, {-6.0f, 0.8f, 0.0f}, 0.5f),
                         "in the atrium",
                         0.06},
                        {{-4.0f, 0.8f, -4.6f},
                         true,
                         looking({-9.0f, 1.6f, -4.6f}, {-4.0f, 0.8f, -4.6f}, 0.5f),
                         "textured, in the gallery",
                         0.05}};
  // Both spheres in one scene: dynamic objects change nothing of the static lighting, so one
  // engine run and one volume serve both views.
  const auto t0 = std::chrono::steady_clock::now();
  const Lit lit(with_ball(with_ball(load_scene("sponza"), cases[0].at, 0.8f, cases[0].textured),
                          cases[1].at, 0.8f, cases[1].textured),
                160.0f, 8);
  std::printf("sponza: engine and volume in %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  for (const Case& c : cases) {
    const Against a = against_path_tracer(lit, c.cam, 64, 64, 256);
    std::printf("sponza sphere %s: %zu pixels, relative MSE %.4f, mean ratio %.4f\n", c.what,
                a.pixels, a.rel_mse, a.mean_ratio);
    EXPECT_GT(a.pixels, 200u) << c.what;
    EXPECT_LE(a.rel_mse, 0.02) << c.what;
    EXPECT_NEAR(a.mean_ratio, 1.0, c.mean_bound) << c.what;
  }
}

}  // namespace irradcast::test_dynamic_view

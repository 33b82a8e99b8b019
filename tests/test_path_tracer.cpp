#include <gtest/gtest.h>

#include <cmath>

#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/path_tracer.h"
#include "scene_builders.h"

namespace irradcast::test_path_tracer {

namespace {

struct Fixture {
  explicit Fixture(Scene s)
      : scene(std::move(s)), world(World::build(scene)), rays(world), lights(world) {}
  Scene scene;
  World world;
  RayScene rays;
  LightSampler lights;
};

// Irradiance at p (normal n) from a uniformly emitting polygon of radiance Le (Lambert's contour
// integral): E = Le / 2 * sum_i angle(v_i, v_{i+1}) * dot(n, unit(v_i x v_{i+1})), with v_i the
// unit vectors from p to the corners, corners ordered so that the polygon faces p.
double polygon_irradiance(glm::dvec3 p, glm::dvec3 n, const std::vector<glm::dvec3>& corners,
                          double le) {
  double sum = 0.0;
  for (std::size_t i = 0; i < corners.size(); ++i) {
    glm::dvec3 a = glm::normalize(corners[i] - p);
    glm::dvec3 b = glm::normalize(corners[(i + 1) % corners.size()] - p);
    double angle = std::acos(glm::clamp(glm::dot(a, b), -1.0, 1.0));
    sum += angle * glm::dot(n, glm::normalize(glm::cross(a, b)));
  }
  return le * 0.5 * std::fabs(sum);
}

}  // namespace

class WhiteFurnace : public ::testing::TestWithParam<std::tuple<float, int>> {};

// Closed room, every surface emitting Le with albedo rho: with 1 direct + K indirect bounces the
// radiance everywhere is Le (1 - rho^(K+2)) / (1 - rho).
TEST_P(WhiteFurnace, PathTracerConvergesToTheGeometricSeries) {
  Progress::set_enabled(false);
  auto [rho, k] = GetParam();
  const float le = 1.5f;
  Fixture f(test::closed_box(glm::vec3(rho), glm::vec3(le)));
  PathTracerOptions o;
  o.indirect_bounces = k;
  o.seed = 7;
  PathTracer tracer(f.world, f.rays, f.lights, o);
  CameraPose cam;
  cam.eye = glm::vec3(0.1f, -0.2f, 0.3f);
  cam.forward = glm::normalize(glm::vec3(0.3f, 0.2f, -1.0f));
  cam.yfov = glm::radians(100.0f);
  ImageRGB img = tracer.render(cam, 24, 24, 256);
  double mean = 0.0;
  for (const glm::vec3& p : img.pixels) mean += (p.x + p.y + p.z) / 3.0;
  mean /= static_cast<double>(img.pixels.size());
  double expected = le * (1.0 - std::pow(rho, k + 2)) / (1.0 - rho);
  EXPECT_NEAR(mean, expected, 0.01 * expected) << "rho " << rho << " K " << k;
  RecordProperty("relative_error", std::to_string(mean / expected - 1.0));
}

INSTANTIATE_TEST_SUITE_P(PathTracer, WhiteFurnace,
                         ::testing::Values(std::make_tuple(0.5f, 2), std::make_tuple(0.8f, 2),
                                           std::make_tuple(0.8f, 0), std::make_tuple(0.3f, 4)));

// Direct irradiance under a square area light against the analytic polygon formula, at points
// on and off the light's axis and on a tilted receiver.
TEST(PathTracer, SquareAreaLightMatchesAnalyticIrradiance) {
  Scene s;
  std::uint32_t black = test::add_material(s, glm::vec3(0.0f));
  const float le = 10.0f;
  std::uint32_t emit = test::add_material(s, glm::vec3(0.0f), glm::vec3(1.0f), le);
  // Light: 1 x 1 square at height 1, facing down (-y).
  glm::vec3 a(-0.5f, 1, -0.5f), b(0.5f, 1, -0.5f), c(0.5f, 1, 0.5f), d(-0.5f, 1, 0.5f);
  test::add_quad_object(s, "light", a, b, c, d, emit);
  test::add_quad_object(s, "floor", {-5, 0, -5}, {-5, 0, 5}, {5, 0, 5}, {5, 0, -5}, black);
  ASSERT_LT(glm::cross(b - a, c - a).y, 0.0f);  // the light faces the floor
  Fixture f(std::move(s));
  PathTracerOptions o;
  o.indirect_bounces = 0;
  PathTracer tracer(f.world, f.rays, f.lights, o);
  std::vector<glm::dvec3> corners = {a, b, c, d};
  struct Case {
    glm::vec3 p, n;
  };
  std::vector<Case> cases = {{{0, 0, 0}, {0, 1, 0}},
                             {{0.3f, 0, -0.2f}, {0, 1, 0}},
                             {{1.2f, 0, 0.7f}, {0, 1, 0}},
                             {{0, 0.5f, 0}, glm::normalize(glm::vec3(0.5f, 1, 0))}};
  for (const Case& cs : cases) {
    Rng rng(42, 1);
    glm::dvec3 sum(0.0);
    const int n = 200000;
    for (int i = 0; i < n; ++i) sum += glm::dvec3(tracer.irradiance(cs.p, cs.n, cs.n, 0, rng));
    double measured = sum.x / n;
    double expected = polygon_irradiance(cs.p, cs.n, corners, le);
    RecordProperty("relative_error", std::to_string(measured / expected - 1.0));
    EXPECT_NEAR(measured, expected, 0.01 * expected)
        << "at " << cs.p.x << "," << cs.p.y << "," << cs.p.z;
  }
}

TEST(PathTracer, PunctualLightsGiveTheInverseSquareLaw) {
  Scene s;
  std::uint32_t grey = test::add_material(s, glm::vec3(0.5f));
  test::add_quad_object(s, "floor", {-5, 0, -5}, {-5, 0, 5}, {5, 0, 5}, {5, 0, -5}, grey);
  Light point;
  point.type = Light::Type::Point;
  point.color = glm::vec3(1.0f, 0.5f, 0.25f);
  point.intensity = 8.0f;
  s.lights.push_back(point);
  Node ln;
  ln.light = 0;
  ln.local[3] = glm::vec4(0, 2, 0, 1);
  s.add_node(ln);
  Fixture f(std::move(s));
  glm::vec3 p(1.0f, 0.0f, 0.0f), n(0, 1, 0);
  glm::vec3 e = f.lights.punctual_irradiance(f.rays, p, n, n);
  float d2 = 5.0f, cos_t = 2.0f / std::sqrt(5.0f);
  EXPECT_NEAR(e.x, 8.0f * cos_t / d2, 1e-5f);
  EXPECT_NEAR(e.z, 0.25f * 8.0f * cos_t / d2, 1e-5f);
  // Below the floor the light is blocked by it.
  glm::vec3 below = f.lights.punctual_irradiance(f.rays, {1.0f, -0.1f, 0.0f}, n, n);
  EXPECT_EQ(below, glm::vec3(0.0f));
}

// Two independent estimators of the same paths: next-event estimation (256 spp) and pure
// cosine-sampled paths (4096 spp) that must hit the light or leave the scene to the sky. Their
// mean over the view agrees within 3 % per channel.
namespace {
void expect_next_event_agrees_with_pure_paths(const Fixture& f, const CameraPose& cam) {
  PathTracerOptions with, without;
  with.indirect_bounces = without.indirect_bounces = 2;
  without.next_event = false;
  with.seed = 3;
  without.seed = 4;
  PathTracer a(f.world, f.rays, f.lights, with), b(f.world, f.rays, f.lights, without);
  const int w = 16, h = 16;
  ImageRGB ia = a.render(cam, w, h, 256), ib = b.render(cam, w, h, 4096);
  glm::dvec3 ma(0.0), mb(0.0);
  for (std::size_t i = 0; i < ia.pixels.size(); ++i) {
    ma += glm::dvec3(ia.pixels[i]);
    mb += glm::dvec3(ib.pixels[i]);
  }
  for (int c = 0; c < 3; ++c) {
    ::testing::Test::RecordProperty("relative_difference", std::to_string(ma[c] / mb[c] - 1.0));
    EXPECT_NEAR(ma[c], mb[c], 0.03 * mb[c]) << "channel " << c;
  }
}
}  // namespace

// On the Cornell box.
TEST(PathTracer, NextEventEstimationAgreesWithPurePathTracing) {
  Progress::set_enabled(false);
  Fixture f(make_cornell_box());
  expect_next_event_agrees_with_pure_paths(f, default_camera(f.scene, f.world));
}

// Under a sky map (a smooth gradient, brighter toward +X and the zenith): a floor with a block
// and a wall, no other light. Pure paths find the sky by leaving the scene.
TEST(PathTracer, NextEventEstimationAgreesWithPurePathTracingUnderASky) {
  Scene s;
  const std::uint32_t m = test::add_material(s, glm::vec3(0.6f));
  test::add_quad_object(s, "floor", {-2, 0, -2}, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, m);
  test::add_block(s, "block", {-0.5f, 0.0f, -0.5f}, {0.5f, 1.0f, 0.5f}, m);
  test::add_quad_object(s, "wall", {-2, 0, -2}, {2, 0, -2}, {2, 2, -2}, {-2, 2, -2}, m);
  s.sky.map = ImageRGB(32, 16);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x)
      s.sky.map.at(x, y) = glm::vec3(0.2f + x / 40.0f, 0.3f, 0.6f) * (1.3f - y / 16.0f);
  Fixture f(std::move(s));
  ASSERT_TRUE(f.lights.sky_distribution().valid());
  CameraPose cam;
  cam.eye = glm::vec3(0.0f, 2.5f, 3.5f);
  cam.forward = glm::normalize(glm::vec3(0.0f, -0.6f, -1.0f));
  cam.up = glm::normalize(glm::cross(glm::cross(cam.forward, glm::vec3(0, 1, 0)), cam.forward));
  expect_next_event_agrees_with_pure_paths(f, cam);
}

}  // namespace irradcast::test_path_tracer

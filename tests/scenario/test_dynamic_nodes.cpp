// Dynamic nodes (issue 32 part 1 and 2, docs/DYNAMIC.md): marked in glTF extras or with
// --dynamic, they take no part in the static scene (the engine's lightmaps and tiles are exactly
// those of the scene without them), they travel in the scene package and glTF exports, and
// moving them costs the engine nothing: no texel, tile version or tile epoch changes.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include "cli.h"
#include "dynamic_scenes.h"
#include "engine_setup.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/camera.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/wire/scene_package.h"
#include "scene_builders.h"
#include "service_fixture.h"

namespace irradcast::test_dynamic_nodes {

using test::cornell_with_prop;
using test::move;
namespace fs = std::filesystem;

namespace {

std::vector<std::pair<std::uint64_t, std::string>> tile_state(const EngineHost& host) {
  std::vector<std::pair<std::uint64_t, std::string>> out;
  for (std::uint32_t i = 0; i < host.tiles().tile_count(); ++i) {
    const auto snap = host.tiles().snapshot(i, wire::TILE_RGB9E5_ZSTD);
    out.emplace_back(snap.version, snap.payload ? *snap.payload : std::string());
  }
  return out;
}

// A started host on the Cornell box with its prop, a server and one connected viewer.
struct Served {
  explicit Served(std::uint32_t max_updates)
      : host(cornell_with_prop(), "cornell", test::quick_host(max_updates)),
        server((host.start(), host), test::loopback()),
        viewer((server.start(), test::client_of(server, "viewer"))) {
    viewer.connect();
  }
  ~Served() {
    viewer.close();
    server.stop();
    host.stop();
  }
  EngineHost host;
  Server server;
  ViewClient viewer;
};

}  // namespace

TEST(DynamicNodes, ASubtreeIsDynamicAndOutOfTheStaticWorld) {
  const Scene s = cornell_with_prop();
  const Scene plain = make_cornell_box();
  const std::vector<bool> dynamic = s.dynamic_nodes();
  int marked = 0;
  for (std::size_t n = 0; n < s.nodes.size(); ++n) {
    marked += dynamic[n] ? 1 : 0;
    EXPECT_EQ(dynamic[n], n > plain.nodes.size()) << s.nodes[n].name;  // all but the rig
  }
  EXPECT_EQ(marked, 3);  // prop, prop_base, lamp
  const World w = World::build(s), wp = World::build(plain);
  EXPECT_EQ(w.bounds.lo, wp.bounds.lo);
  EXPECT_EQ(w.bounds.hi, wp.bounds.hi);
  EXPECT_EQ(w.lights.size(), wp.lights.size());  // the lamp is off for the static scene
  ASSERT_EQ(w.objects.size(), wp.objects.size() + 2);
  EXPECT_TRUE(w.objects.back().dynamic);
  EXPECT_FALSE(w.objects.back().in_static_scene());
  EXPECT_TRUE(w.objects.back().visible);
}

// The acceptance test of part 1: the same texels, the same lightmaps bit for bit.
TEST(DynamicNodes, StaticLightmapsAreThoseOfTheSceneWithoutThem) {
  test::EngineSetup with(cornell_with_prop(), 32.0f), without(make_cornell_box(), 32.0f);
  ASSERT_EQ(with.atlas.texel_count(), without.atlas.texel_count());
  const std::size_t n = without.atlas.objects.size();
  for (std::size_t o = n; o < with.atlas.objects.size(); ++o) {
    EXPECT_EQ(with.atlas.objects[o].width, 0);
    EXPECT_TRUE(with.atlas.objects[o].corner_uv.empty());
  }
  EngineParams p;
  auto a = with.engine(p), b = without.engine(p);
  for (int u = 0; u < 3; ++u) {
    a->update();
    b->update();
  }
  const std::vector<Lightmap> la = a->lightmaps(), lb = b->lightmaps();
  ASSERT_EQ(la.size(), lb.size() + 2);
  for (std::size_t o = 0; o < n; ++o) {
    ASSERT_EQ(la[o].width, lb[o].width);
    ASSERT_EQ(la[o].texels.size(), lb[o].texels.size());
    for (std::size_t t = 0; t < lb[o].texels.size(); ++t)
      ASSERT_EQ(la[o].texels[t], lb[o].texels[t]) << "object " << o << " texel " << t;
  }
}

// Part 2: a moved dynamic node changes no texel, tile version or tile epoch; a moved static
// node does (the same test would see it).
TEST(DynamicNodes, MovingOneCostsTheEngineNothing) {
  EngineHost still(cornell_with_prop(), "cornell", test::quick_host(0));
  EngineHost moved(cornell_with_prop(), "cornell", test::quick_host(0));
  EngineHost moved_static(cornell_with_prop(), "cornell", test::quick_host(0));
  for (EngineHost* h : {&still, &moved, &moved_static}) h->step();
  // A pose: no revision, the first of the pose sequence.
  const EditReceipt r = moved.submit(move("prop", {0.3f, -0.1f, 0.0f}), false);
  EXPECT_EQ(r.revision, 0u);
  EXPECT_EQ(r.pose_sequence, 1u);
  moved_static.submit_edit(move("tall_block", {0.05f, 0.0f, 0.0f}));
  const std::uint64_t epoch = still.tile_epoch();
  const std::string package = still.package()->hash;
  for (EngineHost* h : {&still, &moved, &moved_static}) h->step();
  EXPECT_EQ(moved.revision(), 0u);
  EXPECT_EQ(moved.tile_epoch(), epoch);
  EXPECT_EQ(moved.package()->hash, package);  // the package places it as loaded
  EXPECT_EQ(moved.stats().stale_texels, still.stats().stale_texels);
  EXPECT_TRUE(tile_state(moved) == tile_state(still));
  // The prop's pose is on the board the viewers get their poses from.
  const int prop = static_cast<int>(make_cornell_box().nodes.size()) + 1;  // after the rig
  ASSERT_NE(moved.poses(), nullptr);
  std::uint64_t sequence = 0;
  const std::map<int, NodePoseState> poses = moved.poses()->snapshot(&sequence);
  EXPECT_EQ(sequence, 1u);
  ASSERT_EQ(poses.size(), 1u);
  ASSERT_EQ(poses.begin()->first, prop);
  EXPECT_FLOAT_EQ(poses.begin()->second.local[3].x, 0.3f);
  EXPECT_EQ(still.poses()->sequence(), 0u);
  EXPECT_EQ(EngineHost(make_cornell_box(), "cornell", test::quick_host(0)).poses(), nullptr);
  // The control: a static move restarts texels under a new epoch.
  EXPECT_NE(moved_static.tile_epoch(), epoch);
  EXPECT_FALSE(tile_state(moved_static) == tile_state(still));
}

TEST(DynamicNodes, TheFlagTravelsInPackagesAndGltf) {
  const Scene s = cornell_with_prop();
  test::EngineSetup setup(s, 32.0f);
  const wire::ScenePackage pkg = wire::make_scene_package(setup.scene, setup.atlas);
  const wire::UnpackedScene back = wire::open_scene_package(pkg.bytes, pkg.hash);
  ASSERT_EQ(back.scene.nodes.size(), s.nodes.size());
  for (std::size_t n = 0; n < s.nodes.size(); ++n)
    EXPECT_EQ(back.scene.nodes[n].dynamic, s.nodes[n].dynamic) << n;
  EXPECT_NE(wire::scene_content_hash(s), wire::scene_content_hash(make_cornell_box()));
  // A dynamic object with a lightmap layout is not a valid package.
  Atlas bad = setup.atlas;
  bad.objects.back() = bad.objects.front();
  try {
    wire::make_scene_package(setup.scene, bad);
    ADD_FAILURE() << "a layout on a dynamic object was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("is dynamic and has a lightmap layout"), std::string::npos)
        << e.what();
  }

  const fs::path dir = fs::temp_directory_path() / "irradcast_dynamic_gltf";
  fs::create_directories(dir);
  save_gltf(s, (dir / "prop.glb").string());
  const Scene loaded = load_gltf((dir / "prop.glb").string());
  int dynamic = 0;
  for (const bool d : loaded.dynamic_nodes()) dynamic += d ? 1 : 0;
  EXPECT_EQ(dynamic, 3);

  // Not a boolean: a clear error naming the node.
  std::ofstream((dir / "bad.gltf").string())
      << R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"scene":0,)"
      << R"("nodes":[{"name":"door","extras":{"irradcast":{"dynamic":"yes"}}}]})";
  try {
    load_gltf((dir / "bad.gltf").string());
    ADD_FAILURE() << "a dynamic flag that is not a boolean was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("extras.irradcast.dynamic that is not a boolean"),
              std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

TEST(DynamicNodes, BakeTakesDynamicByName) {
  const fs::path dir = fs::temp_directory_path() / "irradcast_dynamic_bake";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const test::CliResult bad = test::run_cli(
      IRRADCAST_BAKE_EXE, "--scene cornell --dynamic no_such_node --out " + (dir / "x").string() +
                              " --updates 1 --texels-per-scene 32 --width 32 --height 32");
  EXPECT_NE(bad.status, 0) << bad.output;
  EXPECT_NE(bad.output.find("--dynamic: the scene has no node named 'no_such_node'"),
            std::string::npos)
      << bad.output;
  const test::CliResult ok = test::run_cli(
      IRRADCAST_BAKE_EXE, "--scene cornell --dynamic tall_block --out " + (dir / "y").string() +
                              " --updates 1 --texels-per-scene 32 --width 32 --height 32");
  EXPECT_EQ(ok.status, 0) << ok.output;
  EXPECT_NE(ok.output.find("1 dynamic nodes"), std::string::npos) << ok.output;
  fs::remove_all(dir);
}

// A converged server stays idle when a dynamic node moves: the edit is applied and sent, and no
// update runs.
TEST(DynamicNodes, AConvergedHostStaysIdle) {
  EngineHost host(cornell_with_prop(), "cornell", test::quick_host(2));
  host.start();
  ASSERT_TRUE(test::eventually([&] { return host.stats().idle; }));
  const std::uint64_t updates = host.stats().updates;
  std::atomic<std::uint64_t> sent{0};
  host.set_edit_listener([&](const AppliedEdit& a) { sent = a.revision; });
  EXPECT_EQ(host.submit(move("prop", {0.0f, 0.1f, 0.0f}), false).pose_sequence, 1u);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_TRUE(host.stats().idle);
  EXPECT_EQ(host.stats().updates, updates);
  // Nor does a rig: a static node without a mesh whose children are dynamic.
  EXPECT_EQ(host.submit(move("rig", {0.1f, 0.0f, 0.0f}), false).pose_sequence, 2u);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_TRUE(host.stats().idle);
  EXPECT_EQ(host.stats().updates, updates);
  EXPECT_EQ(host.stats().revision, 0u);
  // A static move wakes it.
  EXPECT_EQ(host.submit_edit(move("tall_block", {0.02f, 0.0f, 0.0f})), 1u);
  EXPECT_TRUE(test::eventually([&] { return host.stats().updates > updates; }));
  host.stop();
  EXPECT_EQ(sent, 1u);  // poses are not revisions: the one edit sent is the static move
}

// Through the server to a viewer: the viewer gets the scene with its dynamic nodes, the moved
// pose with the edit, and not one tile more.
TEST(DynamicNodes, AViewerGetsThePoseAndNoTile) {
  using namespace std::chrono_literals;
  Served s(2);
  EngineHost& host = s.host;
  ViewClient& viewer = s.viewer;
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  // Caught up: the engine is done and the viewer holds every tile's last version.
  const auto caught_up = [&] {
    if (!host.stats().idle) return false;
    const TileStore& tiles = host.tiles();
    for (std::uint32_t i = 0; i < tiles.tile_count(); ++i) {
      const TileStore::Tile& t = tiles.tile(i);
      if (viewer.tile_version(t.lightmap, t.tx, t.ty) != tiles.version(i)) return false;
    }
    return true;
  };
  while (std::chrono::steady_clock::now() < deadline && !caught_up()) viewer.poll(50ms);
  ASSERT_TRUE(caught_up());
  const std::vector<Lightmap> before = viewer.lightmaps();
  const CameraPose camera = default_camera(viewer.scene(), viewer.world());
  // The glowing prop's pixels (emission (4, 2, 1)): how many, and their mean column.
  const auto glow = [](const ImageRGB& im) {
    double sx = 0.0;
    int n = 0;
    for (int y = 0; y < im.height; ++y)
      for (int x = 0; x < im.width; ++x) {
        const glm::vec3 p = im.at(x, y);
        if (p.x > 3.5f && p.x > 1.6f * p.y && p.x < 2.6f * p.y) {
          sx += x;
          ++n;
        }
      }
    return std::pair<int, double>(n, n > 0 ? sx / n : 0.0);
  };
  const auto [n0, x0] = glow(viewer.compose(camera, 64, 64));
  EXPECT_GT(n0, 10);  // the viewer draws the dynamic prop
  host.submit_edit(move("prop", {0.2f, 0.0f, 0.1f}));
  while (std::chrono::steady_clock::now() < deadline && viewer.pose_sequence() < 1)
    viewer.poll(50ms);
  ASSERT_EQ(viewer.pose_sequence(), 1u);
  EXPECT_EQ(viewer.scene_revision(), 0u);  // a pose, not a revision
  viewer.poll(300ms);
  const int prop = static_cast<int>(make_cornell_box().nodes.size()) + 1;  // after the rig
  EXPECT_FLOAT_EQ(viewer.scene().nodes[static_cast<std::size_t>(prop)].local[3].x, 0.2f);
  const std::vector<Lightmap> after = viewer.lightmaps();
  ASSERT_EQ(after.size(), before.size());
  for (std::size_t o = 0; o < after.size(); ++o) EXPECT_TRUE(after[o].texels == before[o].texels);
  // The next frame shows the new pose: 0.2 m along +x is to the left in this camera's image.
  const auto [n1, x1] = glow(viewer.compose(camera, 64, 64));
  EXPECT_GT(n1, 10);
  EXPECT_LT(x1, x0 - 5.0) << "the prop did not move on screen";
}

// The server computes the probe volume for a scene with dynamic nodes and every viewer gets it:
// in the middle of the room it agrees with the path tracer.
TEST(DynamicNodes, ViewersGetTheProbeVolume) {
  using namespace std::chrono_literals;
  EXPECT_EQ(EngineHost(cornell_with_prop(), "cornell", test::quick_host(4)).probe_volume(),
            nullptr);  // the first version comes with the first update
  Served s(4);
  EngineHost& host = s.host;
  ViewClient& viewer = s.viewer;
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (std::chrono::steady_clock::now() < deadline &&
         !(host.stats().idle && viewer.probe_volume().has_sh &&
           viewer.probe_volume().version == host.probe_volume()->version))
    viewer.poll(50ms);
  ASSERT_TRUE(viewer.probe_volume().has_sh);
  EXPECT_EQ(viewer.probe_volume().version, host.probe_volume()->version);
  const IrradianceVolume& v = viewer.probe_volume().volume;
  EXPECT_GT(v.probe_count(), 100u);
  // Against the truth at the middle of the static room, for the 6 axis normals.
  test::EngineSetup truth_scene(make_cornell_box(), 32.0f);
  PathTracer truth(truth_scene.world, truth_scene.rays, truth_scene.lights,
                   PathTracerOptions{3, true, 5});
  const glm::vec3 p = truth_scene.world.bounds.center();
  double got = 0.0, expected = 0.0;
  for (const glm::vec3& n : {glm::vec3(1, 0, 0), glm::vec3(-1, 0, 0), glm::vec3(0, 1, 0),
                             glm::vec3(0, -1, 0), glm::vec3(0, 0, 1), glm::vec3(0, 0, -1)}) {
    Rng rng(3, static_cast<std::uint64_t>(n.x * 3 + n.y * 5 + n.z * 7 + 10));
    glm::dvec3 e(0.0);
    for (int s = 0; s < 4000; ++s) e += glm::dvec3(truth.irradiance(p, n, n, 3, rng));
    expected += luminance(glm::vec3(e / 4000.0));
    got += luminance(v.irradiance(p, n));
  }
  std::printf("viewer's volume / path tracer at the centre: %.4f\n", got / expected);
  EXPECT_NEAR(got / expected, 1.0, 0.1);
}

}  // namespace irradcast::test_dynamic_nodes

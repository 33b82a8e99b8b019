// irradcast-edit --export: the live scene, every edit applied, written as glTF 2.0 with the
// control token only; loaded back it is the server's scene (transforms, hidden nodes through
// KHR_node_visibility, materials), and irradcast-bake on it renders what a viewer of the server
// sees, within Monte Carlo noise, while a bake of the scene as loaded does not.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "cli.h"
#include "dynamic_scenes.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/image.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "service_fixture.h"

namespace irradcast::test_scene_export {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::string kToken = "export-token-0123456789";

const char* const kEdits[] = {
    R"({"op": "move", "node": "tall_block", "by": [0.1, 0, -0.05]})",
    R"({"op": "albedo", "material": "red", "color": [0.1, 0.15, 0.65]})",
    R"({"op": "emission", "material": "light", "color": [12, 14, 17], "strength": 1.5})",
    R"({"op": "hide", "node": "short_block"})",
};

struct ExportServer {
  EngineHost host;
  Server server;
  explicit ExportServer(std::uint32_t updates)
      : host(make_cornell_box(), "cornell", test::small_host(updates)), server(host, options()) {
    server.start();
    for (const char* e : kEdits) host.submit_edit(parse_edit_json(e));
    host.start();
  }
  ~ExportServer() {
    server.stop();
    host.stop();
  }
  static ServerOptions options() {
    ServerOptions o = test::loopback();
    o.control_token = kToken;
    return o;
  }
  std::string connect() const { return "--connect 127.0.0.1:" + std::to_string(server.port()); }
};

TEST(SceneExport, NeedsTheTokenAndWritesTheEditedSceneAsGltf) {
  ExportServer s(1);
  ASSERT_TRUE(test::eventually([&] { return s.host.revision() == 4; }));
  const fs::path out = fs::path(::testing::TempDir()) / "export_scene.glb";
  fs::remove(out);

  test::CliResult r = test::run_cli(IRRADCAST_EDIT_EXE,
                                    s.connect() + " --token wrong-token --export " + out.string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_FALSE(fs::exists(out));
  r = test::run_cli(IRRADCAST_EDIT_EXE, s.connect() + " --token " + kToken + " --export x.obj");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("must end in .glb or .gltf"), std::string::npos) << r.output;

  r = test::run_cli(IRRADCAST_EDIT_EXE,
                    s.connect() + " --token " + kToken + " --export " + out.string());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("exported revision 4 of cornell"), std::string::npos) << r.output;

  const Scene back = load_gltf(out.string());
  const Scene& live = s.host.scene();  // the engine is idle (one update): safe to read
  ASSERT_EQ(back.nodes.size(), live.nodes.size());
  for (std::size_t i = 0; i < live.nodes.size(); ++i) {
    EXPECT_EQ(back.nodes[i].name, live.nodes[i].name);
    EXPECT_EQ(back.nodes[i].local, live.nodes[i].local) << live.nodes[i].name;
    EXPECT_EQ(back.nodes[i].visible, live.nodes[i].visible) << live.nodes[i].name;
  }
  ASSERT_EQ(back.materials.size(), live.materials.size());
  for (std::size_t i = 0; i < live.materials.size(); ++i) {
    EXPECT_EQ(back.materials[i].base_color, live.materials[i].base_color) << i;
    EXPECT_EQ(back.materials[i].emission(), live.materials[i].emission()) << i;
  }
  // The hidden block is not part of the exported world; the moved one is where it was moved.
  const World w = World::build(back);
  const World lw = World::build(live);
  ASSERT_EQ(w.objects.size(), lw.objects.size());
  for (std::size_t i = 0; i < w.objects.size(); ++i) {
    EXPECT_EQ(w.objects[i].visible, lw.objects[i].visible) << i;
    EXPECT_EQ(w.objects[i].positions, lw.objects[i].positions) << i;
  }
  // The state differs from the scene as loaded in exactly the four edits.
  EXPECT_EQ(state_edit(make_cornell_box(), back).ops.size(), 4u);
}

// Dynamic nodes are exported where their poses put them (the package places them as loaded;
// docs/DYNAMIC.md#moving-them-poses), with their flag.
TEST(SceneExport, HoldsThePosesOfDynamicNodes) {
  EngineHost host(test::cornell_with_prop(), "cornell", test::small_host(1));
  Server server(host, ExportServer::options());
  server.start();
  host.start();
  host.submit(parse_edit_json(R"({"op": "move", "node": "prop", "by": [0.1, 0, 0]})"), false);
  host.submit(parse_edit_json(R"({"op": "hide", "node": "prop_base"})"), false);
  const fs::path out = fs::path(::testing::TempDir()) / "export_poses.glb";
  fs::remove(out);
  const test::CliResult r =
      test::run_cli(IRRADCAST_EDIT_EXE, "--connect 127.0.0.1:" + std::to_string(server.port()) +
                                            " --token " + kToken + " --export " + out.string());
  server.stop();
  host.stop();
  ASSERT_EQ(r.status, 0) << r.output;
  const Scene back = load_gltf(out.string());
  const Scene loaded = test::cornell_with_prop();
  ASSERT_EQ(back.nodes.size(), loaded.nodes.size());
  const auto prop = static_cast<std::size_t>(make_cornell_box().nodes.size()) + 1;
  EXPECT_TRUE(back.nodes[prop].dynamic);
  EXPECT_FLOAT_EQ(back.nodes[prop].local[3].x, loaded.nodes[prop].local[3].x + 0.1f);
  EXPECT_FALSE(back.nodes[prop + 1].visible);  // prop_base
  // Of the nodes, exactly those two differ (glTF writes emission as a factor and a strength).
  int node_ops = 0;
  for (const EditOp& op : state_edit(loaded, back).ops)
    node_ops += op.kind == EditOp::Kind::SetTransform || op.kind == EditOp::Kind::Show ||
                        op.kind == EditOp::Kind::Hide
                    ? 1
                    : 0;
  EXPECT_EQ(node_ops, 2) << edit_to_json(state_edit(loaded, back));
}

// What a viewer of the server sees against irradcast-bake of the export, and of the scene as
// loaded: 48 texels per scene, 8 updates on both sides, the scene's camera.
TEST(SceneExport, ABakeOfTheExportRendersWhatTheViewersSee) {
  ExportServer s(8);
  ASSERT_TRUE(test::eventually([&] { return s.host.revision() == 4; }));
  const fs::path dir = fs::path(::testing::TempDir()) / "export_render";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string glb = (dir / "live.glb").string();
  test::CliResult r =
      test::run_cli(IRRADCAST_EDIT_EXE, s.connect() + " --token " + kToken + " --export " + glb);
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string size = " --width 96 --height 96";
  r = test::run_cli(IRRADCAST_VIEW_EXE, s.connect() + " --out " + (dir / "viewer.exr").string() +
                                            " --until-converged --timeout 120" + size);
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string bake = " --texels-per-scene 48 --updates 8 --log-level warn" + size;
  r = test::run_cli(IRRADCAST_BAKE_EXE,
                    "--scene " + glb + " --out " + (dir / "export").string() + bake);
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_cli(IRRADCAST_BAKE_EXE,
                    "--scene cornell --out " + (dir / "loaded").string() + bake);
  ASSERT_EQ(r.status, 0) << r.output;
  const ImageRGB viewer = read_exr((dir / "viewer.exr").string());
  const ImageError same = compare(read_exr((dir / "export" / "view.exr").string()), viewer);
  const ImageError other = compare(read_exr((dir / "loaded" / "view.exr").string()), viewer);
  // Two independent 8-update estimates at a low texel density: noise and the atlas of the export
  // (built from the edited geometry) keep them apart by a little; the unedited scene by far more.
  EXPECT_LT(same.rel_mse, 0.005) << "rmse " << same.rmse;
  EXPECT_GT(other.rel_mse, 10.0 * same.rel_mse) << "rmse " << other.rmse;
  std::printf("export vs viewer: rel MSE %.5f rmse %.5f; loaded scene vs viewer: rel MSE %.5f\n",
              same.rel_mse, same.rmse, other.rel_mse);
}

}  // namespace
}  // namespace irradcast::test_scene_export

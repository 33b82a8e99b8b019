// Live scene edits end to end over loopback TCP: the control token, refused edits, the
// acknowledgement and the broadcast, a viewer applying the edit to its own scene, a client that
// connects after the edit, and the irradcast-edit tool.
#include <gtest/gtest.h>

#include <unistd.h>
#include <asio.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <string>

#include "cli.h"
#include "engine_setup.h"
#include "irradcast/client/camera_message.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/net_server.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/scene_package.h"
#include "scene_builders.h"
#include "service_fixture.h"

namespace irradcast::test_edit_service {

using asio::ip::tcp;
using namespace std::chrono_literals;

namespace {

// At least kMinTokenLength characters.
const std::string kToken = "secret-token-for-tests";

using test::quick_host;

ServerOptions edit_server(const std::string& token) {
  ServerOptions o = test::loopback(10000ms);
  o.control_token = token;
  return o;
}

// A raw protocol client: Hello, then whatever the test sends.
struct Raw : test::RawConnection {
  explicit Raw(std::uint16_t port) : RawConnection(port) { EXPECT_TRUE(join("raw-editor")); }
  // The next SceneEdit or Error frame (others, e.g. Pong, are skipped).
  std::optional<wire::Envelope> reply(std::chrono::milliseconds limit = 5000ms) {
    while (auto e = read(limit))
      if (e->has_scene_edit() || e->has_error()) return e;
    return std::nullopt;
  }
  void edit(const std::string& json, const std::string& token, std::uint64_t request_id = 1) {
    wire::Envelope e;
    wire::to_proto(parse_edit_json(json), e.mutable_scene_edit());
    e.mutable_scene_edit()->set_token(token);
    e.mutable_scene_edit()->set_request_id(request_id);
    send(e);
  }
  // Sends a Ping and expects its Pong (skipping anything else): the session is alive.
  bool alive() {
    wire::Envelope p;
    p.mutable_ping()->set_nonce(4242);
    send(p);
    while (auto e = read())
      if (e->has_pong()) return e->pong().nonce() == 4242;
    return false;
  }
};

// The Error a raw client gets for `json` with `token` (code and message), after which the
// session must still answer a Ping.
std::pair<wire::ErrorCode, std::string> refused(Raw& r, const std::string& json,
                                                const std::string& token) {
  r.edit(json, token);
  auto e = r.reply();
  EXPECT_TRUE(e && e->has_error()) << json;
  EXPECT_TRUE(r.alive()) << "the session should go on after a refused edit";
  if (!e || !e->has_error()) return {wire::ERROR_UNSPECIFIED, ""};
  return {e->error().code(), e->error().message()};
}

const char* kMove = R"({"op": "move", "node": "tall_block", "by": [0.05, 0, 0]})";

int node_index(const Scene& s, const std::string& name) {
  for (std::size_t i = 0; i < s.nodes.size(); ++i)
    if (s.nodes[i].name == name) return static_cast<int>(i);
  return -1;
}

// An open plane facing up (+Y), 2 x 2 m, albedo 0.5, with no lights: only a sky lights it.
Scene open_plane() {
  Scene s;
  s.name = "plane";
  const std::uint32_t m = test::add_material(s, glm::vec3(0.5f));
  test::add_quad_object(s, "plane", {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, {-1, 0, -1}, m);
  return s;
}

// Mean irradiance over the valid texels of object 0 (luminance).
double mean_e(const std::vector<Lightmap>& maps, const TexelGBuffer& g) {
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < maps[0].texels.size(); ++i)
    if (g.valid(i)) {
      sum += (maps[0].texels[i].x + maps[0].texels[i].y + maps[0].texels[i].z) / 3.0;
      ++n;
    }
  return n ? sum / static_cast<double>(n) : 0.0;
}

}  // namespace

TEST(EditService, SkyColourEditRelightsEveryTexelToPiTimesTheNewSky) {
  // Open plane under a constant sky of radiance L: E = pi L at every texel (each cosine ray
  // escapes, so every sample is exactly pi L; nothing bounces back). After an edit to L' every
  // texel restarts and converges to pi L', with no trace of L.
  Scene s = open_plane();
  s.sky.color = glm::vec3(0.2f);
  test::EngineSetup setup(std::move(s), 16.0f);
  EngineParams params;
  params.edit_blend = 0;  // the new estimate at once (no blend from the old value)
  // Unbiased mode: bounce rays that leave the scene bring nothing (the sky is direct light).
  // With probes, a plane alone reads its own light back through probes below it (+65 % here;
  // issue 18 item 3 is about such leaks), which is not what this test is about.
  params.tracing_range = std::numeric_limits<float>::infinity();
  auto engine = setup.engine(params);
  for (int i = 0; i < 2; ++i) engine->update();
  EXPECT_NEAR(mean_e(engine->lightmaps(), setup.gbuffers[0]), kPi * 0.2, 1e-3 * kPi * 0.2);
  const SceneEdit edit = parse_edit_json(R"({"op": "sky", "color": [1.5, 1.5, 1.5]})");
  EditReport report;
  const SceneChange change = setup.prepared.apply(std::span(&edit, 1), &report);
  EXPECT_TRUE(report.sky);
  EXPECT_TRUE(change.sky);
  engine->scene_changed(change, {});
  EXPECT_EQ(engine->stale_texels(), engine->texel_count()) << "every texel restarts";
  for (int i = 0; i < 8 && engine->stale_texels() > 0; ++i) engine->update();
  engine->update();
  const std::vector<Lightmap> maps = engine->lightmaps();
  for (std::size_t i = 0; i < maps[0].texels.size(); ++i) {
    if (!setup.gbuffers[0].valid(i)) continue;
    for (int c = 0; c < 3; ++c)
      ASSERT_NEAR(maps[0].texels[i][c], kPi * 1.5, 1e-3 * kPi * 1.5) << "texel " << i;
  }
}

TEST(EditService, EditsNeedTheControlToken) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  {
    Server server(host, edit_server(kToken));
    server.start();
    Raw r(server.port());
    auto [code, message] = refused(r, kMove, "");
    EXPECT_EQ(code, wire::PERMISSION_DENIED);
    EXPECT_EQ(message, "scene edits need the control token");
    std::tie(code, message) = refused(r, kMove, "Secret");
    EXPECT_EQ(code, wire::PERMISSION_DENIED);
    std::tie(code, message) = refused(r, kMove, "secret-and-more");
    EXPECT_EQ(code, wire::PERMISSION_DENIED);
    EXPECT_EQ(host.revision(), 0u);
    server.stop();
  }
  {  // A server without a token takes no edits, whatever the client sends.
    Server server(host, edit_server(""));
    server.start();
    Raw r(server.port());
    auto [code, message] = refused(r, kMove, "secret");
    EXPECT_EQ(code, wire::PERMISSION_DENIED);
    EXPECT_NE(message.find("this server takes no edits"), std::string::npos) << message;
    std::tie(code, message) = refused(r, kMove, "");
    EXPECT_EQ(code, wire::PERMISSION_DENIED);
    server.stop();
  }
  host.step();  // nothing was queued: the scene is as loaded
  EXPECT_EQ(host.revision(), 0u);
  EXPECT_EQ(host.stats().revision, 0u);
}

TEST(EditService, BadEditsAndCamerasGetBadRequestAndChangeNothing) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  const std::string hash = host.package()->hash;
  Server server(host, edit_server(kToken));
  server.start();
  Raw r(server.port());
  auto [code, message] =
      refused(r, R"({"op": "move", "node": "no_such_node", "by": [1, 0, 0]})", kToken);
  EXPECT_EQ(code, wire::BAD_REQUEST);
  EXPECT_NE(message.find("no node 'no_such_node'"), std::string::npos) << message;

  {  // NaN cannot be written in JSON: straight into the message.
    wire::Envelope e;
    wire::SceneEdit* m = e.mutable_scene_edit();
    m->set_token(kToken);
    wire::EditOp* op = m->add_ops();
    op->set_kind(wire::EditOp::MOVE);
    op->set_target("tall_block");
    op->mutable_vector()->set_y(std::numeric_limits<float>::quiet_NaN());
    r.send(e);
    auto err = r.reply();
    ASSERT_TRUE(err && err->has_error());
    EXPECT_EQ(err->error().code(), wire::BAD_REQUEST);
    EXPECT_NE(err->error().message().find("not finite"), std::string::npos)
        << err->error().message();
    // A matrix of the wrong size is refused by the wire conversion.
    op->set_kind(wire::EditOp::SET_TRANSFORM);
    op->mutable_vector()->set_y(0.0f);
    op->add_matrix(1.0f);
    r.send(e);
    err = r.reply();
    ASSERT_TRUE(err && err->has_error());
    EXPECT_EQ(err->error().code(), wire::BAD_REQUEST);
    EXPECT_NE(err->error().message().find("the matrix has 1 values"), std::string::npos)
        << err->error().message();
  }
  std::tie(code, message) = refused(
      r, R"({"op": "rotate", "node": "tall_block", "axis": [0, 0, 0], "degrees": 30})", kToken);
  EXPECT_EQ(code, wire::BAD_REQUEST);
  EXPECT_NE(message.find("rotation axis is zero"), std::string::npos) << message;
  {  // An empty edit.
    wire::Envelope e;
    e.mutable_scene_edit()->set_token(kToken);
    r.send(e);
    auto err = r.reply();
    ASSERT_TRUE(err && err->has_error());
    EXPECT_EQ(err->error().code(), wire::BAD_REQUEST);
    EXPECT_NE(err->error().message().find("no operations"), std::string::npos);
  }
  {  // Cameras: non-finite numbers and a zero forward direction.
    CameraPose pose;
    pose.eye = glm::vec3(0.2f, 0.2f, -0.5f);
    pose.forward = glm::vec3(0.0f);
    r.send(camera_update(pose));
    auto err = r.read();
    ASSERT_TRUE(err && err->has_error());
    EXPECT_EQ(err->error().code(), wire::BAD_REQUEST);
    EXPECT_NE(err->error().message().find("forward direction is zero"), std::string::npos);
    pose.forward = glm::vec3(0.0f, 0.0f, 1.0f);
    pose.yfov = std::numeric_limits<float>::infinity();
    r.send(camera_update(pose));
    err = r.read();
    ASSERT_TRUE(err && err->has_error());
    EXPECT_EQ(err->error().code(), wire::BAD_REQUEST);
    EXPECT_NE(err->error().message().find("not finite"), std::string::npos);
    pose.yfov = 0.7f;
    r.send(camera_update(pose));  // a good one: no answer, the session goes on
    EXPECT_TRUE(r.alive());
  }
  host.step();
  EXPECT_EQ(host.revision(), 0u);
  EXPECT_EQ(host.package()->hash, hash);
  server.stop();
}

TEST(EditService, AnEditIsAcknowledgedBroadcastAndAppliedByViewers) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  const int tall = node_index(host.scene(), "tall_block");
  ASSERT_GE(tall, 0);
  const glm::mat4 before = host.scene().nodes[static_cast<std::size_t>(tall)].local;
  const std::string hash_before = host.package()->hash;
  Server server(host, edit_server(kToken));
  server.start();
  host.start();

  ViewClientOptions vo;
  vo.port = server.port();
  vo.name = "viewer";
  ViewClient viewer(vo);
  viewer.connect();
  EXPECT_EQ(viewer.scene_revision(), 0u);
  EXPECT_EQ(viewer.scene_hash(), hash_before);
  const std::size_t object = [&] {
    const std::vector<Object> objects = viewer.scene().objects();
    for (std::size_t i = 0; i < objects.size(); ++i)
      if (objects[i].node == tall) return i;
    return objects.size();
  }();
  ASSERT_LT(object, viewer.world().objects.size());
  const glm::vec3 p0 = viewer.world().objects[object].positions.at(0);

  // The editor gets the acknowledgement, then (like every client) the applied edit.
  Raw editor(server.port());
  editor.edit(kMove, kToken, 77);
  auto ack = editor.reply();
  ASSERT_TRUE(ack && ack->has_scene_edit())
      << (ack && ack->has_error() ? ack->error().message() : std::string("none"));
  EXPECT_FALSE(ack->scene_edit().applied());
  EXPECT_EQ(ack->scene_edit().request_id(), 77u);
  EXPECT_EQ(ack->scene_edit().revision(), 1u);
  EXPECT_TRUE(ack->scene_edit().token().empty());
  auto applied = editor.reply(10000ms);
  ASSERT_TRUE(applied && applied->has_scene_edit());
  const wire::SceneEdit& b = applied->scene_edit();
  EXPECT_TRUE(b.applied());
  EXPECT_EQ(b.revision(), 1u);
  EXPECT_EQ(b.request_id(), 0u);
  EXPECT_TRUE(b.token().empty());
  EXPECT_GT(b.applied_us(), 0u);
  EXPECT_EQ(b.scene_hash(), host.package()->hash);
  EXPECT_NE(b.scene_hash(), hash_before);
  ASSERT_EQ(b.ops_size(), 1);
  EXPECT_EQ(b.ops(0).kind(), wire::EditOp::MOVE);
  EXPECT_EQ(b.ops(0).target(), "tall_block");

  // The viewer applies it to its own scene: the node and its triangles moved by 5 cm.
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (viewer.scene_revision() < 1 && std::chrono::steady_clock::now() < deadline)
    viewer.poll(20ms);
  ASSERT_EQ(viewer.scene_revision(), 1u);
  EXPECT_EQ(viewer.counters().edits_applied, 1u);
  glm::mat4 expected = before;
  expected[3].x += 0.05f;
  EXPECT_EQ(viewer.scene().nodes[static_cast<std::size_t>(tall)].local, expected);
  const glm::vec3 p1 = viewer.world().objects[object].positions.at(0);
  EXPECT_NEAR(p1.x - p0.x, 0.05f, 1e-6f);
  EXPECT_EQ(p1.y, p0.y);
  EXPECT_EQ(p1.z, p0.z);
  // The stats say so too.
  auto stats = viewer.request_stats(5s);
  ASSERT_TRUE(stats);
  EXPECT_EQ(stats->scene_revision(), 1u);
  EXPECT_GT(stats->last_edit_ms(), 0.0);

  // A client that connects now gets the edited scene in its Welcome.
  ViewClient late(vo);
  late.connect();
  EXPECT_NE(late.scene_hash(), hash_before);
  EXPECT_EQ(late.scene_hash(), host.package()->hash);
  EXPECT_EQ(late.scene_revision(), 1u);
  EXPECT_EQ(late.counters().edits_applied, 0u);  // from the package, not from an edit
  EXPECT_EQ(late.scene().nodes[static_cast<std::size_t>(tall)].local, expected);
  {  // The raw package as well.
    Raw r(server.port());
    EXPECT_NE(r.welcome.scene_hash(), hash_before);
    const auto pkg = host.package();
    EXPECT_EQ(r.welcome.scene_hash(), pkg->hash);
    const wire::UnpackedScene u = wire::open_scene_package(pkg->bytes, r.welcome.scene_hash());
    EXPECT_EQ(u.revision, 1u);
    EXPECT_EQ(u.scene.nodes[static_cast<std::size_t>(tall)].local, expected);
  }
  late.close();
  viewer.close();
  server.stop();
  host.stop();
}

TEST(EditService, IrradcastEditReportsRefusalsAndAppliedEdits) {
  EngineHost host(make_cornell_box(), "cornell", quick_host());
  Server server(host, edit_server(kToken));
  server.start();
  host.start();
  const std::string exe = IRRADCAST_EDIT_EXE;
  const std::string connect = "--connect 127.0.0.1:" + std::to_string(server.port());

  test::CliResult r = test::run_cli(exe, connect + " --move tall_block 0.05,0,0");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("irradcast-edit: scene edits need the control token"), std::string::npos)
      << r.output;
  r = test::run_cli(exe, connect + " --token wrong --hide short_block");
  EXPECT_EQ(r.status, 2) << r.output;

  r = test::run_cli(exe, connect + " --token " + kToken + " --move no_such_node 0.05,0,0");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("irradcast-edit: edit op 1 (move): the scene has no node 'no_such_node'"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(host.revision(), 0u);

  r = test::run_cli(exe, connect + " --token " + kToken + " --move tall_block 0.05,0,0");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("revision 1 applied in"), std::string::npos) << r.output;
  EXPECT_EQ(host.revision(), 1u);

  r = test::run_cli(exe,
                    connect + " --token " + kToken +
                        " --no-wait --json "
                        "'{\"op\": \"albedo\", \"material\": \"red\", \"color\": [0.5, 0, 0]}'");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("revision 2 queued"), std::string::npos) << r.output;

  // A script with a delay, the token from a file.
  const std::string dir = ::testing::TempDir();
  {
    std::ofstream(dir + "/edit_token") << "  " << kToken << " \n";
    std::ofstream(dir + "/edit_script.json") << R"([{"op": "hide", "node": "short_block"},
               {"after_ms": 50, "op": "show", "node": "short_block"}])";
  }
  r = test::run_cli(
      exe, connect + " --token-file " + dir + "/edit_token --script " + dir + "/edit_script.json");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("revision 3 applied in"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("revision 4 applied in"), std::string::npos) << r.output;
  EXPECT_EQ(host.revision(), 4u);

  // Usage errors: no edit, two edits.
  r = test::run_cli(exe, connect + " --token " + kToken);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("give exactly one edit"), std::string::npos) << r.output;
  r = test::run_cli(exe, connect + " --token " + kToken + " --show a --hide b");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("give exactly one edit"), std::string::npos) << r.output;
  server.stop();
  host.stop();
}

TEST(EditService, ASkyFileEditReachesViewersAsBackgroundAndLight) {
  // The server's sky folder holds an 8 x 4 map: upper half 0.5, lower half 0.25, one texel of
  // the upper half brighter (values exact in RGB9E5, so the viewer's copy is the same).
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("irradcast-sky-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  ImageRGB map(8, 4, glm::vec3(0.5f));
  for (int y = 2; y < 4; ++y)
    for (int x = 0; x < 8; ++x) map.at(x, y) = glm::vec3(0.25f);
  map.at(3, 1) = glm::vec3(2.0f, 1.0f, 0.5f);
  write_exr((dir / "dusk.exr").string(), map);
  std::ofstream(dir.parent_path() / "outside.exr") << "x";

  EngineHostOptions ho = quick_host();
  ho.engine.tracing_range = std::numeric_limits<float>::infinity();  // as in the test above
  ho.sky_dir = dir.string();
  EngineHost host(open_plane(), "plane", ho);
  Server server(host, edit_server(kToken));
  server.start();
  host.start();
  ViewClient viewer(test::client_of(server, "viewer"));
  viewer.connect();
  CameraPose cam;  // at the plane's edge looking along it: half plane, half sky
  cam.eye = glm::vec3(0.0f, 0.3f, 3.0f);
  cam.forward = glm::normalize(glm::vec3(0.0f, -0.05f, -1.0f));
  cam.yfov = glm::radians(70.0f);
  const ImageRGB dark = viewer.compose(cam, 32, 24);
  EXPECT_EQ(dark.at(16, 0), glm::vec3(0.0f)) << "no sky yet: misses are black";

  Raw editor(server.port());
  // Names outside the folder, absolute paths and missing files are refused by name.
  for (const char* bad : {"../outside.exr", "/etc/passwd", "missing.exr"}) {
    const auto [code, message] =
        refused(editor, std::string(R"({"op": "sky", "file": ")") + bad + "\"}", kToken);
    EXPECT_EQ(code, wire::BAD_REQUEST) << message;
    EXPECT_NE(message.find("refused"), std::string::npos) << message;
  }
  editor.edit(R"({"op": "sky", "file": "dusk.exr", "strength": 2})", kToken);
  auto ack = editor.reply();
  ASSERT_TRUE(ack && ack->has_scene_edit())
      << (ack && ack->has_error() ? ack->error().message() : std::string("none"));
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (viewer.scene_revision() < 1 && std::chrono::steady_clock::now() < deadline)
    viewer.poll(20ms);
  ASSERT_EQ(viewer.scene_revision(), 1u);
  EXPECT_EQ(viewer.scene().sky.source, "dusk.exr");
  EXPECT_EQ(viewer.scene().sky.map.pixels, map.pixels);
  EXPECT_EQ(viewer.scene().sky.strength, 2.0f);
  EXPECT_EQ(host.scene().sky.map.pixels, map.pixels);
  // The background: every pixel whose ray misses the plane shows the sky in its direction.
  const ImageRGB lit = viewer.compose(cam, 32, 24);
  const RayScene rays(viewer.world());
  int sky_pixels = 0;
  for (int y = 0; y < lit.height; ++y)
    for (int x = 0; x < lit.width; ++x) {
      const Ray r = camera_ray(cam, lit.width, lit.height, x + 0.5f, y + 0.5f);
      if (rays.intersect(r).valid()) continue;
      ++sky_pixels;
      EXPECT_EQ(lit.at(x, y), host.scene().sky.radiance(r.direction)) << x << ", " << y;
    }
  EXPECT_GT(sky_pixels, 100);
  // The light: the plane sees the upper half, mostly 0.5 x 2 = 1 (the bright texel adds a
  // little): E within [pi x 1, pi x 1.3], once the restarted texels have blended from the old
  // sky's value to the new estimate (a slow machine, ASan, shows the blend on the way).
  const auto until = std::chrono::steady_clock::now() + 30s;
  double e = 0.0;
  while (std::chrono::steady_clock::now() < until) {
    viewer.poll(50ms);
    const Lightmap& m = viewer.lightmaps().at(0);  // its middle texel: inside the chart
    const glm::vec3 t = m.texels[static_cast<std::size_t>(m.height / 2 * m.width + m.width / 2)];
    e = (t.x + t.y + t.z) / 3.0;
    if (e >= 0.97 * kPi) break;
  }
  EXPECT_GE(e, 0.97 * kPi);
  EXPECT_LE(e, 1.3 * kPi);
  viewer.close();
  server.stop();
  host.stop();
  std::filesystem::remove_all(dir);
  std::filesystem::remove(dir.parent_path() / "outside.exr");
}

TEST(EditService, FileSkyEditsAreRefusedWithoutASkyFolder) {
  EngineHost host(open_plane(), "plane", quick_host());
  try {
    host.submit_edit(parse_edit_json(R"({"op": "sky", "file": "dusk.exr"})"));
    FAIL() << "a file sky edit was accepted without --sky-dir";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--sky-dir"), std::string::npos) << e.what();
  }
  // A colour needs no file: accepted.
  EXPECT_EQ(host.submit_edit(parse_edit_json(R"({"op": "sky", "color": [1, 1, 1]})")), 1u);
}

}  // namespace irradcast::test_edit_service

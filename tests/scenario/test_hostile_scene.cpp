// Hostile scenes and edits (issue 16, items 1-4, in the order they were fixed): glTF URIs that
// read files outside the scene's folder (or block on a FIFO), node hierarchies 200 000 deep,
// scenes whose triangles are all degenerate or non-finite, and edits whose ops compose to
// infinity. Every glTF is written here, in a temporary directory.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli.h"
#include "gltf_builders.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/image.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/service/engine_host.h"
#include "scene_builders.h"

namespace irradcast::test_hostile_scene {

using nlohmann::json;
namespace fs = std::filesystem;

namespace {

class HostileScene : public test::ScratchDirTest {
 protected:
  HostileScene() : ScratchDirTest("irradcast_hostile_") {}
};

void write_bytes(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(f.good()) << path;
}

// One triangle (0,0,0) (1,0,0) (0,1,0), non-indexed: the buffer is its 36 position bytes.
std::string triangle_bin() {
  const float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  return std::string(reinterpret_cast<const char*>(pos), sizeof pos);
}

json triangle_gltf(const std::string& buffer_uri) {
  return {{"asset", {{"version", "2.0"}}},
          {"buffers", {{{"byteLength", 36}, {"uri", buffer_uri}}}},
          {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 36}}}},
          {"accessors", json::array({test::triangle_positions_accessor()})},
          {"meshes", {{{"name", "tri"}, {"primitives", {{{"attributes", {{"POSITION", 0}}}}}}}}},
          {"nodes", {{{"mesh", 0}}}},
          {"scenes", {{{"nodes", {0}}}}},
          {"scene", 0}};
}

// The message of the irradcast::Error that loading `path` throws ("" if it loads).
std::string load_error(const std::string& path) {
  try {
    load_scene(path);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// Runs `work` on its own thread and waits at most `limit` for it: a liveness guard (a hung or
// quadratic load fails the test instead of hanging it), not a timing assertion. Returns false on
// a timeout (the thread is left to finish on its own: it owns everything it uses).
bool finishes_within(std::chrono::seconds limit, std::function<void()> work) {
  struct State {
    std::mutex m;
    std::condition_variable cv;
    bool done = false;
  };
  auto state = std::make_shared<State>();
  std::thread([state, work = std::move(work)] {
    work();
    std::lock_guard lock(state->m);
    state->done = true;
    state->cv.notify_all();
  }).detach();
  std::unique_lock lock(state->m);
  return state->cv.wait_for(lock, limit, [&] { return state->done; });
}

test::CliResult run_tool(const char* exe, const std::string& args) {
  // `timeout`: a tool that does not exit (a server that should have refused its scene) fails the
  // test instead of hanging it.
  return test::run_cli(std::string("timeout 30 ") + exe, args);
}

// ---------------------------------------------------------------------------------------------
// 1. URIs confined to the scene's folder

TEST_F(HostileScene, GltfBufferUriOutsideTheFolderIsRefusedByName) {
  // The "secret" has exactly the bytes a buffer needs, so that today's loader reads it happily.
  write_bytes(dir_ / "token.bin", triangle_bin());
  const fs::path scene = dir_ / "scenes" / "a" / "scene.gltf";
  write_bytes(scene, triangle_gltf("../../token.bin").dump());
  std::string m = load_error(scene.string());
  EXPECT_TRUE(contains(m, "buffer 0 URI '../../token.bin' is refused")) << m;
  EXPECT_TRUE(contains(m, "outside")) << m;
  EXPECT_EQ(m.find('\n'), std::string::npos) << m;

  // Percent-encoded dots and slashes are decoded (as tinygltf does) before the check.
  write_bytes(scene, triangle_gltf("%2e%2e/%2E%2E%2ftoken.bin").dump());
  m = load_error(scene.string());
  EXPECT_TRUE(contains(m, "buffer 0 URI '%2e%2e/%2E%2E%2ftoken.bin' is refused")) << m;

  // An absolute path never worked; it is now refused by name too.
  write_bytes(scene, triangle_gltf((dir_ / "token.bin").string()).dump());
  m = load_error(scene.string());
  EXPECT_TRUE(contains(m, "is refused: it is an absolute path")) << m;

  // Inside the folder (a subfolder too, and a "../" that stays inside) it loads.
  write_bytes(dir_ / "scenes" / "a" / "bin" / "tri.bin", triangle_bin());
  write_bytes(scene, triangle_gltf("bin/../bin/tri.bin").dump());
  EXPECT_EQ(load_error(scene.string()), "");
  // data: URIs need no file.
  write_bytes(scene, triangle_gltf(test::data_uri(triangle_bin())).dump());
  EXPECT_EQ(load_error(scene.string()), "");
}

TEST_F(HostileScene, GltfSymlinkPointingOutsideIsRefused) {
  write_bytes(dir_ / "outside" / "tri.bin", triangle_bin());
  const fs::path folder = dir_ / "scene";
  fs::create_directories(folder);
  fs::create_symlink(dir_ / "outside" / "tri.bin", folder / "link.bin");
  write_bytes(folder / "scene.gltf", triangle_gltf("link.bin").dump());
  std::string m = load_error((folder / "scene.gltf").string());
  EXPECT_TRUE(contains(m, "buffer 0 URI 'link.bin' is refused: it resolves to")) << m;
  // A symlinked folder inside is no way out either.
  fs::create_directory_symlink(dir_ / "outside", folder / "sub");
  write_bytes(folder / "scene.gltf", triangle_gltf("sub/tri.bin").dump());
  m = load_error((folder / "scene.gltf").string());
  EXPECT_TRUE(contains(m, "buffer 0 URI 'sub/tri.bin' is refused")) << m;
  // A symlink that stays inside the folder is fine.
  write_bytes(folder / "real" / "tri.bin", triangle_bin());
  fs::create_symlink(folder / "real" / "tri.bin", folder / "inside.bin");
  write_bytes(folder / "scene.gltf", triangle_gltf("inside.bin").dump());
  EXPECT_EQ(load_error((folder / "scene.gltf").string()), "");
}

TEST_F(HostileScene, GltfImageUriOutsideTheFolderIsRefused) {
  write_png((dir_ / "secret.png").string(), 2, 2, std::vector<std::uint8_t>(12, 200));
  json g = triangle_gltf(test::data_uri(triangle_bin()));
  g["images"] = {{{"uri", "../secret.png"}}};
  g["textures"] = {{{"source", 0}}};
  g["materials"] = {{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}};
  g["meshes"][0]["primitives"][0]["material"] = 0;
  const fs::path scene = dir_ / "scene" / "scene.gltf";
  write_bytes(scene, g.dump());
  const std::string m = load_error(scene.string());
  EXPECT_TRUE(contains(m, "image 0 URI '../secret.png' is refused")) << m;
}

TEST_F(HostileScene, GltfFifoAsBufferIsRefusedInsteadOfBlocking) {
  const fs::path folder = dir_ / "scene";
  fs::create_directories(folder);
  const fs::path fifo = folder / "fifo.bin";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  write_bytes(folder / "scene.gltf", triangle_gltf("fifo.bin").dump());
  auto message = std::make_shared<std::string>();
  const std::string path = (folder / "scene.gltf").string();
  const bool done =
      finishes_within(std::chrono::seconds(20), [path, message] { *message = load_error(path); });
  if (!done) {
    // Unblock the reader (a writer that opens and closes: it reads end-of-file), then wait.
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) ::close(fd);
    std::this_thread::sleep_for(std::chrono::seconds(1));
    FAIL() << "loading a glTF whose buffer is a FIFO blocked for 20 s";
  }
  EXPECT_TRUE(contains(*message, "buffer 0 URI 'fifo.bin' is refused: it is not a regular file"))
      << *message;
}

TEST_F(HostileScene, SceneRootWidensTheFolderForBakeAndLoadScene) {
  write_bytes(dir_ / "shared" / "tri.bin", triangle_bin());
  const fs::path scene = dir_ / "scenes" / "a" / "scene.gltf";
  write_bytes(scene, triangle_gltf("../../shared/tri.bin").dump());
  const std::string out = (dir_ / "out.glb").string();
  // Refused by default...
  test::CliResult r = run_tool(IRRADCAST_BAKE_EXE,
                               "--scene " + scene.string() + " --export-gltf " + out + " --quiet");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "irradcast-bake: error: ")) << r.output;
  EXPECT_TRUE(contains(r.output, "buffer 0 URI '../../shared/tri.bin' is refused")) << r.output;
  // ... read with --scene-root naming a folder that holds both.
  r = run_tool(IRRADCAST_BAKE_EXE, "--scene " + scene.string() + " --scene-root " + dir_.string() +
                                       " --export-gltf " + out + " --quiet");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::exists(out)) << r.output;
  // A root that is not a folder is an error.
  r = run_tool(IRRADCAST_BAKE_EXE, "--scene " + scene.string() + " --scene-root " +
                                       (dir_ / "nope").string() + " --export-gltf " + out);
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "not a directory")) << r.output;
}

TEST_F(HostileScene, ServerRefusesASceneThatReadsOutsideItsFolder) {
  write_bytes(dir_ / "token.bin", triangle_bin());
  const fs::path scene = dir_ / "scene" / "scene.gltf";
  write_bytes(scene, triangle_gltf("../token.bin").dump());
  const test::CliResult r =
      run_tool(IRRADCAST_SERVER_EXE,
               "--scene " + scene.string() + " --port 0 --bind 127.0.0.1 --status-every 0");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "irradcast-server: error: ")) << r.output;
  EXPECT_TRUE(contains(r.output, "buffer 0 URI '../token.bin' is refused")) << r.output;
}

// ---------------------------------------------------------------------------------------------
// 4. Deep hierarchies

// `chain` nodes, each the only child of the one before (node 0 the root, the last one carries a
// triangle, every node moves 1 mm along x), then `ring` nodes that form one cycle.
std::string hierarchy_gltf(int chain, int ring) {
  json g = triangle_gltf(test::data_uri(triangle_bin()));
  json nodes = json::array();
  for (int i = 0; i < chain; ++i) {
    json n = {{"translation", {0.001, 0, 0}}};
    if (i + 1 < chain) n["children"] = {i + 1};
    if (i + 1 == chain) n["mesh"] = 0;
    nodes.push_back(std::move(n));
  }
  for (int i = 0; i < ring; ++i) nodes.push_back({{"children", {chain + (i + 1) % ring}}});
  g["nodes"] = std::move(nodes);
  if (ring > 0) g.erase("scenes"), g.erase("scene");
  return g.dump();
}

TEST_F(HostileScene, GltfChainOf200kNodesLoadsExportsAndBuilds) {
  constexpr int kNodes = 200000;
  const fs::path path = dir_ / "chain.gltf";
  write_bytes(path, hierarchy_gltf(kNodes, 0));
  struct Result {
    std::string error;
    std::size_t nodes = 0, objects = 0, reloaded = 0;
    glm::vec3 corner{0.0f};
  };
  auto result = std::make_shared<Result>();
  const std::string file = path.string(), glb = (dir_ / "chain.glb").string();
  const bool done = finishes_within(std::chrono::seconds(60), [file, glb, result] {
    try {
      const Scene s = load_scene(file);
      result->nodes = s.nodes.size();
      result->objects = s.objects().size();
      const World w = World::build(s);
      if (!w.objects.empty()) result->corner = w.objects[0].positions[0];
      save_gltf(s, glb);
      result->reloaded = load_gltf(glb).nodes.size();
    } catch (const std::exception& e) {
      result->error = e.what();
    }
  });
  ASSERT_TRUE(done) << "loading a " << kNodes << "-deep chain did not finish within 60 s";
  EXPECT_EQ(result->error, "");
  EXPECT_EQ(result->nodes, static_cast<std::size_t>(kNodes));
  EXPECT_EQ(result->objects, 1u);
  EXPECT_NEAR(result->corner.x, 0.001f * kNodes, 2.0f);
  EXPECT_EQ(result->reloaded, static_cast<std::size_t>(kNodes));
}

TEST_F(HostileScene, GltfCycleBesideALongChainIsReported) {
  const fs::path path = dir_ / "cycle.gltf";
  write_bytes(path, hierarchy_gltf(200000, 1000));
  auto message = std::make_shared<std::string>();
  const std::string file = path.string();
  const bool done =
      finishes_within(std::chrono::seconds(60), [file, message] { *message = load_error(file); });
  ASSERT_TRUE(done) << "checking 201 000 nodes for cycles did not finish within 60 s";
  EXPECT_TRUE(contains(*message, "is part of a cycle in the hierarchy")) << *message;
}

// ---------------------------------------------------------------------------------------------
// 3. Degenerate and non-finite triangles

EngineHostOptions small_host() {
  log::set_level(log::Level::Warn);
  Progress::set_enabled(false);
  EngineHostOptions o;
  o.atlas.texels_per_scene = 32.0f;
  o.max_updates = 1;
  o.engine_nice = 0;
  o.backend.kind = BackendKind::Embree;
  return o;
}

TEST_F(HostileScene, EngineHostRefusesASceneWithOnlyDegenerateTriangles) {
  Scene s;
  const std::uint32_t mat = test::add_material(s, glm::vec3(0.5f), glm::vec3(1.0f));
  test::add_quad_object(s, "line", {0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}, mat);
  test::add_quad_object(s, "point", {1, 1, 1}, {1, 1, 1}, {1, 1, 1}, {1, 1, 1}, mat);
  try {
    EngineHost host(s, "degenerate", small_host());
    FAIL() << "a scene of degenerate triangles was accepted";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(),
                         "degenerate: the scene has no triangles with area after "
                         "dropping 4 degenerate or non-finite ones"))
        << e.what();
  }
}

TEST_F(HostileScene, EngineHostDropsDegenerateTrianglesAndKeepsTheRest) {
  Scene s;
  const std::uint32_t white = test::add_material(s, glm::vec3(0.8f));
  const std::uint32_t light = test::add_material(s, glm::vec3(0.8f), glm::vec3(5.0f));
  test::add_quad_object(s, "floor", {-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}, white);
  test::add_quad_object(s, "lamp", {-0.2f, 1, -0.2f}, {0.2f, 1, -0.2f}, {0.2f, 1, 0.2f},
                        {-0.2f, 1, 0.2f}, light);
  const int line = test::add_quad_object(s, "line", {0, 0.5f, 0}, {1, 0.5f, 0}, {2, 0.5f, 0},
                                         {3, 0.5f, 0}, white);
  // One good triangle and one with a repeated corner.
  const int mixed = test::add_quad_object(s, "mixed", {0, 0, 0}, {0, 0.5f, 0}, {0, 0.5f, 0.5f},
                                          {0, 0.5f, 0.5f}, white);
  EngineHost host(s, "mostly fine", small_host());
  const Scene& kept = host.scene();
  EXPECT_EQ(kept.nodes[static_cast<std::size_t>(line)].mesh, -1);
  const int m = kept.nodes[static_cast<std::size_t>(mixed)].mesh;
  ASSERT_GE(m, 0);
  EXPECT_EQ(kept.meshes[static_cast<std::size_t>(m)].triangles.size(), 1u);
  EXPECT_EQ(kept.meshes[static_cast<std::size_t>(m)].positions.size(), 3u);
  EXPECT_EQ(kept.objects().size(), 3u);
  host.step();
  EXPECT_EQ(host.stats().updates, 1u);
}

// A glTF whose mesh 0 is degenerate (collinear) and whose mesh 1 is placed by a node scaled so
// far that its corners overflow to infinity in the world; with `good`, also a fine triangle lit
// by a point light.
json broken_gltf(bool good) {
  const float pos[] = {0,     0, 0, 1,     0, 0, 2,     0, 0,   // collinear
                       1e15f, 0, 0, 1e15f, 1, 0, 1e15f, 0, 1,   // x 1e30 = infinity
                       0,     0, 0, 1,     0, 0, 0,     0, 1};  // fine (facing -y)
  const std::string bin(reinterpret_cast<const char*>(pos), sizeof pos);
  auto accessor = [](int offset, float max) {
    return json{{"bufferView", 0}, {"byteOffset", offset}, {"componentType", 5126}, {"count", 3},
                {"type", "VEC3"},  {"min", {0, 0, 0}},     {"max", {max, max, max}}};
  };
  json g = {{"asset", {{"version", "2.0"}}},
            {"buffers", {{{"byteLength", bin.size()}, {"uri", test::data_uri(bin)}}}},
            {"bufferViews", {{{"buffer", 0}, {"byteLength", bin.size()}}}},
            {"accessors", {accessor(0, 2), accessor(36, 1e15f), accessor(72, 1)}},
            {"meshes",
             {{{"primitives", {{{"attributes", {{"POSITION", 0}}}}}}},
              {{"primitives", {{{"attributes", {{"POSITION", 1}}}}}}},
              {{"primitives", {{{"attributes", {{"POSITION", 2}}}}}}}}},
            {"nodes", {{{"mesh", 0}}, {{"mesh", 1}, {"scale", {1e30, 1e30, 1e30}}}}},
            {"scenes", {{{"nodes", {0, 1}}}}},
            {"scene", 0}};
  if (good) {
    g["nodes"].push_back({{"mesh", 2}});
    g["nodes"].push_back({{"translation", {0.3, 1, 0.3}},
                          {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    g["scenes"][0]["nodes"] = {0, 1, 2, 3};
    g["extensionsUsed"] = {"KHR_lights_punctual"};
    g["extensions"] = {
        {"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 5}}}}}}};
  }
  return g;
}

TEST_F(HostileScene, ServerAndBakeExitCleanlyOnASceneWithNoUsableTriangle) {
  const fs::path scene = dir_ / "broken.gltf";
  write_bytes(scene, broken_gltf(false).dump());
  const std::string expected =
      "the scene has no triangles with area after dropping 2 degenerate or non-finite ones";
  test::CliResult r =
      run_tool(IRRADCAST_SERVER_EXE,
               "--scene " + scene.string() + " --port 0 --bind 127.0.0.1 --status-every 0");
  EXPECT_EQ(r.status, 1) << r.output;  // today: Embree aborts (ray.valid())
  EXPECT_TRUE(contains(r.output, "irradcast-server: error: ")) << r.output;
  EXPECT_TRUE(contains(r.output, expected)) << r.output;
  r = run_tool(IRRADCAST_BAKE_EXE,
               "--scene " + scene.string() + " --out " + (dir_ / "out").string() + " --quiet");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_TRUE(contains(r.output, expected)) << r.output;
}

TEST_F(HostileScene, BakeDropsNonFiniteTrianglesWithOneWarning) {
  const fs::path scene = dir_ / "mostly.gltf";
  write_bytes(scene, broken_gltf(true).dump());
  const test::CliResult r =
      run_tool(IRRADCAST_BAKE_EXE, "--scene " + scene.string() + " --out " +
                                       (dir_ / "out").string() + " --updates 1 --quiet");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "dropped 2 of 3 triangles with zero area")) << r.output;
  std::size_t warnings = 0;
  for (std::size_t at = r.output.find("WARN"); at != std::string::npos;
       at = r.output.find("WARN", at + 1))
    ++warnings;
  EXPECT_EQ(warnings, 1u) << r.output;
}

// ---------------------------------------------------------------------------------------------
// 2. Edits: the resulting transforms are checked, not each op alone

SceneEdit scales(const std::string& node, int times, float factor) {
  SceneEdit e;
  for (int i = 0; i < times; ++i) {
    EditOp op;
    op.kind = EditOp::Kind::Scale;
    op.target = node;
    op.vector = glm::vec3(factor);
    e.ops.push_back(op);
  }
  return e;
}

std::string read_bytes(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

// The scene as save_gltf writes it: equal bytes, equal scene.
std::string saved(const Scene& s, const fs::path& path) {
  save_gltf(s, path.string());
  return read_bytes(path);
}

TEST_F(HostileScene, EditThirteenScalesOfOneNodeIsRefusedAndChangesNothing) {
  Scene scene = make_cornell_box();
  const std::string before = saved(scene, dir_ / "before.gltf");
  const SceneEdit edit = scales("tall_block", 13, 1000.0f);  // 1000^13: far beyond float
  try {
    apply_edit(scene, edit);
    FAIL() << "13 x scale 1000 accepted";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), "(scale): the node's transform would leave +-1e9")) << e.what();
  }
  EXPECT_EQ(saved(scene, dir_ / "after.gltf"), before);

  // The server refuses it when it is submitted; nothing is queued, nothing changes.
  EngineHost host(make_cornell_box(), "cornell", small_host());
  host.step();
  const std::string hash = host.package()->hash;
  ASSERT_THROW(host.submit_edit(edit), Error);  // (today: accepted, and Embree aborts on step)
  host.step();
  EXPECT_EQ(host.revision(), 0u);
  EXPECT_EQ(host.package()->hash, hash);
  EXPECT_EQ(saved(host.scene(), dir_ / "host.gltf"), before);
  // A sane edit of the same node still goes through.
  host.submit_edit(scales("tall_block", 2, 1.1f));
  host.step();
  EXPECT_EQ(host.revision(), 1u);
}

// Thirteen edits of one scale 1000 each, submitted before the engine applies any: each is
// checked against the transform the ones before it lead to, so the one that would leave the
// bound is refused (checking each against the scene as loaded let all through).
TEST_F(HostileScene, EditsSubmittedTogetherAreCheckedInSequence) {
  EngineHost host(make_cornell_box(), "cornell", small_host());
  host.step();
  int accepted = 0;
  std::string refusal;
  for (int i = 0; i < 13; ++i) {
    try {
      host.submit_edit(scales("tall_block", 1, 1000.0f));
      ++accepted;
    } catch (const Error& e) {
      refusal = e.what();
      break;
    }
  }
  EXPECT_EQ(accepted, 2) << "1000^3 times the block's extent leaves +-1e9";
  EXPECT_TRUE(contains(refusal, "(scale): the node's transform would leave +-1e9")) << refusal;
  host.step();
  EXPECT_EQ(host.revision(), static_cast<std::uint64_t>(accepted));
}

TEST_F(HostileScene, EditParentScaleTimesChildScaleMustStayFinite) {
  // A chain of five nodes, the last with a quad; each within the +-1e9 bound on its own.
  Scene s;
  const std::uint32_t mat = test::add_material(s, glm::vec3(0.5f));
  int parent = -1;
  for (int i = 0; i < 5; ++i) {
    Node n;
    n.name = "n" + std::to_string(i);
    n.parent = parent;
    parent = s.add_node(n);
  }
  const int quad =
      test::add_quad_object(s, "quad", {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, mat);
  s.nodes[static_cast<std::size_t>(quad)].parent = parent;
  s.roots.pop_back();
  s.nodes[static_cast<std::size_t>(parent)].children.push_back(quad);
  const std::string before = saved(s, dir_ / "before.gltf");

  SceneEdit edit;
  for (int i = 0; i < 5; ++i) {
    for (float f : {9e5f, 1e3f}) {  // 9e8 per node: (9e8)^5 overflows float
      EditOp op;
      op.kind = EditOp::Kind::Scale;
      op.target = "n" + std::to_string(i);
      op.vector = glm::vec3(f);
      edit.ops.push_back(op);
    }
  }
  try {
    apply_edit(s, edit);
    FAIL() << "an edit whose world transforms overflow was accepted";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), "world transform that is not finite")) << e.what();
  }
  EXPECT_EQ(saved(s, dir_ / "after.gltf"), before);

  // Three of them: finite transforms, but the quad's corners beyond Embree's range (~1e26).
  edit.ops.resize(6);
  try {
    validate_edit(s, edit);
    FAIL() << "an edit that puts vertices at 7e26 was accepted";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), "node 5 'quad' would place a vertex beyond +-1e18")) << e.what();
  }
  // One is fine (9e8).
  edit.ops.resize(2);
  EXPECT_NO_THROW(apply_edit(s, edit));
}

}  // namespace

}  // namespace irradcast::test_hostile_scene

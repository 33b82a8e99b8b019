// glTF 2.0 loader and exporter: bad input, primitive modes and accessor layouts, the Khronos
// sample models, and export -> load round trips (.gltf and .glb).
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include "gltf_builders.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/cutout.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/scene.h"
#include "testdata.h"

namespace irradcast::test_gltf {

using nlohmann::json;
namespace fs = std::filesystem;

namespace {

const std::string kSamples = irradcast::test::testdata("gltf-samples");

// A fresh temporary directory per test, removed afterwards.
class GltfTest : public test::ScratchDirTest {
 protected:
  GltfTest() : ScratchDirTest("irradcast_gltf_") {}
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
};

void write_bytes(const std::string& path, const void* data, std::size_t size) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  ASSERT_TRUE(f.good()) << path;
}
void write_text(const std::string& path, const std::string& text) {
  write_bytes(path, text.data(), text.size());
}
std::vector<unsigned char> read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<unsigned char>((std::istreambuf_iterator<char>(f)),
                                    std::istreambuf_iterator<char>());
}

template <class T>
void put(std::vector<unsigned char>& bin, std::size_t offset, T value) {
  if (bin.size() < offset + sizeof(T)) bin.resize(offset + sizeof(T));
  std::memcpy(bin.data() + offset, &value, sizeof(T));
}

// A one-triangle model with an external buffer "<name>.bin":
//   bytes [0, 36) POSITION (0,0,0) (1,0,0) (0,1,0), [36, 42) u16 indices 0 1 2, then 2 bytes
//   padding; bufferView 0 = positions, 1 = indices; accessor 0 = POSITION, 1 = indices.
struct TestModel {
  json gltf;
  std::vector<unsigned char> bin;
};

TestModel triangle_model() {
  TestModel m;
  const float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  m.bin.assign(44, 0);  // not resize(): GCC 12 -O3 -Warray-bounds misfires in it
  std::memcpy(m.bin.data(), pos, sizeof pos);
  put<std::uint16_t>(m.bin, 36, 0);
  put<std::uint16_t>(m.bin, 38, 1);
  put<std::uint16_t>(m.bin, 40, 2);
  m.gltf = {
      {"asset", {{"version", "2.0"}}},
      {"buffers", {{{"byteLength", 44}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 36}},
        {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 6}}}},
      {"accessors",
       {test::triangle_positions_accessor(),
        {{"bufferView", 1}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}}}},
      {"meshes",
       {{{"name", "tri"}, {"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"scenes", {{{"nodes", {0}}}}},
      {"scene", 0}};
  return m;
}

// Writes dir/name.gltf and, unless bin_name is empty, dir/<bin_name> with the buffer.
std::string write_model(const fs::path& dir, const std::string& name, TestModel m,
                        const std::string& bin_name = "buf.bin") {
  if (m.gltf.contains("buffers") && !m.gltf["buffers"][0].contains("uri"))
    m.gltf["buffers"][0]["uri"] = bin_name;
  std::string path = (dir / (name + ".gltf")).string();
  write_text(path, m.gltf.dump(1));
  if (!bin_name.empty()) write_bytes((dir / bin_name).string(), m.bin.data(), m.bin.size());
  return path;
}

// Loading `path` must throw irradcast::Error with a one-line message naming the file and
// containing `problem`.
void expect_load_error(const std::string& path, const std::string& problem) {
  try {
    load_gltf(path);
    ADD_FAILURE() << "no error for " << path << " (expected \"" << problem << "\")";
  } catch (const Error& e) {
    std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path + ": ", 0), 0u) << "message does not start with the path: " << msg;
    EXPECT_NE(msg.find(problem), std::string::npos) << "expected \"" << problem << "\" in: " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "message is not one line: " << msg;
  }
}

// Every triangle of every object in world space, three corners each, in object order.
std::vector<glm::vec3> world_corners(const Scene& s) {
  std::vector<glm::vec3> out;
  auto world = s.world_matrices();
  for (const Object& o : s.objects()) {
    const Mesh& m = s.meshes[o.mesh];
    for (const glm::uvec3& t : m.triangles)
      for (int k = 0; k < 3; ++k)
        out.push_back(glm::vec3(world[o.node] * glm::vec4(m.positions[t[k]], 1.0f)));
  }
  return out;
}

void expect_near(glm::vec3 a, glm::vec3 b, float eps, const std::string& what) {
  EXPECT_NEAR(a.x, b.x, eps) << what;
  EXPECT_NEAR(a.y, b.y, eps) << what;
  EXPECT_NEAR(a.z, b.z, eps) << what;
}

bool has_warning(const GltfLoadReport& r, const std::string& fragment) {
  for (const std::string& w : r.warnings)
    if (w.find(fragment) != std::string::npos) return true;
  return false;
}

// ---- bad input ------------------------------------------------------------------------------

TEST_F(GltfTest, GltfMissingFile) {
  expect_load_error(path("nope.gltf"), "file not found");
  expect_load_error(path("nope.glb"), "file not found");
}

TEST_F(GltfTest, GltfBrokenJson) {
  write_text(path("broken.gltf"), "{ \"asset\": { \"version\": \"2.0\" }, \"nodes\": [ {");
  expect_load_error(path("broken.gltf"), "invalid glTF");
  write_text(path("empty.gltf"), "");
  expect_load_error(path("empty.gltf"), "empty file");
}

TEST_F(GltfTest, GltfMissingBufferFile) {
  TestModel m = triangle_model();
  m.gltf["buffers"][0]["uri"] = "missing.bin";
  expect_load_error(write_model(dir_, "nobuf", m, ""), "missing.bin");
}

TEST_F(GltfTest, GltfBufferShorterThanByteLength) {
  TestModel m = triangle_model();
  m.bin.resize(30);  // byteLength says 44
  std::string p = write_model(dir_, "short", m);
  expect_load_error(p, "File size mismatch");
}

TEST_F(GltfTest, GltfBufferViewPastBufferEnd) {
  TestModel m = triangle_model();
  // The buffer file matches its byteLength (44); the view claims more.
  m.gltf["bufferViews"][0]["byteLength"] = 400;
  std::string p = write_model(dir_, "view", m);
  expect_load_error(p, "runs past the end of buffer 0");
}

TEST_F(GltfTest, GltfAccessorPastBufferViewEnd) {
  TestModel m = triangle_model();
  m.gltf["accessors"][0]["count"] = 4;  // 48 bytes from a 36-byte view
  expect_load_error(write_model(dir_, "acc", m), "reads past the end of bufferView 0");
  m = triangle_model();
  m.gltf["accessors"][0]["byteOffset"] = 4;  // 4 + 36 > 36
  expect_load_error(write_model(dir_, "acc2", m), "reads past the end of bufferView 0");
  m = triangle_model();
  m.gltf["accessors"][0]["count"] = 0x40000000000000ull;  // overflowing sizes
  expect_load_error(write_model(dir_, "acc3", m), "reads past the end");
}

TEST_F(GltfTest, GltfIndexOutOfRange) {
  TestModel m = triangle_model();
  put<std::uint16_t>(m.bin, 40, 3);  // only 3 vertices
  expect_load_error(write_model(dir_, "index", m), "index 3 (at position 2) is out of range");
}

TEST_F(GltfTest, GltfNonFinitePositions) {
  TestModel m = triangle_model();
  put<float>(m.bin, 16, std::nanf(""));
  expect_load_error(write_model(dir_, "nan", m), "non-finite");
  m = triangle_model();
  put<float>(m.bin, 24, INFINITY);
  expect_load_error(write_model(dir_, "inf", m), "non-finite");
}

TEST_F(GltfTest, GltfAttributeCountMismatch) {
  TestModel m = triangle_model();
  m.gltf["accessors"].push_back(
      {{"bufferView", 0}, {"componentType", 5126}, {"count", 2}, {"type", "VEC3"}});
  m.gltf["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 2;
  expect_load_error(write_model(dir_, "count", m), "NORMAL has 2 elements but POSITION has 3");
}

TEST_F(GltfTest, GltfBadComponentTypes) {
  TestModel m = triangle_model();
  m.gltf["accessors"][0]["componentType"] = 5121;  // POSITION as bytes
  expect_load_error(write_model(dir_, "pos", m), "bad component type 5121");
  m = triangle_model();
  m.gltf["accessors"][1]["componentType"] = 5126;  // float indices
  expect_load_error(write_model(dir_, "idx", m), "bad component type 5126");
  m = triangle_model();
  m.gltf["accessors"][0]["type"] = "VEC2";
  expect_load_error(write_model(dir_, "type", m), "has type VEC2, expected VEC3");
  m = triangle_model();
  m.gltf["accessors"].push_back(
      {{"bufferView", 1}, {"componentType", 5123}, {"count", 3}, {"type", "VEC2"}});
  m.gltf["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = 2;  // not normalized
  expect_load_error(write_model(dir_, "uv", m), "not normalized");
}

TEST_F(GltfTest, GltfBadReferences) {
  TestModel m = triangle_model();
  m.gltf["nodes"][0]["mesh"] = 7;
  expect_load_error(write_model(dir_, "mesh", m), "refers to mesh 7");
  m = triangle_model();
  m.gltf["meshes"][0]["primitives"][0]["material"] = 3;
  expect_load_error(write_model(dir_, "mat", m), "refers to material 3");
  m = triangle_model();
  m.gltf["meshes"][0]["primitives"][0]["attributes"] = {{"NORMAL", 0}};
  expect_load_error(write_model(dir_, "nopos", m), "has no POSITION attribute");
  m = triangle_model();
  m.gltf["nodes"] = {{{"mesh", 0}, {"children", {1}}}, {{"children", {0}}}};
  expect_load_error(write_model(dir_, "cycle", m), "cycle");
  m = triangle_model();
  m.gltf["nodes"] = {{{"children", {2}}}, {{"children", {2}}}, {{"mesh", 0}}};
  m.gltf["scenes"][0]["nodes"] = {0, 1};
  expect_load_error(write_model(dir_, "twoparents", m), "more than one parent");
  m = triangle_model();
  m.gltf["scenes"][0]["nodes"] = {4};
  expect_load_error(write_model(dir_, "root", m), "refers to node 4");
  m = triangle_model();
  m.gltf["nodes"][0]["extensions"] = {{"KHR_lights_punctual", {{"light", 0}}}};
  expect_load_error(write_model(dir_, "light", m), "light that does not exist");
}

TEST_F(GltfTest, GltfBadSparse) {
  TestModel m = triangle_model();
  // Sparse substitution whose index (5) is past the accessor's 3 elements.
  put<std::uint16_t>(m.bin, 44, 5);
  const float value[3] = {9, 9, 9};
  m.bin.resize(48 + 12);
  std::memcpy(m.bin.data() + 48, value, 12);
  m.gltf["buffers"][0]["byteLength"] = m.bin.size();
  m.gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 44}, {"byteLength", 2}});
  m.gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 12}});
  m.gltf["accessors"][0]["sparse"] = {{"count", 1},
                                      {"indices", {{"bufferView", 2}, {"componentType", 5123}}},
                                      {"values", {{"bufferView", 3}}}};
  expect_load_error(write_model(dir_, "sparse_index", m), "sparse index 5 out of range");
  m.gltf["accessors"][0]["sparse"]["count"] = 2;  // reads past both views
  expect_load_error(write_model(dir_, "sparse_len", m), "past the end of bufferView");
}

TEST_F(GltfTest, GltfBadGlb) {
  Scene s;
  Mesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  mesh.triangle_material = {0};
  s.meshes.push_back(mesh);
  s.materials.push_back(Material{});
  Node n;
  n.mesh = 0;
  s.add_node(n);
  std::string good = path("good.glb");
  save_gltf(s, good);
  ASSERT_EQ(load_gltf(good).triangle_count(), 1u);
  std::vector<unsigned char> bytes = read_bytes(good);

  std::vector<unsigned char> cut(bytes.begin(), bytes.begin() + bytes.size() - 8);
  write_bytes(path("cut.glb"), cut.data(), cut.size());
  expect_load_error(path("cut.glb"), "GLB header declares");

  std::vector<unsigned char> v1 = bytes;
  put<std::uint32_t>(v1, 4, 1);
  write_bytes(path("v1.glb"), v1.data(), v1.size());
  expect_load_error(path("v1.glb"), "unsupported GLB version 1");

  std::vector<unsigned char> chunk = bytes;
  put<std::uint32_t>(chunk, 12, 0x7fffff00u);  // JSON chunk length past the end
  write_bytes(path("chunk.glb"), chunk.data(), chunk.size());
  expect_load_error(path("chunk.glb"), "JSON chunk runs past the end");

  write_text(path("text.glb"), "{\"asset\":{\"version\":\"2.0\"}}");
  expect_load_error(path("text.glb"), "not a binary glTF file");
}

// Random corruptions of a valid file must produce errors or scenes, never crashes (run under
// ASan/UBSan to make this meaningful).
TEST_F(GltfTest, GltfCorruptedBytesNeverCrash) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/Box/Box.gltf");
  std::string good = path("box.glb");
  save_gltf(s, good);
  const std::vector<unsigned char> bytes = read_bytes(good);
  std::uint32_t state = 12345;
  auto next = [&] {
    state = state * 1664525u + 1013904223u;
    return state >> 8;
  };
  int errors = 0, loaded = 0;
  for (int round = 0; round < 200; ++round) {
    std::vector<unsigned char> b = bytes;
    int flips = 1 + next() % 8;
    for (int k = 0; k < flips; ++k) b[next() % b.size()] = static_cast<unsigned char>(next());
    std::string p = path("fuzz.glb");
    write_bytes(p, b.data(), b.size());
    try {
      Scene r = load_gltf(p);
      ++loaded;
      for (const Object& o : r.objects()) EXPECT_GT(r.meshes[o.mesh].triangle_count(), 0u);
    } catch (const Error& e) {
      ++errors;
      EXPECT_EQ(std::string(e.what()).rfind(p + ": ", 0), 0u) << e.what();
    }
  }
  EXPECT_EQ(errors + loaded, 200);
  EXPECT_GT(errors, 0);
}

// ---- primitive modes and accessor layouts ---------------------------------------------------

TEST_F(GltfTest, GltfUnsupportedPrimitivesSkippedWithWarning) {
  TestModel m = triangle_model();
  auto& prims = m.gltf["meshes"][0]["primitives"];
  prims.push_back({{"attributes", {{"POSITION", 0}}}, {"mode", 1}});  // LINES
  prims.push_back({{"attributes", {{"POSITION", 0}}}, {"mode", 0}});  // POINTS
  // A second mesh with nothing but a line strip, used by a second node.
  m.gltf["meshes"].push_back({{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"mode", 3}}}}});
  m.gltf["nodes"].push_back({{"mesh", 1}});
  m.gltf["scenes"][0]["nodes"] = {0, 1};
  GltfLoadReport report;
  Scene s = load_gltf(write_model(dir_, "lines", m), &report);
  EXPECT_TRUE(has_warning(report, "LINES")) << ::testing::PrintToString(report.warnings);
  EXPECT_TRUE(has_warning(report, "POINTS"));
  EXPECT_TRUE(has_warning(report, "LINE_STRIP"));
  ASSERT_EQ(s.meshes.size(), 2u);
  EXPECT_EQ(s.meshes[0].triangle_count(), 1u);
  EXPECT_EQ(s.meshes[1].triangle_count(), 0u);
  EXPECT_EQ(s.nodes[1].mesh, -1);  // reference dropped: no zero-triangle objects
  auto objects = s.objects();
  ASSERT_EQ(objects.size(), 1u);
  EXPECT_EQ(objects[0].mesh, 0);
  EXPECT_EQ(s.triangle_count(), 1u);
  // The primitive without a material got the default (glTF: base colour 1).
  ASSERT_EQ(s.materials.size(), 1u);
  EXPECT_EQ(s.materials[0].base_color, glm::vec3(1.0f));
  EXPECT_EQ(s.meshes[0].triangle_material[0], 0u);
}

TEST_F(GltfTest, GltfStripFanAndNonIndexed) {
  TestModel m = triangle_model();
  // 4 vertices of a unit quad (strip order), non-indexed as TRIANGLE_STRIP, and indexed
  // (u16 0 1 3 2: around the quad) as TRIANGLE_FAN.
  const float quad[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  m.bin.resize(44 + 48);
  std::memcpy(m.bin.data() + 44, quad, 48);
  for (std::uint16_t i : {0, 1, 3, 2}) put<std::uint16_t>(m.bin, m.bin.size(), i);
  m.gltf["buffers"][0]["byteLength"] = m.bin.size();
  m.gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 44}, {"byteLength", 48}});
  m.gltf["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 92}, {"byteLength", 8}});
  m.gltf["accessors"].push_back(
      {{"bufferView", 2}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}});
  m.gltf["accessors"].push_back(
      {{"bufferView", 3}, {"componentType", 5123}, {"count", 4}, {"type", "SCALAR"}});
  m.gltf["meshes"] = {{{"primitives",
                        {{{"attributes", {{"POSITION", 2}}}, {"mode", 5}},
                         {{"attributes", {{"POSITION", 2}}}, {"mode", 6}, {"indices", 3}},
                         {{"attributes", {{"POSITION", 0}}}}}}}};  // non-indexed TRIANGLES
  Scene s = load_gltf(write_model(dir_, "strip", m));
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& mesh = s.meshes[0];
  ASSERT_EQ(mesh.triangle_count(), 5u);
  // Primitives with the same attribute accessors share their vertices.
  EXPECT_EQ(mesh.positions.size(), 7u);
  EXPECT_EQ(mesh.triangles[0], glm::uvec3(0, 1, 2));  // strip, even
  EXPECT_EQ(mesh.triangles[1], glm::uvec3(1, 3, 2));  // strip, odd: winding kept
  EXPECT_EQ(mesh.triangles[2], glm::uvec3(1, 3, 0));  // fan (v1, v2, v0)
  EXPECT_EQ(mesh.triangles[3], glm::uvec3(3, 2, 0));
  EXPECT_EQ(mesh.triangles[4], glm::uvec3(4, 5, 6));  // non-indexed, offset past the quad
  // Every triangle faces +z (counter-clockwise seen from +z).
  for (const glm::uvec3& t : mesh.triangles) {
    glm::vec3 n = glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                             mesh.positions[t.z] - mesh.positions[t.x]);
    EXPECT_GT(n.z, 0.0f);
  }
}

TEST_F(GltfTest, GltfInterleavedNormalizedSparseAndU8Indices) {
  // One interleaved view: per vertex float3 position + u16x2 normalized uv + u8x2 normalized uv
  // (stride 20). u8 indices. NORMAL from an accessor with no bufferView (zeros) + sparse values.
  std::vector<unsigned char> bin(3 * 20 + 4 + 2 + 2 + 24, 0);
  const float pos[3][3] = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}};
  const std::uint16_t uv0[3][2] = {{0, 0}, {65535, 0}, {0, 32768}};
  const std::uint8_t uv1[3][2] = {{255, 255}, {0, 255}, {51, 0}};
  for (int v = 0; v < 3; ++v) {
    std::memcpy(&bin[v * 20], pos[v], 12);
    std::memcpy(&bin[v * 20 + 12], uv0[v], 4);
    std::memcpy(&bin[v * 20 + 16], uv1[v], 2);
  }
  bin[60] = 0, bin[61] = 1, bin[62] = 2;  // u8 indices at 60
  put<std::uint16_t>(bin, 64, 2);         // sparse indices (u16: vertex 2, 0) at 64
  put<std::uint16_t>(bin, 66, 0);
  const float normals[6] = {0, 0, 1, 0, 0, -1};  // sparse values at 68
  std::memcpy(&bin[68], normals, 24);
  TestModel m;
  m.bin = bin;
  m.gltf = {
      {"asset", {{"version", "2.0"}}},
      {"buffers", {{{"byteLength", bin.size()}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 60}, {"byteStride", 20}},
        {{"buffer", 0}, {"byteOffset", 60}, {"byteLength", 3}},
        {{"buffer", 0}, {"byteOffset", 64}, {"byteLength", 4}},
        {{"buffer", 0}, {"byteOffset", 68}, {"byteLength", 24}}}},
      {"accessors",
       {{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}},
        {{"bufferView", 0},
         {"byteOffset", 12},
         {"componentType", 5123},
         {"normalized", true},
         {"count", 3},
         {"type", "VEC2"}},
        {{"bufferView", 0},
         {"byteOffset", 16},
         {"componentType", 5121},
         {"normalized", true},
         {"count", 3},
         {"type", "VEC2"}},
        {{"bufferView", 1}, {"componentType", 5121}, {"count", 3}, {"type", "SCALAR"}},
        {{"componentType", 5126},
         {"count", 3},
         {"type", "VEC3"},
         {"sparse",
          {{"count", 2},
           {"indices", {{"bufferView", 2}, {"componentType", 5123}}},
           {"values", {{"bufferView", 3}}}}}}}},
      {"meshes",
       {{{"primitives",
          {{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}, {"TEXCOORD_1", 2}, {"NORMAL", 4}}},
            {"indices", 3}}}}}}},
      {"nodes", {{{"mesh", 0}}}}};  // no scenes: parentless nodes are the roots
  Scene s = load_gltf(write_model(dir_, "inter", m));
  ASSERT_EQ(s.roots, std::vector<int>{0});
  const Mesh& mesh = s.meshes.at(0);
  ASSERT_EQ(mesh.positions.size(), 3u);
  EXPECT_EQ(mesh.positions[1], glm::vec3(2, 0, 0));
  EXPECT_EQ(mesh.positions[2], glm::vec3(0, 2, 0));
  ASSERT_EQ(mesh.uv0.size(), 3u);
  EXPECT_FLOAT_EQ(mesh.uv0[1].x, 1.0f);
  EXPECT_NEAR(mesh.uv0[2].y, 0.5f, 1e-4f);
  ASSERT_EQ(mesh.uv1.size(), 3u);
  EXPECT_FLOAT_EQ(mesh.uv1[0].x, 1.0f);
  EXPECT_FLOAT_EQ(mesh.uv1[2].x, 0.2f);
  ASSERT_EQ(mesh.normals.size(), 3u);
  EXPECT_EQ(mesh.normals[2], glm::vec3(0, 0, 1));
  EXPECT_EQ(mesh.normals[0], glm::vec3(0, 0, -1));
  EXPECT_EQ(mesh.normals[1], glm::vec3(0, 0, 0));  // not substituted: zero
  EXPECT_EQ(mesh.triangles.at(0), glm::uvec3(0, 1, 2));
}

TEST_F(GltfTest, GltfHierarchyTrsLightsMaterialsCameras) {
  TestModel m = triangle_model();
  m.gltf["buffers"][0]["uri"] = test::data_uri(std::string(m.bin.begin(), m.bin.end()));
  // Parent: T(10,0,0) * R(90 deg about z) * S(2); child: translation (0,0,1), has the mesh.
  const float h = std::sqrt(0.5f);
  m.gltf["nodes"] = {{{"name", "parent"},
                      {"translation", {10, 0, 0}},
                      {"rotation", {0, 0, h, h}},
                      {"scale", {2, 2, 2}},
                      {"children", {1, 2}}},
                     {{"name", "child"}, {"translation", {0, 0, 1}}, {"mesh", 0}},
                     {{"name", "lamp"},
                      {"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1}},
                      {"extensions", {{"KHR_lights_punctual", {{"light", 1}}}}},
                      {"camera", 0}}};
  m.gltf["extensionsUsed"] = {"KHR_lights_punctual", "KHR_materials_emissive_strength"};
  m.gltf["extensions"] = {
      {"KHR_lights_punctual",
       {{"lights",
         {{{"type", "point"}, {"color", {1, 0.5, 0.25}}, {"intensity", 20}, {"range", 7}},
          {{"type", "spot"},
           {"name", "spotty"},
           {"intensity", 3},
           {"spot", {{"innerConeAngle", 0.1}, {"outerConeAngle", 0.5}}}},
          {{"type", "directional"}, {"intensity", 2.5}}}}}}};
  m.gltf["materials"] = {
      {{"name", "glow"},
       {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.25, 0.125, 1}}}},
       {"emissiveFactor", {1, 0.5, 0}},
       {"doubleSided", true},
       {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 4}}}}}}};
  m.gltf["meshes"][0]["primitives"][0]["material"] = 0;
  m.gltf["cameras"] = {
      {{"type", "perspective"},
       {"perspective", {{"yfov", 0.9}, {"aspectRatio", 1.5}, {"znear", 0.1}, {"zfar", 50}}}}};
  std::string p = path("scene.gltf");
  write_text(p, m.gltf.dump());
  Scene s = load_gltf(p);

  ASSERT_EQ(s.nodes.size(), 3u);
  EXPECT_EQ(s.roots, std::vector<int>{0});
  EXPECT_EQ(s.nodes[0].children, (std::vector<int>{1, 2}));
  EXPECT_EQ(s.nodes[1].parent, 0);
  EXPECT_EQ(s.nodes[2].parent, 0);
  EXPECT_EQ(s.nodes[1].name, "child");
  // Vertex (1,0,0) of the child: child -> (1,0,1); S -> (2,0,2); R -> (0,2,2); T -> (10,2,2).
  auto corners = world_corners(s);
  ASSERT_EQ(corners.size(), 3u);
  expect_near(corners[0], glm::vec3(10, 0, 2), 1e-5f, "v0");
  expect_near(corners[1], glm::vec3(10, 2, 2), 1e-5f, "v1");
  expect_near(corners[2], glm::vec3(8, 0, 2), 1e-5f, "v2");

  ASSERT_EQ(s.lights.size(), 3u);
  EXPECT_EQ(s.lights[0].type, Light::Type::Point);
  EXPECT_EQ(s.lights[0].color, glm::vec3(1, 0.5f, 0.25f));
  EXPECT_FLOAT_EQ(s.lights[0].intensity, 20.0f);
  EXPECT_FLOAT_EQ(s.lights[0].range, 7.0f);
  EXPECT_EQ(s.lights[1].type, Light::Type::Spot);
  EXPECT_EQ(s.lights[1].name, "spotty");
  EXPECT_EQ(s.lights[1].color, glm::vec3(1.0f));
  EXPECT_FLOAT_EQ(s.lights[1].inner_cone_angle, 0.1f);
  EXPECT_FLOAT_EQ(s.lights[1].outer_cone_angle, 0.5f);
  EXPECT_EQ(s.lights[2].type, Light::Type::Directional);
  EXPECT_FLOAT_EQ(s.lights[2].intensity, 2.5f);
  EXPECT_EQ(s.nodes[2].light, 1);
  EXPECT_EQ(s.nodes[2].camera, 0);
  auto world = s.world_matrices();
  expect_near(glm::vec3(world[2][3]), glm::vec3(10, 0, 0) + glm::vec3(-10, 0, 0), 1e-5f, "lamp");

  ASSERT_EQ(s.materials.size(), 1u);
  const Material& mat = s.materials[0];
  EXPECT_EQ(mat.name, "glow");
  EXPECT_EQ(mat.base_color, glm::vec3(0.5f, 0.25f, 0.125f));
  EXPECT_EQ(mat.emissive, glm::vec3(1, 0.5f, 0));
  EXPECT_FLOAT_EQ(mat.emissive_strength, 4.0f);
  EXPECT_TRUE(mat.double_sided);
  EXPECT_TRUE(mat.is_emissive());

  ASSERT_EQ(s.cameras.size(), 1u);
  EXPECT_FLOAT_EQ(s.cameras[0].yfov, 0.9f);
  EXPECT_FLOAT_EQ(s.cameras[0].aspect_ratio, 1.5f);
  EXPECT_FLOAT_EQ(s.cameras[0].znear, 0.1f);
  EXPECT_FLOAT_EQ(s.cameras[0].zfar, 50.0f);
  EXPECT_EQ(s.first_camera_node(), 2);
}

// ---- the Khronos sample models --------------------------------------------------------------

// Triangle count of a sample's default scene, computed straight from its JSON (accessor counts
// and modes), independently of the loader.
std::size_t expected_triangles(const std::string& file) {
  json g = json::parse(read_bytes(file));
  std::size_t total = 0;
  std::function<void(int)> walk = [&](int n) {
    const json& node = g["nodes"][n];
    if (node.contains("mesh"))
      for (const json& p : g["meshes"][node["mesh"].get<int>()]["primitives"]) {
        int mode = p.value("mode", 4);
        std::size_t count =
            p.contains("indices")
                ? g["accessors"][p["indices"].get<int>()]["count"].get<std::size_t>()
                : g["accessors"][p["attributes"]["POSITION"].get<int>()]["count"]
                      .get<std::size_t>();
        if (mode == 4) total += count / 3;
        if (mode == 5 || mode == 6) total += count >= 2 ? count - 2 : 0;
      }
    if (node.contains("children"))
      for (int c : node["children"]) walk(c);
  };
  for (int r : g["scenes"][g.value("scene", 0)]["nodes"]) walk(r);
  return total;
}

TEST(GltfSamples, GltfAllSamplesLoadWithTheirTriangleCounts) {
  IRRADCAST_NEED_TESTDATA();
  const char* names[] = {"2CylinderEngine",
                         "Box",
                         "BoxInterleaved",
                         "BoxTextured",
                         "Cameras",
                         "Duck",
                         "MultiUVTest",
                         "OrientationTest",
                         "SimpleMeshes",
                         "SimpleSparseAccessor",
                         "TextureCoordinateTest",
                         "TriangleWithoutIndices"};
  int checked = 0;
  for (const char* name : names) {
    std::string file = kSamples + "/" + name + "/" + name + ".gltf";
    SCOPED_TRACE(file);
    ASSERT_TRUE(fs::exists(file));
    Scene s = load_gltf(file);
    std::size_t expected = expected_triangles(file);
    EXPECT_GT(expected, 0u);
    EXPECT_EQ(s.triangle_count(), expected);
    for (const Object& o : s.objects()) {
      const Mesh& m = s.meshes[o.mesh];
      EXPECT_GT(m.triangle_count(), 0u);
      EXPECT_EQ(m.triangle_material.size(), m.triangle_count());
      for (std::uint32_t mi : m.triangle_material) ASSERT_LT(mi, s.materials.size());
      for (const glm::uvec3& t : m.triangles)
        ASSERT_LT(glm::max(t.x, glm::max(t.y, t.z)), m.positions.size());
      if (!m.normals.empty()) {
        EXPECT_EQ(m.normals.size(), m.positions.size());
      }
      if (!m.uv0.empty()) {
        EXPECT_EQ(m.uv0.size(), m.positions.size());
      }
    }
    ++checked;
  }
  EXPECT_EQ(checked, 12);
}

TEST(GltfSamples, GltfCylinderEngine) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/2CylinderEngine/2CylinderEngine.gltf");
  EXPECT_EQ(s.triangle_count(), 121496u);
  EXPECT_EQ(s.meshes.size(), 29u);
  EXPECT_EQ(s.materials.size(), 34u);
  EXPECT_EQ(s.nodes.size(), 82u);
  EXPECT_EQ(s.cameras.size(), 1u);
}

TEST(GltfSamples, GltfBoxAndBoxInterleavedAgree) {
  IRRADCAST_NEED_TESTDATA();
  Scene box = load_gltf(kSamples + "/Box/Box.gltf");
  Scene inter = load_gltf(kSamples + "/BoxInterleaved/BoxInterleaved.gltf");
  EXPECT_EQ(box.triangle_count(), 12u);
  auto a = world_corners(box), b = world_corners(inter);
  ASSERT_EQ(a.size(), 36u);
  ASSERT_EQ(b.size(), 36u);
  for (std::size_t i = 0; i < a.size(); ++i) expect_near(a[i], b[i], 1e-6f, "corner");
  // A unit cube.
  glm::vec3 lo(1e9f), hi(-1e9f);
  for (glm::vec3 p : a) lo = glm::min(lo, p), hi = glm::max(hi, p);
  expect_near(hi - lo, glm::vec3(1.0f), 1e-5f, "box extent");
  const Mesh& m = inter.meshes.at(0);
  ASSERT_EQ(m.normals.size(), m.positions.size());
  for (glm::vec3 n : m.normals) EXPECT_NEAR(glm::length(n), 1.0f, 1e-5f);
  ASSERT_EQ(box.materials.size(), 1u);
  EXPECT_NEAR(box.materials[0].base_color.x, 0.8f, 1e-6f);
}

TEST(GltfSamples, GltfBoxTexturedHasItsTexture) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/BoxTextured/BoxTextured.gltf");
  ASSERT_EQ(s.textures.size(), 1u);
  const Texture& t = s.textures[0];
  EXPECT_EQ(t.width, 256);
  EXPECT_EQ(t.height, 256);
  ASSERT_EQ(t.rgba8.size(), 256u * 256u * 4u);
  // Not a blank image: several distinct colours.
  std::set<std::uint32_t> colours;
  for (std::size_t i = 0; i < t.rgba8.size(); i += 4 * 97) {
    std::uint32_t c;
    std::memcpy(&c, &t.rgba8[i], 4);
    colours.insert(c);
  }
  EXPECT_GT(colours.size(), 3u);
  ASSERT_EQ(s.materials.size(), 1u);
  EXPECT_EQ(s.materials[0].base_color_texture, 0);
  EXPECT_EQ(s.materials[0].base_color_uv, 0);
  EXPECT_EQ(s.meshes[0].uv0.size(), s.meshes[0].positions.size());
}

TEST(GltfSamples, GltfCamerasSkipsOrthographicWithWarning) {
  IRRADCAST_NEED_TESTDATA();
  GltfLoadReport report;
  Scene s = load_gltf(kSamples + "/Cameras/Cameras.gltf", &report);
  ASSERT_EQ(s.cameras.size(), 1u);
  EXPECT_FLOAT_EQ(s.cameras[0].yfov, 0.7f);
  EXPECT_FLOAT_EQ(s.cameras[0].aspect_ratio, 1.0f);
  EXPECT_FLOAT_EQ(s.cameras[0].znear, 0.01f);
  EXPECT_FLOAT_EQ(s.cameras[0].zfar, 100.0f);
  EXPECT_EQ(s.nodes.at(1).camera, 0);
  EXPECT_EQ(s.nodes.at(2).camera, -1);
  EXPECT_EQ(s.first_camera_node(), 1);
  EXPECT_TRUE(has_warning(report, "orthographic"));
  auto world = s.world_matrices();
  expect_near(glm::vec3(world[1][3]), glm::vec3(0.5f, 0.5f, 3.0f), 1e-6f, "camera position");
}

TEST(GltfSamples, GltfDuck) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/Duck/Duck.gltf");
  EXPECT_EQ(s.triangle_count(), 4212u);
  ASSERT_EQ(s.textures.size(), 1u);
  EXPECT_EQ(s.textures[0].width, 512);
  EXPECT_EQ(s.textures[0].height, 512);
  EXPECT_EQ(s.cameras.size(), 1u);
  EXPECT_EQ(s.materials.at(0).base_color_texture, 0);
}

TEST(GltfSamples, GltfMultiUVTestHasTexcoord1) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/MultiUVTest/MultiUVTest.gltf");
  const Mesh& m = s.meshes.at(0);
  ASSERT_EQ(m.uv1.size(), m.positions.size());
  ASSERT_EQ(m.uv0.size(), m.positions.size());
  bool differ = false;
  for (std::size_t i = 0; i < m.uv0.size(); ++i) differ |= m.uv0[i] != m.uv1[i];
  EXPECT_TRUE(differ);
  ASSERT_EQ(s.textures.size(), 2u);
  const Material& mat = s.materials.at(0);
  EXPECT_EQ(mat.base_color_texture, 0);
  EXPECT_EQ(mat.base_color_uv, 0);
  EXPECT_EQ(mat.emissive_texture, 1);
  EXPECT_EQ(mat.emissive_uv, 1);
  EXPECT_EQ(mat.emissive, glm::vec3(1.0f));
}

TEST(GltfSamples, GltfSimpleSparseAccessorSubstitutes) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/SimpleSparseAccessor/SimpleSparseAccessor.gltf");
  const Mesh& m = s.meshes.at(0);
  ASSERT_EQ(m.positions.size(), 14u);
  EXPECT_EQ(m.positions[8], glm::vec3(1, 2, 0));
  EXPECT_EQ(m.positions[10], glm::vec3(3, 3, 0));
  EXPECT_EQ(m.positions[12], glm::vec3(5, 4, 0));
  EXPECT_EQ(m.positions[9], glm::vec3(2, 1, 0));  // untouched
  EXPECT_EQ(m.positions[6], glm::vec3(6, 0, 0));
  EXPECT_EQ(m.triangle_count(), 12u);
}

TEST(GltfSamples, GltfSimpleMeshesInstancesOneMesh) {
  IRRADCAST_NEED_TESTDATA();
  Scene s = load_gltf(kSamples + "/SimpleMeshes/SimpleMeshes.gltf");
  auto objects = s.objects();
  ASSERT_EQ(objects.size(), 2u);
  EXPECT_EQ(objects[0].mesh, objects[1].mesh);
  EXPECT_EQ(s.triangle_count(), 2u);
  ASSERT_EQ(s.materials.size(), 1u);  // the default material, appended once
  EXPECT_EQ(s.materials[0].base_color, glm::vec3(1.0f));
  auto c = world_corners(s);
  ASSERT_EQ(c.size(), 6u);
  expect_near(c[3] - c[0], glm::vec3(1, 0, 0), 1e-6f, "second instance translated");
}

TEST(GltfSamples, GltfTriangleWithoutIndicesAndOrientation) {
  IRRADCAST_NEED_TESTDATA();
  Scene t = load_gltf(kSamples + "/TriangleWithoutIndices/TriangleWithoutIndices.gltf");
  ASSERT_EQ(t.meshes.at(0).triangles.size(), 1u);
  EXPECT_EQ(t.meshes[0].triangles[0], glm::uvec3(0, 1, 2));
  Scene o = load_gltf(kSamples + "/OrientationTest/OrientationTest.gltf");
  EXPECT_EQ(o.triangle_count(), 524u);
  EXPECT_EQ(o.objects().size(), 13u);
  Scene tc = load_gltf(kSamples + "/TextureCoordinateTest/TextureCoordinateTest.gltf");
  EXPECT_EQ(tc.triangle_count(), 10u);
  EXPECT_EQ(tc.textures.size(), 1u);
}

// ---- export -> load round trips ---------------------------------------------------------------

Scene make_test_scene() {
  Scene s;
  s.name = "roundtrip";
  Texture tex;
  tex.name = "checker";
  tex.width = 3;
  tex.height = 2;
  for (int i = 0; i < 6; ++i)
    for (int c = 0; c < 4; ++c) tex.rgba8.push_back(static_cast<std::uint8_t>(i * 40 + c * 7 + 3));
  s.textures.push_back(tex);

  Material plain;
  plain.name = "plain";
  plain.base_color = glm::vec3(0.2f, 0.4f, 0.6f);
  plain.base_color_texture = 0;
  plain.base_color_uv = 0;
  Material lamp;
  lamp.name = "lamp";
  lamp.base_color = glm::vec3(0.9f);
  lamp.emissive = glm::vec3(1.0f, 0.8f, 0.5f);
  lamp.emissive_strength = 12.5f;
  lamp.emissive_texture = 0;
  lamp.emissive_uv = 1;
  lamp.double_sided = true;
  Material hot;  // emissive beyond glTF's [0,1] factor range
  hot.emissive = glm::vec3(6.0f, 3.0f, 0.0f);
  s.materials = {plain, lamp, hot};

  Mesh quad;
  quad.name = "quad";
  quad.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, 0.5f, 1}};
  quad.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 1, 0}};
  quad.uv0 = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {0.5f, 0.5f}};
  quad.uv1 = {{0.1f, 0.1f}, {0.9f, 0.1f}, {0.9f, 0.9f}, {0.1f, 0.9f}, {0.5f, 0.25f}};
  quad.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 1, 4}, {2, 3, 4}};
  quad.triangle_material = {0, 0, 1, 2};
  s.meshes.push_back(quad);
  Mesh tri;
  tri.positions = {{0, 0, 0}, {2, 0, 0}, {0, 0, -2}};
  tri.triangles = {{0, 1, 2}};
  tri.triangle_material = {1};
  s.meshes.push_back(tri);
  s.meshes.push_back(Mesh{});  // empty: must not break the export

  Light point;
  point.name = "bulb";
  point.color = glm::vec3(1.0f, 0.9f, 0.8f);
  point.intensity = 40.0f;
  point.range = 12.0f;
  Light spot;
  spot.type = Light::Type::Spot;
  spot.intensity = 100.0f;
  spot.inner_cone_angle = 0.2f;
  spot.outer_cone_angle = 0.6f;
  Light sun;
  sun.type = Light::Type::Directional;
  sun.color = glm::vec3(1.0f, 1.0f, 0.9f);
  sun.intensity = 3.0f;
  s.lights = {point, spot, sun};

  Camera cam;
  cam.name = "eye";
  cam.yfov = 0.8f;
  cam.aspect_ratio = 16.0f / 9.0f;
  cam.znear = 0.05f;
  cam.zfar = 200.0f;
  s.cameras.push_back(cam);

  Node root;
  root.name = "root";
  root.local =
      glm::rotate(glm::translate(glm::mat4(1.0f), glm::vec3(1, 2, 3)), 0.7f, glm::vec3(0, 1, 0));
  int r = s.add_node(root);
  Node a;
  a.name = "a";
  a.parent = r;
  a.mesh = 0;
  a.local = glm::scale(glm::mat4(1.0f), glm::vec3(2.0f, 1.0f, 0.5f));
  s.add_node(a);
  Node b;
  b.name = "b";
  b.parent = r;
  b.mesh = 1;
  b.light = 0;
  b.local = glm::translate(glm::mat4(1.0f), glm::vec3(0, 0, -4));
  int ib = s.add_node(b);
  Node c;
  c.parent = ib;
  c.light = 1;
  c.camera = 0;
  c.local = glm::rotate(glm::mat4(1.0f), -0.3f, glm::vec3(1, 0, 0));
  s.add_node(c);
  Node d;
  d.light = 2;
  d.mesh = 0;  // instanced a second time
  s.add_node(d);
  return s;
}

// Compares the loaded scene with the original: geometry in world space, per-triangle material
// (colour, emission, textures with their pixels), lights placed by nodes, cameras.
void expect_same_scene(const Scene& a, const Scene& b) {
  auto ca = world_corners(a), cb = world_corners(b);
  ASSERT_EQ(ca.size(), cb.size());
  for (std::size_t i = 0; i < ca.size(); ++i)
    expect_near(ca[i], cb[i], 1e-5f, "corner " + std::to_string(i));

  auto oa = a.objects(), ob = b.objects();
  ASSERT_EQ(oa.size(), ob.size());
  for (std::size_t i = 0; i < oa.size(); ++i) {
    const Mesh& ma = a.meshes[oa[i].mesh];
    const Mesh& mb = b.meshes[ob[i].mesh];
    ASSERT_EQ(ma.triangle_count(), mb.triangle_count());
    EXPECT_EQ(ma.normals.empty(), mb.normals.empty());
    EXPECT_EQ(ma.uv1.empty(), mb.uv1.empty());
    for (std::size_t t = 0; t < ma.triangle_count(); ++t) {
      for (int k = 0; k < 3; ++k) {
        if (!ma.normals.empty())
          expect_near(ma.normals[ma.triangles[t][k]], mb.normals[mb.triangles[t][k]], 1e-5f,
                      "normal");
        if (!ma.uv0.empty()) {
          glm::vec2 ua = ma.uv0[ma.triangles[t][k]], ub = mb.uv0[mb.triangles[t][k]];
          EXPECT_NEAR(ua.x, ub.x, 1e-6f);
          EXPECT_NEAR(ua.y, ub.y, 1e-6f);
        }
        if (!ma.uv1.empty()) {
          glm::vec2 ua = ma.uv1[ma.triangles[t][k]], ub = mb.uv1[mb.triangles[t][k]];
          EXPECT_NEAR(ua.x, ub.x, 1e-6f);
          EXPECT_NEAR(ua.y, ub.y, 1e-6f);
        }
      }
      const Material& pa = a.materials.at(ma.triangle_material[t]);
      const Material& pb = b.materials.at(mb.triangle_material[t]);
      SCOPED_TRACE("material " + pa.name);
      EXPECT_EQ(pa.name, pb.name);
      expect_near(pa.base_color, pb.base_color, 1e-6f, "base colour");
      expect_near(pa.emission(), pb.emission(), 1e-4f * (1.0f + glm::length(pa.emission())),
                  "emission");
      EXPECT_EQ(pa.double_sided, pb.double_sided);
      EXPECT_EQ(pa.alpha_mode, pb.alpha_mode);
      EXPECT_FLOAT_EQ(pa.base_alpha, pb.base_alpha);
      if (pa.cut_out()) {
        EXPECT_FLOAT_EQ(pa.alpha_cutoff, pb.alpha_cutoff);
      }
      EXPECT_EQ(pa.base_color_texture >= 0, pb.base_color_texture >= 0);
      EXPECT_EQ(pa.emissive_texture >= 0, pb.emissive_texture >= 0);
      if (pa.base_color_texture >= 0 && pb.base_color_texture >= 0) {
        EXPECT_EQ(pa.base_color_uv, pb.base_color_uv);
        const Texture& ta = a.textures[pa.base_color_texture];
        const Texture& tb = b.textures[pb.base_color_texture];
        EXPECT_EQ(ta.width, tb.width);
        EXPECT_EQ(ta.height, tb.height);
        EXPECT_EQ(ta.rgba8, tb.rgba8);
      }
      if (pa.emissive_texture >= 0 && pb.emissive_texture >= 0) {
        EXPECT_EQ(pa.emissive_uv, pb.emissive_uv);
        EXPECT_EQ(a.textures[pa.emissive_texture].rgba8, b.textures[pb.emissive_texture].rgba8);
      }
    }
  }

  // Lights and cameras, matched through the nodes that place them.
  auto wa = a.world_matrices(), wb = b.world_matrices();
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  ASSERT_EQ(a.lights.size(), b.lights.size());
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (std::size_t n = 0; n < a.nodes.size(); ++n) {
    SCOPED_TRACE("node " + std::to_string(n));
    for (int col = 0; col < 4; ++col)
      expect_near(glm::vec3(wa[n][col]), glm::vec3(wb[n][col]), 1e-5f, "world");
    ASSERT_EQ(a.nodes[n].light >= 0, b.nodes[n].light >= 0);
    if (a.nodes[n].light >= 0) {
      const Light& la = a.lights[a.nodes[n].light];
      const Light& lb = b.lights[b.nodes[n].light];
      EXPECT_EQ(la.type, lb.type);
      EXPECT_EQ(la.name, lb.name);
      expect_near(la.color, lb.color, 1e-6f, "light colour");
      EXPECT_FLOAT_EQ(la.intensity, lb.intensity);
      if (la.type != Light::Type::Directional) {
        EXPECT_FLOAT_EQ(la.range, lb.range);
      }
      if (la.type == Light::Type::Spot) {
        EXPECT_FLOAT_EQ(la.inner_cone_angle, lb.inner_cone_angle);
        EXPECT_FLOAT_EQ(la.outer_cone_angle, lb.outer_cone_angle);
      }
    }
    ASSERT_EQ(a.nodes[n].camera >= 0, b.nodes[n].camera >= 0);
    if (a.nodes[n].camera >= 0) {
      const Camera& xa = a.cameras[a.nodes[n].camera];
      const Camera& xb = b.cameras[b.nodes[n].camera];
      EXPECT_EQ(xa.name, xb.name);
      EXPECT_FLOAT_EQ(xa.yfov, xb.yfov);
      EXPECT_FLOAT_EQ(xa.aspect_ratio, xb.aspect_ratio);
      EXPECT_FLOAT_EQ(xa.znear, xb.znear);
      EXPECT_FLOAT_EQ(xa.zfar, xb.zfar);
    }
  }
}

TEST_F(GltfTest, GltfRoundTripGltfAndGlb) {
  const Scene original = make_test_scene();
  for (const char* name : {"out.gltf", "out.glb"}) {
    SCOPED_TRACE(name);
    std::string p = path(name);
    save_gltf(original, p);
    GltfLoadReport report;
    Scene loaded = load_gltf(p, &report);
    EXPECT_TRUE(report.warnings.empty()) << ::testing::PrintToString(report.warnings);
    expect_same_scene(original, loaded);
    EXPECT_EQ(loaded.name, "roundtrip");
    EXPECT_EQ(loaded.triangle_count(), original.triangle_count());
    EXPECT_EQ(loaded.objects().size(), 3u);
    // Exact emissive fields where they are in glTF's range; the strength carries the rest.
    const Material* lamp = nullptr;
    for (const Material& m : loaded.materials)
      if (m.name == "lamp") lamp = &m;
    ASSERT_NE(lamp, nullptr);
    EXPECT_FLOAT_EQ(lamp->emissive_strength, 12.5f);
    EXPECT_EQ(lamp->emissive, glm::vec3(1.0f, 0.8f, 0.5f));
    EXPECT_EQ(lamp->emissive_uv, 1);
    EXPECT_EQ(loaded.textures.size(), 1u);  // one image shared by both materials
  }
  // The .gltf is self-contained JSON: one buffer as a data URI, the extensions declared.
  json j = json::parse(read_bytes(path("out.gltf")));
  EXPECT_EQ(j["asset"]["version"], "2.0");
  ASSERT_EQ(j["buffers"].size(), 1u);
  EXPECT_EQ(
      j["buffers"][0]["uri"].get<std::string>().rfind("data:application/octet-stream;base64,", 0),
      0u);
  auto used = j["extensionsUsed"].get<std::vector<std::string>>();
  EXPECT_NE(std::find(used.begin(), used.end(), "KHR_lights_punctual"), used.end());
  EXPECT_NE(std::find(used.begin(), used.end(), "KHR_materials_emissive_strength"), used.end());
  for (const json& mesh : j["meshes"])
    for (const json& prim : mesh["primitives"]) {
      const json& pos = j["accessors"][prim["attributes"]["POSITION"].get<int>()];
      EXPECT_EQ(pos["min"].size(), 3u);
      EXPECT_EQ(pos["max"].size(), 3u);
    }
  EXPECT_EQ(j["images"][0]["mimeType"], "image/png");
  // The .glb starts with the GLB header and declares its own length.
  auto glb = read_bytes(path("out.glb"));
  ASSERT_GE(glb.size(), 20u);
  EXPECT_EQ(std::memcmp(glb.data(), "glTF", 4), 0);
  std::uint32_t length;
  std::memcpy(&length, &glb[8], 4);
  EXPECT_EQ(length, glb.size());
}

TEST_F(GltfTest, GltfRoundTripSamples) {
  IRRADCAST_NEED_TESTDATA();
  for (const char* name : {"Duck", "MultiUVTest", "2CylinderEngine", "SimpleSparseAccessor"}) {
    SCOPED_TRACE(name);
    Scene original = load_gltf(kSamples + "/" + name + "/" + name + ".gltf");
    std::string p = path(std::string(name) + ".glb");
    save_gltf(original, p);
    Scene loaded = load_gltf(p);
    expect_same_scene(original, loaded);
  }
}

TEST_F(GltfTest, GltfRoundTripBuiltinCornellBox) {
  Scene original = make_cornell_box();
  ASSERT_GT(original.triangle_count(), 0u);
  for (const char* name : {"cornell.gltf", "cornell.glb"}) {
    SCOPED_TRACE(name);
    save_gltf(original, path(name));
    expect_same_scene(original, load_gltf(path(name)));
  }
}

TEST_F(GltfTest, GltfSaveErrors) {
  Scene s = make_test_scene();
  try {
    save_gltf(s, path("scene.obj"));
    ADD_FAILURE() << "no error for an unknown extension";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("scene.obj"), std::string::npos);
  }
  try {
    save_gltf(s, path("no/such/dir/scene.gltf"));
    ADD_FAILURE() << "no error for an unwritable path";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open"), std::string::npos) << e.what();
  }
  s.meshes[0].triangles.push_back({0, 1, 99});
  s.meshes[0].triangle_material.push_back(0);
  EXPECT_THROW(save_gltf(s, path("bad.glb")), Error);
}

TEST_F(GltfTest, GltfImageViewPastBufferEnd) {
  std::string p = path("tex.gltf");
  save_gltf(make_test_scene(), p);
  json j = json::parse(read_bytes(p));
  const int v = j["images"][0]["bufferView"];
  j["bufferViews"][v]["byteLength"] = 1 << 20;
  write_text(p, j.dump());
  expect_load_error(p, "of image 0 runs past the end of buffer 0");
}

}  // namespace

// ---- cut-out materials (alphaMode) ---------------------------------------------------------

namespace {

// triangle_model() with the given materials, its primitive using material 0.
std::string write_material_model(const fs::path& dir, const std::string& name, json materials) {
  TestModel m = triangle_model();
  m.gltf["materials"] = std::move(materials);
  m.gltf["meshes"][0]["primitives"][0]["material"] = 0;
  return write_model(dir, name, std::move(m), name + ".bin");
}

}  // namespace

TEST_F(GltfTest, AlphaModeMaskLoadsCutoffAndBaseAlpha) {
  const std::string p = write_material_model(
      dir_, "mask",
      {{{"name", "leaves"},
        {"alphaMode", "MASK"},
        {"alphaCutoff", 0.25},
        {"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.6, 0.7, 0.4}}}}},
       {{"name", "wall"}, {"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, 0.3}}}}},
       {{"name", "default-cutoff"}, {"alphaMode", "MASK"}}});
  GltfLoadReport report;
  Scene s = load_gltf(p, &report);
  EXPECT_TRUE(report.warnings.empty()) << ::testing::PrintToString(report.warnings);
  ASSERT_GE(s.materials.size(), 3u);
  EXPECT_EQ(s.materials[0].alpha_mode, Material::AlphaMode::Mask);
  EXPECT_FLOAT_EQ(s.materials[0].alpha_cutoff, 0.25f);
  EXPECT_FLOAT_EQ(s.materials[0].base_alpha, 0.4f);
  EXPECT_EQ(s.materials[1].alpha_mode, Material::AlphaMode::Opaque);  // alpha kept, not used
  EXPECT_FLOAT_EQ(s.materials[1].base_alpha, 0.3f);
  EXPECT_FLOAT_EQ(s.materials[2].alpha_cutoff, 0.5f);  // glTF's default
  // Alpha 0.4 >= 0.25: the whole triangle stays; at cutoff 0.5 it would all be cut out.
  World world = World::build(s);
  EXPECT_FLOAT_EQ(surface_alpha(world, 0, 0, 0.2f, 0.2f), 0.4f);
  EXPECT_FALSE(cut_out(world, 0, 0, 0.2f, 0.2f));
  s.materials[0].alpha_cutoff = 0.5f;
  EXPECT_TRUE(cut_out(world, 0, 0, 0.2f, 0.2f));
}

TEST_F(GltfTest, AlphaModeBlendLoadsAsMaskAtOneHalfWithOneWarning) {
  const std::string p =
      write_material_model(dir_, "blend",
                           {{{"name", "glass"}, {"alphaMode", "BLEND"}, {"alphaCutoff", 0.1}},
                            {{"name", "curtain"}, {"alphaMode", "BLEND"}},
                            {{"name", "opaque"}}});
  GltfLoadReport report;
  Scene s = load_gltf(p, &report);
  ASSERT_EQ(report.warnings.size(), 1u) << ::testing::PrintToString(report.warnings);
  EXPECT_TRUE(has_warning(report, "BLEND"));
  EXPECT_TRUE(has_warning(report, "glass"));
  EXPECT_TRUE(has_warning(report, "curtain"));
  EXPECT_FALSE(has_warning(report, "opaque"));
  for (int i : {0, 1}) {
    EXPECT_EQ(s.materials[i].alpha_mode, Material::AlphaMode::Mask);
    EXPECT_FLOAT_EQ(s.materials[i].alpha_cutoff, 0.5f);  // the file's alphaCutoff is for MASK
  }
  EXPECT_EQ(s.materials[2].alpha_mode, Material::AlphaMode::Opaque);
}

TEST_F(GltfTest, BadAlphaValuesAreErrors) {
  expect_load_error(
      write_material_model(dir_, "neg", {{{"alphaMode", "MASK"}, {"alphaCutoff", -0.5}}}),
      "invalid alphaCutoff");
  // 1e999 overflows to infinity in the JSON parser.
  const std::string inf = write_material_model(dir_, "inf", {{{"alphaMode", "MASK"}}});
  std::string text;
  {
    std::ifstream f(inf);
    text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  const std::size_t at = text.find("\"MASK\"");
  ASSERT_NE(at, std::string::npos);
  text.insert(at + 6, ", \"alphaCutoff\": 1e999");
  write_text(inf, text);
  try {
    load_gltf(inf);
    ADD_FAILURE() << "no error for alphaCutoff 1e999";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
  }
  expect_load_error(write_material_model(dir_, "mode", {{{"alphaMode", "CLIP"}}}),
                    "unknown alphaMode");
}

TEST_F(GltfTest, MaskMaterialsRoundTrip) {
  Scene original = make_test_scene();
  Material& plain = original.materials[0];  // textured: the texture's alpha counts
  plain.alpha_mode = Material::AlphaMode::Mask;
  plain.alpha_cutoff = 0.3f;
  plain.base_alpha = 0.75f;
  original.materials[2].base_alpha = 0.5f;  // opaque: alpha carried, not used
  for (const char* name : {"mask.gltf", "mask.glb"}) {
    SCOPED_TRACE(name);
    save_gltf(original, path(name));
    GltfLoadReport report;
    Scene loaded = load_gltf(path(name), &report);
    EXPECT_TRUE(report.warnings.empty()) << ::testing::PrintToString(report.warnings);
    expect_same_scene(original, loaded);
  }
  json j = json::parse(read_bytes(path("mask.gltf")));
  EXPECT_EQ(j["materials"][0]["alphaMode"], "MASK");
  EXPECT_FALSE(j["materials"][1].contains("alphaMode"));
}

}  // namespace irradcast::test_gltf

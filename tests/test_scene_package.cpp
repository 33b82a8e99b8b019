// Scene package: the scene download round-trips exactly (a client composes the same image as the
// server), is deterministic, and corrupt or mismatched packages are refused with a clear error.
#include <gtest/gtest.h>

#include <zstd.h>

#include <random>
#include <string>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast/wire/sky_message.h"
#include "irradcast/wire/tile_codec.h"

namespace irradcast::test_scene_package {

namespace {

// The Cornell box plus what it lacks, so every part of the model is exercised: a texture on a
// material (sampled through TEXCOORD_0), a spot light on a node, and an instanced mesh.
Scene rich_cornell() {
  Scene s = make_cornell_box();
  Texture t;
  t.name = "checker";
  t.width = 4;
  t.height = 4;
  for (int i = 0; i < 16; ++i) {
    const std::uint8_t v = ((i + i / 4) % 2) ? 230 : 40;
    t.rgba8.insert(t.rgba8.end(), {v, static_cast<std::uint8_t>(255 - v), 128, 255});
  }
  s.textures.push_back(t);
  for (Mesh& m : s.meshes)
    if (m.uv0.empty()) {
      m.uv0.resize(m.positions.size());
      for (std::size_t i = 0; i < m.positions.size(); ++i)
        m.uv0[i] = glm::vec2(m.positions[i].x * 3.1f, m.positions[i].y * 2.3f + m.positions[i].z);
    }
  for (Material& mat : s.materials)
    if (!mat.is_emissive()) {
      mat.base_color_texture = 0;
      break;
    }
  Light spot;
  spot.name = "spot";
  spot.type = Light::Type::Spot;
  spot.color = glm::vec3(1.0f, 0.9f, 0.8f);
  spot.intensity = 3.5f;
  spot.range = 10.0f;
  spot.inner_cone_angle = 0.2f;
  spot.outer_cone_angle = 0.6f;
  s.lights.push_back(spot);
  Node ln;
  ln.name = "spot-node";
  ln.light = 0;
  ln.local[3] = glm::vec4(0.1f, 0.5f, 0.2f, 1.0f);
  s.add_node(ln);
  // An instance of the first mesh, scaled down and moved: a second object sharing a mesh.
  Node inst;
  inst.name = "instance";
  inst.mesh = s.nodes[s.objects().front().node].mesh;
  inst.local = glm::mat4(0.1f);
  inst.local[3] = glm::vec4(0.05f, 0.05f, 0.05f, 1.0f);
  s.add_node(inst);
  return s;
}

struct Prepared {
  explicit Prepared(Scene s) : scene(std::move(s)), world(World::build(scene)) {
    AtlasOptions ao;
    ao.texels_per_scene = 64.0f;
    atlas = build_atlas(world, ao);
  }
  Scene scene;
  World world;
  Atlas atlas;
};

// Lightmaps that vary across every texel, so a wrong lightmap coordinate shows.
std::vector<Lightmap> gradient_lightmaps(const Atlas& atlas) {
  std::vector<Lightmap> maps;
  for (std::size_t o = 0; o < atlas.objects.size(); ++o) {
    Lightmap m(atlas.objects[o].width, atlas.objects[o].height);
    for (int y = 0; y < m.height; ++y)
      for (int x = 0; x < m.width; ++x)
        m.texels[static_cast<std::size_t>(y) * m.width + x] =
            glm::vec3(0.1f * x, 0.05f * y, 0.3f + static_cast<float>(o));
    maps.push_back(m);
  }
  return maps;
}

std::string zstd(const std::string& raw) {
  std::string out(ZSTD_compressBound(raw.size()), '\0');
  out.resize(ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), 3));
  return out;
}

std::string unzstd(const std::string& bytes) {
  std::string raw(ZSTD_getFrameContentSize(bytes.data(), bytes.size()), '\0');
  raw.resize(ZSTD_decompress(raw.data(), raw.size(), bytes.data(), bytes.size()));
  return raw;
}

// Re-packs a (possibly tampered) SceneData, with a correct hash, so that only validation stops it.
std::string repack(const wire::SceneData& d) {
  return zstd(d.SerializeAsString());
}

std::string expect_error(const std::string& bytes, const std::string& hash) {
  try {
    wire::open_scene_package(bytes, hash);
  } catch (const irradcast::Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "open_scene_package accepted a bad package";
  return "";
}

}  // namespace

TEST(ScenePackage, Sha256MatchesTheStandardVectors) {
  EXPECT_EQ(wire::hex(wire::sha256("")),
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(wire::hex(wire::sha256("abc")),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(wire::hex(wire::sha256("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq")),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  // Padding boundaries.
  const std::pair<int, const char*> sizes[] = {
      {55, "9f4390f8d30c2dd92ec9f095b65e2b9ae9b0a925a5258e241c9f1e910f734318"},
      {56, "b35439a4ac6f0948b6d6f9e3c6af0f5f590ce20f1bde7090ef7970686ec6738a"},
      {63, "7d3e74a05d7db15bce4ad9ec0658ea98e3f06eeecf16b4c6fff2da457ddc2f34"},
      {64, "ffe054fe7ae0cb6dc65c3af9b61d5209f439851db43d0ba5997337df154668eb"},
      {65, "635361c48bb9eab14198e76ea8ab7f1a41685d6ad62aa9146d301d4f17eb0ae0"},
      {119, "31eba51c313a5c08226adf18d4a359cfdfd8d2e816b13f4af952f7ea6584dcfb"},
      {120, "2f3d335432c70b580af0e8e1b3674a7c020d683aa5f73aaaedfdc55af904c21c"},
      {1000000, "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0"}};
  for (const auto& [n, digest] : sizes)
    EXPECT_EQ(wire::hex(wire::sha256(std::string(n, 'a'))), digest) << n;
}

TEST(ScenePackage, RoundTripIsExactAndComposesTheSameImage) {
  const Prepared p(rich_cornell());
  ASSERT_GE(p.world.objects.size(), 2u);
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  EXPECT_EQ(pkg.hash.size(), 32u);
  EXPECT_EQ(pkg.hash, wire::sha256(pkg.bytes));
  RecordProperty("package_bytes", std::to_string(pkg.bytes.size()));
  RecordProperty("package_sha256", wire::hex(pkg.hash));

  const wire::UnpackedScene u = wire::open_scene_package(pkg.bytes, pkg.hash);
  const Scene& a = p.scene;
  const Scene& b = u.scene;
  EXPECT_EQ(b.name, a.name);
  ASSERT_EQ(b.nodes.size(), a.nodes.size());
  for (std::size_t i = 0; i < a.nodes.size(); ++i) {
    EXPECT_EQ(b.nodes[i].name, a.nodes[i].name);
    EXPECT_EQ(b.nodes[i].local, a.nodes[i].local);
    EXPECT_EQ(b.nodes[i].parent, a.nodes[i].parent);
    EXPECT_EQ(b.nodes[i].children, a.nodes[i].children);
    EXPECT_EQ(b.nodes[i].mesh, a.nodes[i].mesh);
    EXPECT_EQ(b.nodes[i].camera, a.nodes[i].camera);
    EXPECT_EQ(b.nodes[i].light, a.nodes[i].light);
  }
  EXPECT_EQ(b.roots, a.roots);
  ASSERT_EQ(b.meshes.size(), a.meshes.size());
  for (std::size_t i = 0; i < a.meshes.size(); ++i) {
    EXPECT_EQ(b.meshes[i].name, a.meshes[i].name);
    EXPECT_EQ(b.meshes[i].positions, a.meshes[i].positions);
    EXPECT_EQ(b.meshes[i].normals, a.meshes[i].normals);
    EXPECT_EQ(b.meshes[i].uv0, a.meshes[i].uv0);
    EXPECT_EQ(b.meshes[i].uv1, a.meshes[i].uv1);
    EXPECT_EQ(b.meshes[i].triangles, a.meshes[i].triangles);
    EXPECT_EQ(b.meshes[i].triangle_material, a.meshes[i].triangle_material);
  }
  ASSERT_EQ(b.materials.size(), a.materials.size());
  for (std::size_t i = 0; i < a.materials.size(); ++i) {
    const Material &x = a.materials[i], &y = b.materials[i];
    EXPECT_EQ(y.name, x.name);
    EXPECT_EQ(y.base_color, x.base_color);
    EXPECT_EQ(y.base_color_texture, x.base_color_texture);
    EXPECT_EQ(y.base_color_uv, x.base_color_uv);
    EXPECT_EQ(y.emissive, x.emissive);
    EXPECT_EQ(y.emissive_texture, x.emissive_texture);
    EXPECT_EQ(y.emissive_uv, x.emissive_uv);
    EXPECT_EQ(y.emissive_strength, x.emissive_strength);
    EXPECT_EQ(y.double_sided, x.double_sided);
  }
  ASSERT_EQ(b.textures.size(), 1u);
  EXPECT_EQ(b.textures[0].name, "checker");
  EXPECT_EQ(b.textures[0].width, 4);
  EXPECT_EQ(b.textures[0].rgba8, a.textures[0].rgba8);
  ASSERT_EQ(b.lights.size(), a.lights.size());
  EXPECT_EQ(b.lights[0].type, Light::Type::Spot);
  EXPECT_EQ(b.lights[0].color, a.lights[0].color);
  EXPECT_EQ(b.lights[0].intensity, a.lights[0].intensity);
  EXPECT_EQ(b.lights[0].range, a.lights[0].range);
  EXPECT_EQ(b.lights[0].inner_cone_angle, a.lights[0].inner_cone_angle);
  EXPECT_EQ(b.lights[0].outer_cone_angle, a.lights[0].outer_cone_angle);
  ASSERT_EQ(b.cameras.size(), a.cameras.size());
  for (std::size_t i = 0; i < a.cameras.size(); ++i) {
    EXPECT_EQ(b.cameras[i].yfov, a.cameras[i].yfov);
    EXPECT_EQ(b.cameras[i].aspect_ratio, a.cameras[i].aspect_ratio);
    EXPECT_EQ(b.cameras[i].znear, a.cameras[i].znear);
    EXPECT_EQ(b.cameras[i].zfar, a.cameras[i].zfar);
  }
  ASSERT_EQ(u.atlas.objects.size(), p.atlas.objects.size());
  for (std::size_t i = 0; i < p.atlas.objects.size(); ++i) {
    const ObjectLightmap &x = p.atlas.objects[i], &y = u.atlas.objects[i];
    EXPECT_EQ(y.width, x.width);
    EXPECT_EQ(y.height, x.height);
    EXPECT_EQ(y.corner_uv, x.corner_uv);
    EXPECT_EQ(y.triangle_chart, x.triangle_chart);
    EXPECT_EQ(y.chart_count, x.chart_count);
    EXPECT_EQ(y.from_file_uv1, x.from_file_uv1);
    EXPECT_EQ(y.texels_per_unit, x.texels_per_unit);
  }

  // The client's view: identical pixels, with constant and with varying lightmaps.
  const World wb = World::build(u.scene);
  ASSERT_EQ(wb.objects.size(), p.world.objects.size());
  const RayScene ra(p.world), rb(wb);
  const CameraPose cam = camera_pose(p.scene, p.scene.first_camera_node());
  std::vector<Lightmap> constant;
  for (const ObjectLightmap& o : p.atlas.objects)
    constant.emplace_back(o.width, o.height, glm::vec3(1.0f, 2.0f, 3.0f));
  for (const std::vector<Lightmap>& maps : {constant, gradient_lightmaps(p.atlas)}) {
    const ImageRGB ia = compose(p.world, ra, p.atlas, maps, cam, 96, 96);
    const ImageRGB ib = compose(wb, rb, u.atlas, maps, cam, 96, 96);
    int lit = 0;
    for (std::size_t i = 0; i < ia.pixels.size(); ++i) {
      ASSERT_EQ(ia.pixels[i], ib.pixels[i]) << "pixel " << i;
      lit += ia.pixels[i] != glm::vec3(0.0f);
    }
    EXPECT_GT(lit, 96 * 96 / 2);
  }
}

TEST(ScenePackage, IsDeterministic) {
  const Prepared p(make_cornell_box());
  const wire::ScenePackage a = wire::make_scene_package(p.scene, p.atlas);
  const wire::ScenePackage b = wire::make_scene_package(p.scene, p.atlas);
  EXPECT_EQ(a.bytes, b.bytes);
  EXPECT_EQ(a.hash, b.hash);
  // A changed scene gets a new hash.
  Scene moved = p.scene;
  moved.nodes[moved.objects().front().node].local[3].x += 0.01f;
  EXPECT_NE(wire::make_scene_package(moved, p.atlas).hash, a.hash);
}

TEST(ScenePackage, RoomsSceneRoundTrips) {
  const Prepared p(load_scene("rooms:2", 0.5f));
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  const wire::UnpackedScene u = wire::open_scene_package(pkg.bytes, pkg.hash);
  ASSERT_EQ(u.atlas.objects.size(), p.atlas.objects.size());
  for (std::size_t i = 0; i < p.atlas.objects.size(); ++i)
    ASSERT_EQ(u.atlas.objects[i].corner_uv, p.atlas.objects[i].corner_uv);
  EXPECT_EQ(u.scene.triangle_count(), p.scene.triangle_count());
  RecordProperty("rooms2_triangles", std::to_string(p.scene.triangle_count()));
  RecordProperty("rooms2_package_bytes", std::to_string(pkg.bytes.size()));
}

TEST(ScenePackage, HashMismatchIsAnError) {
  const Prepared p(make_cornell_box());
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  std::string wrong = pkg.hash;
  wrong[0] = static_cast<char>(wrong[0] ^ 1);
  const std::string msg = expect_error(pkg.bytes, wrong);
  EXPECT_NE(msg.find("hash mismatch"), std::string::npos) << msg;
  EXPECT_NE(msg.find(wire::hex(wrong)), std::string::npos) << msg;
  // Skipping the check (empty hash) opens it.
  EXPECT_NO_THROW(wire::open_scene_package(pkg.bytes, ""));
}

TEST(ScenePackage, CorruptedBytesAreRefusedWithAClearError) {
  const Prepared p(make_cornell_box());
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  // With the expected hash the hash check catches any change.
  std::string bad = pkg.bytes;
  bad[bad.size() / 2] = static_cast<char>(bad[bad.size() / 2] ^ 0x10);
  EXPECT_NE(expect_error(bad, pkg.hash).find("hash mismatch"), std::string::npos);
  // Without it (or with a hash computed over the corrupted bytes), decompression and parsing
  // must still refuse: flip bytes all over the package.
  // A few zstd header bytes (e.g. the window size) do not change the content: such a package
  // opens to exactly the original scene. Everything else must be refused.
  std::mt19937 rng(2);
  int refused = 0;
  for (int k = 0; k < 200; ++k) {
    std::string b = pkg.bytes;
    const std::size_t i = k < 40 ? static_cast<std::size_t>(k) : rng() % b.size();
    b[i] = static_cast<char>(b[i] ^ (1 + rng() % 255));
    try {
      const wire::UnpackedScene u = wire::open_scene_package(b, wire::sha256(b));
      EXPECT_EQ(wire::make_scene_package(u.scene, u.atlas).bytes, pkg.bytes)
          << "byte " << i << " changed the content without being noticed";
    } catch (const irradcast::Error& e) {
      EXPECT_EQ(std::string(e.what()).rfind("scene package: ", 0), 0u) << e.what();
      ++refused;
    }
  }
  EXPECT_GE(refused, 190);
  EXPECT_NE(expect_error(pkg.bytes.substr(0, pkg.bytes.size() - 10), "").find("corrupt"),
            std::string::npos);
  EXPECT_NE(expect_error("", "").find("corrupt"), std::string::npos);
  EXPECT_NE(expect_error("hello, world", "").find("corrupt"), std::string::npos);
  // A valid zstd frame around something that is not a SceneData.
  EXPECT_NE(expect_error(zstd(std::string(100, '\xff')), "").find("does not parse"),
            std::string::npos);
}

TEST(ScenePackage, InvalidContentIsRefusedWithAClearError) {
  const Prepared p(make_cornell_box());
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  wire::SceneData good;
  ASSERT_TRUE(good.ParseFromString(unzstd(pkg.bytes)));
  auto check = [&](const char* expected, auto&& tamper) {
    wire::SceneData d = good;
    tamper(d);
    const std::string msg = expect_error(repack(d), "");
    EXPECT_NE(msg.find(expected), std::string::npos) << msg;
  };
  check("format 2", [](wire::SceneData& d) { d.set_format(2); });
  check("does not exist", [](wire::SceneData& d) { d.mutable_nodes(0)->set_mesh(999); });
  check("does not exist", [](wire::SceneData& d) { d.mutable_nodes(0)->add_children(-3); });
  check("does not exist", [](wire::SceneData& d) { d.set_roots(0, 12345); });
  check("does not exist",
        [](wire::SceneData& d) { d.mutable_materials(0)->set_base_color_texture(4); });
  check("out of range", [](wire::SceneData& d) { d.mutable_meshes(0)->set_triangles(1, 1000000); });
  check("not a multiple of 3",
        [](wire::SceneData& d) { d.mutable_meshes(0)->mutable_positions()->RemoveLast(); });
  check("non-finite", [](wire::SceneData& d) {
    d.mutable_meshes(0)->set_positions(0, std::numeric_limits<float>::quiet_NaN());
  });
  check("normals", [](wire::SceneData& d) {
    d.mutable_meshes(0)->mutable_normals()->Resize(d.meshes(0).positions_size() - 3, 0.0f);
  });
  check("RGBA8", [](wire::SceneData& d) {
    wire::SceneTexture* t = d.add_textures();
    t->set_width(100);
    t->set_height(100);
    t->set_rgba8("tiny");
  });
  check("layout has", [](wire::SceneData& d) { d.mutable_layouts()->RemoveLast(); });
  check("lightmap coordinates for", [](wire::SceneData& d) {
    d.mutable_layouts(0)->mutable_corner_uv()->Resize(d.layouts(0).corner_uv_size() - 6, 0.0f);
  });
  check("non-finite lightmap", [](wire::SceneData& d) {
    d.mutable_layouts(0)->set_corner_uv(0, std::numeric_limits<float>::infinity());
  });
  check("unknown type",
        [](wire::SceneData& d) { d.add_lights()->set_type(static_cast<wire::LightType>(7)); });
}

TEST(ScenePackage, LayoutThatDoesNotMatchTheSceneIsRefused) {
  const Prepared p(make_cornell_box());
  Atlas fewer = p.atlas;
  fewer.objects.pop_back();
  EXPECT_THROW(wire::make_scene_package(p.scene, fewer), irradcast::Error);
  Atlas short_uv = p.atlas;
  short_uv.objects[0].corner_uv.pop_back();
  EXPECT_THROW(wire::make_scene_package(p.scene, short_uv), irradcast::Error);
  Scene broken = p.scene;
  broken.meshes[0].triangles[0].x = 1u << 30;
  EXPECT_THROW(wire::make_scene_package(broken, p.atlas), irradcast::Error);
}

TEST(ScenePackage, ChunksReassembleInOrderOnly) {
  const Prepared p(make_cornell_box());
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  const std::vector<std::string> parts = wire::chunk(pkg.bytes, 1000);
  ASSERT_EQ(parts.size(), (pkg.bytes.size() + 999) / 1000);
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) EXPECT_EQ(parts[i].size(), 1000u);
  EXPECT_TRUE(wire::chunk("", 10).empty());
  EXPECT_THROW(wire::chunk("abc", 0), irradcast::Error);

  auto make_chunk = [&](std::size_t i) {
    wire::SceneChunk c;
    c.set_scene_hash(pkg.hash);
    c.set_offset(i * 1000);
    c.set_total(pkg.bytes.size());
    c.set_data(parts[i]);
    return c;
  };
  wire::SceneAssembler as(pkg.hash, pkg.bytes.size());
  for (std::size_t i = 0; i < parts.size(); ++i) {
    EXPECT_FALSE(as.complete());
    EXPECT_EQ(as.add(make_chunk(i)), i + 1 == parts.size());
  }
  EXPECT_EQ(as.bytes(), pkg.bytes);
  EXPECT_NO_THROW(wire::open_scene_package(as.bytes(), pkg.hash));

  wire::SceneAssembler gap(pkg.hash, pkg.bytes.size());
  EXPECT_THROW(gap.add(make_chunk(1)), irradcast::Error);
  wire::SceneAssembler other(std::string(32, 'x'), pkg.bytes.size());
  EXPECT_THROW(other.add(make_chunk(0)), irradcast::Error);
  wire::SceneAssembler smaller(pkg.hash, 500);
  EXPECT_THROW(smaller.add(make_chunk(0)), irradcast::Error);
  EXPECT_THROW(wire::SceneAssembler(pkg.hash, std::uint64_t{1} << 40), irradcast::Error);
}

TEST(ScenePackage, SkyAndAlphaFieldsTravelAndTheHashCoversThem) {
  Prepared p(make_cornell_box());
  const wire::ScenePackage plain = wire::make_scene_package(p.scene, p.atlas);
  // Defaults are not written: a sky-less, opaque scene's package holds no sky field at all.
  wire::SceneData d;
  ASSERT_TRUE(d.ParseFromString(unzstd(plain.bytes)));
  EXPECT_FALSE(d.has_sky());
  EXPECT_FALSE(d.materials(0).has_alpha_cutoff());
  EXPECT_FALSE(d.materials(0).has_base_alpha());

  p.scene.sky.color = glm::vec3(0.25f, 0.5f, 1.0f);
  p.scene.sky.strength = 2.5f;
  p.scene.materials[0].alpha_mode = Material::AlphaMode::Mask;
  p.scene.materials[0].alpha_cutoff = 0.3f;
  p.scene.materials[0].base_alpha = 0.75f;
  const wire::ScenePackage sky = wire::make_scene_package(p.scene, p.atlas);
  EXPECT_NE(sky.hash, plain.hash);
  const wire::UnpackedScene u = wire::open_scene_package(sky.bytes, sky.hash);
  EXPECT_EQ(u.scene.sky.color, p.scene.sky.color);
  EXPECT_EQ(u.scene.sky.strength, 2.5f);
  EXPECT_EQ(u.scene.sky.map.width, 0);
  EXPECT_EQ(u.scene.materials[0].alpha_mode, Material::AlphaMode::Mask);
  EXPECT_EQ(u.scene.materials[0].alpha_cutoff, 0.3f);
  EXPECT_EQ(u.scene.materials[0].base_alpha, 0.75f);
  EXPECT_EQ(u.scene.materials[1].alpha_mode, Material::AlphaMode::Opaque);
  EXPECT_EQ(u.scene.materials[1].alpha_cutoff, 0.5f);
  EXPECT_EQ(u.scene.materials[1].base_alpha, 1.0f);
  // Only the strength differs: another hash.
  p.scene.sky.strength = 2.0f;
  EXPECT_NE(wire::make_scene_package(p.scene, p.atlas).hash, sky.hash);
}

TEST(ScenePackage, ALargeSkyMapTravelsBoxDownsampledToTheViewerLimit) {
  Prepared p(make_cornell_box());
  // 2048 x 1024: each 2 x 2 block of the source becomes one texel of the 1024 x 512 map sent,
  // the block's mean.
  ImageRGB map(2048, 1024);
  auto block = [](int tx, int ty) {
    return glm::vec3(0.01f * static_cast<float>(tx % 97), 0.02f * static_cast<float>(ty % 53),
                     100.0f + static_cast<float>(tx % 7));
  };
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x)
      map.at(x, y) = block(x / 2, y / 2) + glm::vec3(x % 2 ? 0.004f : 0.0f, y % 2 ? 0.006f : 0.0f,
                                                     (x + y) % 2 ? 1.0f : -1.0f);
  p.scene.sky.map = map;
  p.scene.sky.source = "big.exr";
  p.scene.sky.strength = 0.5f;
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  RecordProperty("package_bytes_with_sky", std::to_string(pkg.bytes.size()));
  const Sky s = wire::open_scene_package(pkg.bytes, pkg.hash).scene.sky;
  ASSERT_EQ(s.map.width, wire::kMaxViewerSkyWidth);
  ASSERT_EQ(s.map.height, wire::kMaxViewerSkyHeight);
  EXPECT_EQ(s.source, "big.exr");
  EXPECT_EQ(s.strength, 0.5f);
  double worst = 0.0;
  for (int ty = 0; ty < s.map.height; ++ty)
    for (int tx = 0; tx < s.map.width; ++tx) {
      const glm::vec3 want = block(tx, ty) + glm::vec3(0.002f, 0.003f, 0.0f);
      const float m = std::max(want.x, std::max(want.y, want.z));
      const float bound =
          wire::rgb9e5_max_relative_error() * m + wire::tile_absolute_error_floor() + 1e-5f * m;
      for (int c = 0; c < 3; ++c)
        worst =
            std::max(worst, static_cast<double>(std::abs(s.map.at(tx, ty)[c] - want[c]) / bound));
    }
  EXPECT_LE(worst, 1.0) << "largest error over the RGB9E5 bound";
}

TEST(ScenePackage, BadSkiesAreRefusedWithAClearError) {
  Prepared p(make_cornell_box());
  p.scene.sky.map = ImageRGB(8, 4, glm::vec3(1.0f));
  const wire::ScenePackage pkg = wire::make_scene_package(p.scene, p.atlas);
  wire::SceneData good;
  ASSERT_TRUE(good.ParseFromString(unzstd(pkg.bytes)));
  ASSERT_TRUE(good.has_sky());
  auto check = [&](const char* expected, auto&& tamper) {
    wire::SceneData d = good;
    tamper(d);
    const std::string msg = expect_error(repack(d), "");
    EXPECT_NE(msg.find(expected), std::string::npos) << msg;
  };
  check("sky strength", [](wire::SceneData& d) {
    d.mutable_sky()->set_strength(std::numeric_limits<float>::quiet_NaN());
  });
  check("sky colour", [](wire::SceneData& d) { d.mutable_sky()->mutable_color()->set_y(-1.0f); });
  check("sky colour", [](wire::SceneData& d) {
    d.mutable_sky()->mutable_color()->set_x(std::numeric_limits<float>::infinity());
  });
  check("4096 x 4", [](wire::SceneData& d) { d.mutable_sky()->mutable_map()->set_width(4096); });
  check("0 x 4", [](wire::SceneData& d) { d.mutable_sky()->mutable_map()->set_width(0); });
  check("not zstd of 256 bytes",
        [](wire::SceneData& d) { d.mutable_sky()->mutable_map()->set_height(8); });
  check("not zstd", [](wire::SceneData& d) { d.mutable_sky()->mutable_map()->set_data("junk"); });
  check("unknown alpha mode", [](wire::SceneData& d) {
    d.mutable_materials(0)->set_alpha_mode(static_cast<wire::AlphaMode>(5));
  });
  check("alpha", [](wire::SceneData& d) { d.mutable_materials(0)->set_base_alpha(2.0f); });
}

}  // namespace irradcast::test_scene_package

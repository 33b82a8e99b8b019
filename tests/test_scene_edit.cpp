// Scene edits as data: the JSON form of every operation, the wire form, validation (a bad edit is
// refused with a message that names the problem and leaves the scene alone), what apply_edit
// changes, and the scene package carrying visibility and the revision.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/common/world.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast::test_scene_edit {

namespace {

// The Cornell box plus a point light on a node, so that light edits have a target.
Scene cornell_with_lamp() {
  Scene s = make_cornell_box();
  Light l;
  l.name = "lamp";
  l.color = glm::vec3(1.0f, 0.9f, 0.8f);
  l.intensity = 2.0f;
  s.lights.push_back(l);
  Node n;
  n.name = "lamp_node";
  n.light = 0;
  n.local[3] = glm::vec4(0.278f, 0.5f, 0.278f, 1.0f);
  s.add_node(n);
  return s;
}

int node_index(const Scene& s, const std::string& name) {
  for (std::size_t i = 0; i < s.nodes.size(); ++i)
    if (s.nodes[i].name == name) return static_cast<int>(i);
  return -1;
}

// Every op kind once, in JSON.
const char* kAllKinds = R"({"ops": [
  {"op": "move", "node": "tall_block", "by": [0.05, 0, -0.01]},
  {"op": "rotate", "node": "short_block", "axis": [0, 1, 0], "degrees": 30},
  {"op": "scale", "node": "tall_block", "by": [1, 1.5, 1]},
  {"op": "transform", "node": "camera",
   "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0.1,0.2,0.3,1]},
  {"op": "hide", "node": "short_block"},
  {"op": "show", "node": "short_block"},
  {"op": "light_color", "light": "lamp", "color": [0.5, 0.25, 1]},
  {"op": "light_intensity", "light": "#0", "intensity": 7.5},
  {"op": "albedo", "material": "red", "color": [0.2, 0.3, 0.4]},
  {"op": "emission", "material": "light", "color": [1, 1, 1], "strength": 3}
]})";

void expect_same_ops(const SceneEdit& a, const SceneEdit& b) {
  ASSERT_EQ(a.ops.size(), b.ops.size());
  for (std::size_t i = 0; i < a.ops.size(); ++i) {
    SCOPED_TRACE("op " + std::to_string(i + 1));
    EXPECT_EQ(a.ops[i].kind, b.ops[i].kind);
    EXPECT_EQ(a.ops[i].target, b.ops[i].target);
    EXPECT_EQ(a.ops[i].vector, b.ops[i].vector);
    EXPECT_EQ(a.ops[i].value, b.ops[i].value);
    EXPECT_EQ(a.ops[i].matrix, b.ops[i].matrix);
  }
}

// The message of the Error validate_edit throws ("" if none).
std::string validation_error(const Scene& s, const SceneEdit& e) {
  try {
    validate_edit(s, e);
  } catch (const Error& err) {
    return err.what();
  }
  return "";
}

EditOp op(EditOp::Kind kind, const std::string& target, glm::vec3 v = glm::vec3(0.0f),
          float value = 0.0f) {
  EditOp o;
  o.kind = kind;
  o.target = target;
  o.vector = v;
  o.value = value;
  return o;
}

void expect_same_scene(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (std::size_t i = 0; i < a.nodes.size(); ++i) {
    EXPECT_EQ(a.nodes[i].local, b.nodes[i].local) << a.nodes[i].name;
    EXPECT_EQ(a.nodes[i].visible, b.nodes[i].visible) << a.nodes[i].name;
  }
  ASSERT_EQ(a.lights.size(), b.lights.size());
  for (std::size_t i = 0; i < a.lights.size(); ++i) {
    EXPECT_EQ(a.lights[i].color, b.lights[i].color);
    EXPECT_EQ(a.lights[i].intensity, b.lights[i].intensity);
  }
  ASSERT_EQ(a.materials.size(), b.materials.size());
  for (std::size_t i = 0; i < a.materials.size(); ++i) {
    EXPECT_EQ(a.materials[i].base_color, b.materials[i].base_color) << a.materials[i].name;
    EXPECT_EQ(a.materials[i].emissive, b.materials[i].emissive) << a.materials[i].name;
    EXPECT_EQ(a.materials[i].emissive_strength, b.materials[i].emissive_strength);
  }
}

}  // namespace

TEST(SceneEdit, JsonOfEveryKindParsesAndRoundTrips) {
  const SceneEdit e = parse_edit_json(kAllKinds);
  ASSERT_EQ(e.ops.size(), 10u);
  using K = EditOp::Kind;
  EXPECT_EQ(e.ops[0].kind, K::Move);
  EXPECT_EQ(e.ops[0].target, "tall_block");
  EXPECT_EQ(e.ops[0].vector, glm::vec3(0.05f, 0.0f, -0.01f));
  EXPECT_EQ(e.ops[1].kind, K::Rotate);
  EXPECT_EQ(e.ops[1].vector, glm::vec3(0, 1, 0));
  EXPECT_EQ(e.ops[1].value, 30.0f);
  EXPECT_EQ(e.ops[2].kind, K::Scale);
  EXPECT_EQ(e.ops[2].vector, glm::vec3(1.0f, 1.5f, 1.0f));
  EXPECT_EQ(e.ops[3].kind, K::SetTransform);
  EXPECT_EQ(e.ops[3].matrix[3], glm::vec4(0.1f, 0.2f, 0.3f, 1.0f));  // column-major
  EXPECT_EQ(e.ops[4].kind, K::Hide);
  EXPECT_EQ(e.ops[5].kind, K::Show);
  EXPECT_EQ(e.ops[6].kind, K::LightColor);
  EXPECT_EQ(e.ops[6].vector, glm::vec3(0.5f, 0.25f, 1.0f));
  EXPECT_EQ(e.ops[7].kind, K::LightIntensity);
  EXPECT_EQ(e.ops[7].target, "#0");
  EXPECT_EQ(e.ops[7].value, 7.5f);
  EXPECT_EQ(e.ops[8].kind, K::MaterialAlbedo);
  EXPECT_EQ(e.ops[9].kind, K::MaterialEmission);
  EXPECT_EQ(e.ops[9].value, 3.0f);
  // A uniform scale and a single op without "ops".
  const SceneEdit single = parse_edit_json(R"({"op": "scale", "node": "floor", "by": 2})");
  ASSERT_EQ(single.ops.size(), 1u);
  EXPECT_EQ(single.ops[0].vector, glm::vec3(2.0f));
  // Through edit_to_json and back: the same edit.
  expect_same_ops(parse_edit_json(edit_to_json(e)), e);
  // And it is valid on the scene.
  EXPECT_EQ(validation_error(cornell_with_lamp(), e), "");
}

TEST(SceneEdit, ScriptStepsKeepTheirDelays) {
  const std::vector<EditStep> steps = parse_edit_script(R"([
    {"op": "hide", "node": "short_block"},
    {"after_ms": 250, "op": "show", "node": "short_block"},
    {"after_ms": 10, "ops": [{"op": "move", "node": "tall_block", "by": [0, 0.1, 0]}]}])");
  ASSERT_EQ(steps.size(), 3u);
  EXPECT_EQ(steps[0].after_ms, 0.0);
  EXPECT_EQ(steps[1].after_ms, 250.0);
  EXPECT_EQ(steps[1].edit.ops[0].kind, EditOp::Kind::Show);
  EXPECT_EQ(steps[2].edit.ops[0].vector, glm::vec3(0.0f, 0.1f, 0.0f));
  EXPECT_THROW(parse_edit_script(R"([{"after_ms": -1, "op": "hide", "node": "a"}])"), Error);
}

TEST(SceneEdit, WireFormRoundTripsEveryKind) {
  const SceneEdit e = parse_edit_json(kAllKinds);
  wire::SceneEdit m;
  m.set_token("t");
  wire::to_proto(e, &m);
  ASSERT_EQ(m.ops_size(), 10);
  EXPECT_EQ(m.ops(0).kind(), wire::EditOp::MOVE);
  EXPECT_EQ(m.ops(3).kind(), wire::EditOp::SET_TRANSFORM);
  EXPECT_EQ(m.ops(3).matrix_size(), 16);
  EXPECT_EQ(m.ops(0).matrix_size(), 0);  // only transforms carry a matrix
  EXPECT_EQ(m.ops(9).kind(), wire::EditOp::MATERIAL_EMISSION);
  EXPECT_EQ(m.token(), "t");  // left alone
  // Through the bytes too.
  wire::SceneEdit parsed;
  ASSERT_TRUE(parsed.ParseFromString(m.SerializeAsString()));
  expect_same_ops(wire::from_proto(parsed), e);
}

TEST(SceneEdit, WireFormRefusesUnknownKindsAndBadMatrices) {
  wire::SceneEdit m;
  wire::EditOp* o = m.add_ops();
  o->set_kind(static_cast<wire::EditOp::Kind>(42));
  o->set_target("floor");
  try {
    wire::from_proto(m);
    FAIL() << "an unknown kind was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown operation kind 42"), std::string::npos)
        << e.what();
  }
  o->set_kind(wire::EditOp::SET_TRANSFORM);
  for (int i = 0; i < 5; ++i) o->add_matrix(1.0f);
  try {
    wire::from_proto(m);
    FAIL() << "a 5-value matrix was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the matrix has 5 values"), std::string::npos) << e.what();
  }
}

TEST(SceneEdit, ValidationNamesTheProblem) {
  const Scene s = cornell_with_lamp();
  using K = EditOp::Kind;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  auto one = [](EditOp o) { return SceneEdit{{std::move(o)}}; };

  std::string m = validation_error(s, one(op(K::Move, "no_such_node", {1, 0, 0})));
  EXPECT_NE(m.find("no node 'no_such_node'"), std::string::npos) << m;
  EXPECT_NE(m.find("edit op 1 (move)"), std::string::npos) << m;

  m = validation_error(s, one(op(K::Move, "tall_block", {nan, 0, 0})));
  EXPECT_NE(m.find("not finite"), std::string::npos) << m;

  EditOp t = op(K::SetTransform, "tall_block");
  t.matrix[2][1] = nan;
  m = validation_error(s, one(t));
  EXPECT_NE(m.find("matrix has a non-finite entry"), std::string::npos) << m;

  m = validation_error(s, one(op(K::Rotate, "tall_block", {0, 0, 0}, 45.0f)));
  EXPECT_NE(m.find("rotation axis is zero"), std::string::npos) << m;

  m = validation_error(s, SceneEdit{});
  EXPECT_NE(m.find("no operations"), std::string::npos) << m;

  m = validation_error(s, one(op(K::LightIntensity, "no_lamp", {}, 1.0f)));
  EXPECT_NE(m.find("no light 'no_lamp'"), std::string::npos) << m;
  m = validation_error(s, one(op(K::MaterialAlbedo, "#99", {0.5f, 0.5f, 0.5f})));
  EXPECT_NE(m.find("no material '#99'"), std::string::npos) << m;

  // The position of the bad op among good ones.
  SceneEdit two{{op(K::Hide, "floor"), op(K::Scale, "tall_block", {1, 0, 1})}};
  m = validation_error(s, two);
  EXPECT_NE(m.find("edit op 2 (scale)"), std::string::npos) << m;

  // Bad JSON and bad ops in JSON.
  auto json_error = [](const std::string& text) {
    try {
      parse_edit_json(text);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  m = json_error(R"({"op": "move", "node": "tall_block", "by": [1, 2)");
  EXPECT_NE(m.find("edit JSON"), std::string::npos) << m;
  m = json_error(R"({"op": "teleport", "node": "tall_block"})");
  EXPECT_NE(m.find("unknown edit operation 'teleport'"), std::string::npos) << m;
  m = json_error(R"({"op": "move", "node": "tall_block", "by": [1, 2]})");
  EXPECT_NE(m.find("\"by\" must be an array of 3 numbers"), std::string::npos) << m;
  m = json_error(R"({"op": "move", "by": [1, 2, 3]})");
  EXPECT_NE(m.find("missing \"node\""), std::string::npos) << m;
  m = json_error(R"({"ops": []})");
  EXPECT_NE(m.find("no operations"), std::string::npos) << m;
}

TEST(SceneEdit, ApplyChangesExactlyTheNamedThing) {
  const Scene before = cornell_with_lamp();
  const int tall = node_index(before, "tall_block");
  const int shorter = node_index(before, "short_block");
  ASSERT_GE(tall, 0);
  ASSERT_GE(shorter, 0);
  using K = EditOp::Kind;

  {  // Move: only the tall block's transform, by exactly the offset.
    Scene s = before;
    const EditEffect fx = apply_edit(s, SceneEdit{{op(K::Move, "tall_block", {0.05f, 0, 0})}});
    EXPECT_EQ(fx.nodes, std::vector<int>{tall});
    EXPECT_TRUE(fx.lights.empty() && fx.materials.empty());
    glm::mat4 expected = before.nodes[tall].local;
    expected[3] += glm::vec4(0.05f, 0.0f, 0.0f, 0.0f);
    EXPECT_EQ(s.nodes[tall].local, expected);
    s.nodes[tall].local = before.nodes[tall].local;
    expect_same_scene(s, before);
  }
  {  // Hide: only the short block's visibility; visible_nodes follows it.
    Scene s = before;
    apply_edit(s, SceneEdit{{op(K::Hide, "short_block")}});
    EXPECT_FALSE(s.nodes[shorter].visible);
    EXPECT_FALSE(s.visible_nodes()[static_cast<std::size_t>(shorter)]);
    s.nodes[shorter].visible = true;
    expect_same_scene(s, before);
  }
  {  // Rotate about the node's origin keeps the origin.
    Scene s = before;
    s.nodes[tall].local[3] = glm::vec4(0.3f, 0.0f, 0.2f, 1.0f);
    apply_edit(s, SceneEdit{{op(K::Rotate, "tall_block", {0, 2, 0}, 90.0f)}});
    EXPECT_NEAR(s.nodes[tall].local[3].x, 0.3f, 1e-6f);
    EXPECT_NEAR(s.nodes[tall].local[3].z, 0.2f, 1e-6f);
    EXPECT_NEAR(s.nodes[tall].local[0].z, -1.0f, 1e-6f);  // x axis turned to -z
  }
  {  // Light and material ops.
    Scene s = before;
    const EditEffect fx =
        apply_edit(s, SceneEdit{{op(K::LightIntensity, "lamp", {}, 9.0f),
                                 op(K::MaterialEmission, "light", {1.0f, 0.5f, 0.25f}, 4.0f)}});
    EXPECT_EQ(fx.lights, std::vector<int>{0});
    ASSERT_EQ(fx.materials.size(), 1u);
    EXPECT_EQ(s.lights[0].intensity, 9.0f);
    const int light_material = fx.materials[0];
    EXPECT_EQ(s.materials[light_material].name, "light");
    EXPECT_EQ(s.materials[light_material].emissive, glm::vec3(1.0f, 0.5f, 0.25f));
    EXPECT_EQ(s.materials[light_material].emissive_strength, 4.0f);
    s.lights[0].intensity = before.lights[0].intensity;
    s.materials[light_material] = before.materials[light_material];
    expect_same_scene(s, before);
  }
  {  // An edit whose second op is bad changes nothing, not even the first op's node.
    Scene s = before;
    EXPECT_THROW(apply_edit(s, SceneEdit{{op(K::Move, "tall_block", {0.05f, 0, 0}),
                                          op(K::Hide, "no_such_node")}}),
                 Error);
    expect_same_scene(s, before);
  }
}

TEST(SceneEdit, ScenePackageKeepsVisibilityAndRevision) {
  Scene s = make_cornell_box();
  apply_edit(s, SceneEdit{{op(EditOp::Kind::Hide, "short_block"),
                           op(EditOp::Kind::Move, "tall_block", {0.05f, 0, 0})}});
  const World world = World::build(s);
  const Atlas atlas = build_atlas(world);
  const wire::ScenePackage pkg = wire::make_scene_package(s, atlas, 3);
  const wire::UnpackedScene u = wire::open_scene_package(pkg.bytes, pkg.hash);
  EXPECT_EQ(u.revision, 3u);
  expect_same_scene(u.scene, s);
  EXPECT_FALSE(u.scene.nodes[node_index(s, "short_block")].visible);
  // The revision is part of the package: another revision, another hash.
  EXPECT_NE(wire::make_scene_package(s, atlas, 4).hash, pkg.hash);
  EXPECT_EQ(wire::open_scene_package(wire::make_scene_package(s, atlas).bytes, "").revision, 0u);
}

TEST(SceneEdit, SkyOpsParseRoundTripAndApply) {
  const SceneEdit e = parse_edit_json(R"({"ops": [
    {"op": "sky", "color": [0.5, 0.75, 1.0]},
    {"op": "sky", "strength": 2.5},
    {"op": "sky", "file": "dusk.exr", "strength": 0.5}]})");
  ASSERT_EQ(e.ops.size(), 3u);
  EXPECT_EQ(e.ops[0].kind, EditOp::Kind::Sky);
  EXPECT_EQ(e.ops[0].sky_parts, unsigned{EditOp::kSkyColor});
  EXPECT_EQ(e.ops[0].vector, glm::vec3(0.5f, 0.75f, 1.0f));
  EXPECT_EQ(e.ops[1].sky_parts, unsigned{EditOp::kSkyStrength});
  EXPECT_EQ(e.ops[1].value, 2.5f);
  EXPECT_EQ(e.ops[2].sky_parts, unsigned{EditOp::kSkyFile | EditOp::kSkyStrength});
  EXPECT_EQ(e.ops[2].target, "dusk.exr");
  const SceneEdit back = parse_edit_json(edit_to_json(e));
  ASSERT_EQ(back.ops.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(back.ops[i].sky_parts, e.ops[i].sky_parts);
    EXPECT_EQ(back.ops[i].target, e.ops[i].target);
  }
  EXPECT_EQ(back.ops[0].vector, e.ops[0].vector);
  EXPECT_EQ(back.ops[2].value, 0.5f);

  // Colour and strength apply; a file needs its map (read by a server), so it is refused here.
  Scene s = cornell_with_lamp();
  SceneEdit colour;
  colour.ops = {e.ops[0], e.ops[1]};
  const EditEffect fx = apply_edit(s, colour);
  EXPECT_TRUE(fx.sky);
  EXPECT_FALSE(fx.empty());
  EXPECT_EQ(s.sky.color, glm::vec3(0.5f, 0.75f, 1.0f));
  EXPECT_EQ(s.sky.strength, 2.5f);
  SceneEdit file;
  file.ops = {e.ops[2]};
  EXPECT_NE(validation_error(s, file).find("was not read"), std::string::npos)
      << validation_error(s, file);
  file.ops[0].sky_map = std::make_shared<const ImageRGB>(4, 2, glm::vec3(3.0f));
  apply_edit(s, file);
  EXPECT_EQ(s.sky.map.width, 4);
  EXPECT_EQ(s.sky.source, "dusk.exr");
  EXPECT_EQ(s.sky.strength, 0.5f);
  EXPECT_EQ(s.sky.radiance(glm::vec3(0, 1, 0)), glm::vec3(1.5f));
  // A colour drops the map again.
  apply_edit(s, colour);
  EXPECT_EQ(s.sky.map.width, 0);
  EXPECT_EQ(s.sky.source, "");
}

TEST(SceneEdit, SkyOpWireFormCarriesTheMap) {
  SceneEdit e = parse_edit_json(R"({"op": "sky", "file": "a.exr", "strength": 3})");
  ImageRGB map(32, 16);
  for (std::size_t i = 0; i < map.pixels.size(); ++i)
    map.pixels[i] = glm::vec3(0.125f * static_cast<float>(i % 16), 0.5f, 2.0f);  // exact in RGB9E5
  e.ops[0].sky_map = std::make_shared<const ImageRGB>(map);
  wire::SceneEdit m;
  wire::to_proto(e, &m);
  EXPECT_EQ(m.ops(0).kind(), wire::EditOp::SKY);
  wire::SceneEdit parsed;
  ASSERT_TRUE(parsed.ParseFromString(m.SerializeAsString()));
  const SceneEdit back = wire::from_proto(parsed);
  ASSERT_EQ(back.ops.size(), 1u);
  EXPECT_EQ(back.ops[0].sky_parts, e.ops[0].sky_parts);
  EXPECT_EQ(back.ops[0].target, "a.exr");
  EXPECT_EQ(back.ops[0].value, 3.0f);
  ASSERT_TRUE(back.ops[0].sky_map);
  EXPECT_EQ(back.ops[0].sky_map->pixels, map.pixels);
  // A corrupt map is refused with the op's position.
  parsed.mutable_ops(0)->mutable_sky_map()->set_data("xx");
  try {
    wire::from_proto(parsed);
    FAIL() << "a corrupt sky map was accepted";
  } catch (const Error& err) {
    EXPECT_NE(std::string(err.what()).find("edit op 1"), std::string::npos) << err.what();
  }
}

TEST(SceneEdit, BadSkyOpsAreRefusedWithTheReason) {
  const Scene s = cornell_with_lamp();
  auto error_of = [&](const char* json) {
    try {
      return validation_error(s, parse_edit_json(json));
    } catch (const Error& err) {
      return std::string(err.what());
    }
  };
  EXPECT_NE(error_of(R"({"op": "sky"})").find("needs \"color\", \"strength\" or \"file\""),
            std::string::npos);
  EXPECT_NE(error_of(R"({"op": "sky", "color": [1, -1, 0]})").find("negative"), std::string::npos);
  EXPECT_NE(error_of(R"({"op": "sky", "strength": -2})").find("sky strength is negative"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"op": "sky", "strength": 1e7})").find("beyond"), std::string::npos);
  EXPECT_NE(error_of(R"({"op": "sky", "color": [1, 1, 1], "file": "a.exr"})").find("together"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"op": "sky", "file": ""})").find("\"file\" must be"), std::string::npos);
  EXPECT_NE(error_of(R"({"op": "sky", "color": 3})").find("array of 3"), std::string::npos);
  // Parts from the wire that no JSON makes: none, or unknown bits.
  SceneEdit e;
  e.ops.emplace_back().kind = EditOp::Kind::Sky;
  EXPECT_NE(validation_error(s, e).find("set the sky's colour, strength or file"),
            std::string::npos);
  e.ops[0].sky_parts = 8;
  EXPECT_NE(validation_error(s, e).find("parts 8"), std::string::npos);
  // A map with a NaN texel (only in-process code could build one: the wire carries RGB9E5).
  e.ops[0].sky_parts = EditOp::kSkyFile;
  e.ops[0].target = "n.exr";
  ImageRGB bad(2, 2, glm::vec3(1.0f));
  bad.pixels[3].y = std::numeric_limits<float>::quiet_NaN();
  e.ops[0].sky_map = std::make_shared<const ImageRGB>(bad);
  EXPECT_NE(validation_error(s, e).find("not finite"), std::string::npos) << validation_error(s, e);
}

}  // namespace irradcast::test_scene_edit

// Scene edits as JSON (scene_edit.h): one edit, its ops, and edit scripts. Checked by
// validate_edit() as any edit is; here only their shape and numbers.
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "irradcast/common/error.h"
#include "irradcast/common/scene_edit.h"

namespace irradcast {

namespace {

using Json = nlohmann::json;
using Kind = EditOp::Kind;

glm::vec3 vec3_of(const Json& j, const std::string& where, const char* key) {
  if (!j.is_array() || j.size() != 3)
    throw Error(where + ": \"" + key + "\" must be an array of 3 numbers");
  glm::vec3 v;
  for (int i = 0; i < 3; ++i) {
    if (!j[static_cast<std::size_t>(i)].is_number())
      throw Error(where + ": \"" + key + "\" must be an array of 3 numbers");
    v[i] = j[static_cast<std::size_t>(i)].get<float>();
  }
  return v;
}

float number_of(const Json& j, const std::string& where, const char* key) {
  if (!j.is_number()) throw Error(where + ": \"" + key + "\" must be a number");
  return j.get<float>();
}

const Json& need(const Json& op, const std::string& where, const char* key) {
  auto it = op.find(key);
  if (it == op.end()) throw Error(where + ": missing \"" + key + "\"");
  return *it;
}

// {"op": "sky"} with any of "color" or "file" (not both) and "strength".
EditOp sky_op_from_json(const Json& j, const std::string& where) {
  EditOp op;
  op.kind = Kind::Sky;
  if (j.contains("color")) {
    op.vector = vec3_of(j["color"], where, "color");
    op.sky_parts |= EditOp::kSkyColor;
  }
  if (j.contains("strength")) {
    op.value = number_of(j["strength"], where, "strength");
    op.sky_parts |= EditOp::kSkyStrength;
  }
  if (j.contains("file")) {
    if (!j["file"].is_string() || j["file"].get<std::string>().empty())
      throw Error(where +
                  ": \"file\" must be the name of a sky map (.exr) in the server's sky folder");
    op.target = j["file"].get<std::string>();
    op.sky_parts |= EditOp::kSkyFile;
  }
  if (op.sky_parts == 0)
    throw Error(where + ": a sky op needs \"color\", \"strength\" or \"file\"");
  return op;
}

EditOp op_from_json(const Json& j, const std::string& where) {
  if (!j.is_object()) throw Error(where + ": an operation must be a JSON object");
  if (!j.contains("op") || !j["op"].is_string())
    throw Error(where +
                ": missing \"op\" (move, rotate, scale, transform, show, hide, "
                "light_color, light_intensity, albedo, emission, sky)");
  EditOp op;
  op.kind = parse_edit_kind(j["op"].get<std::string>());
  if (op.kind == Kind::Sky) return sky_op_from_json(j, where);
  const char* key = edit_target_name(op.kind);
  const Json& t = need(j, where, key);
  if (t.is_string())
    op.target = t.get<std::string>();
  else if (t.is_number_unsigned())
    // Appended rather than `"#" + std::to_string(...)`: GCC 12 at -O3 sees an overlap in the
    // inlined insert at 0 of that form (-Werror=restrict, GCC bug 105329).
    op.target = std::string("#").append(std::to_string(t.get<unsigned>()));
  else
    throw Error(where + ": \"" + key + "\" must be a name or an index");
  switch (op.kind) {
    case Kind::Move:
      op.vector = vec3_of(need(j, where, "by"), where, "by");
      break;
    case Kind::Rotate:
      op.vector = vec3_of(need(j, where, "axis"), where, "axis");
      op.value = number_of(need(j, where, "degrees"), where, "degrees");
      break;
    case Kind::Scale: {
      const Json& by = need(j, where, "by");
      op.vector = by.is_number() ? glm::vec3(number_of(by, where, "by")) : vec3_of(by, where, "by");
      break;
    }
    case Kind::SetTransform: {
      const Json& m = need(j, where, "matrix");
      if (!m.is_array() || m.size() != 16)
        throw Error(where + ": \"matrix\" must be 16 numbers, column-major");
      for (int i = 0; i < 16; ++i) {
        if (!m[static_cast<std::size_t>(i)].is_number())
          throw Error(where + ": \"matrix\" must be 16 numbers, column-major");
        op.matrix[i / 4][i % 4] = m[static_cast<std::size_t>(i)].get<float>();
      }
      break;
    }
    case Kind::Show:
    case Kind::Hide:
      break;
    case Kind::LightColor:
    case Kind::MaterialAlbedo:
      op.vector = vec3_of(need(j, where, "color"), where, "color");
      break;
    case Kind::LightIntensity:
      op.value = number_of(need(j, where, "intensity"), where, "intensity");
      break;
    case Kind::MaterialEmission:
      op.vector = vec3_of(need(j, where, "color"), where, "color");
      op.value = j.contains("strength") ? number_of(j["strength"], where, "strength") : 1.0f;
      break;
    case Kind::Sky:
      break;
  }
  return op;
}

Json op_to_json(const EditOp& op) {
  Json j;
  j["op"] = edit_kind_name(op.kind);
  auto vec = [](glm::vec3 v) { return Json::array({v.x, v.y, v.z}); };
  if (op.kind == Kind::Sky) {
    if (op.sky_parts & EditOp::kSkyColor) j["color"] = vec(op.vector);
    if (op.sky_parts & EditOp::kSkyFile) j["file"] = op.target;
    if (op.sky_parts & EditOp::kSkyStrength) j["strength"] = op.value;
    return j;
  }
  j[edit_target_name(op.kind)] = op.target;
  switch (op.kind) {
    case Kind::Move:
    case Kind::Scale:
      j["by"] = vec(op.vector);
      break;
    case Kind::Rotate:
      j["axis"] = vec(op.vector);
      j["degrees"] = op.value;
      break;
    case Kind::SetTransform: {
      Json m = Json::array();
      for (int i = 0; i < 16; ++i) m.push_back(op.matrix[i / 4][i % 4]);
      j["matrix"] = m;
      break;
    }
    case Kind::LightColor:
    case Kind::MaterialAlbedo:
      j["color"] = vec(op.vector);
      break;
    case Kind::LightIntensity:
      j["intensity"] = op.value;
      break;
    case Kind::MaterialEmission:
      j["color"] = vec(op.vector);
      j["strength"] = op.value;
      break;
    case Kind::Show:
    case Kind::Hide:
    case Kind::Sky:
      break;  // the target is all (the sky: written above)
  }
  return j;
}

SceneEdit edit_from_json(const Json& j, const std::string& where) {
  SceneEdit edit;
  if (j.is_object() && j.contains("ops")) {
    const Json& ops = j["ops"];
    if (!ops.is_array()) throw Error(where + ": \"ops\" must be an array");
    for (std::size_t i = 0; i < ops.size(); ++i)
      edit.ops.push_back(op_from_json(ops[i], where + " op " + std::to_string(i + 1)));
  } else {
    edit.ops.push_back(op_from_json(j, where));
  }
  if (edit.ops.empty()) throw Error(where + ": no operations");
  return edit;
}

Json parse_json(std::string_view text) {
  try {
    return Json::parse(text);
  } catch (const Json::parse_error& e) {
    throw Error(std::string("edit JSON: ") + e.what());
  }
}

}  // namespace

SceneEdit parse_edit_json(std::string_view text) {
  return edit_from_json(parse_json(text), "edit");
}

std::string edit_to_json(const SceneEdit& edit) {
  Json ops = Json::array();
  for (const EditOp& op : edit.ops) ops.push_back(op_to_json(op));
  Json j;
  j["ops"] = ops;
  return j.dump();
}

std::vector<EditStep> parse_edit_script(std::string_view text) {
  const Json j = parse_json(text);
  std::vector<EditStep> steps;
  auto step = [&](const Json& s, const std::string& where) {
    EditStep e;
    if (s.is_object() && s.contains("after_ms")) {
      e.after_ms = number_of(s["after_ms"], where, "after_ms");
      if (!(e.after_ms >= 0.0) || !std::isfinite(e.after_ms))
        throw Error(where + ": \"after_ms\" must be a finite number >= 0");
    }
    e.edit = edit_from_json(s, where);
    steps.push_back(std::move(e));
  };
  if (j.is_array()) {
    for (std::size_t i = 0; i < j.size(); ++i) step(j[i], "script step " + std::to_string(i + 1));
  } else {
    step(j, "script");
  }
  if (steps.empty()) throw Error("edit script: no steps");
  return steps;
}

}  // namespace irradcast

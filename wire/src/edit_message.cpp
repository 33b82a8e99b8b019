#include "irradcast/wire/edit_message.h"

#include <memory>
#include <string>

#include "irradcast/common/error.h"
#include "irradcast/wire/sky_message.h"

namespace irradcast::wire {
namespace {

using Kind = irradcast::EditOp::Kind;

struct KindPair {
  Kind kind;
  EditOp::Kind wire;
};
constexpr KindPair kKinds[] = {
    {Kind::Move, EditOp::MOVE},
    {Kind::Rotate, EditOp::ROTATE},
    {Kind::Scale, EditOp::SCALE},
    {Kind::SetTransform, EditOp::SET_TRANSFORM},
    {Kind::Show, EditOp::SHOW},
    {Kind::Hide, EditOp::HIDE},
    {Kind::LightColor, EditOp::LIGHT_COLOR},
    {Kind::LightIntensity, EditOp::LIGHT_INTENSITY},
    {Kind::MaterialAlbedo, EditOp::MATERIAL_ALBEDO},
    {Kind::MaterialEmission, EditOp::MATERIAL_EMISSION},
    {Kind::Sky, EditOp::SKY},
};

}  // namespace

void to_proto(const irradcast::SceneEdit& edit, SceneEdit* out) {
  out->clear_ops();
  for (const irradcast::EditOp& op : edit.ops) {
    EditOp* o = out->add_ops();
    for (const KindPair& k : kKinds)
      if (k.kind == op.kind) o->set_kind(k.wire);
    o->set_target(op.target);
    o->mutable_vector()->set_x(op.vector.x);
    o->mutable_vector()->set_y(op.vector.y);
    o->mutable_vector()->set_z(op.vector.z);
    o->set_value(op.value);
    if (op.kind == Kind::SetTransform)
      for (int i = 0; i < 16; ++i) o->add_matrix(op.matrix[i / 4][i % 4]);
    if (op.kind == Kind::Sky) {
      o->set_sky_parts(op.sky_parts);
      if (op.sky_map) sky_map_to_proto(*op.sky_map, o->mutable_sky_map());
    }
  }
}

irradcast::SceneEdit from_proto(const SceneEdit& msg) {
  irradcast::SceneEdit edit;
  for (int i = 0; i < msg.ops_size(); ++i) {
    const EditOp& o = msg.ops(i);
    const std::string where = "edit op " + std::to_string(i + 1);
    irradcast::EditOp op;
    bool known = false;
    for (const KindPair& k : kKinds)
      if (k.wire == o.kind()) {
        op.kind = k.kind;
        known = true;
      }
    if (!known)
      throw irradcast::Error(where + ": unknown operation kind " + std::to_string(o.kind()));
    op.target = o.target();
    op.vector = glm::vec3(o.vector().x(), o.vector().y(), o.vector().z());
    op.value = o.value();
    if (o.matrix_size() != 0 && o.matrix_size() != 16)
      throw irradcast::Error(where + ": the matrix has " + std::to_string(o.matrix_size()) +
                             " values (16 expected, column-major)");
    if (o.matrix_size() == 16)
      for (int j = 0; j < 16; ++j) op.matrix[j / 4][j % 4] = o.matrix(j);
    if (op.kind == Kind::Sky) {
      op.sky_parts = o.sky_parts();
      if (o.has_sky_map())
        op.sky_map = std::make_shared<const ImageRGB>(sky_map_from_proto(o.sky_map(), where));
    }
    edit.ops.push_back(std::move(op));
  }
  return edit;
}

}  // namespace irradcast::wire

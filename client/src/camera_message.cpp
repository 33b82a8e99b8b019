#include "irradcast/client/camera_message.h"

namespace irradcast {

wire::Envelope camera_update(const CameraPose& c) {
  wire::Envelope e;
  wire::CameraUpdate* u = e.mutable_camera_update();
  auto set = [](wire::Vec3* v, glm::vec3 x) {
    v->set_x(x.x);
    v->set_y(x.y);
    v->set_z(x.z);
  };
  set(u->mutable_eye(), c.eye);
  set(u->mutable_forward(), c.forward);
  set(u->mutable_up(), c.up);
  u->set_yfov(c.yfov);
  return e;
}

}  // namespace irradcast

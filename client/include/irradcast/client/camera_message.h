// The CameraUpdate frame a client sends for a pose (viewer and simulated users alike).
#pragma once

#include "irradcast.pb.h"
#include "irradcast/common/world.h"

namespace irradcast {

wire::Envelope camera_update(const CameraPose& pose);

}  // namespace irradcast

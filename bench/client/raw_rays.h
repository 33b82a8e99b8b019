// The client bench's `raw` row: the compositor's primary rays (one through each pixel centre,
// PinholeRays) straight through Embree's rtcIntersect16 in coherent 4 x 4 pixel packets, tiles
// of packets in parallel, no shading and no image: the floor a compositor on the same Embree
// scene can approach.
#pragma once

#include <cstdint>

#include "irradcast/common/world.h"

struct RTCSceneTy;

namespace irradcast::bench {

// The number of pixels whose ray hits (so that the work cannot be optimised away).
std::uint64_t trace_raw_primary(RTCSceneTy* scene, const CameraPose& camera, int width, int height);

}  // namespace irradcast::bench

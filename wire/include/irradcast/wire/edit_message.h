// Scene edits on the wire (docs/PROTOCOL.md, "Scene edits"): irradcast::SceneEdit (the model of
// scene_edit.h) to and from the SceneEdit message's operations.
#pragma once

#include "irradcast.pb.h"
#include "irradcast/common/scene_edit.h"

namespace irradcast::wire {

// Writes the operations of `edit` into `out` (replacing its ops; the other fields are left as
// they are). A sky op's map goes at most 1024 x 512 (sky_message.h: viewers' backgrounds).
void to_proto(const irradcast::SceneEdit& edit, SceneEdit* out);
// The operations of `msg`. Throws irradcast::Error on an unknown kind, a matrix that is not 0
// or 16 values or a bad sky map (the contents are checked against a scene by validate_edit, not
// here).
irradcast::SceneEdit from_proto(const SceneEdit& msg);

}  // namespace irradcast::wire

// The client's optional frame passes (seed 002), in order: the frame's G-buffer and lightmap
// lookup (trace_frame), screen-space ambient occlusion (ssao.h) on the lightmap term, and the
// reverse-reprojection cache (reprojection.h) that reuses converged SSAO while the camera moves.
// Stateful across frames (the history); with every pass off, compose() gives exactly
// irradcast::compose()'s image.
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast/client/reprojection.h"
#include "irradcast/client/ssao.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/dynamic_view.h"
#include "irradcast/common/image.h"
#include "irradcast/common/lightmap.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct ClientPassOptions {
  bool ssao = false;
  SsaoParams ssao_params;
  bool reproject = false;  // needs ssao: the history holds the SSAO result
  ReprojectionParams reprojection;

  // Throws irradcast::Error naming the bad value (or --reproject without --ssao).
  void validate() const;
};

struct ClientFrameStats {
  double trace_s = 0.0;      // primary rays + lightmap lookup
  double reproject_s = 0.0;  // history lookups and blending
  double ssao_s = 0.0;
  double resolve_s = 0.0;
  double total_s = 0.0;
  std::size_t ssao_pixels = 0;  // pixels whose SSAO was estimated this frame
  std::size_t forgotten = 0;    // history pixels forgotten because a dynamic object moved
  ReprojectionStats reprojection;
};

class ClientPasses {
 public:
  explicit ClientPasses(ClientPassOptions options = {});
  // The next frame. Linear radiance like irradcast::compose(); with `dynamic`, the dynamic
  // objects drawn too (dynamic_view.h). SSAO sees them (contact shadows), and where one moved
  // (its transform or visibility changed) since the last frame, the history of what it covers
  // and shadows (its old and new boxes grown by the SSAO radius) is forgotten, so a moving
  // object leaves no ghost; past 64 moved objects at once the whole history goes.
  ImageRGB compose(const World& world, const RayScene& rays, const Atlas& atlas,
                   const std::vector<Lightmap>& lightmaps, const CameraPose& camera, int width,
                   int height, ClientFrameStats* stats = nullptr,
                   const DynamicView* dynamic = nullptr);
  // Forget the history (a camera cut, an edit of the static scene; a dynamic object's move needs
  // no reset).
  void reset();
  const ClientPassOptions& options() const { return options_; }
  // The SSAO visibility of the last frame (empty without --ssao).
  const std::vector<float>& visibility() const { return visibility_; }

 private:
  ClientPassOptions options_;
  ReprojectionCache cache_;
  std::vector<float> visibility_;
  std::vector<std::uint8_t> compute_;
  std::uint32_t frame_ = 0;
  // Per world object, a dynamic one's pose at the last frame and its box there.
  struct DynamicState {
    bool known = false;
    bool visible = false;
    glm::mat4 transform{1.0f};
    Bounds box;
  };
  std::vector<DynamicState> dynamic_state_;
  static constexpr std::size_t kMaxForgetRegions = 64;
  // The old and new boxes (grown by `margin`) of the dynamic objects whose transform or
  // visibility changed since the last frame; updates dynamic_state_.
  std::vector<Bounds> moved_dynamic_objects(const World& world, float margin);
};

}  // namespace irradcast

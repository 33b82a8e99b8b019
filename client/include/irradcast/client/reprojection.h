// Seed 002's reverse-reprojection cache (Nehab et al.): a screen-sized history of the previous
// frame (world position and an accumulated per-pixel value, here the SSAO visibility, with the
// number of frames accumulated). Each frame, every pixel's world position W_t is projected with
// the previous camera (Eq. 1); the history is fetched bilinearly from the neighbours whose stored
// position W_{t-1} lies within epsilon of W_t (Eqs. 2-3; none: disoccluded, recomputed from
// scratch). A pixel with `converge_frames` accumulated is converged and reused without
// recomputation; otherwise one more estimate, with the pattern turned, is blended in with the
// confidence of Eqs. 4-5. Randomly ordered, non-repeating 64 x 64 tiles are refreshed (fully
// recomputed) each frame, against the blur of repeated bilinear resampling and stale values.
// The history only holds shading that depends on the static scene and the viewpoint; the
// lightmap term is always looked up anew (the seed's "current direct lighting").
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast/client/frame_gbuffer.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct ReprojectionParams {
  // Disocclusion tolerance of Eq. 3 as a fraction of the largest extent of the scene's bounds
  // (the seed illustrates 0.1 and 0.01 in unstated units).
  float epsilon = 0.01f;
  // Eq. 4's bias (user-chosen in the seed): the least weight the history keeps is
  // bias / (1 + bias).
  float confidence_bias = 0.25f;
  // Frames accumulated (pattern rotations) after which a pixel counts as converged and is
  // reused without recomputation (the seed's user-set rotation cap).
  int converge_frames = 4;
  // Fraction of the screen's tiles recomputed from scratch each frame (at least one tile when
  // positive; 0 = no refresh), and the tile size (seed 002: 64 x 64 for SSAO).
  float refresh = 1.0f / 32.0f;
  int tile = 64;
  std::uint64_t seed = 1;  // order of the refreshed tiles

  // Throws irradcast::Error naming the parameter and its value when out of range.
  void validate() const;
};

// What happened to the frame's pixels (hit pixels only; misses are never cached).
struct ReprojectionStats {
  std::size_t pixels = 0;
  std::size_t reused = 0;       // converged: cached value reused, nothing computed
  std::size_t accumulated = 0;  // reprojected, one more estimate blended in
  std::size_t disoccluded = 0;  // no history (first frame, newly visible): computed from scratch
  std::size_t refreshed = 0;    // in a refresh tile: computed from scratch
  std::size_t computed() const { return accumulated + disoccluded + refreshed; }
  double reused_fraction() const {
    return pixels ? static_cast<double>(reused) / static_cast<double>(pixels) : 0.0;
  }
};

class ReprojectionCache {
 public:
  explicit ReprojectionCache(ReprojectionParams params = {});

  // Step 1 for frame `g`: reprojects the history and decides per pixel. `compute[i]` != 0 marks
  // the pixels whose value must be estimated this frame (fill them, then call resolve()).
  // `world_epsilon` is the tolerance in world units.
  void reproject(const FrameGBuffer& g, float world_epsilon, std::vector<std::uint8_t>& compute,
                 ReprojectionStats* stats = nullptr);
  // Step 2: `current` holds this frame's estimates at the pixels reproject() marked. Blends them
  // with the reprojected history (Eqs. 4-5), writes the result into `current` for every pixel
  // and keeps it, with g's positions and camera, as the history for the next frame.
  void resolve(const FrameGBuffer& g, std::vector<float>& current);

  // Forgets the history: the next frame is computed from scratch.
  void clear();
  // Forgets the history of the points inside any of `regions` (world space): what a moved
  // dynamic object covered or shadowed is computed from scratch in the next frame. Returns the
  // number of history pixels forgotten.
  std::size_t forget(const std::vector<Bounds>& regions);
  const ReprojectionParams& params() const { return params_; }
  std::uint64_t frames() const { return frame_; }

 private:
  struct History {
    int width = 0, height = 0;
    ScreenProjection projection;
    std::vector<glm::vec3> position;
    std::vector<float> value;
    std::vector<std::uint8_t> count;  // frames accumulated; 0 = no value (miss)
    // Eqs. 1-3: the value at world point w seen by the previous camera, bilinear over the
    // history pixels that stored the same surface point (within eps2, squared); the weight is
    // 0 where none did. `frames`: the fewest frames accumulated among them.
    struct Sample {
      float value = 0.0f, weight = 0.0f;
      int frames = 255;
    };
    Sample sample(const glm::vec3& w, float eps2) const;
  };
  std::vector<int> refresh_tiles(int width, int height);

  ReprojectionParams params_;
  History history_;
  // This frame's reprojected history, between reproject() and resolve().
  std::vector<float> reprojected_;
  std::vector<std::uint8_t> reprojected_count_;
  // Non-repeating random tile order; position in it.
  std::vector<int> tile_order_;
  std::size_t tile_next_ = 0;
  std::uint64_t frame_ = 0;
};

}  // namespace irradcast

// Screen-space ambient occlusion of a client frame: contact shadows finer than a lightmap texel.
// A blocker search in the pixel's screen neighbourhood (seed 003 §8.3.9: march in 4 orthogonal
// directions, 4 samples each), with seed 002's occlusion term n . pq / |pq| (Eq. 6) and samples
// spaced near * (far / near)^(i / m) along each direction (Eq. 8). Each direction counts its
// highest attenuated term (a horizon search, as HBAO [Bavoil], which seed 002 cites), and the
// visibility is 1 - strength * mean over the directions. The pattern is turned per pixel by a
// hashed angle and jitter (seed 002's random 2-D vector texture) and by 10 degrees per frame
// (§3.2.2). Geometry-aware: samples on misses, farther than the world-space radius (a depth
// discontinuity) or below the tangent plane do not occlude, and a smooth window 1 - d^2 / R^2
// takes a sample's weight to zero at the radius (seed 002's attenuation against artifacts at
// object borders; its D(d) = 1 + a d + b d^2 has no stated a, b and no cut-off).
#pragma once

#include <cstdint>
#include <vector>

#include "irradcast/client/frame_gbuffer.h"
#include "irradcast/common/world.h"

namespace irradcast {

struct SsaoParams {
  // World-space search radius as a fraction of the largest extent of the scene's bounds
  // (irradcast-view --ssao-radius); the seeds state no radius.
  float radius = 0.04f;
  // Scales the occlusion: visibility = clamp(1 - strength * occlusion, 0, 1) (--ssao-strength).
  float strength = 1.0f;
  int directions = 4;  // seed 003
  int steps = 4;       // samples per direction, seed 003
  // Innermost sample distance as a fraction of the radius in pixels (Eq. 8's near / far), and
  // the largest screen radius searched (a close-up surface would otherwise scan the screen).
  float near_fraction = 0.1f;
  float max_radius_px = 64.0f;
  // Angle bias: n . pq below this cosine does not occlude (tessellated curved surfaces).
  float cos_bias = 0.1f;

  // Throws irradcast::Error naming the parameter and its value when out of range.
  void validate() const;
  // The radius in world units for a scene with these bounds.
  float world_radius(const Bounds& bounds) const { return radius * bounds.max_extent(); }
};

// Per pixel the ambient visibility in [0, 1] (1 = nothing occludes; misses get 1). `frame`
// turns the pattern (10 degrees and a jitter step per frame); `which`, when given, limits the
// work to pixels with which[i] != 0 and leaves the others of `out` unchanged. Returns the number
// of pixels computed.
std::size_t ssao(const FrameGBuffer& g, const SsaoParams& params, float world_radius,
                 std::uint32_t frame, std::vector<float>& out,
                 const std::vector<std::uint8_t>* which = nullptr);

}  // namespace irradcast

// The gap fill of a lightmap (dilate(), gbuffer.h) worked out once from the texel kinds, which
// change only with the geometry: which texels each ring fills and from which of their
// 8-neighbours. Applying a plan is then a pass per ring over a list, the same arithmetic in the
// same order as dilate() (which applies a plan made for the call), so the engine fills its
// lightmaps every bounce without searching the gutters again, and a device can run the same
// lists (5 bytes per filled texel: its index and a mask of its sources).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "irradcast/engine/gbuffer.h"

namespace irradcast {

class DilationPlan {
 public:
  DilationPlan() = default;
  // The plan for a width x height lightmap whose texels holding estimates `valid` marks
  // (holds_estimate), `rings` rings at most (-1: until every reachable texel is filled).
  // Throws irradcast::Error when valid's size is not width x height.
  DilationPlan(int width, int height, const std::vector<TexelKind>& valid, int rings = -1);

  // Fills the plan's texels of `texels` (width x height values, in place); bit for bit what
  // dilate() makes of the same values.
  void apply(std::vector<glm::vec3>& texels) const;

  int width() const { return width_; }
  int height() const { return height_; }
  std::size_t rings() const { return ring_end_.size(); }
  // Ring r fills target()[k] for k in [ring_begin(r), ring_end(r)).
  std::uint32_t ring_begin(std::size_t r) const { return r == 0 ? 0 : ring_end_[r - 1]; }
  std::uint32_t ring_end(std::size_t r) const { return ring_end_[r]; }
  const std::vector<std::uint32_t>& target() const { return target_; }
  // Per target: bit b set where neighbour b (row by row over the 3 x 3 block, the centre left
  // out: b = 0..7) was filled before its ring; the sources are read in that order.
  const std::vector<std::uint8_t>& sources() const { return sources_; }

 private:
  int width_ = 0, height_ = 0;
  std::vector<std::uint32_t> target_;
  std::vector<std::uint8_t> sources_;
  std::vector<std::uint32_t> ring_end_;
};

}  // namespace irradcast

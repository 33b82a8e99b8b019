#include "irradcast/client/ssao.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>

#include "float_text.h"
#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

namespace {

constexpr float kTwoPi = 6.28318530717958647692f;
constexpr float kRotationPerFrame = 10.0f * kTwoPi / 360.0f;  // seed 002 §3.2.2
constexpr float kGolden = 0.61803398875f;

}  // namespace

void SsaoParams::validate() const {
  if (!(radius > 0.0f && radius <= 1.0f))
    throw Error("ssao radius " + float_text(radius) +
                " must be in (0, 1] (a fraction of the scene's largest extent)");
  if (!(strength >= 0.0f && strength <= 10.0f))
    throw Error("ssao strength " + float_text(strength) + " must be in [0, 10]");
  if (directions < 1 || directions > 16)
    throw Error("ssao directions " + std::to_string(directions) + " must be in [1, 16]");
  if (steps < 1 || steps > 16)
    throw Error("ssao steps " + std::to_string(steps) + " must be in [1, 16]");
  if (!(near_fraction > 0.0f && near_fraction <= 1.0f))
    throw Error("ssao near fraction " + float_text(near_fraction) + " must be in (0, 1]");
  if (!(max_radius_px >= 1.0f))
    throw Error("ssao max radius " + float_text(max_radius_px) + " px must be at least 1");
  if (!(cos_bias >= 0.0f && cos_bias < 1.0f))
    throw Error("ssao cosine bias " + float_text(cos_bias) + " must be in [0, 1)");
}

namespace {

// One direction's occlusion at pixel i (position P, normal N, centre cx, cy): march outwards
// over the distances dist_px; the highest attenuated horizon.
struct HorizonMarch {
  const FrameGBuffer& g;
  int steps;
  float inv_r2, cos_bias, bias_scale;

  float operator()(std::size_t i, const glm::vec3& P, const glm::vec3& N, float cx, float cy,
                   float dx, float dy, const float* dist_px) const {
    float horizon = 0.0f;
    for (int s = 0; s < steps; ++s) {
      const int qx = static_cast<int>(std::floor(cx + dx * dist_px[s]));
      const int qy = static_cast<int>(std::floor(cy + dy * dist_px[s]));
      if (qx < 0 || qy < 0 || qx >= g.width || qy >= g.height) continue;
      const std::size_t q = g.index(qx, qy);
      if (q == i || !g.hit(q)) continue;
      const glm::vec3 v = g.position[q] - P;
      const float d2 = glm::dot(v, v);
      const float window = 1.0f - d2 * inv_r2;  // 0 at the radius: depth discontinuity
      if (window <= 0.0f || d2 <= 0.0f) continue;
      const float c = glm::dot(N, v) / std::sqrt(d2);
      if (c <= cos_bias) continue;
      horizon = std::max(horizon, (c - cos_bias) * bias_scale * window);
    }
    return horizon;
  }
};

}  // namespace

std::size_t ssao(const FrameGBuffer& g, const SsaoParams& p, float world_radius,
                 std::uint32_t frame, std::vector<float>& out,
                 const std::vector<std::uint8_t>* which) {
  p.validate();
  if (!(world_radius > 0.0f))
    throw Error("ssao: world radius " + float_text(world_radius) + " <= 0");
  if (which && which->size() != g.size())
    throw Error("ssao: mask has " + std::to_string(which->size()) + " entries for " +
                std::to_string(g.size()) + " pixels");
  if (out.size() != g.size()) out.assign(g.size(), 1.0f);
  const float inv_r2 = 1.0f / (world_radius * world_radius);
  const float inv_k = 1.0f / static_cast<float>(p.directions);
  const float bias_scale = 1.0f / (1.0f - p.cos_bias);
  const float dir_step = kTwoPi / static_cast<float>(p.directions);
  const float rot_c = std::cos(dir_step), rot_s = std::sin(dir_step);
  const float frame_angle = kRotationPerFrame * static_cast<float>(frame % 36u);
  const float frame_jitter = kGolden * static_cast<float>(frame % 64u);
  const HorizonMarch march{g, p.steps, inv_r2, p.cos_bias, bias_scale};
  std::atomic<std::size_t> computed{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, g.height, 4), [&](const tbb::blocked_range<int>& r) {
    std::size_t local = 0;
    for (int y = r.begin(); y < r.end(); ++y)
      for (int x = 0; x < g.width; ++x) {
        const std::size_t i = g.index(x, y);
        if (which && !(*which)[i]) continue;
        ++local;
        if (!g.hit(i)) {
          out[i] = 1.0f;
          continue;
        }
        // The radius on screen at this depth; below a pixel there is nothing to find.
        const float far_px =
            std::min(world_radius * g.projection.pixels_per_unit(g.depth[i]), p.max_radius_px);
        if (far_px < 1.0f) {
          out[i] = 1.0f;
          continue;
        }
        const float near_px = std::max(1.0f, far_px * p.near_fraction);
        const float log_span = std::log(far_px / near_px);
        // Per-pixel rotation and jitter from a hash (the random 2-D vector texture).
        const std::uint64_t h =
            mix64((static_cast<std::uint64_t>(y) << 32) | static_cast<std::uint32_t>(x));
        const float pixel_angle = dir_step * static_cast<float>(h & 0xffffff) * 0x1p-24f;
        float jitter = static_cast<float>((h >> 24) & 0xffffff) * 0x1p-24f + frame_jitter;
        jitter -= std::floor(jitter);
        const glm::vec3 P = g.position[i], N = g.normal[i];
        const float cx = static_cast<float>(x) + 0.5f, cy = static_cast<float>(y) + 0.5f;
        // Eq. 8 with a jittered index, the same distances in every direction:
        // S_s = near * (far / near)^((s - jitter) / m).
        float dist_px[16];
        const float step_ratio = std::exp(log_span / static_cast<float>(p.steps));
        dist_px[0] = near_px * std::exp(log_span * (1.0f - jitter) / static_cast<float>(p.steps));
        for (int s = 1; s < p.steps; ++s) dist_px[s] = dist_px[s - 1] * step_ratio;
        const float a0 = pixel_angle + frame_angle;
        float dx = std::cos(a0), dy = std::sin(a0);
        float occlusion = 0.0f;
        for (int d = 0; d < p.directions; ++d) {
          occlusion += march(i, P, N, cx, cy, dx, dy, dist_px);
          const float ndx = dx * rot_c - dy * rot_s;  // the next direction
          dy = dx * rot_s + dy * rot_c;
          dx = ndx;
        }
        out[i] = std::clamp(1.0f - p.strength * occlusion * inv_k, 0.0f, 1.0f);
      }
    computed += local;
  });
  return computed.load();
}

}  // namespace irradcast

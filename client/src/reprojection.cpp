#include "irradcast/client/reprojection.h"

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

void ReprojectionParams::validate() const {
  if (!(epsilon > 0.0f && epsilon <= 1.0f))
    throw Error("reprojection epsilon " + float_text(epsilon) +
                " must be in (0, 1] (a fraction of the scene's largest extent)");
  if (!(confidence_bias > 0.0f && confidence_bias <= 100.0f))
    throw Error("reprojection confidence bias " + float_text(confidence_bias) +
                " must be in (0, 100]");
  if (converge_frames < 1 || converge_frames > 250)
    throw Error("reprojection converge frames " + std::to_string(converge_frames) +
                " must be in [1, 250]");
  if (!(refresh >= 0.0f && refresh <= 1.0f))
    throw Error("reprojection refresh " + float_text(refresh) + " must be in [0, 1]");
  if (tile < 1 || tile > 4096)
    throw Error("reprojection tile " + std::to_string(tile) + " px must be in [1, 4096]");
}

ReprojectionCache::ReprojectionCache(ReprojectionParams params) : params_(params) {
  params_.validate();
}

void ReprojectionCache::clear() {
  history_ = History{};
  tile_order_.clear();
  tile_next_ = 0;
}

std::size_t ReprojectionCache::forget(const std::vector<Bounds>& regions) {
  if (regions.empty()) return 0;
  std::atomic<std::size_t> forgotten{0};
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, history_.count.size(), 4096),
      [&](const tbb::blocked_range<std::size_t>& r) {
        std::size_t local = 0;
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
          if (history_.count[i] == 0) continue;
          const glm::vec3 p = history_.position[i];
          for (const Bounds& b : regions)
            if (glm::all(glm::greaterThanEqual(p, b.lo)) && glm::all(glm::lessThanEqual(p, b.hi))) {
              history_.count[i] = 0;
              ++local;
              break;
            }
        }
        forgotten += local;
      });
  return forgotten;
}

std::vector<int> ReprojectionCache::refresh_tiles(int width, int height) {
  const int tx = (width + params_.tile - 1) / params_.tile;
  const int ty = (height + params_.tile - 1) / params_.tile;
  const int count = tx * ty;
  std::vector<int> out;
  if (params_.refresh <= 0.0f) return out;
  const int want = std::clamp(
      static_cast<int>(std::lround(params_.refresh * static_cast<float>(count))), 1, count);
  if (static_cast<int>(tile_order_.size()) != count) {
    tile_order_.clear();
    tile_next_ = 0;
  }
  Rng rng(params_.seed, frame_);
  for (int k = 0; k < want; ++k) {
    if (tile_next_ >= tile_order_.size()) {
      // A new random permutation: every tile once per round, in random order.
      tile_order_.resize(static_cast<std::size_t>(count));
      for (int i = 0; i < count; ++i) tile_order_[static_cast<std::size_t>(i)] = i;
      for (int i = count - 1; i > 0; --i)
        std::swap(tile_order_[static_cast<std::size_t>(i)],
                  tile_order_[rng.next_u32() % static_cast<std::uint32_t>(i + 1)]);
      tile_next_ = 0;
    }
    out.push_back(tile_order_[tile_next_++]);
  }
  return out;
}

ReprojectionCache::History::Sample ReprojectionCache::History::sample(const glm::vec3& w,
                                                                      float eps2) const {
  Sample out;
  // Eq. 1: the current world position seen by the previous camera.
  const glm::vec3 s = projection.project(w);
  if (!(s.z > 0.0f)) return out;
  const float fx = s.x - 0.5f, fy = s.y - 0.5f;
  const float x0f = std::floor(fx), y0f = std::floor(fy);
  const float ax = fx - x0f, ay = fy - y0f;
  const int x0 = static_cast<int>(x0f), y0 = static_cast<int>(y0f);
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      const int hx = x0 + dx, hy = y0 + dy;
      if (hx < 0 || hy < 0 || hx >= width || hy >= height) continue;
      const std::size_t j = static_cast<std::size_t>(hy) * width + hx;
      const std::uint8_t c = count[j];
      if (c == 0) continue;
      // Eqs. 2-3: the stored position must be the same surface point (within eps).
      const glm::vec3 d = position[j] - w;
      if (glm::dot(d, d) > eps2) continue;
      const float wt = 1e-4f + (dx ? ax : 1.0f - ax) * (dy ? ay : 1.0f - ay);
      out.weight += wt;
      out.value += wt * value[j];
      out.frames = std::min<int>(out.frames, c);
    }
  return out;
}

void ReprojectionCache::reproject(const FrameGBuffer& g, float world_epsilon,
                                  std::vector<std::uint8_t>& compute, ReprojectionStats* stats) {
  if (!(world_epsilon > 0.0f))
    throw Error("reprojection: world epsilon " + float_text(world_epsilon) + " must be positive");
  const std::size_t n = g.size();
  compute.assign(n, 0);
  reprojected_.assign(n, 1.0f);
  reprojected_count_.assign(n, 0);
  const bool have_history =
      history_.width == g.width && history_.height == g.height && history_.position.size() == n;
  const int tiles_x = (g.width + params_.tile - 1) / params_.tile;
  std::vector<std::uint8_t> refresh(
      static_cast<std::size_t>(tiles_x) *
          static_cast<std::size_t>((g.height + params_.tile - 1) / params_.tile),
      0);
  if (have_history)
    for (int t : refresh_tiles(g.width, g.height)) refresh[static_cast<std::size_t>(t)] = 1;
  const float eps2 = world_epsilon * world_epsilon;
  const int converged = params_.converge_frames;
  std::atomic<std::size_t> pixels{0}, reused{0}, accumulated{0}, disoccluded{0}, refreshed{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, g.height, 8), [&](const tbb::blocked_range<int>& r) {
    std::size_t c_pix = 0, c_reu = 0, c_acc = 0, c_dis = 0, c_ref = 0;
    for (int y = r.begin(); y < r.end(); ++y)
      for (int x = 0; x < g.width; ++x) {
        const std::size_t i = g.index(x, y);
        if (!g.hit(i)) continue;
        ++c_pix;
        if (!have_history) {
          compute[i] = 1;
          ++c_dis;
          continue;
        }
        if (refresh[static_cast<std::size_t>(y / params_.tile) * tiles_x + x / params_.tile]) {
          compute[i] = 1;
          ++c_ref;
          continue;
        }
        const History::Sample h = history_.sample(g.position[i], eps2);
        if (h.weight <= 0.0f) {
          compute[i] = 1;
          ++c_dis;
          continue;
        }
        reprojected_[i] = h.value / h.weight;
        reprojected_count_[i] = static_cast<std::uint8_t>(h.frames);
        if (h.frames >= converged) {
          ++c_reu;
        } else {
          compute[i] = 1;
          ++c_acc;
        }
      }
    pixels += c_pix;
    reused += c_reu;
    accumulated += c_acc;
    disoccluded += c_dis;
    refreshed += c_ref;
  });
  if (stats) {
    stats->pixels = pixels;
    stats->reused = reused;
    stats->accumulated = accumulated;
    stats->disoccluded = disoccluded;
    stats->refreshed = refreshed;
  }
}

void ReprojectionCache::resolve(const FrameGBuffer& g, std::vector<float>& current) {
  const std::size_t n = g.size();
  if (current.size() != n || reprojected_.size() != n)
    throw Error("reprojection: resolve() without a matching reproject() (" +
                std::to_string(current.size()) + " values for " + std::to_string(n) + " pixels)");
  const float inv_bias = 1.0f / (1.0f + params_.confidence_bias);
  const int converged = params_.converge_frames;
  std::vector<std::uint8_t> count(n, 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
          if (!g.hit(i)) {
            current[i] = 1.0f;
            continue;
          }
          const int c = reprojected_count_[i];
          const float h = reprojected_[i];
          if (c >= converged) {  // reused as it is
            current[i] = h;
            count[i] = static_cast<std::uint8_t>(c);
          } else if (c == 0) {  // from scratch
            count[i] = 1;
          } else {
            // Eq. 4: confidence = 1 - saturate(|V_{t-1} - V_t|) / (1 + bias);
            // Eq. 5: V = confidence V_{t-1} + (1 - confidence) V_t. The new
            // estimate keeps at least a running mean's weight 1 / (c + 1), so
            // the value converges to the mean over the turned patterns.
            const float diff = std::min(std::abs(h - current[i]), 1.0f);
            const float conf = 1.0f - diff * inv_bias;
            const float w_new = std::max(1.0f - conf, 1.0f / static_cast<float>(c + 1));
            current[i] = (1.0f - w_new) * h + w_new * current[i];
            count[i] = static_cast<std::uint8_t>(c + 1);
          }
        }
      });
  history_.width = g.width;
  history_.height = g.height;
  history_.projection = g.projection;
  history_.position = g.position;
  history_.value = current;
  history_.count = std::move(count);
  ++frame_;
}

}  // namespace irradcast

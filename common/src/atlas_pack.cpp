// Lightmap atlas: packing generated charts into one object's lightmap. Shelf packing (tallest
// first, charts turned landscape, `gutter` empty texels between charts and along the border),
// each chart centred in a block of whole texels; when the result exceeds max_lightmap_size the
// density drops (bisection in log space) until it fits, or to one texel per chart.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "atlas_internal.h"
#include "irradcast/common/log.h"

namespace irradcast::atlas_detail {
namespace {

struct Placement {
  int x = 0, y = 0;      // lower corner of the chart's cell block
  int cw = 1, ch = 1;    // cells before rotation
  bool rotated = false;  // rotated by +90 degrees
};

struct Packing {
  int width = 0, height = 0;
  std::vector<Placement> place;
};

int cells(float extent_texels) {
  // At least 0.01 texel of slack on each side, at least one texel.
  double c = std::floor(static_cast<double>(extent_texels) + 0.02) + 1.0;
  return static_cast<int>(std::clamp(c, 1.0, 1e9));
}

// Shelf packing, tallest first, charts turned landscape, `gutter` empty texels between charts and
// along the border. Tries a few shelf widths and keeps the most square result.
Packing pack(const std::vector<Chart>& charts, float density, int gutter) {
  const std::size_t m = charts.size();
  std::vector<Placement> place(m);
  double area = 0.0;
  int widest = 0;
  for (std::size_t i = 0; i < m; ++i) {
    Placement& p = place[i];
    p.cw = cells(charts[i].extent.x * density);
    p.ch = cells(charts[i].extent.y * density);
    p.rotated = p.ch > p.cw;
    int w = (p.rotated ? p.ch : p.cw) + gutter;
    int h = (p.rotated ? p.cw : p.ch) + gutter;
    area += static_cast<double>(w) * h;
    widest = std::max(widest, w);
  }
  std::vector<std::uint32_t> order(m);
  std::iota(order.begin(), order.end(), 0u);
  auto hw = [&](std::uint32_t i) {
    const Placement& p = place[i];
    return p.rotated ? std::pair(p.cw, p.ch) : std::pair(p.ch, p.cw);
  };
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    auto ha = hw(a), hb = hw(b);
    if (ha != hb) return ha > hb;
    return a < b;
  });
  Packing best;
  long best_side = std::numeric_limits<long>::max();
  double best_area = 0.0;
  for (double f : {0.9, 1.0, 1.1, 1.25, 1.5}) {
    long shelf = std::max<long>(widest, static_cast<long>(std::ceil(std::sqrt(area) * f)));
    long x = gutter, y = gutter, shelf_h = 0, used_w = gutter;
    std::vector<Placement> trial = place;
    for (std::uint32_t i : order) {
      auto [h, w] = hw(i);
      h += gutter;
      w += gutter;
      if (x + w > gutter + shelf && x > gutter) {
        y += shelf_h;
        x = gutter;
        shelf_h = 0;
      }
      trial[i].x = static_cast<int>(x);
      trial[i].y = static_cast<int>(y);
      x += w;
      shelf_h = std::max<long>(shelf_h, h);
      used_w = std::max(used_w, x);
    }
    long width = used_w, height = y + shelf_h;
    long side = std::max(width, height);
    double a = static_cast<double>(width) * height;
    if (side < best_side || (side == best_side && a < best_area)) {
      best_side = side;
      best_area = a;
      best.width = static_cast<int>(std::min<long>(width, std::numeric_limits<int>::max()));
      best.height = static_cast<int>(std::min<long>(height, std::numeric_limits<int>::max()));
      best.place = std::move(trial);
    }
  }
  return best;
}

bool fits_cap(const Packing& p, int cap) {
  return p.width <= cap && p.height <= cap;
}

// The packing at base_density if it fits in cap x cap texels, else at the largest density that
// fits (or, if none does, at one texel per chart, with a warning). Sets *density to the one used.
Packing fit_packing(const ChartSet& cs, std::size_t oi, float base_density, int gutter, int cap,
                    float* density) {
  *density = base_density;
  Packing packing = pack(cs.charts, *density, gutter);
  if (fits_cap(packing, cap)) return packing;
  float max_extent = 0.0f;
  for (const Chart& ch : cs.charts) max_extent = std::max({max_extent, ch.extent.x, ch.extent.y});
  // Below this density every chart is a single cell: the smallest packing there is.
  float floor_density = max_extent > 0.0f ? 0.5f / max_extent : base_density;
  floor_density = std::min(floor_density, base_density);
  Packing smallest = pack(cs.charts, floor_density, gutter);
  if (!fits_cap(smallest, cap)) {
    log::warn("atlas", "object " + std::to_string(oi) + ": " + std::to_string(cs.charts.size()) +
                           " charts do not fit in " + std::to_string(cap) + "x" +
                           std::to_string(cap) + " texels even at one texel each; using " +
                           std::to_string(smallest.width) + "x" + std::to_string(smallest.height));
    *density = floor_density;
    return smallest;
  }
  // Largest density that fits: bisection in log space between floor (fits) and base.
  double lo = std::log(floor_density), hi = std::log(base_density);
  Packing best = std::move(smallest);
  double guess = std::log(base_density) +
                 std::log(static_cast<double>(cap) / std::max(packing.width, packing.height));
  if (guess > lo && guess < hi) {
    Packing p = pack(cs.charts, static_cast<float>(std::exp(guess)), gutter);
    if (fits_cap(p, cap))
      lo = guess, best = std::move(p);
    else
      hi = guess;
  }
  for (int it = 0; it < 16 && hi - lo > 1e-3; ++it) {
    double mid = 0.5 * (lo + hi);
    Packing p = pack(cs.charts, static_cast<float>(std::exp(mid)), gutter);
    if (fits_cap(p, cap))
      lo = mid, best = std::move(p);
    else
      hi = mid;
  }
  *density = static_cast<float>(std::exp(lo));
  return best;
}

// Lightmap coordinates of every triangle corner: chart uv scaled, centred in its cell block,
// rotated if the chart was, moved to the block's place.
void place_corners(const ChartSet& cs, const Packing& packing, float density, std::size_t n,
                   ObjectLightmap& lm) {
  lm.corner_uv.resize(3 * n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t t = r.begin(); t < r.end(); ++t) {
                        std::uint32_t ci = lm.triangle_chart[t];
                        const Placement& p = packing.place[ci];
                        glm::vec2 ext = cs.charts[ci].extent * density;
                        glm::vec2 off = 0.5f * (glm::vec2(p.cw, p.ch) - ext);
                        for (int j = 0; j < 3; ++j) {
                          glm::vec2 q = cs.uv[3 * t + j] * density + off;
                          if (p.rotated) q = glm::vec2(static_cast<float>(p.ch) - q.y, q.x);
                          lm.corner_uv[3 * t + j] = q + glm::vec2(p.x, p.y);
                        }
                      }
                    });
}

}  // namespace

void build_generated(const World& world, std::size_t oi, const AtlasOptions& options,
                     float base_density, ObjectLightmap& lm) {
  const WorldObject& wo = world.objects[oi];
  const std::size_t n = wo.triangles().size();
  const auto t0 = std::chrono::steady_clock::now();
  ChartSet cs = make_charts(wo, options);
  const auto t1 = std::chrono::steady_clock::now();
  const int gutter = std::max(0, options.gutter);
  const int cap = std::max(1, options.max_lightmap_size);
  float density = base_density;
  const Packing packing = fit_packing(cs, oi, base_density, gutter, cap, &density);

  lm.width = packing.width;
  lm.height = packing.height;
  lm.texels_per_unit = density;
  lm.chart_count = static_cast<int>(cs.charts.size());
  lm.from_file_uv1 = false;
  lm.triangle_chart = std::move(cs.tri_chart);
  place_corners(cs, packing, density, n, lm);
  if (log::level() <= log::Level::Debug) {
    const auto t2 = std::chrono::steady_clock::now();
    double used = 0.0;
    for (const Placement& p : packing.place) used += static_cast<double>(p.cw) * p.ch;
    auto ms = [](auto a, auto b) {
      return std::to_string(std::chrono::duration<double, std::milli>(b - a).count());
    };
    log::debug("atlas",
               "object " + std::to_string(oi) + ": " + std::to_string(n) + " triangles, " +
                   std::to_string(cs.charts.size()) + " charts, " + std::to_string(lm.width) + "x" +
                   std::to_string(lm.height) + " at " + std::to_string(density) +
                   " texels/unit, chart cells " +
                   std::to_string(100.0 * used / std::max(1.0, 1.0 * lm.width * lm.height)) +
                   "% of the map; charts " + ms(t0, t1) + " ms, packing " + ms(t1, t2) + " ms");
  }
}

}  // namespace irradcast::atlas_detail

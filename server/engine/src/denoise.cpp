// The lightmap denoiser (denoise.h): per a-trous iteration a hash grid over the world positions
// of that iteration's texels, then one cross-bilateral pass per texel over those within its
// radius; at the end the confidence test against each texel's own mean.
#include "irradcast/engine/denoise.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <unordered_map>

#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

DenoiseGuide denoise_guide(const SurfaceTexels& texels, const Atlas& atlas,
                           const std::vector<TexelGBuffer>& gbuffers) {
  DenoiseGuide g;
  // Scene-wide chart ids: each object's charts after those of the objects before it.
  std::vector<std::uint32_t> first(atlas.objects.size() + 1, 0);
  g.texel_size.resize(atlas.objects.size(), 0.0f);
  g.width.resize(atlas.objects.size(), 1);
  for (std::size_t o = 0; o < atlas.objects.size(); ++o) {
    const ObjectLightmap& m = atlas.objects[o];
    first[o + 1] = first[o] + static_cast<std::uint32_t>(std::max(m.chart_count, 1));
    g.texel_size[o] = m.texels_per_unit > 0.0f ? 1.0f / m.texels_per_unit : 0.0f;
    g.width[o] = std::max(m.width, 1);
  }
  g.chart.resize(texels.size());
  for (std::size_t i = 0; i < texels.size(); ++i) {
    const std::uint32_t o = texels.object[i];
    const std::int32_t t = gbuffers[o].triangle[texels.texel[i]];
    const auto& charts = atlas.objects[o].triangle_chart;
    const std::uint32_t c = t >= 0 && static_cast<std::size_t>(t) < charts.size() ? charts[t] : 0;
    g.chart[i] = first[o] + c;
  }
  return g;
}

namespace {

// Texels bucketed by a cubic cell of their world position.
class TexelGrid {
 public:
  TexelGrid(const std::vector<glm::vec3>& position, const std::vector<std::uint32_t>& members,
            float cell)
      : inv_cell_(1.0f / cell) {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed(members.size());
    for (std::size_t k = 0; k < members.size(); ++k)
      keyed[k] = {key(cell_of(position[members[k]])), members[k]};
    std::sort(keyed.begin(), keyed.end());
    order_.resize(keyed.size());
    for (std::size_t k = 0; k < keyed.size(); ++k) {
      order_[k] = keyed[k].second;
      if (k == 0 || keyed[k].first != keyed[k - 1].first)
        cells_.emplace(keyed[k].first, std::pair<std::uint32_t, std::uint32_t>(k, k));
      cells_[keyed[k].first].second = static_cast<std::uint32_t>(k + 1);
    }
  }

  glm::ivec3 cell_of(glm::vec3 p) const { return glm::ivec3(glm::floor(p * inv_cell_)); }

  // Calls f(texel) for every texel in the cells that overlap the box [p - r, p + r].
  template <class F>
  void for_each_near(glm::vec3 p, float r, F&& f) const {
    const glm::ivec3 lo = cell_of(p - glm::vec3(r)), hi = cell_of(p + glm::vec3(r));
    for (int z = lo.z; z <= hi.z; ++z)
      for (int y = lo.y; y <= hi.y; ++y)
        for (int x = lo.x; x <= hi.x; ++x) {
          auto it = cells_.find(key(glm::ivec3(x, y, z)));
          if (it == cells_.end()) continue;
          for (std::uint32_t k = it->second.first; k < it->second.second; ++k) f(order_[k]);
        }
  }

 private:
  static std::uint64_t key(glm::ivec3 c) {
    const auto part = [](int v) { return static_cast<std::uint64_t>(v + (1 << 20)) & 0x1FFFFF; };
    return part(c.x) | part(c.y) << 21 | part(c.z) << 42;
  }

  float inv_cell_;
  std::vector<std::uint32_t> order_;
  std::unordered_map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> cells_;
};

// What one iteration reads and writes.
struct Pass {
  const SurfaceTexels& texels;
  const DenoiseGuide& guide;
  const DenoiseOptions& o;
  const std::vector<float>& radius;         // per texel, iteration 0
  const std::vector<std::uint32_t>& known;  // texels with a noise estimate
  int step = 1;                             // 2^iteration
  const std::vector<glm::vec3>* value = nullptr;
  const std::vector<float>* var = nullptr;  // of *value, per texel
  std::vector<glm::vec3>* out_value = nullptr;
  std::vector<float>* out_var = nullptr;
  // Iteration 0 only: the original standard errors, pooled over the geometric weights, and
  // whether a neighbour from another chart counted.
  std::vector<float>* pooled = nullptr;
  std::vector<std::uint8_t>* seam = nullptr;
};

// The texels of an iteration: all known ones at step 1, else those on the lattice of every
// step-th row and column of their lightmap.
std::vector<std::uint32_t> lattice(const Pass& p) {
  if (p.step == 1) return p.known;
  std::vector<std::uint32_t> m;
  for (std::uint32_t q : p.known) {
    const int w = p.guide.width[p.texels.object[q]];
    const auto t = static_cast<int>(p.texels.texel[q]);
    if ((t % w) % p.step == 0 && (t / w) % p.step == 0) m.push_back(q);
  }
  return m;
}

void run_pass(const Pass& p) {
  const std::vector<std::uint32_t> members = lattice(p);
  if (members.empty()) {
    *p.out_value = *p.value;
    *p.out_var = *p.var;
    return;
  }
  // Cells of the median radius: a texel scans the cells its own radius overlaps.
  std::vector<float> radii(members.size());
  for (std::size_t k = 0; k < members.size(); ++k) radii[k] = p.radius[members[k]] * p.step;
  std::nth_element(radii.begin(), radii.begin() + radii.size() / 2, radii.end());
  const TexelGrid grid(p.texels.position, members, radii[radii.size() / 2]);
  const std::vector<glm::vec3>& v = *p.value;
  const std::vector<float>& var = *p.var;
  const DenoiseOptions& o = p.o;
  const float k2 = o.range_sigmas * o.range_sigmas;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, p.known.size(), 256), [&](const auto& range) {
        for (std::size_t k = range.begin(); k < range.end(); ++k) {
          const std::uint32_t i = p.known[k];
          const glm::vec3 xi = p.texels.position[i], ni = p.texels.normal[i];
          const float r = p.radius[i] * p.step, hi = p.guide.texel_size[p.texels.object[i]];
          const float li = luminance(v[i]);
          const float inv_s2 = 2.0f / (r * r);  // spatial Gaussian, sigma r / 2
          // The texel itself, weight 1.
          glm::dvec3 sum = glm::dvec3(v[i]);
          double wsum = 1.0, w2var = var[i];
          double pooled = var[i], geo = 1.0;
          bool seam = false;
          grid.for_each_near(xi, r, [&](std::uint32_t q) {
            if (q == i) return;
            const glm::vec3 d = p.texels.position[q] - xi;
            const float d2 = glm::dot(d, d);
            if (d2 > r * r) return;
            const glm::vec3 nq = p.texels.normal[q];
            if (glm::dot(ni, nq) < o.normal_cos) return;
            const float plane =
                o.plane * p.step * std::max(hi, p.guide.texel_size[p.texels.object[q]]);
            if (std::abs(glm::dot(ni, d)) > plane || std::abs(glm::dot(nq, d)) > plane) return;
            const float ws = std::exp(-d2 * inv_s2);
            const float dl = luminance(v[q]) - li;
            const float wr = std::exp(-0.5f * dl * dl / (k2 * (var[i] + var[q])));
            const double w = static_cast<double>(ws) * wr;
            sum += w * glm::dvec3(v[q]);
            wsum += w;
            w2var += w * w * var[q];
            pooled += static_cast<double>(ws) * var[q];
            geo += ws;
            if (w > 1e-3 && p.guide.chart[q] != p.guide.chart[i]) seam = true;
          });
          (*p.out_value)[i] = glm::vec3(sum / wsum);
          (*p.out_var)[i] = static_cast<float>(w2var / (wsum * wsum));
          if (p.pooled) (*p.pooled)[i] = static_cast<float>(std::sqrt(pooled / geo));
          if (p.seam) (*p.seam)[i] = seam;
        }
      });
}

}  // namespace

std::vector<glm::vec3> denoise(const SurfaceTexels& texels, const DenoiseGuide& guide,
                               const std::vector<glm::vec3>& value,
                               const std::vector<float>& standard_error, const DenoiseOptions& o,
                               DenoiseStats* stats) {
  const std::size_t n = texels.size();
  if (value.size() != n || standard_error.size() != n || guide.chart.size() != n ||
      texels.normal.size() != n || texels.object.size() != n || texels.texel.size() != n ||
      guide.width.size() != guide.texel_size.size())
    throw Error("denoise: " + std::to_string(n) + " texels, " + std::to_string(value.size()) +
                " values, " + std::to_string(standard_error.size()) + " standard errors, " +
                std::to_string(guide.chart.size()) + " charts");
  std::vector<float> radius(n, 0.0f), var(n);
  std::vector<std::uint32_t> known;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t obj = texels.object[i];
    if (obj >= guide.texel_size.size() || guide.width[obj] < 1)
      throw Error("denoise: texel of an unknown object");
    radius[i] = o.radius * guide.texel_size[obj];
    var[i] = standard_error[i] * standard_error[i];
    if (standard_error[i] > 0.0f && radius[i] > 0.0f)
      known.push_back(static_cast<std::uint32_t>(i));
  }
  DenoiseStats st;
  st.unknown = n - known.size();
  std::vector<glm::vec3> cur = value, next = value;
  std::vector<float> next_var = var, pooled(n, 0.0f);
  std::vector<std::uint8_t> seam(n, 0);
  for (int it = 0; it < o.iterations && !known.empty(); ++it) {
    Pass p{texels, guide, o, radius, known, 1 << it, &cur, &var, &next, &next_var};
    if (it == 0) {
      p.pooled = &pooled;
      p.seam = &seam;
    }
    run_pass(p);
    std::swap(cur, next);
    std::swap(var, next_var);
  }
  // The confidence test against each texel's own mean.
  std::vector<glm::vec3> out = value;
  for (std::uint32_t i : known) {
    if (std::abs(luminance(cur[i]) - luminance(value[i])) > o.confidence * pooled[i]) {
      ++st.kept;
      continue;
    }
    out[i] = cur[i];
    ++st.filtered;
    st.seams += seam[i];
  }
  if (stats) *stats = st;
  return out;
}

}  // namespace irradcast

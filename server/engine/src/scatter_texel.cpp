#include "scatter_texel.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "irradcast/common/sampling.h"

namespace irradcast::embree_sampling {

struct ScatterTexel::Texel {
  glm::vec3 p, ng;
  Frame frame{glm::vec3(0.0f, 0.0f, 1.0f)};
  Rng rng;   // the ray directions
  Rng pick;  // the probe choices: a stream of its own, so that the directions do not depend on
             // which rays missed
  float range = 0.0f;
  bool probes = false;
  bool weighed = false;  // `weights` and `sums` set: at its first miss that reads a probe
  ProbeWeights weights;  // its probes (when it reads them)
  // The running sums of its probe weights as pick_probe forms them (the unused ones +inf), and
  // whether they never fall (weights >= 0, as CellsMethod makes them).
  float sums[7];
  bool sums_rise = false;
};

namespace {

using Batch = ScatterTexel::Batch;
constexpr std::size_t kAhead = 4;  // how many texels ahead run() requests a texel's data

// The hit's lightmap coordinates, with the two lightmap rows its bilinear lookup reads requested
// from memory (a hint: it changes no result).
glm::vec2 prefetch_radiance(const RadianceField& f, const Hit& h) {
  const glm::vec2 uv = f.atlas->objects[h.object].uv(h.triangle, h.u, h.v);
  const Lightmap& m = (*f.irradiance)[h.object];
  const int x = std::clamp(static_cast<int>(uv.x - 0.5f), 0, m.width - 1);
  const int y = std::clamp(static_cast<int>(uv.y - 0.5f), 0, m.height - 1);
  const glm::vec3* row = m.texels.data() + static_cast<std::size_t>(y) * m.width + x;
  __builtin_prefetch(row);
  if (y + 1 < m.height) __builtin_prefetch(row + m.width);
  return uv;
}

// pick_probe without a branch on u: the first k whose running sum of weights exceeds u, else
// the last (the same sums, in the same order).
int pick_probe_flat(const ProbeWeights& w, float u) {
  float acc = 0.0f;
  const int count = w.count();
  int k = count - 1;
  bool found = false;
  for (int j = 0; j + 1 < count; ++j) {
    acc += w.weight[j];
    const bool here = !found && u < acc;
    k = here ? j : k;
    found = found || here;
  }
  return k;
}

}  // namespace

// The misses of batch b that go on past the tracing range inside the scene read one probe each
// (ScatterMiss::operator(), step by step over arrays): which misses do, their picks in ray order,
// the direction to the picked probe and its octahedral coordinates four at a time, the lookups.
void ScatterTexel::shade_misses(std::uint32_t i, Texel& t, Batch& b) const {
  const ScatterMiss& miss = *miss_;
  const RayBatch& r = b.rays;
  const int m = r.count;
  const glm::vec3 p = t.p;
  Rng& pick = t.pick;
  for (int s = 0; s < m; ++s) {
    float e = 3.4e38f;
    e = exit_axis(e, miss.lo_.x, miss.hi_.x, p.x, r.dx[s]);
    e = exit_axis(e, miss.lo_.y, miss.hi_.y, p.y, r.dy[s]);
    e = exit_axis(e, miss.lo_.z, miss.hi_.z, p.z, r.dz[s]);
    b.exit[s] = std::max(e, 0.0f);
  }
  // The misses that read a probe (operator() returns zero where the ray left the scene).
  int idx[kBatch];
  int k = 0;
  for (int s = 0; s < m; ++s) {
    idx[k] = s;
    k += !r.hit[s].valid() && !(b.exit[s] <= miss.range_);
  }
  // The picks, in ray order (pick_probe's result: with running sums that never fall, the count
  // of those at or below u).
  if (k == 0) return;
  if (!t.weighed) weigh(i, t);
  alignas(16) float u[kBatch];
  alignas(16) int which[kBatch];
  for (int j = 0; j < k; ++j) u[j] = pick.next_float();
  const ProbeWeights& w = t.weights;
  if (t.sums_rise) {
    for (int j = 0; j < k; ++j) {
      int c = 0;
      for (int q = 0; q < 7; ++q) c += u[j] >= t.sums[q];
      which[j] = c;
    }
  } else {
    for (int j = 0; j < k; ++j) which[j] = pick_probe_flat(w, u[j]);
  }
  const std::vector<glm::vec3>& position = in_->probes.position;
  alignas(16) float tx[kBatch], ty[kBatch], tz[kBatch];
  std::uint32_t probe[kBatch];
  for (int j = 0; j < k; ++j) {
    const int s = idx[j];
    probe[j] = w.probe(which[j], in_->probes.dims);
    const glm::vec3 d(r.dx[s], r.dy[s], r.dz[s]);
    const glm::vec3 q = miss.fixed_ ? p + miss.extent_ * d : p + b.exit[s] * d;
    const glm::vec3 to = q - position[probe[j]];
    tx[j] = to.x;
    ty[j] = to.y;
    tz[j] = to.z;
  }
  // to / |to|, then octahedral_encode of it: the same operations in the same order, as arrays.
  alignas(16) float ex[kBatch], ey[kBatch];
  alignas(16) int valid[kBatch];
  for (int j = 0; j < k; ++j) {
    const float len = std::sqrt(tx[j] * tx[j] + ty[j] * ty[j] + tz[j] * tz[j]);
    valid[j] = len > 0.0f;
    float x = tx[j] / len, y = ty[j] / len, z = tz[j] / len;
    const float l1 = std::fabs(x) + std::fabs(y) + std::fabs(z);
    x /= l1;
    y /= l1;
    z /= l1;
    const float fx = (1.0f - std::fabs(y)) * (x >= 0.0f ? 1.0f : -1.0f);
    const float fy = (1.0f - std::fabs(x)) * (y >= 0.0f ? 1.0f : -1.0f);
    // (A zero-length direction reads nothing: its coordinates are kept finite for the lookups.)
    ex[j] = valid[j] ? 0.5f * (z < 0.0f ? fx : x) + 0.5f : 0.5f;
    ey[j] = valid[j] ? 0.5f * (z < 0.0f ? fy : y) + 0.5f : 0.5f;
  }
  probe_lookups(k, idx, probe, ex, ey, valid, b);
}

// sample_probe_at for each of the k misses (probe[j] at octahedral coordinates ex[j], ey[j];
// zero where !valid[j]) into b.radiance[idx[j]]: its texel coordinates and weights four at a
// time, then the four taps and their blend.
void ScatterTexel::probe_lookups(int k, const int* idx, const std::uint32_t* probe, const float* ex,
                                 const float* ey, const int* valid, Batch& b) const {
  const int res = in_->probes.resolution;
  const float fres = static_cast<float>(res);
  alignas(16) float ax[kBatch], ay[kBatch];
  alignas(16) int x0[kBatch], x1[kBatch], y0[kBatch], y1[kBatch];
  for (int j = 0; j < k; ++j) {
    const float uvx = ex[j] * fres - 0.5f, uvy = ey[j] * fres - 0.5f;
    // floor() as truncation, one lower where that rounded up (exact: |uv| < 2^31).
    const int tx = static_cast<int>(uvx), ty = static_cast<int>(uvy);
    const int fx = tx - (uvx < static_cast<float>(tx)), fy = ty - (uvy < static_cast<float>(ty));
    ax[j] = uvx - static_cast<float>(fx);
    ay[j] = uvy - static_cast<float>(fy);
    x0[j] = std::clamp(fx, 0, res - 1);
    x1[j] = std::clamp(fx + 1, 0, res - 1);
    y0[j] = std::clamp(fy, 0, res - 1);
    y1[j] = std::clamp(fy + 1, 0, res - 1);
  }
  const glm::vec3* radiance = miss_->radiance_->data();
  const std::size_t per = static_cast<std::size_t>(res) * res;
  for (int j = 0; j < k; ++j) {
    const glm::vec3* map = radiance + probe[j] * per;
    const std::size_t r0 = static_cast<std::size_t>(y0[j]) * res,
                      r1 = static_cast<std::size_t>(y1[j]) * res;
    const glm::vec3 c = glm::mix(glm::mix(map[r0 + x0[j]], map[r0 + x1[j]], ax[j]),
                                 glm::mix(map[r1 + x0[j]], map[r1 + x1[j]], ax[j]), ay[j]);
    b.radiance[idx[j]] = valid[j] ? c : glm::vec3(0.0f);
  }
}

// The texel's streams, frame and range, set up before its first batch.
void ScatterTexel::begin(std::uint32_t i, Texel& t) const {
  const PassInput& in = *in_;
  t.p = in.texels.position[i];
  t.ng = in.texels.geo_normal(in.world, i);
  t.frame = Frame(in.texels.normal[i]);
  t.rng = texel_rng(in.params, i, in.update, kScatter, in.bounce);
  t.pick = texel_rng(in.params, i, in.update, kProbePick, in.bounce);
  t.range = scatter_range(in, i);
  t.probes = miss_->reads_probes(i);
  t.weighed = false;
}

void ScatterTexel::weigh(std::uint32_t i, Texel& t) const {
  t.weights = in_->probe_weights(i);
  t.weighed = true;
  const ProbeWeights& w = t.weights;
  float acc = 0.0f;
  t.sums_rise = true;
  const int count = w.count();
  for (int q = 0; q < 7; ++q) {
    const bool used = q + 1 < count;
    const float next = used ? acc + w.weight[q] : acc;
    t.sums_rise = t.sums_rise && next >= acc;
    acc = next;
    t.sums[q] = used ? acc : std::numeric_limits<float>::infinity();  // u >= it never holds
  }
}

void ScatterTexel::draw(Texel& t, RayBatch& b) const {
  alignas(16) float u0[kBatch], u1[kBatch];
  for (int s = 0; s < b.count; ++s) {
    u0[s] = t.rng.next_float();
    u1[s] = t.rng.next_float();
  }
  for (int s = 0; s < b.count; ++s) {
    const glm::vec3 d = t.frame.to_world(cosine_hemisphere_fast(glm::vec2(u0[s], u1[s])));
    const glm::vec3 o = rays_->offset(t.p, t.ng, d);
    b.dx[s] = d.x;
    b.dy[s] = d.y;
    b.dz[s] = d.z;
    b.ox[s] = o.x;
    b.oy[s] = o.y;
    b.oz[s] = o.z;
  }
  b.tmax = t.range;
}

// The hits' radiance (HitShader::diffuse), their lightmap rows fetched together first so that
// their cache misses overlap.
void ScatterTexel::shade_hits(Batch& b) const {
  const RayBatch& r = b.rays;
  int idx[kBatch];
  int k = 0;
  for (int s = 0; s < r.count; ++s) {
    idx[k] = s;
    k += r.hit[s].valid();
  }
  glm::vec2 uv[kBatch];
  for (int j = 0; j < k; ++j) uv[j] = prefetch_radiance(*prev_, r.hit[idx[j]]);
  for (int j = 0; j < k; ++j) b.radiance[idx[j]] = shader_->diffuse(r.hit[idx[j]], uv[j]);
}

void ScatterTexel::run(const std::uint32_t* texels, std::size_t count,
                       std::vector<glm::vec3>& out) const {
  const int n = in_->params.indirect_samples;
  Batch b;  // once per run: its arrays are not cleared per texel
  Texel t;
  const PassInput& in = *in_;
  for (std::size_t k = 0; k < count; ++k) {
    const std::uint32_t i = texels[k];
    // The texels of a work unit lie scattered in memory: what a texel a few ahead reads is
    // requested now (a hint: it changes no result).
    if (k + kAhead < count) {
      const std::uint32_t a = texels[k + kAhead];
      __builtin_prefetch(&in.texels.position[a]);
      __builtin_prefetch(&in.texels.normal[a]);
      __builtin_prefetch(&in.texels.triangle[a]);
      if (t.probes) __builtin_prefetch(&in.probe_corners[a]);
    }
    begin(i, t);
    glm::vec3 sum(0.0f);
    for (int s0 = 0; s0 < n; s0 += kBatch) {
      const int m = std::min(kBatch, n - s0);
      b.rays.count = m;
      draw(t, b.rays);
      rays_->intersect(b.rays);
      for (int s = 0; s < m; ++s) b.radiance[s] = glm::vec3(0.0f);
      shade_hits(b);
      if (t.probes) shade_misses(i, t, b);
      for (int s = 0; s < m; ++s) sum += b.radiance[s];
    }
    // Cosine-weighted sampling: E = pi / N * sum L.
    out[i] = sum * (kPi / static_cast<float>(n));
  }
}

}  // namespace irradcast::embree_sampling

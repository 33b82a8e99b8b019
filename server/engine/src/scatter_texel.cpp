#include "scatter_texel.h"

#include <algorithm>
#include <cmath>

#include "irradcast/common/sampling.h"

namespace irradcast::embree_sampling {

namespace {

using Batch = ScatterTexel::Batch;
constexpr int kBatch = ScatterTexel::kBatch;

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
  int k = w.count - 1;
  bool found = false;
  for (int j = 0; j + 1 < w.count; ++j) {
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
void ScatterTexel::shade_misses(std::uint32_t i, glm::vec3 p, Batch& b, Rng& pick) const {
  const ScatterMiss& miss = *miss_;
  const int m = b.count;
  for (int s = 0; s < m; ++s) {
    float t = 3.4e38f;
    t = exit_axis(t, miss.lo_.x, miss.hi_.x, p.x, b.dx[s]);
    t = exit_axis(t, miss.lo_.y, miss.hi_.y, p.y, b.dy[s]);
    t = exit_axis(t, miss.lo_.z, miss.hi_.z, p.z, b.dz[s]);
    b.exit[s] = std::max(t, 0.0f);
  }
  // The misses that read a probe (operator() returns zero where the ray left the scene).
  int idx[kBatch];
  int k = 0;
  for (int s = 0; s < m; ++s) {
    idx[k] = s;
    k += !b.hit[s].valid() && !(b.exit[s] <= miss.range_);
  }
  const ProbeWeights& w = in_->probe_weights[i];
  const std::vector<glm::vec3>& position = in_->probes.position;
  alignas(16) float tx[kBatch], ty[kBatch], tz[kBatch];
  std::uint32_t probe[kBatch];
  for (int j = 0; j < k; ++j) {
    const int s = idx[j];
    probe[j] = w.probe[pick_probe_flat(w, pick.next_float())];
    const glm::vec3 d(b.dx[s], b.dy[s], b.dz[s]);
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
    ex[j] = 0.5f * (z < 0.0f ? fx : x) + 0.5f;
    ey[j] = 0.5f * (z < 0.0f ? fy : y) + 0.5f;
  }
  const int res = in_->probes.resolution;
  for (int j = 0; j < k; ++j)
    b.radiance[idx[j]] = valid[j] ? sample_probe_at(*miss.radiance_, probe[j], res,
                                                    glm::vec2(ex[j], ey[j]))
                                  : glm::vec3(0.0f);
}

void ScatterTexel::draw(Rng& rng, const Frame& frame, glm::vec3 p, glm::vec3 ng,
                        Batch& b) const {
  alignas(16) float u0[kBatch], u1[kBatch];
  for (int s = 0; s < b.count; ++s) {
    u0[s] = rng.next_float();
    u1[s] = rng.next_float();
  }
  for (int s = 0; s < b.count; ++s) {
    const glm::vec3 d = frame.to_world(cosine_hemisphere_fast(glm::vec2(u0[s], u1[s])));
    const glm::vec3 o = rays_->offset(p, ng, d);
    b.dx[s] = d.x;
    b.dy[s] = d.y;
    b.dz[s] = d.z;
    b.ox[s] = o.x;
    b.oy[s] = o.y;
    b.oz[s] = o.z;
  }
}

void ScatterTexel::trace(float range, Batch& b) const {
  for (int s = 0; s < b.count; ++s) {
    Ray ray;
    ray.origin = glm::vec3(b.ox[s], b.oy[s], b.oz[s]);
    ray.direction = glm::vec3(b.dx[s], b.dy[s], b.dz[s]);
    ray.tmax = range;
    b.hit[s] = rays_->intersect(ray);
    b.radiance[s] = glm::vec3(0.0f);
  }
}

// The hits' radiance (HitShader::diffuse), their lightmap rows fetched together first so that
// their cache misses overlap.
void ScatterTexel::shade_hits(Batch& b) const {
  int idx[kBatch];
  int k = 0;
  for (int s = 0; s < b.count; ++s) {
    idx[k] = s;
    k += b.hit[s].valid();
  }
  glm::vec2 uv[kBatch];
  for (int j = 0; j < k; ++j) uv[j] = prefetch_radiance(*prev_, b.hit[idx[j]]);
  for (int j = 0; j < k; ++j) b.radiance[idx[j]] = shader_->diffuse(b.hit[idx[j]], uv[j]);
}

glm::vec3 ScatterTexel::operator()(std::uint32_t i) const {
  const PassInput& in = *in_;
  const int n = in.params.indirect_samples;
  const glm::vec3 p = in.texels.position[i], ng = in.texels.geo_normal[i];
  Rng rng = texel_rng(in.params, i, in.update, kScatter, in.bounce);
  // A stream of its own for probe choices, so the ray directions do not depend on which rays
  // missed.
  Rng pick = texel_rng(in.params, i, in.update, kProbePick, in.bounce);
  const float range = scatter_range(in, i);
  const bool probes = miss_->reads_probes(i);
  const Frame frame(in.texels.normal[i]);
  Batch b;
  glm::vec3 sum(0.0f);
  for (int s0 = 0; s0 < n; s0 += kBatch) {
    b.count = std::min(kBatch, n - s0);
    draw(rng, frame, p, ng, b);
    trace(range, b);
    shade_hits(b);
    if (probes) shade_misses(i, p, b, pick);
    for (int s = 0; s < b.count; ++s) sum += b.radiance[s];
  }
  // Cosine-weighted sampling: E = pi / N * sum L.
  return sum * (kPi / static_cast<float>(n));
}

}  // namespace irradcast::embree_sampling

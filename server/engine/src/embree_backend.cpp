#include "irradcast/engine/embree_backend.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <cmath>

#include "irradcast/common/sampling.h"

namespace irradcast {
namespace embree_sampling {

Rng texel_rng(const EngineParams& p, std::uint64_t index, std::uint32_t update, Stream stream,
              std::uint32_t bounce) {
  return Rng(mix64(p.seed) ^ index,
             (static_cast<std::uint64_t>(update) << 16) ^ (stream << 8) ^ bounce);
}

glm::vec3 sample_probe(const std::vector<glm::vec3>& radiance, std::size_t probe, int res,
                       glm::vec3 dir) {
  glm::vec2 uv = octahedral_encode(dir) * static_cast<float>(res) - 0.5f;
  glm::vec2 f = glm::floor(uv);
  glm::vec2 a = uv - f;
  auto at = [&](int x, int y) {
    x = glm::clamp(x, 0, res - 1);
    y = glm::clamp(y, 0, res - 1);
    return radiance[probe * res * res + static_cast<std::size_t>(y) * res + x];
  };
  int x = static_cast<int>(f.x), y = static_cast<int>(f.y);
  return glm::mix(glm::mix(at(x, y), at(x + 1, y), a.x),
                  glm::mix(at(x, y + 1), at(x + 1, y + 1), a.x), a.y);
}

glm::vec3 exit_point(const Bounds& b, glm::vec3 p, glm::vec3 d) {
  glm::vec3 pad = 1e-3f * glm::max(b.extent(), glm::vec3(1e-6f));
  float t = 3.4e38f;
  for (int a = 0; a < 3; ++a) {
    if (d[a] > 0.0f) t = std::min(t, (b.hi[a] + pad[a] - p[a]) / d[a]);
    if (d[a] < 0.0f) t = std::min(t, (b.lo[a] - pad[a] - p[a]) / d[a]);
  }
  return p + std::max(t, 0.0f) * d;
}

glm::vec3 probe_direction(std::size_t t, int res, glm::vec2 jitter) {
  glm::vec2 uv((static_cast<float>(t % res) + jitter.x) / res,
               (static_cast<float>(t / res) + jitter.y) / res);
  return octahedral_decode(uv);
}

int pick_probe(const ProbeWeights& w, float u) {
  float acc = 0.0f;
  for (int k = 0; k + 1 < w.count; ++k) {
    acc += w.weight[k];
    if (u < acc) return k;
  }
  return w.count - 1;
}

}  // namespace embree_sampling

namespace {

using Clock = std::chrono::steady_clock;
using namespace embree_sampling;

// Runs body(texel) over every work unit (cell or object) in dispatch order, units in parallel
// and large units split further; each worker adds its ray count.
template <typename Body>
std::uint64_t for_each_texel(const PassInput& in, Body&& body) {
  std::atomic<std::uint64_t> rays{0};
  const std::size_t units = in.unit_offsets.empty() ? 0 : in.unit_offsets.size() - 1;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, units, 1), [&](const tbb::blocked_range<std::size_t>& ur) {
        for (std::size_t u = ur.begin(); u < ur.end(); ++u) {
          tbb::parallel_for(
              tbb::blocked_range<std::uint32_t>(in.unit_offsets[u], in.unit_offsets[u + 1], 256),
              [&](const tbb::blocked_range<std::uint32_t>& r) {
                std::uint64_t local = 0;
                for (std::uint32_t k = r.begin(); k < r.end(); ++k)
                  local += body(in.unit_texels[k]);
                rays += local;
              });
        }
      });
  return rays.load();
}

}  // namespace

glm::vec3 radiance_at(const RadianceField& f, const Hit& h) {
  glm::vec2 uv = f.atlas->objects[h.object].uv(h.triangle, h.u, h.v);
  glm::vec3 e = (*f.irradiance)[h.object].bilinear(uv);
  return f.world->albedo(h.object, h.triangle, h.u, h.v) * kInvPi * e;
}

PassResult EmbreeBackend::direct(const PassInput& in, std::vector<glm::vec3>& out) {
  auto start = Clock::now();
  out.assign(in.texels.size(), glm::vec3(0.0f));
  const int n = in.params.direct_samples;
  const bool area = !lights_->emissive_triangles().empty();
  const std::uint64_t punctual = in.world.lights.size();
  PassResult r;
  r.rays = for_each_texel(in, [&](std::uint32_t i) -> std::uint64_t {
    const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                    ng = in.texels.geo_normal[i];
    glm::vec3 e = lights_->punctual_irradiance(*rays_, p, nrm, ng);
    if (area) {
      Rng rng = texel_rng(in.params, i, in.update, kDirect, 0);
      glm::vec3 sum(0.0f);
      for (int s = 0; s < n; ++s) {
        float pick = (static_cast<float>(s) + rng.next_float()) / static_cast<float>(n);
        glm::vec2 pos = rng.next_2d();
        sum += lights_->area_irradiance(*rays_, p, nrm, ng, glm::vec3(pick, pos));
      }
      e += sum / static_cast<float>(n);
    }
    out[i] = e;
    return punctual + (area ? static_cast<std::uint64_t>(n) : 0u);
  });
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

PassResult EmbreeBackend::gather_probes(const PassInput& in, const RadianceField& prev,
                                        std::vector<glm::vec3>& out) {
  auto start = Clock::now();
  const ProbeGrid& g = in.probes;
  const int res = g.resolution;
  const std::size_t per = g.texels_per_probe();
  out.assign(g.count() * per, glm::vec3(0.0f));
  std::atomic<std::uint64_t> rays{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, g.count()),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::uint64_t local = 0;
                      for (std::size_t pi = r.begin(); pi < r.end(); ++pi) {
                        if (!g.usable[pi]) continue;
                        Rng rng = texel_rng(in.params, pi, in.update, kProbe, in.bounce);
                        for (std::size_t t = 0; t < per; ++t) {
                          Ray ray;
                          ray.origin = g.position[pi];
                          ray.direction = probe_direction(t, res, rng.next_2d());
                          Hit h = rays_->intersect(ray);
                          ++local;
                          if (h.valid()) out[pi * per + t] = radiance_at(prev, h);
                        }
                      }
                      rays += local;
                    });
  PassResult result;
  result.rays = rays.load();
  result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

PassResult EmbreeBackend::scatter(const PassInput& in, const RadianceField& prev,
                                  const std::vector<glm::vec3>& probe_radiance,
                                  std::vector<glm::vec3>& out) {
  auto start = Clock::now();
  out.assign(in.texels.size(), glm::vec3(0.0f));
  const int n = in.params.indirect_samples;
  const float extent = in.world.bounds.max_extent();
  const bool unbiased = in.params.unbiased();
  const float range = unbiased ? 3.4e38f : in.params.tracing_range * extent;
  const bool fixed = in.params.distant_point == DistantPoint::FixedDistance;
  const int res = in.probes.resolution;
  PassResult r;
  r.rays = for_each_texel(in, [&](std::uint32_t i) -> std::uint64_t {
    const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                    ng = in.texels.geo_normal[i];
    Rng rng = texel_rng(in.params, i, in.update, kScatter, in.bounce);
    // A stream of its own for probe choices, so the ray directions do not depend on which rays
    // missed.
    Rng pick = texel_rng(in.params, i, in.update, kProbePick, in.bounce);
    // A texel that sees no probe (ProbeWeights::count 0) traces its rays to their hit.
    const bool weighed = !unbiased && !in.probe_weights.empty();
    const bool probes = weighed && in.probe_weights[i].count > 0;
    Frame frame(nrm);
    glm::vec3 sum(0.0f);
    for (int s = 0; s < n; ++s) {
      Ray ray;
      ray.direction = frame.to_world(cosine_hemisphere(rng.next_2d()));
      ray.origin = rays_->offset(p, ng, ray.direction);
      ray.tmax = weighed && !probes ? 3.4e38f : range;
      Hit h = rays_->intersect(ray);
      if (h.valid()) {
        sum += radiance_at(prev, h);
      } else if (probes) {
        // A ray that leaves the scene's bounds within the range has passed everything it could
        // hit: a true miss (no bounce radiance), not the probes' business. Looking a probe up
        // here lit the faces next to an opening (cornell's front) with the probes' view inside.
        const glm::vec3 exit = exit_point(in.world.bounds, p, ray.direction);
        if (glm::dot(exit - p, ray.direction) <= range) continue;
        // One probe, picked with probability equal to its interpolation weight: the same
        // expectation as the weighted sum over all (up to 8) of them, at one lookup instead of
        // eight; over many rays and updates the choice averages out.
        glm::vec3 q = fixed ? p + extent * ray.direction : exit;
        const ProbeWeights& w = in.probe_weights[i];
        const int k = pick_probe(w, pick.next_float());
        glm::vec3 d = q - in.probes.position[w.probe[k]];
        float len = glm::length(d);
        if (len > 0.0f) sum += sample_probe(probe_radiance, w.probe[k], res, d / len);
      }
    }
    // Cosine-weighted sampling: E = pi / N * sum L.
    out[i] = sum * (kPi / static_cast<float>(n));
    return static_cast<std::uint64_t>(n);
  });
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

}  // namespace irradcast

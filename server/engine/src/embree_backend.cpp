#include "embree_backend.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

#include "irradcast/common/hit_shader.h"
#include "irradcast/common/sampling.h"
#include "scatter_texel.h"

namespace irradcast {
namespace embree_sampling {

Rng texel_rng(const EngineParams& p, std::uint64_t index, std::uint32_t update, Stream stream,
              std::uint32_t bounce) {
  return Rng(mix64(p.seed) ^ index,
             (static_cast<std::uint64_t>(update) << 16) ^ (stream << 8) ^ bounce);
}

glm::vec3 sample_probe(const std::vector<glm::vec3>& radiance, std::size_t probe, int res,
                       glm::vec3 dir) {
  return sample_probe_at(radiance, probe, res, octahedral_encode(dir));
}

glm::vec3 sample_probe_at(const std::vector<glm::vec3>& radiance, std::size_t probe, int res,
                          glm::vec2 enc) {
  glm::vec2 uv = enc * static_cast<float>(res) - 0.5f;
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

namespace {

// The enlarged bounds exit_distance runs to.
glm::vec3 exit_pad(const Bounds& b) {
  return 1e-3f * glm::max(b.extent(), glm::vec3(1e-6f));
}

float exit_distance_to(glm::vec3 lo, glm::vec3 hi, glm::vec3 p, glm::vec3 d) {
  float t = 3.4e38f;
  for (int a = 0; a < 3; ++a) t = exit_axis(t, lo[a], hi[a], p[a], d[a]);
  return std::max(t, 0.0f);
}

}  // namespace

float exit_distance(const Bounds& b, glm::vec3 p, glm::vec3 d) {
  const glm::vec3 pad = exit_pad(b);
  return exit_distance_to(b.lo - pad, b.hi + pad, p, d);
}

glm::vec3 exit_point(const Bounds& b, glm::vec3 p, glm::vec3 d) {
  return p + exit_distance(b, p, d) * d;
}

float scatter_range(const PassInput& in, std::uint32_t i) {
  return in.reads_probes(i) ? in.params.tracing_range.resolve(in.world.bounds.max_extent())
                            : 3.4e38f;
}

ScatterMiss::ScatterMiss(const PassInput& in, const std::vector<glm::vec3>& probe_radiance)
    : in_(&in),
      radiance_(&probe_radiance),
      lo_(in.world.bounds.lo - exit_pad(in.world.bounds)),
      hi_(in.world.bounds.hi + exit_pad(in.world.bounds)),
      range_(in.params.tracing_range.resolve(in.world.bounds.max_extent())),
      extent_(in.world.bounds.max_extent()),
      fixed_(in.params.distant_point == DistantPoint::FixedDistance) {}

glm::vec3 ScatterMiss::operator()(std::uint32_t i, glm::vec3 p, glm::vec3 d, Rng& pick) const {
  const float exit = exit_distance_to(lo_, hi_, p, d);
  if (exit <= range_) return glm::vec3(0.0f);  // it left the scene: nothing out there
  // One probe, picked with probability equal to its interpolation weight: the same expectation
  // as the weighted sum over all (up to 8) of them, at one lookup instead of eight; over many
  // rays and updates the choice averages out.
  const glm::vec3 q = fixed_ ? p + extent_ * d : p + exit * d;
  const ProbeWeights w = in_->probe_weights(i);
  const int k = pick_probe(w, pick.next_float());
  const std::uint32_t probe = w.probe(k, in_->probes.dims);
  const glm::vec3 to = q - in_->probes.position[probe];
  const float len = glm::length(to);
  return len > 0.0f ? sample_probe(*radiance_, probe, in_->probes.resolution, to / len)
                    : glm::vec3(0.0f);
}

glm::vec3 scatter_miss(const PassInput& in, const std::vector<glm::vec3>& probe_radiance,
                       std::uint32_t i, glm::vec3 p, glm::vec3 d, Rng& pick) {
  const ScatterMiss miss(in, probe_radiance);
  return miss.reads_probes(i) ? miss(i, p, d, pick) : glm::vec3(0.0f);
}

glm::vec3 probe_direction(std::size_t t, int res, glm::vec2 jitter) {
  glm::vec2 uv((static_cast<float>(t % res) + jitter.x) / res,
               (static_cast<float>(t / res) + jitter.y) / res);
  return octahedral_decode(uv);
}

int pick_probe(const ProbeWeights& w, float u) {
  float acc = 0.0f;
  for (int k = 0; k + 1 < w.count(); ++k) {
    acc += w.weight[k];
    if (u < acc) return k;
  }
  return w.count() - 1;
}

}  // namespace embree_sampling

namespace {

using Clock = std::chrono::steady_clock;
using namespace embree_sampling;

// Runs body(texels, count) over runs of consecutive texels of every work unit (cell or object)
// in dispatch order, units in parallel and large units split further into runs of >= 256.
template <typename Body>
void for_each_texel_run(const PassInput& in, Body&& body) {
  const std::size_t units = in.unit_offsets.empty() ? 0 : in.unit_offsets.size() - 1;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, units, 1), [&](const tbb::blocked_range<std::size_t>& ur) {
        for (std::size_t u = ur.begin(); u < ur.end(); ++u) {
          tbb::parallel_for(
              tbb::blocked_range<std::uint32_t>(in.unit_offsets[u], in.unit_offsets[u + 1], 256),
              [&](const tbb::blocked_range<std::uint32_t>& r) {
                body(in.unit_texels.data() + r.begin(), r.size());
              });
        }
      });
}

}  // namespace

glm::vec3 radiance_at(const RadianceField& f, const Hit& h) {
  const glm::vec3 e =
      (*f.irradiance)[h.object].bilinear(f.atlas->objects[h.object].uv(h.triangle, h.u, h.v));
  return f.world->albedo(h.object, h.triangle, h.u, h.v) * kInvPi * e;
}

glm::vec3 EmbreeBackend::sky_direct(const PassInput& in, std::uint32_t i,
                                    std::uint64_t* traced) const {
  // The mean of direct_samples sky estimates, from a stream of their own, stratified in the
  // coordinate that matters most: the map sample's row (its u.y; elevation), and the cosine
  // rays' sin^2 theta (their u.x, in the reverse order of strata for a map's second ray).
  const int n = in.params.direct_samples;
  const float inv = 1.0f / static_cast<float>(n);
  const bool map = lights_->sky_distribution().valid();
  Rng rng = texel_rng(in.params, i, in.update, kSky, 0);
  const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                  ng = in.texels.geo_normal(in.world, i);
  glm::vec3 sum(0.0f);
  for (int s = 0; s < n; ++s) {
    const float a = (static_cast<float>(s) + rng.next_float()) * inv;
    const float b = rng.next_float();
    const float c = (static_cast<float>(n - 1 - s) + rng.next_float()) * inv;
    const glm::vec4 u =
        map ? glm::vec4(b, a, c, rng.next_float()) : glm::vec4(a, b, c, rng.next_float());
    sum += lights_->sky_irradiance(*rays_, p, nrm, ng, u, traced);
  }
  return sum * inv;
}

namespace {

// N values of T that construction leaves uninitialised (the shadow samples have default member
// initialisers: zeroing a batch of them per texel cost a fifth of area_direct's own work). Each
// element is written before it is read.
template <typename T, int N>
struct Uninitialized {
  union {
    T v[N];
  };
  Uninitialized() {}
  T& operator[](int i) { return v[i]; }
};

}  // namespace

bool EmbreeBackend::few_lights(const LightSampler::FrontLights& front) const {
  // An object's emissive triangles are listed together, and so are the front lights (in the
  // order of the list): each change of object along the list is one more object.
  int objects = 0;
  std::int32_t last = -1;
  for (int k = 0; k < front.count; ++k) {
    const std::int32_t o = light_object_[front.index[k]];
    if (o == last) continue;
    if (++objects > kPacketLights) return false;
    last = o;
  }
  return true;
}

glm::vec3 EmbreeBackend::area_direct(const PassInput& in, std::uint32_t i, AreaRays& counts,
                                     LightCache::Record* learned) const {
  // direct_samples samples of the lights in front of the texel (LightSampler::front_lights),
  // stratified in the pick; every sample drawn first (4 at a time in SIMD lanes), then the shadow
  // rays of those that can contribute traced (8 to a packet), then summed in order.
  const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                  ng = in.texels.geo_normal(in.world, i);
  LightSampler::FrontLights front;
  const bool culled = lights_->front_lights(p, nrm, front);
  if (culled && front.count == 0) return glm::vec3(0.0f);
  const bool packets = shadow_rays_ == ShadowRays::Packets ||
                       (shadow_rays_ == ShadowRays::Auto && culled && few_lights(front));
  // The lights in front (or past kMaxFront lights the hierarchy) mixed with what the texel's
  // region has learned, where the pass learns (prepare_light_cache).
  const bool learn = learned != nullptr;
  const std::uint64_t region = learn ? cache_.region(p, nrm, in.texels.object[i]) : 0;
  const LightCache::Table* table = learn ? cache_.table_for(region, culled) : nullptr;
  // Fewer samples where the texel's patch has seen no light (LightCache::samples_in).
  const std::uint64_t patch = learn ? cache_.patch(p, nrm, in.texels.object[i]) : 0;
  const int n =
      learn ? cache_.samples_in(patch, in.params.direct_samples) : in.params.direct_samples;
  Rng rng = texel_rng(in.params, i, in.update, kDirect, 0);
  constexpr int kBatch = 16;
  Uninitialized<LightSampler::ShadowSample, kBatch> sample;
  glm::vec3 weight[kBatch];
  bool lit[kBatch];
  glm::vec3 sum(0.0f);
  std::uint64_t rays = 0;
  std::uint32_t lit_rays = 0;
  for (int s0 = 0; s0 < n; s0 += kBatch) {
    const int m = std::min(kBatch, n - s0);
    lights_->direct_samples(*rays_, culled ? &front : nullptr, p, nrm, ng, rng, s0, m, n,
                            &sample[0], weight, lit, table);
    // The shadow rays to trace, 8 to a packet or one by one (ShadowRays).
    Uninitialized<Ray, kBatch> shadow;
    int which[kBatch];
    int count = 0;
    for (int s = 0; s < m; ++s)
      if (lit[s] && sample[s].shadow.tmax > 0.0f) {
        shadow[count] = sample[s].shadow;
        which[count++] = s;
      }
    bool blocked[kBatch];
    if (packets)
      for (int k = 0; k < count; k += 8)
        rays_->occluded8(&shadow[k], std::min(8, count - k), blocked + k);
    else
      for (int k = 0; k < count; ++k) blocked[k] = rays_->occluded(shadow[k]);
    for (int k = 0; k < count; ++k) {
      lit[which[k]] = !blocked[k];
      counts.occluded += blocked[k] ? 1u : 0u;
    }
    if (learn)  // what each ray brought, not divided by the pick's probability
      for (int k = 0; k < count; ++k) {
        const LightSampler::ShadowSample& t = sample[which[k]];
        const float brought = blocked[k] ? 0.0f : luminance(lights_->triangle_emitted(t));
        learned->add(region, static_cast<std::uint32_t>(t.triangle), brought);
        lit_rays += brought > 0.0f ? 1u : 0u;
      }
    rays += static_cast<std::uint64_t>(count);
    for (int s = 0; s < m; ++s)
      if (lit[s]) sum += weight[s];
  }
  if (learn) learned->add_patch(patch, static_cast<std::uint32_t>(rays), lit_rays);
  counts.traced += rays;
  if (packets) counts.packed += rays;
  return sum / static_cast<float>(n);
}

const char* shadow_rays_name(ShadowRays mode) {
  switch (mode) {
    case ShadowRays::Packets:
      return "packets";
    case ShadowRays::Single:
      return "single";
    case ShadowRays::Auto:
      break;
  }
  return "auto";
}

void EmbreeBackend::prepare_light_cache(const PassInput& in) {
  const std::size_t lights = lights_->emissive_triangles().size();
  if (!learn_lights_ || lights < LightCache::kLearnFrom) {
    cache_ = LightCache();
    return;
  }
  if (cache_.valid() && cache_.lights() == lights) return;
  // The fixed point's unit: the brightest uniform emitter's radiance (1 without one).
  float unit = 0.0f;
  for (const EmissiveTriangle& t : lights_->emissive_triangles())
    if (t.uniform_emission) unit = std::max(unit, luminance(t.emission));
  cache_ = LightCache(in.world.bounds, lights, unit > 0.0f ? unit : 1.0f);
}

PassResult EmbreeBackend::direct(const PassInput& in, std::vector<glm::vec3>& out) {
  auto start = Clock::now();
  out.assign(in.texels.size(), glm::vec3(0.0f));
  const bool area = !lights_->emissive_triangles().empty();
  const std::uint64_t punctual = in.world.lights.size();
  const bool sky = lights_->has_sky();
  // Each emissive triangle's object, for few_lights: taken anew each pass, as an edit replaces
  // the light sampler (PreparedScene::apply).
  light_object_.clear();
  for (const EmissiveTriangle& t : lights_->emissive_triangles()) light_object_.push_back(t.object);
  prepare_light_cache(in);
  const bool learn = cache_.valid();
  tbb::enumerable_thread_specific<LightCache::Record> records(
      [&] { return LightCache::Record(cache_.unit()); });
  std::atomic<std::uint64_t> rays{0}, area_rays{0}, packed{0}, occluded{0};
  for_each_texel_run(in, [&](const std::uint32_t* run, std::size_t size) {
    std::uint64_t traced = 0;
    AreaRays area_counts;
    LightCache::Record* learned = learn ? &records.local() : nullptr;
    for (std::size_t k = 0; k < size; ++k) {
      const std::uint32_t i = run[k];
      const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                      ng = in.texels.geo_normal(in.world, i);
      glm::vec3 e =
          punctual > 0 ? lights_->punctual_irradiance(*rays_, p, nrm, ng) : glm::vec3(0.0f);
      traced += punctual;
      if (area) e += area_direct(in, i, area_counts, learned);
      if (sky) e += sky_direct(in, i, &traced);
      out[i] = e;
    }
    rays += traced + area_counts.traced;
    area_rays += area_counts.traced;
    packed += area_counts.packed;
    occluded += area_counts.occluded;
  });
  direct_area_rays_ = {area_rays.load(), packed.load(), occluded.load()};
  if (learn) {
    std::vector<LightCache::Record*> learned;
    for (LightCache::Record& r : records) learned.push_back(&r);
    cache_.learn(std::move(learned));
  }
  PassResult r;
  r.rays = rays.load();
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
  const ScatterMiss miss(in, probe_radiance);
  const HitShader shader(*prev.world, *prev.atlas, *prev.irradiance);
  const ScatterTexel texels(in, *rays_, prev, miss, shader);
  std::atomic<std::uint64_t> count{0};
  for_each_texel_run(in, [&](const std::uint32_t* run, std::size_t size) {
    texels.run(run, size, out);
    count += size;
  });
  PassResult r;
  r.rays = count.load() * static_cast<std::uint64_t>(in.params.indirect_samples);
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

}  // namespace irradcast

// irradcast-bench-engine, part 1: the engine's passes against RayScene and raw Embree on the very
// same rays. The engine runs on a BenchBackend, a TraceBackend that forwards every pass to the
// real EmbreeBackend; in the measured update it regenerates, from the PassInput it is handed, the
// rays that pass traces (with the backend's own sampling: embree_sampling, LightSampler's sample
// steps), times the three side by side, and checks the regenerated rays: shading them with the
// engine's formulas must reproduce the pass's output.
#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <utility>

#include "bench_util.h"
#include "embree_backend.h"
#include "engine_bench.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/engine.h"

namespace irradcast::bench {
namespace {

using namespace embree_sampling;

// ---------------------------------------------------------------------------------------------
// The rays of one pass.

enum class Kind { Occlusion, Intersection };

struct RawRay {
  glm::vec3 org;
  float tmin;
  glm::vec3 dir;
  float tmax;
};

RawRay to_raw(const Ray& r) {
  return {r.origin, r.tmin, r.direction, r.tmax};
}

Ray to_ray(const RawRay& s) {
  Ray r;
  r.origin = s.org;
  r.direction = s.dir;
  r.tmin = s.tmin;
  r.tmax = s.tmax;
  return r;
}

struct Capture {
  Kind kind = Kind::Intersection;
  std::vector<RawRay> rays;
  // Direct pass, per light sample that passed the cosine tests, in the order the backend sums
  // them: its unoccluded contribution and its shadow ray (-1: none traced, always visible).
  struct LightSample {
    std::uint32_t texel;
    std::int32_t ray;
    glm::vec3 weight;
    bool area;
  };
  std::vector<LightSample> samples;
  // Direct pass: per texel, its area-light samples (fewer in a dark region, LightCache).
  std::vector<int> area_samples;
  // Gather / scatter: the output entry each ray belongs to (probe texel / surface texel).
  std::vector<std::uint32_t> owner;
  // The packets the engine traces (first ray and count). Direct pass: the area lights' shadow
  // rays in packets of up to 8 (a texel's traced rays, per batch of 16 samples, 8 at a time).
  // Scatter (where the CPU has AVX-512): a texel's rays 16 at a time.
  std::vector<std::pair<std::size_t, int>> packets;
};

// Texels in the order the backend's for_each_texel visits them (units in dispatch order).
template <typename Body>
void for_each_texel_in_order(const PassInput& in, Body&& body) {
  for (std::size_t k = 0; k < in.unit_texels.size(); ++k) body(in.unit_texels[k]);
}

// Direct pass rays: LightSampler's punctual and area samples, as EmbreeBackend::direct (through
// punctual_irradiance and area_irradiance) takes them.
Capture capture_direct(const RayScene& rays, const LightSampler& lights, const LightCache& cache,
                       const PassInput& in) {
  Capture c;
  c.kind = Kind::Occlusion;
  const bool area = !lights.emissive_triangles().empty();
  c.area_samples.assign(in.texels.size(), in.params.direct_samples);
  for_each_texel_in_order(in, [&](std::uint32_t i) {
    const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                    ng = in.texels.geo_normal(in.world, i);
    LightSampler::ShadowSample s;
    for (const WorldLight& l : in.world.lights) {
      if (!LightSampler::punctual_sample(rays, l, p, nrm, ng, s)) continue;
      c.samples.push_back({i, static_cast<std::int32_t>(c.rays.size()), s.irradiance, false});
      c.rays.push_back(to_raw(s.shadow));
    }
    if (!area) return;
    LightSampler::FrontLights front;
    const bool culled = lights.front_lights(p, nrm, front);
    if (culled && front.count == 0) return;
    const bool learned = !culled && cache.valid();
    const std::uint64_t region = learned ? cache.region(p, nrm, in.texels.object[i]) : 0;
    const LightCache::Table* table = learned ? cache.find(region) : nullptr;
    const int n = learned ? cache.samples_in(cache.patch(p, nrm, in.texels.object[i]),
                                             in.params.direct_samples)
                          : in.params.direct_samples;
    c.area_samples[i] = n;
    Rng rng = texel_rng(in.params, i, in.update, kDirect, 0);
    int packet_rays = 0, packet_batch = -1;  // the current packet's rays and sample batch
    for (int k = 0; k < n; ++k) {
      float pick = (static_cast<float>(k) + rng.next_float()) / static_cast<float>(n);
      glm::vec2 pos = rng.next_2d();
      glm::vec3 w;
      if (!lights.direct_sample(rays, culled ? &front : nullptr, p, nrm, ng, glm::vec3(pick, pos),
                                s, w, table))
        continue;
      std::int32_t index = -1;
      if (s.shadow.tmax > 0.0f) {
        if (packet_rays == 8 || packet_batch != k / 16) {  // a batch of 16 samples starts anew
          c.packets.push_back({c.rays.size(), 0});
          packet_rays = 0;
          packet_batch = k / 16;
        }
        ++packet_rays;
        ++c.packets.back().second;
        index = static_cast<std::int32_t>(c.rays.size());
        c.rays.push_back(to_raw(s.shadow));
      }
      c.samples.push_back({i, index, w, true});
    }
  });
  return c;
}

// Probe gather rays: EmbreeBackend::gather_probes.
Capture capture_probes(const PassInput& in) {
  Capture c;
  const ProbeGrid& g = in.probes;
  const int res = g.resolution;
  const std::size_t per = g.texels_per_probe();
  for (std::size_t pi = 0; pi < g.count(); ++pi) {
    if (!g.usable[pi]) continue;
    Rng rng = texel_rng(in.params, pi, in.update, kProbe, in.bounce);
    for (std::size_t t = 0; t < per; ++t) {
      c.rays.push_back({g.position[pi], 0.0f, probe_direction(t, res, rng.next_2d()), 3.4e38f});
      c.owner.push_back(static_cast<std::uint32_t>(pi * per + t));
    }
  }
  return c;
}

// Scatter rays: EmbreeBackend::scatter.
Capture capture_scatter(const RayScene& rays, const PassInput& in) {
  Capture c;
  const int n = in.params.indirect_samples;
  const bool packets = __builtin_cpu_supports("avx512f");
  c.rays.reserve(in.texels.size() * static_cast<std::size_t>(n));
  for_each_texel_in_order(in, [&](std::uint32_t i) {
    const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                    ng = in.texels.geo_normal(in.world, i);
    Rng rng = texel_rng(in.params, i, in.update, kScatter, in.bounce);
    const float range = scatter_range(in, i);
    Frame frame(nrm);
    for (int s = 0; s < n; ++s) {
      // The engine's packets where it traces them (RayScene::intersect(RayBatch&)): 16 at a time
      // within each batch of 32 of a texel's rays.
      if (packets && s % 16 == 0) c.packets.push_back({c.rays.size(), 0});
      if (packets) ++c.packets.back().second;
      glm::vec3 dir = frame.to_world(cosine_hemisphere_fast(rng.next_2d()));
      c.rays.push_back({rays.offset(p, ng, dir), 0.0f, dir, range});
      c.owner.push_back(i);
    }
  });
  return c;
}

// ---------------------------------------------------------------------------------------------
// Tracing the captured rays: raw Embree, and through RayScene.

void to_embree(const RawRay& s, RTCRay& ray) {
  ray.org_x = s.org.x;
  ray.org_y = s.org.y;
  ray.org_z = s.org.z;
  ray.tnear = s.tmin;
  ray.dir_x = s.dir.x;
  ray.dir_y = s.dir.y;
  ray.dir_z = s.dir.z;
  ray.time = 0.0f;
  ray.tfar = s.tmax;
  ray.mask = 0xFFFFFFFFu;
  ray.id = 0;
  ray.flags = 0;
}

std::uint64_t trace_raw(RTCScene scene, const Capture& c) {
  std::atomic<std::uint64_t> hits{0};
  const RawRay* rays = c.rays.data();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, c.rays.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      RTCIntersectContext ctx;
                      rtcInitIntersectContext(&ctx);
                      std::uint64_t local = 0;
                      if (c.kind == Kind::Occlusion) {
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          RTCRay ray;
                          to_embree(rays[i], ray);
                          rtcOccluded1(scene, &ctx, &ray);
                          local += ray.tfar < 0.0f;
                        }
                      } else {
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          RTCRayHit rh;
                          to_embree(rays[i], rh.ray);
                          rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                          rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
                          rtcIntersect1(scene, &ctx, &rh);
                          local += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
                        }
                      }
                      hits += local;
                    });
  return hits.load();
}

// Lanes 0 .. N of a raw Embree packet (RTCRay8 / RTCRay16) from rays first .. end of c (the
// lanes past end repeat the first ray and are marked invalid).
template <int N, typename RayN>
void fill_packet(const Capture& c, std::size_t first, std::size_t end, int* valid, RayN& ray) {
  for (std::size_t i = 0; i < static_cast<std::size_t>(N); ++i) {
    const RawRay& s = c.rays[first + i < end ? first + i : first];
    valid[i] = first + i < end ? -1 : 0;
    ray.org_x[i] = s.org.x;
    ray.org_y[i] = s.org.y;
    ray.org_z[i] = s.org.z;
    ray.tnear[i] = s.tmin;
    ray.dir_x[i] = s.dir.x;
    ray.dir_y[i] = s.dir.y;
    ray.dir_z[i] = s.dir.z;
    ray.time[i] = 0.0f;
    ray.tfar[i] = s.tmax;
    ray.mask[i] = 0xFFFFFFFFu;
    ray.id[i] = 0;
    ray.flags[i] = 0;
  }
}

// The scatter pass's rays through raw rtcIntersect16, in the engine's packets (Capture::packets).
std::uint64_t trace_raw_packets16(RTCScene scene, const Capture& c) {
  std::atomic<std::uint64_t> hits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, c.packets.size(), 32),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::uint64_t local = 0;
                      RTCIntersectContext ctx;
                      rtcInitIntersectContext(&ctx);
                      for (std::size_t p = r.begin(); p < r.end(); ++p) {
                        const std::size_t first = c.packets[p].first;
                        const std::size_t end =
                            first + static_cast<std::size_t>(c.packets[p].second);
                        alignas(64) int valid[16];
                        alignas(64) RTCRayHit16 rh;
                        fill_packet<16>(c, first, end, valid, rh.ray);
                        for (int i = 0; i < 16; ++i) {
                          rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
                          rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
                        }
                        rtcIntersect16(valid, scene, &ctx, &rh);
                        for (std::size_t i = 0; first + i < end; ++i)
                          local += rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
                      }
                      hits += local;
                    });
  return hits.load();
}

// The direct pass's rays through raw rtcOccluded8, in the engine's packets (Capture::packets).
std::uint64_t trace_raw_packets(RTCScene scene, const Capture& c) {
  if (c.kind != Kind::Occlusion) return trace_raw_packets16(scene, c);
  std::atomic<std::uint64_t> hits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, c.packets.size(), 32),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::uint64_t local = 0;
                      for (std::size_t p = r.begin(); p < r.end(); ++p) {
                        const std::size_t first = c.packets[p].first;
                        const std::size_t end =
                            first + static_cast<std::size_t>(c.packets[p].second);
                        alignas(32) int valid[8];
                        alignas(32) RTCRay8 ray;
                        fill_packet<8>(c, first, end, valid, ray);
                        RTCIntersectContext ctx;
                        rtcInitIntersectContext(&ctx);
                        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
                        rtcOccluded8(valid, scene, &ctx, &ray);
                        for (std::size_t i = 0; first + i < end; ++i) local += ray.tfar[i] < 0.0f;
                      }
                      hits += local;
                    });
  return hits.load();
}

// The occlusion rays on which raw rtcOccluded8 in the engine's packets and rtcOccluded1 answer
// differently (Embree's packet and single-ray kernels are not bit-identical: about one shadow ray
// in millions, at a triangle's edge). The first is described on stderr.
std::uint64_t packet_disagreements(RTCScene scene, const Capture& c) {
  if (c.kind != Kind::Occlusion) return 0;
  std::uint64_t differ = 0;
  for (const auto& [first, count] : c.packets) {
    const std::size_t end = first + static_cast<std::size_t>(count);
    alignas(32) int valid[8];
    alignas(32) RTCRay8 packet;
    fill_packet<8>(c, first, end, valid, packet);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcOccluded8(valid, scene, &ctx, &packet);
    for (std::size_t i = 0; first + i < end; ++i) {
      RTCRay ray;
      to_embree(c.rays[first + i], ray);
      RTCIntersectContext one;
      rtcInitIntersectContext(&one);
      rtcOccluded1(scene, &one, &ray);
      const bool single = ray.tfar < 0.0f, in_packet = packet.tfar[i] < 0.0f;
      if (single == in_packet) continue;
      if (differ++ == 0) {
        const RawRay& r = c.rays[first + i];
        std::fprintf(stderr,
                     "  a ray the packet calls %s and the single ray %s: origin %.9g %.9g %.9g, "
                     "direction %.9g %.9g %.9g, t %.9g .. %.9g\n",
                     in_packet ? "occluded" : "free", single ? "occluded" : "free", r.org.x,
                     r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, r.tmin, r.tmax);
      }
    }
  }
  return differ;
}

std::uint64_t trace_rayscene(const RayScene& scene, const Capture& c) {
  std::atomic<std::uint64_t> hits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, c.rays.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::uint64_t local = 0;
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        Ray ray = to_ray(c.rays[i]);
                        local += c.kind == Kind::Occlusion ? scene.occluded(ray)
                                                           : scene.intersect(ray).valid();
                      }
                      hits += local;
                    });
  return hits.load();
}

std::vector<Hit> intersect_all(const RayScene& rays, const Capture& c) {
  std::vector<Hit> hits(c.rays.size());
  tbb::parallel_for(std::size_t(0), c.rays.size(),
                    [&](std::size_t i) { hits[i] = rays.intersect(to_ray(c.rays[i])); });
  return hits;
}

// ---------------------------------------------------------------------------------------------
// Shading the captured rays with the engine's formulas (the check against the pass's output).

void shade_direct(const RayScene& rays, const LightSampler& lights, const PassInput& in,
                  const Capture& c, std::vector<glm::vec3>& est) {
  std::vector<std::uint8_t> blocked(c.rays.size());
  tbb::parallel_for(std::size_t(0), c.rays.size(),
                    [&](std::size_t i) { blocked[i] = rays.occluded(to_ray(c.rays[i])); });
  est.assign(in.texels.size(), glm::vec3(0.0f));
  const bool area = !lights.emissive_triangles().empty();
  for (std::size_t s = 0; s < c.samples.size();) {
    const std::uint32_t t = c.samples[s].texel;
    glm::vec3 e(0.0f), sum(0.0f);
    for (; s < c.samples.size() && c.samples[s].texel == t; ++s) {
      const Capture::LightSample& ls = c.samples[s];
      if (ls.ray >= 0 && blocked[ls.ray]) continue;
      (ls.area ? sum : e) += ls.weight;
    }
    if (area) e += sum / static_cast<float>(c.area_samples[t]);
    est[t] = e;
  }
}

void shade_probes(const RayScene& rays, const PassInput& in, const RadianceField& prev,
                  const Capture& c, std::vector<glm::vec3>& est) {
  std::vector<Hit> hits = intersect_all(rays, c);
  est.assign(in.probes.count() * in.probes.texels_per_probe(), glm::vec3(0.0f));
  for (std::size_t r = 0; r < c.rays.size(); ++r)
    if (hits[r].valid()) est[c.owner[r]] = radiance_at(prev, hits[r]);
}

void shade_scatter(const RayScene& rays, const PassInput& in, const RadianceField& prev,
                   const std::vector<glm::vec3>& probe_radiance, const Capture& c,
                   std::vector<glm::vec3>& est) {
  std::vector<Hit> hits = intersect_all(rays, c);
  const int n = in.params.indirect_samples;
  est.assign(in.texels.size(), glm::vec3(0.0f));
  for (std::size_t r0 = 0; r0 < c.rays.size(); r0 += static_cast<std::size_t>(n)) {
    const std::uint32_t i = c.owner[r0];
    const glm::vec3 p = in.texels.position[i];
    Rng pick = texel_rng(in.params, i, in.update, kProbePick, in.bounce);
    glm::vec3 sum(0.0f);
    for (int s = 0; s < n; ++s) {
      const Hit& h = hits[r0 + s];
      sum += h.valid() ? radiance_at(prev, h)
                       : scatter_miss(in, probe_radiance, i, p, c.rays[r0 + s].dir, pick);
    }
    est[i] = sum * (kPi / static_cast<float>(n));
  }
}

// ---------------------------------------------------------------------------------------------
// The backend the engine runs on during the benchmark.

struct PassMeasure {
  std::string pass;  // direct | probes | scatter
  std::uint32_t bounce = 0;
  Kind kind = Kind::Intersection;
  std::uint64_t engine_rays = 0;  // what the pass reports (PassResult::rays)
  std::uint64_t traced_rays = 0;  // rays actually sent to Embree
  std::uint64_t hits = 0;         // occluded / hit rays (raw and RayScene agree)
  std::vector<double> pipeline_s, rayscene_s, raw_s;
  // raw Embree in the engine's packets: direct rtcOccluded8, scatter rtcIntersect16 (AVX-512)
  std::vector<double> raw_packet_s;
  // Direct pass: the engine's pass with its shadow rays forced into packets and one by one
  // (ShadowRays), interleaved with the others, and the way its default (Auto) takes here.
  std::vector<double> packets_s, single_s;
  double auto_packet_share = 0;            // of the default's shadow rays, in packets
  std::uint64_t packet_disagreements = 0;  // rays raw packets and single rays answer differently
  std::uint64_t forced_differ = 0;  // texels where a forced way's output differs from the default
  double max_abs_diff = 0.0;        // regenerated-ray shading vs the pass's output
  double max_abs_value = 0.0;       // of the pass's output
};

// The largest difference between the pass's output and the shaded regenerated rays.
void compare(const std::vector<glm::vec3>& out, const std::vector<glm::vec3>& est, PassMeasure& m) {
  for (std::size_t i = 0; i < out.size() && i < est.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      m.max_abs_diff =
          std::max(m.max_abs_diff, static_cast<double>(std::fabs(out[i][k] - est[i][k])));
      m.max_abs_value = std::max(m.max_abs_value, static_cast<double>(std::fabs(out[i][k])));
    }
  if (est.size() != out.size()) m.max_abs_diff = INFINITY;
}

class BenchBackend final : public TraceBackend {
 public:
  BenchBackend(const RayScene& rays, const LightSampler& lights, MeasureOptions options)
      : rays_(&rays),
        lights_(&lights),
        inner_(rays, lights),
        packets_(rays, lights),
        single_(rays, lights),
        options_(options) {
    packets_.set_shadow_rays(ShadowRays::Packets);
    single_.set_shadow_rays(ShadowRays::Single);
  }

  bool measuring = false;
  std::vector<PassMeasure> results;

  std::string name() const override { return "embree (benchmarked)"; }
  void scene_changed() override {
    for (EmbreeBackend* b : {&inner_, &packets_, &single_}) b->scene_changed();
  }

  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override {
    if (!measuring) return inner_.direct(in, out);
    // The learned light cache as the pass about to run sees it (each run learns from its
    // samples): the captured rays and the forced ways use that state.
    // Every repetition starts from the state before the first (else each would learn from the
    // same update's random numbers and the returned output would be tuned to them).
    const LightCache before = inner_.light_cache();
    Capture c = capture_direct(*rays_, *lights_, before, in);
    auto run = [&] {
      inner_.set_light_cache(before);
      return inner_.direct(in, out);
    };
    auto shade = [&](std::vector<glm::vec3>& est) { shade_direct(*rays_, *lights_, in, c, est); };
    std::vector<glm::vec3> forced_out;
    auto forced = [&](ShadowRays mode) {
      EmbreeBackend& way = mode == ShadowRays::Packets ? packets_ : single_;
      way.set_light_cache(before);
      const PassResult r = way.direct(in, forced_out);
      if (forced_out.size() != out.size())
        throw Error("direct: a forced way's output has another size");
      std::uint64_t differ = 0;
      for (std::size_t i = 0; i < out.size(); ++i)
        differ += std::memcmp(&out[i], &forced_out[i], sizeof(glm::vec3)) != 0;
      forced_differ_ += differ;
      return r;
    };
    return measure("direct", in, c, run, shade, out, forced);
  }

  PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                           std::vector<glm::vec3>& out) override {
    if (!measuring) return inner_.gather_probes(in, prev, out);
    Capture c = capture_probes(in);
    auto run = [&] { return inner_.gather_probes(in, prev, out); };
    auto shade = [&](std::vector<glm::vec3>& est) { shade_probes(*rays_, in, prev, c, est); };
    return measure("probes", in, c, run, shade, out);
  }

  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override {
    if (!measuring) return inner_.scatter(in, prev, probe_radiance, out);
    Capture c = capture_scatter(*rays_, in);
    auto run = [&] { return inner_.scatter(in, prev, probe_radiance, out); };
    auto shade = [&](std::vector<glm::vec3>& est) {
      shade_scatter(*rays_, in, prev, probe_radiance, c, est);
    };
    return measure("scatter", in, c, run, shade, out);
  }

 private:
  // Runs the engine pass, RayScene and raw Embree on the captured rays, interleaved, and
  // checks the captured rays against the pass's output.
  template <typename Run, typename Shade>
  PassResult measure(const char* pass, const PassInput& in, const Capture& c, Run&& run,
                     Shade&& shade, std::vector<glm::vec3>& out) {
    return measure(pass, in, c, run, shade, out, std::function<PassResult(ShadowRays)>());
  }
  // The same, and where `forced` is given (the direct pass) also forced(Packets) and
  // forced(Single) in each repetition.
  template <typename Run, typename Shade>
  PassResult measure(const char* pass, const PassInput& in, const Capture& c, Run&& run,
                     Shade&& shade, std::vector<glm::vec3>& out,
                     const std::function<PassResult(ShadowRays)>& forced) {
    PassMeasure m;
    m.pass = pass;
    m.bounce = in.bounce;
    m.kind = c.kind;
    m.traced_rays = c.rays.size();
    PassResult first = run();  // warm-up, and the output to verify
    m.engine_rays = first.rays;
    std::vector<glm::vec3> est;
    shade(est);
    compare(out, est, m);
    const RTCScene scene = rays_->embree_scene();
    trace_raw(scene, c);  // warm-up
    m.packet_disagreements = packet_disagreements(scene, c);
    int reps = options_.min_reps;
    if (first.seconds > 0.0)
      reps = std::clamp(static_cast<int>(std::ceil(options_.min_seconds / first.seconds)),
                        options_.min_reps, options_.max_reps);
    PassResult last = first;
    const bool cpu = options_.cpu_time;
    for (int r = 0; r < reps; ++r) {
      double c0 = thread_cpu_seconds();
      last = run();
      m.pipeline_s.push_back(cpu ? thread_cpu_seconds() - c0 : last.seconds);
      if (forced) {
        for (ShadowRays mode : {ShadowRays::Packets, ShadowRays::Single}) {
          c0 = thread_cpu_seconds();
          const PassResult f = forced(mode);
          (mode == ShadowRays::Packets ? m.packets_s : m.single_s)
              .push_back(cpu ? thread_cpu_seconds() - c0 : f.seconds);
        }
        // What Auto did in this scene.
        m.auto_packet_share = last.rays > 0 ? static_cast<double>(inner_.direct_packet_rays()) /
                                                  static_cast<double>(last.rays)
                                            : 0.0;
        m.forced_differ = forced_differ_;
      }
      auto t0 = Clock::now();
      c0 = thread_cpu_seconds();
      std::uint64_t raw_hits = trace_raw(scene, c);
      m.raw_s.push_back(cpu ? thread_cpu_seconds() - c0 : seconds_since(t0));
      t0 = Clock::now();
      c0 = thread_cpu_seconds();
      std::uint64_t scene_hits = trace_rayscene(*rays_, c);
      m.rayscene_s.push_back(cpu ? thread_cpu_seconds() - c0 : seconds_since(t0));
      if (raw_hits != scene_hits)
        throw Error(std::string(pass) + ": raw Embree and RayScene disagree on the hits");
      if (!c.packets.empty()) {
        t0 = Clock::now();
        c0 = thread_cpu_seconds();
        const std::uint64_t packet_hits = trace_raw_packets(scene, c);
        m.raw_packet_s.push_back(cpu ? thread_cpu_seconds() - c0 : seconds_since(t0));
        if (c.kind != Kind::Occlusion && packet_hits != raw_hits)
          throw Error(std::string(pass) + ": raw packets and single rays disagree on the hits");
      }
      m.hits = raw_hits;
    }
    results.push_back(std::move(m));
    return last;
  }

  const RayScene* rays_;
  const LightSampler* lights_;
  EmbreeBackend inner_;
  EmbreeBackend packets_, single_;   // the direct pass with its shadow rays forced either way
  std::uint64_t forced_differ_ = 0;  // texels, over the forced passes so far
  MeasureOptions options_;
};

json pass_json(const PassMeasure& m) {
  return {{"pass", m.pass},
          {"bounce", m.bounce},
          {"kind", m.kind == Kind::Occlusion ? "occluded" : "intersect"},
          {"engine_rays", m.engine_rays},
          {"traced_rays", m.traced_rays},
          {"hits", m.hits},
          {"reps", m.pipeline_s.size()},
          {"pipeline_s_min", minimum(m.pipeline_s)},
          {"rayscene_s_min", minimum(m.rayscene_s)},
          {"raw_s_min", minimum(m.raw_s)},
          {"pipeline_s_median", median(m.pipeline_s)},
          {"rayscene_s_median", median(m.rayscene_s)},
          {"raw_s_median", median(m.raw_s)},
          {"pipeline_s", m.pipeline_s},
          {"rayscene_s", m.rayscene_s},
          {"raw_s", m.raw_s},
          {"raw_packet_s_min", m.raw_packet_s.empty() ? 0.0 : minimum(m.raw_packet_s)},
          {"raw_packet_s", m.raw_packet_s},
          {"packets_s_min", m.packets_s.empty() ? 0.0 : minimum(m.packets_s)},
          {"single_s_min", m.single_s.empty() ? 0.0 : minimum(m.single_s)},
          {"auto_packet_share", m.auto_packet_share},
          {"packet_disagreements", m.packet_disagreements},
          {"forced_differ_texels", m.forced_differ},
          {"verify_max_abs_diff", m.max_abs_diff},
          {"verify_max_abs_value", m.max_abs_value}};
}

}  // namespace

std::vector<PassRow> bench_passes(const std::string& spec, float texels_per_scene,
                                  const MeasureOptions& mo, json& out) {
  auto t0 = Clock::now();
  const PreparedScene s = prepare(load_scene(spec), density(texels_per_scene));
  auto backend = std::make_unique<BenchBackend>(s.rays(), s.lights(), mo);
  BenchBackend* bench = backend.get();
  Engine engine(s.world(), s.atlas(), s.gbuffers(), s.rays(), std::move(backend), EngineParams{});
  const double setup_s = seconds_since(t0);
  engine.update();  // warm-up: caches, TBB threads, probe radiance
  bench->measuring = true;
  t0 = Clock::now();
  engine.update();
  const double measure_s = seconds_since(t0);
  bench->measuring = false;

  std::vector<PassRow> rows;
  json passes = json::array();
  for (const char* pass : {"direct", "probes", "scatter"}) {
    PassRow row;
    row.scene = spec;
    row.pass = pass;
    row.texels = engine.texel_count();
    for (const PassMeasure& m : bench->results) {
      if (m.pass != pass) continue;
      row.engine_rays += m.engine_rays;
      row.traced_rays += m.traced_rays;
      row.hits += m.hits;
      row.pipeline_s += minimum(m.pipeline_s);
      row.rayscene_s += minimum(m.rayscene_s);
      row.raw_s += minimum(m.raw_s);
      if (!m.packets_s.empty()) {
        row.packets_s += minimum(m.packets_s);
        row.single_s += minimum(m.single_s);
        row.auto_packet_share = m.auto_packet_share;
        row.packet_disagreements += m.packet_disagreements;
      }
      row.reps = static_cast<int>(m.pipeline_s.size());
      double rel = m.max_abs_value > 0 ? m.max_abs_diff / m.max_abs_value : m.max_abs_diff;
      row.max_rel_diff = std::max(row.max_rel_diff, rel);
    }
    rows.push_back(row);
  }
  for (const PassMeasure& m : bench->results) passes.push_back(pass_json(m));
  out.push_back({{"scene", spec},
                 {"texels_per_scene", texels_per_scene},
                 {"texels", engine.texel_count()},
                 {"atlas_texels", s.atlas().texel_count()},
                 {"triangles",
                  [&] {
                    std::size_t n = 0;
                    for (const auto& o : s.world().objects) n += o.triangles().size();
                    return n;
                  }()},
                 {"probes", engine.probes().count()},
                 {"setup_s", setup_s},
                 {"measured_update_wall_s", measure_s},
                 {"passes", passes}});
  return rows;
}

}  // namespace irradcast::bench

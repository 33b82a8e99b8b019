// irradcast-bench-engine: how fast the GI engine's passes trace rays compared with raw Embree on
// the very same rays, and how the cost of a full update grows with the number of texels.
//
// 1. Pass throughput. The engine runs on a BenchBackend, a TraceBackend that forwards every pass
//    to the real EmbreeBackend. In the measured update it also regenerates, from the PassInput it
//    is handed, the exact rays that pass traces (the backend's own sampling code, copied below),
//    and then times, side by side and interleaved, repetitions of
//      - the engine pass itself (EmbreeBackend, as the engine calls it),
//      - the same rays through RayScene::intersect / occluded (the wrapper alone),
//      - the same rays through rtcIntersect1 / rtcOccluded1 in a tight TBB loop (raw Embree),
//    all on the same BVH (RayScene::embree_scene()) and the same TBB thread pool. Regenerated rays
//    are checked against the engine: shading them with the engine's formulas must reproduce the
//    pass's output.
// 2. Scaling. Full updates (1 direct + K indirect bounces, default parameters) on rooms:N for
//    growing N at a constant number of texels per metre, and on one rooms:M at growing density,
//    all measured in interleaved rounds (fastest kept); a least-squares line through update time
//    against texel count gives the cost per texel and R^2.
//
// Prints a table, writes JSON and two PNG plots (see docs/BENCHMARKS.md).
#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/common/atlas.h"
#include "irradcast/common/builtin.h"
#include "irradcast/engine/embree_backend.h"
#include "irradcast/engine/engine.h"
#include "irradcast/common/error.h"
#include "irradcast/engine/gbuffer.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/texel_validity.h"
#include "irradcast/common/world.h"
#include "plot.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

double minimum(const std::vector<double>& v) {
  return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end());
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// ---------------------------------------------------------------------------------------------
// The rays of one pass.

enum class Kind { Occlusion, Intersection };

struct RawRay {
  glm::vec3 org;
  float tmin;
  glm::vec3 dir;
  float tmax;
};

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
  // Gather / scatter: the output entry each ray belongs to (probe texel / surface texel).
  std::vector<std::uint32_t> owner;
};

// Copies of the backend's private helpers (server/engine/src/embree_backend.cpp): stream ids, the
// per-texel RNG, and the shading of a hit and of a probe lookup.
enum Stream : std::uint64_t { kDirect = 1, kProbe = 2, kScatter = 3, kProbePick = 4 };

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

// Texels in the order the backend's for_each_texel visits them (units in dispatch order).
template <typename Body>
void for_each_texel_in_order(const PassInput& in, Body&& body) {
  for (std::size_t k = 0; k < in.unit_texels.size(); ++k) body(in.unit_texels[k]);
}

// ---------------------------------------------------------------------------------------------
// Tracing the captured rays: raw Embree, and through RayScene.

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
                          const RawRay& s = rays[i];
                          RTCRay ray;
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
                          rtcOccluded1(scene, &ctx, &ray);
                          local += ray.tfar < 0.0f;
                        }
                      } else {
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          const RawRay& s = rays[i];
                          RTCRayHit rh;
                          rh.ray.org_x = s.org.x;
                          rh.ray.org_y = s.org.y;
                          rh.ray.org_z = s.org.z;
                          rh.ray.tnear = s.tmin;
                          rh.ray.dir_x = s.dir.x;
                          rh.ray.dir_y = s.dir.y;
                          rh.ray.dir_z = s.dir.z;
                          rh.ray.time = 0.0f;
                          rh.ray.tfar = s.tmax;
                          rh.ray.mask = 0xFFFFFFFFu;
                          rh.ray.id = 0;
                          rh.ray.flags = 0;
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

Ray to_ray(const RawRay& s) {
  Ray r;
  r.origin = s.org;
  r.direction = s.dir;
  r.tmin = s.tmin;
  r.tmax = s.tmax;
  return r;
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
  double max_abs_diff = 0.0;   // regenerated-ray shading vs the pass's output
  double max_abs_value = 0.0;  // of the pass's output
};

struct MeasureOptions {
  int min_reps = 5;
  int max_reps = 200;
  double min_seconds = 0.25;  // of pipeline time per pass
};

class BenchBackend final : public TraceBackend {
 public:
  BenchBackend(const RayScene& rays, const LightSampler& lights, MeasureOptions options)
      : rays_(&rays), lights_(&lights), inner_(rays, lights), options_(options) {
    // The light-pick distribution of LightSampler (common/src/lights.cpp), rebuilt from its
    // emissive triangles the same way.
    const World& world = rays.world();
    std::vector<float> power;
    for (const EmissiveTriangle& e : lights.emissive_triangles()) {
      const Material& m = world.material(e.object, e.triangle);
      power.push_back(luminance(m.emission()) * e.area * (e.double_sided ? 2.0f : 1.0f));
    }
    double total = 0.0;
    for (float p : power) total += p;
    double run = 0.0;
    for (float p : power) {
      run += p;
      cdf_.push_back(static_cast<float>(run / total));
      pick_pdf_.push_back(static_cast<float>(p / total));
    }
    if (!cdf_.empty()) cdf_.back() = 1.0f;
  }

  bool measuring = false;
  std::vector<PassMeasure> results;

  std::string name() const override { return "embree (benchmarked)"; }

  PassResult direct(const PassInput& in, std::vector<glm::vec3>& out) override {
    if (!measuring) return inner_.direct(in, out);
    Capture c = capture_direct(in);
    auto run = [&] { return inner_.direct(in, out); };
    auto shade = [&](std::vector<glm::vec3>& est) {
      std::vector<std::uint8_t> blocked(c.rays.size());
      tbb::parallel_for(std::size_t(0), c.rays.size(),
                        [&](std::size_t i) { blocked[i] = rays_->occluded(to_ray(c.rays[i])); });
      est.assign(in.texels.size(), glm::vec3(0.0f));
      const float n = static_cast<float>(in.params.direct_samples);
      const bool area = !lights_->emissive_triangles().empty();
      for (std::size_t s = 0; s < c.samples.size();) {
        const std::uint32_t t = c.samples[s].texel;
        glm::vec3 e(0.0f), sum(0.0f);
        for (; s < c.samples.size() && c.samples[s].texel == t; ++s) {
          const Capture::LightSample& ls = c.samples[s];
          if (ls.ray >= 0 && blocked[ls.ray]) continue;
          (ls.area ? sum : e) += ls.weight;
        }
        if (area) e += sum / n;
        est[t] = e;
      }
    };
    return measure("direct", in, c, run, shade, out);
  }

  PassResult gather_probes(const PassInput& in, const RadianceField& prev,
                           std::vector<glm::vec3>& out) override {
    if (!measuring) return inner_.gather_probes(in, prev, out);
    Capture c = capture_probes(in);
    auto run = [&] { return inner_.gather_probes(in, prev, out); };
    auto shade = [&](std::vector<glm::vec3>& est) {
      std::vector<Hit> hits = intersect_all(c);
      est.assign(in.probes.count() * in.probes.texels_per_probe(), glm::vec3(0.0f));
      for (std::size_t r = 0; r < c.rays.size(); ++r)
        if (hits[r].valid()) est[c.owner[r]] = radiance_at(prev, hits[r]);
    };
    return measure("probes", in, c, run, shade, out);
  }

  PassResult scatter(const PassInput& in, const RadianceField& prev,
                     const std::vector<glm::vec3>& probe_radiance,
                     std::vector<glm::vec3>& out) override {
    if (!measuring) return inner_.scatter(in, prev, probe_radiance, out);
    Capture c = capture_scatter(in);
    auto run = [&] { return inner_.scatter(in, prev, probe_radiance, out); };
    auto shade = [&](std::vector<glm::vec3>& est) {
      std::vector<Hit> hits = intersect_all(c);
      const int n = in.params.indirect_samples;
      const float extent = in.world.bounds.max_extent();
      const bool unbiased = in.params.unbiased();
      const bool fixed = in.params.distant_point == DistantPoint::FixedDistance;
      est.assign(in.texels.size(), glm::vec3(0.0f));
      for (std::size_t r0 = 0; r0 < c.rays.size(); r0 += static_cast<std::size_t>(n)) {
        const std::uint32_t i = c.owner[r0];
        const glm::vec3 p = in.texels.position[i];
        Rng pick = texel_rng(in.params, i, in.update, kProbePick, in.bounce);
        glm::vec3 sum(0.0f);
        for (int s = 0; s < n; ++s) {
          const Hit& h = hits[r0 + s];
          const glm::vec3 d = c.rays[r0 + s].dir;
          if (h.valid()) {
            sum += radiance_at(prev, h);
          } else if (!unbiased && !in.probe_weights.empty()) {
            // One probe picked by weight from the texel's own stream (EmbreeBackend::scatter).
            glm::vec3 q = fixed ? p + extent * d : exit_point(in.world.bounds, p, d);
            const ProbeWeights& w = in.probe_weights[i];
            const float u = pick.next_float();
            int k = w.count - 1;
            float acc = 0.0f;
            for (int j = 0; j + 1 < w.count; ++j) {
              acc += w.weight[j];
              if (u < acc) {
                k = j;
                break;
              }
            }
            glm::vec3 dd = q - in.probes.position[w.probe[k]];
            float len = glm::length(dd);
            if (len > 0.0f)
              sum += sample_probe(probe_radiance, w.probe[k], in.probes.resolution, dd / len);
          }
        }
        est[i] = sum * (kPi / static_cast<float>(n));
      }
    };
    return measure("scatter", in, c, run, shade, out);
  }

 private:
  // Direct pass rays: punctual_irradiance and area_irradiance / triangle_irradiance of
  // LightSampler, as EmbreeBackend::direct calls them.
  Capture capture_direct(const PassInput& in) const {
    Capture c;
    c.kind = Kind::Occlusion;
    const int n = in.params.direct_samples;
    const auto& tris = lights_->emissive_triangles();
    const bool area = !tris.empty();
    const RayScene& rays = *rays_;
    for_each_texel_in_order(in, [&](std::uint32_t i) {
      const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                      ng = in.texels.geo_normal[i];
      for (const WorldLight& l : in.world.lights) {
        glm::vec3 wi;
        float dist = 3.4e38f;
        float falloff = 1.0f;
        if (l.type == Light::Type::Directional) {
          wi = -l.direction;
        } else {
          glm::vec3 d = l.position - p;
          float dist2 = glm::dot(d, d);
          if (!(dist2 > 0.0f)) continue;
          dist = std::sqrt(dist2);
          wi = d / dist;
          falloff = 1.0f / dist2;
          if (l.range > 0.0f) {
            float r = dist / l.range;
            falloff *= glm::clamp(1.0f - r * r * r * r, 0.0f, 1.0f);
          }
          if (l.type == Light::Type::Spot) {
            float cd = glm::dot(l.direction, -wi);
            float denom = std::max(1e-4f, l.cos_inner - l.cos_outer);
            float t = glm::clamp((cd - l.cos_outer) / denom, 0.0f, 1.0f);
            falloff *= t * t;
          }
        }
        float cos_x = glm::dot(nrm, wi);
        if (cos_x <= 0.0f || falloff <= 0.0f) continue;
        RawRay r{rays.offset(p, ng, wi), 0.0f, wi,
                 l.type == Light::Type::Directional ? 3.4e38f : dist - rays.epsilon()};
        c.samples.push_back(
            {i, static_cast<std::int32_t>(c.rays.size()), l.intensity * (cos_x * falloff), false});
        c.rays.push_back(r);
      }
      if (!area) return;
      Rng rng = texel_rng(in.params, i, in.update, kDirect, 0);
      for (int s = 0; s < n; ++s) {
        float pick = (static_cast<float>(s) + rng.next_float()) / static_cast<float>(n);
        glm::vec2 pos = rng.next_2d();
        auto it = std::upper_bound(cdf_.begin(), cdf_.end(), pick);
        std::size_t li =
            std::min<std::size_t>(static_cast<std::size_t>(it - cdf_.begin()), tris.size() - 1);
        const EmissiveTriangle& e = tris[li];
        glm::vec2 b = uniform_triangle(pos);
        glm::vec3 y = e.p0 + b.x * e.e1 + b.y * e.e2;
        glm::vec3 d = y - p;
        float dist2 = glm::dot(d, d);
        if (!(dist2 > 0.0f)) continue;
        float dist = std::sqrt(dist2);
        glm::vec3 wi = d / dist;
        float cos_x = glm::dot(nrm, wi);
        if (cos_x <= 0.0f) continue;
        float cos_y = -glm::dot(e.normal, wi);
        if (e.double_sided) cos_y = std::fabs(cos_y);
        if (cos_y <= 0.0f) continue;
        RawRay r;
        r.org = rays.offset(p, ng, wi);
        glm::vec3 to_light = y - r.org;
        float len = glm::length(to_light);
        r.dir = to_light / len;
        r.tmin = 0.0f;
        r.tmax = len - rays.epsilon();
        glm::vec3 le = in.world.emission(e.object, e.triangle, b.x, b.y);
        glm::vec3 w = le * (cos_x * cos_y * e.area / dist2) / pick_pdf_[li];
        std::int32_t index = -1;
        if (r.tmax > 0.0f) {
          index = static_cast<std::int32_t>(c.rays.size());
          c.rays.push_back(r);
        }
        c.samples.push_back({i, index, w, true});
      }
    });
    return c;
  }

  // Probe gather rays: EmbreeBackend::gather_probes.
  Capture capture_probes(const PassInput& in) const {
    Capture c;
    const ProbeGrid& g = in.probes;
    const int res = g.resolution;
    const std::size_t per = g.texels_per_probe();
    for (std::size_t pi = 0; pi < g.count(); ++pi) {
      if (!g.usable[pi]) continue;
      Rng rng = texel_rng(in.params, pi, in.update, kProbe, in.bounce);
      for (std::size_t t = 0; t < per; ++t) {
        glm::vec2 jitter = rng.next_2d();
        glm::vec2 uv((static_cast<float>(t % res) + jitter.x) / res,
                     (static_cast<float>(t / res) + jitter.y) / res);
        c.rays.push_back({g.position[pi], 0.0f, octahedral_decode(uv), 3.4e38f});
        c.owner.push_back(static_cast<std::uint32_t>(pi * per + t));
      }
    }
    return c;
  }

  // Scatter rays: EmbreeBackend::scatter.
  Capture capture_scatter(const PassInput& in) const {
    Capture c;
    const int n = in.params.indirect_samples;
    const float extent = in.world.bounds.max_extent();
    const float range = in.params.unbiased() ? 3.4e38f : in.params.tracing_range * extent;
    c.rays.reserve(in.texels.size() * static_cast<std::size_t>(n));
    for_each_texel_in_order(in, [&](std::uint32_t i) {
      const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                      ng = in.texels.geo_normal[i];
      Rng rng = texel_rng(in.params, i, in.update, kScatter, in.bounce);
      Frame frame(nrm);
      for (int s = 0; s < n; ++s) {
        glm::vec3 dir = frame.to_world(cosine_hemisphere(rng.next_2d()));
        c.rays.push_back({rays_->offset(p, ng, dir), 0.0f, dir, range});
        c.owner.push_back(i);
      }
    });
    return c;
  }

  std::vector<Hit> intersect_all(const Capture& c) const {
    std::vector<Hit> hits(c.rays.size());
    tbb::parallel_for(std::size_t(0), c.rays.size(),
                      [&](std::size_t i) { hits[i] = rays_->intersect(to_ray(c.rays[i])); });
    return hits;
  }

  // Runs the engine pass, RayScene and raw Embree on the captured rays, interleaved, and
  // checks the captured rays against the pass's output.
  template <typename Run, typename Shade>
  PassResult measure(const char* pass, const PassInput& in, const Capture& c, Run&& run,
                     Shade&& shade, std::vector<glm::vec3>& out) {
    PassMeasure m;
    m.pass = pass;
    m.bounce = in.bounce;
    m.kind = c.kind;
    m.traced_rays = c.rays.size();
    PassResult first = run();  // warm-up, and the output to verify
    m.engine_rays = first.rays;
    std::vector<glm::vec3> est;
    shade(est);
    for (std::size_t i = 0; i < out.size() && i < est.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        m.max_abs_diff =
            std::max(m.max_abs_diff, static_cast<double>(std::fabs(out[i][k] - est[i][k])));
        m.max_abs_value = std::max(m.max_abs_value, static_cast<double>(std::fabs(out[i][k])));
      }
    if (est.size() != out.size()) m.max_abs_diff = INFINITY;
    const RTCScene scene = rays_->embree_scene();
    trace_raw(scene, c);  // warm-up
    int reps = options_.min_reps;
    if (first.seconds > 0.0)
      reps = std::clamp(static_cast<int>(std::ceil(options_.min_seconds / first.seconds)),
                        options_.min_reps, options_.max_reps);
    PassResult last = first;
    for (int r = 0; r < reps; ++r) {
      last = run();
      m.pipeline_s.push_back(last.seconds);
      auto t0 = Clock::now();
      std::uint64_t raw_hits = trace_raw(scene, c);
      m.raw_s.push_back(seconds_since(t0));
      t0 = Clock::now();
      std::uint64_t scene_hits = trace_rayscene(*rays_, c);
      m.rayscene_s.push_back(seconds_since(t0));
      if (raw_hits != scene_hits)
        throw Error(std::string(pass) + ": raw Embree and RayScene disagree on the hits");
      m.hits = raw_hits;
    }
    results.push_back(std::move(m));
    return last;
  }

  const RayScene* rays_;
  const LightSampler* lights_;
  EmbreeBackend inner_;
  MeasureOptions options_;
  std::vector<float> cdf_, pick_pdf_;
};

// ---------------------------------------------------------------------------------------------
// Scene set-up, as the bake tool and the engine tests do it.

struct Setup {
  Setup(Scene s, float texels_per_scene)
      : scene(std::move(s)), world(World::build(scene)), rays(world), lights(world) {
    AtlasOptions ao;
    ao.texels_per_scene = texels_per_scene;
    atlas = build_atlas(world, ao);
    gbuffers = rasterize_gbuffer(world, atlas);
    mark_hidden_texels(rays, gbuffers);
  }
  Scene scene;
  World world;
  RayScene rays;
  LightSampler lights;
  Atlas atlas;
  std::vector<TexelGBuffer> gbuffers;
};

struct PassRow {
  std::string scene, pass;
  std::size_t texels = 0;
  std::uint64_t engine_rays = 0, traced_rays = 0, hits = 0;
  double pipeline_s = 0, rayscene_s = 0, raw_s = 0;  // sums over bounces of the fastest reps
  double max_rel_diff = 0;
  int reps = 0;
  double mrays(double s) const { return s > 0 ? traced_rays / s * 1e-6 : 0.0; }
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
          {"verify_max_abs_diff", m.max_abs_diff},
          {"verify_max_abs_value", m.max_abs_value}};
}

std::vector<PassRow> bench_passes(const std::string& spec, float texels_per_scene,
                                  const MeasureOptions& mo, json& out) {
  auto t0 = Clock::now();
  Setup s(load_scene(spec), texels_per_scene);
  auto backend = std::make_unique<BenchBackend>(s.rays, s.lights, mo);
  BenchBackend* bench = backend.get();
  Engine engine(s.world, s.atlas, s.gbuffers, s.rays, std::move(backend), EngineParams{});
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
                 {"atlas_texels", s.atlas.texel_count()},
                 {"triangles",
                  [&] {
                    std::size_t n = 0;
                    for (const auto& o : s.world.objects) n += o.triangles().size();
                    return n;
                  }()},
                 {"probes", engine.probes().count()},
                 {"setup_s", setup_s},
                 {"measured_update_wall_s", measure_s},
                 {"passes", passes}});
  return rows;
}

struct ScalePoint {
  int n = 0;
  float density = 0;  // texels per metre
  float texels_per_scene = 0;
  std::size_t texels = 0, atlas_texels = 0, triangles = 0;
  std::uint64_t rays = 0;
  double setup_s = 0, update_s = 0, direct_s = 0, probes_s = 0, scatter_s = 0;
  std::vector<double> updates_s;
};

// Builds rooms:N for every size, then runs rounds of one update per size (interleaved, so that
// a burst of other load on the machine spreads over all sizes instead of skewing one).
struct CaseSpec {
  int n = 1;
  float density = 16.0f;  // texels per metre
};

std::vector<ScalePoint> bench_updates(const std::vector<CaseSpec>& specs, int updates) {
  struct Case {
    std::unique_ptr<Setup> setup;
    std::unique_ptr<Engine> engine;
    std::vector<double> direct, probes, scatter;
  };
  std::vector<ScalePoint> pts(specs.size());
  std::vector<Case> cases(specs.size());
  for (std::size_t k = 0; k < specs.size(); ++k) {
    std::fprintf(stderr, "scaling: building rooms:%d at %.0f texels/m ...\n", specs[k].n,
                 specs[k].density);
    ScalePoint& pt = pts[k];
    Case& c = cases[k];
    pt.n = specs[k].n;
    pt.density = specs[k].density;
    auto t0 = Clock::now();
    RoomsOptions ro;
    ro.n = specs[k].n;
    Scene scene = make_rooms(ro);
    float extent = World::build(scene).bounds.max_extent();
    pt.texels_per_scene = pt.density * extent;
    c.setup = std::make_unique<Setup>(std::move(scene), pt.texels_per_scene);
    const Setup& s = *c.setup;
    c.engine =
        std::make_unique<Engine>(s.world, s.atlas, s.gbuffers, s.rays,
                                 std::make_unique<EmbreeBackend>(s.rays, s.lights), EngineParams{});
    pt.setup_s = seconds_since(t0);
    pt.texels = c.engine->texel_count();
    pt.atlas_texels = s.atlas.texel_count();
    for (const auto& o : s.world.objects) pt.triangles += o.triangles().size();
    c.engine->update();  // warm-up
  }
  for (int u = 0; u < updates; ++u) {
    std::fprintf(stderr, "scaling: round %d of %d ...\n", u + 1, updates);
    for (std::size_t k = 0; k < specs.size(); ++k) {
      ScalePoint& pt = pts[k];
      Case& c = cases[k];
      UpdateStats st = c.engine->update();
      pt.updates_s.push_back(st.total_seconds);
      c.direct.push_back(st.direct.seconds);
      double p = 0, sc = 0;
      for (const auto& x : st.probes) p += x.seconds;
      for (const auto& x : st.scatter) sc += x.seconds;
      c.probes.push_back(p);
      c.scatter.push_back(sc);
      pt.rays = st.total_rays();
    }
  }
  for (std::size_t k = 0; k < specs.size(); ++k) {
    // The fastest round, and its passes: the cost without interference from other load.
    const auto& u = pts[k].updates_s;
    const std::size_t best =
        static_cast<std::size_t>(std::min_element(u.begin(), u.end()) - u.begin());
    pts[k].update_s = u[best];
    pts[k].direct_s = cases[k].direct[best];
    pts[k].probes_s = cases[k].probes[best];
    pts[k].scatter_s = cases[k].scatter[best];
  }
  return pts;
}

struct Fit {
  double intercept = 0, slope = 0, r2 = 0;
};

Fit fit_line(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < x.size(); ++i) mx += x[i] / n, my += y[i] / n;
  double sxx = 0, sxy = 0, syy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sxx += (x[i] - mx) * (x[i] - mx);
    sxy += (x[i] - mx) * (y[i] - my);
    syy += (y[i] - my) * (y[i] - my);
  }
  Fit f;
  f.slope = sxx > 0 ? sxy / sxx : 0;
  f.intercept = my - f.slope * mx;
  double ss_res = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    double e = y[i] - (f.intercept + f.slope * x[i]);
    ss_res += e * e;
  }
  f.r2 = syy > 0 ? 1.0 - ss_res / syy : 1.0;
  return f;
}

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0) {
      auto p = line.find(':');
      return p == std::string::npos ? line : line.substr(p + 2);
    }
  return "unknown";
}

std::string load_average() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

std::vector<int> parse_sizes(const std::string& text) {
  std::vector<int> sizes;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) sizes.push_back(std::stoi(item));
  return sizes;
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, v);
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"irradcast-bench-engine: engine passes vs raw Embree, update time vs texels"};
  std::string out_dir = "docs/images", json_path;
  std::string scenes_text = "cornell,rooms:2", sizes_text = "1,2,3,4,6";
  float texels_per_scene = AtlasOptions{}.texels_per_scene;
  float density = 16.0f;
  int updates = 5, threads = 0;
  int sweep_size = 2;
  std::string sweep_text = "8,16,24,32";
  MeasureOptions mo;
  bool skip_passes = false, skip_scaling = false;
  app.add_option("--out", out_dir, "directory for the PNG plots (and the JSON by default)");
  app.add_option("--json", json_path, "JSON results file (default OUT/bench_engine.json)");
  app.add_option("--scenes", scenes_text, "scenes for the pass benchmark, comma separated");
  app.add_option("--texels-per-scene", texels_per_scene,
                 "atlas density for the pass benchmark (the engine default)");
  app.add_option("--sizes", sizes_text, "N of rooms:N for the scaling benchmark");
  app.add_option("--density", density, "texels per metre for the scaling benchmark");
  app.add_option("--sweep-size", sweep_size, "M of rooms:M for the density sweep");
  app.add_option("--sweep-densities", sweep_text,
                 "texels per metre for the density sweep, comma separated (empty: none)");
  app.add_option("--updates", updates, "timed updates (rounds) per configuration; fastest kept");
  app.add_option("--reps", mo.min_reps, "minimum repetitions per pass");
  app.add_option("--min-time", mo.min_seconds, "minimum engine seconds per pass measurement");
  app.add_option("--threads", threads, "TBB threads (0: all cores)");
  app.add_flag("--skip-passes", skip_passes, "skip the pass-vs-Embree benchmark");
  app.add_flag("--skip-scaling", skip_scaling, "skip the update-vs-texels benchmark");
  CLI11_PARSE(app, argc, argv);

  try {
    Progress::set_enabled(false);
    log::set_level(log::Level::Warn);
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0)
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(threads));
    const int used_threads = static_cast<int>(
        tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
    fs::create_directories(out_dir);
    if (json_path.empty()) json_path = (fs::path(out_dir) / "bench_engine.json").string();
    auto start = Clock::now();

    json result;
    result["machine"] = {{"cpu", cpu_model()},
                         {"hardware_threads", std::thread::hardware_concurrency()},
                         {"tbb_threads", used_threads},
                         {"embree", RTC_VERSION_STRING},
                         {"load_average_at_start", load_average()}};
    result["params"] = {{"engine", "EngineParams defaults"},
                        {"pass_texels_per_scene", texels_per_scene},
                        {"scaling_texels_per_metre", density},
                        {"density_sweep_scene", "rooms:" + std::to_string(sweep_size)},
                        {"density_sweep_texels_per_metre", sweep_text},
                        {"scaling_updates", updates},
                        {"min_reps", mo.min_reps},
                        {"min_seconds", mo.min_seconds}};
    std::printf(
        "irradcast-bench-engine: %s, %u hardware threads, %d TBB threads, Embree %s, load "
        "average %s\n",
        cpu_model().c_str(), std::thread::hardware_concurrency(), used_threads, RTC_VERSION_STRING,
        load_average().c_str());

    // 1. Pass throughput against raw Embree.
    if (!skip_passes) {
      std::vector<PassRow> rows;
      json scenes = json::array();
      std::stringstream ss(scenes_text);
      std::string spec;
      while (std::getline(ss, spec, ',')) {
        if (spec.empty()) continue;
        std::fprintf(stderr, "passes: %s ...\n", spec.c_str());
        for (auto& r : bench_passes(spec, texels_per_scene, mo, scenes)) rows.push_back(r);
      }
      result["passes"] = scenes;
      std::printf(
          "\nEngine passes vs raw Embree on the same rays (one update, bounces summed, fastest of "
          "the interleaved repetitions)\n");
      std::printf("%-8s %-8s %9s %11s %11s %6s %10s %10s %10s %10s %8s %8s %9s\n", "scene", "pass",
                  "texels", "rays(eng)", "rays(trc)", "hit", "engine ms", "eng Mr/s", "RS Mr/s",
                  "raw Mr/s", "eng/raw", "RS/raw", "verify");
      json table = json::array();
      for (const PassRow& r : rows) {
        double ratio = r.pipeline_s > 0 ? r.raw_s / r.pipeline_s : 0;
        double rs_ratio = r.rayscene_s > 0 ? r.raw_s / r.rayscene_s : 0;
        std::printf(
            "%-8s %-8s %9zu %11llu %11llu %5.1f%% %10.2f %10.2f %10.2f %10.2f %7.1f%% %7.1f%% "
            "%9.1e\n",
            r.scene.c_str(), r.pass.c_str(), r.texels,
            static_cast<unsigned long long>(r.engine_rays),
            static_cast<unsigned long long>(r.traced_rays),
            r.traced_rays ? 100.0 * r.hits / r.traced_rays : 0.0, r.pipeline_s * 1e3,
            r.mrays(r.pipeline_s), r.mrays(r.rayscene_s), r.mrays(r.raw_s), 100 * ratio,
            100 * rs_ratio, r.max_rel_diff);
        table.push_back({{"scene", r.scene},
                         {"pass", r.pass},
                         {"texels", r.texels},
                         {"engine_rays", r.engine_rays},
                         {"traced_rays", r.traced_rays},
                         {"hits", r.hits},
                         {"engine_s", r.pipeline_s},
                         {"rayscene_s", r.rayscene_s},
                         {"raw_s", r.raw_s},
                         {"engine_mrays_per_s", r.mrays(r.pipeline_s)},
                         {"engine_reported_mrays_per_s",
                          r.pipeline_s > 0 ? r.engine_rays / r.pipeline_s * 1e-6 : 0.0},
                         {"rayscene_mrays_per_s", r.mrays(r.rayscene_s)},
                         {"raw_mrays_per_s", r.mrays(r.raw_s)},
                         {"engine_over_raw", ratio},
                         {"rayscene_over_raw", rs_ratio},
                         {"verify_max_rel_diff", r.max_rel_diff}});
      }
      result["pass_table"] = table;
      std::printf(
          "rays(eng): what the pass reports; rays(trc): rays actually traced (the direct pass "
          "counts light samples, not shadow rays).\nMr/s: traced rays per second; eng/raw = "
          "engine throughput / raw Embree throughput on the same rays; RS = through RayScene.\n"
          "hit: rays occluded (direct) or hitting within their tmax (probes, scatter); a scatter "
          "miss reads one probe, picked by weight.\nverify: max |regenerated-ray shading - pass "
          "output| / "
          "max |pass output|.\n");

      plot::BarChart chart;
      chart.title = "Engine passes vs raw Embree, same rays";
      chart.note =
          std::to_string(used_threads) +
          " threads, default engine params, the same rays on the same BVH; % = engine / raw Embree";
      chart.y_label = "Mrays/s";
      chart.series_labels = {"engine pass", "via RayScene", "raw Embree"};
      chart.colors = {plot::kBlue, plot::kGreen, plot::kOrange};
      chart.mark_label = "70% of raw (goal)";
      chart.values.assign(3, {});
      for (const PassRow& r : rows) {
        double ratio = r.pipeline_s > 0 ? r.raw_s / r.pipeline_s : 0;
        chart.categories.push_back(r.scene + "\n" + r.pass + "\n" + fmt("%.0f%%", 100 * ratio));
        chart.values[0].push_back(r.mrays(r.pipeline_s));
        chart.values[1].push_back(r.mrays(r.rayscene_s));
        chart.values[2].push_back(r.mrays(r.raw_s));
        chart.marks.push_back(0.7 * r.mrays(r.raw_s));
      }
      chart.height = 640;
      std::string png = (fs::path(out_dir) / "bench_pass_vs_embree.png").string();
      plot::write_bar_chart(png, chart);
      std::printf("wrote %s\n", png.c_str());
    }

    // 2. Update time against texel count: rooms:N at a fixed density (the building grows), and
    // rooms:M at growing density (the same building, more texels).
    if (!skip_scaling) {
      std::vector<CaseSpec> specs;
      const std::vector<int> sizes = parse_sizes(sizes_text);
      const std::vector<int> densities = parse_sizes(sweep_text);
      for (int n : sizes) specs.push_back({n, density});
      for (int d : densities) specs.push_back({sweep_size, static_cast<float>(d)});
      // The same configuration in both series (rooms:M at the fixed density) is measured once.
      std::vector<CaseSpec> unique;
      std::vector<std::size_t> slot;
      for (const CaseSpec& c : specs) {
        auto it = std::find_if(unique.begin(), unique.end(), [&](const CaseSpec& u) {
          return u.n == c.n && u.density == c.density;
        });
        slot.push_back(static_cast<std::size_t>(it - unique.begin()));
        if (it == unique.end()) unique.push_back(c);
      }
      const std::vector<ScalePoint> measured = bench_updates(unique, updates);
      std::vector<ScalePoint> all;
      for (std::size_t k : slot) all.push_back(measured[k]);
      struct Sweep {
        std::string key, title;
        std::vector<ScalePoint> pts;
        Fit fit;
        double cmin = INFINITY, cmax = 0, cmean = 0;
      };
      std::vector<Sweep> sweeps(2);
      sweeps[0].key = "scaling";
      sweeps[0].title = "rooms:N at " + fmt("%.0f", density) + " texels/m";
      sweeps[0].pts.assign(all.begin(), all.begin() + static_cast<long>(sizes.size()));
      sweeps[1].key = "density_sweep";
      sweeps[1].title = "rooms:" + std::to_string(sweep_size) + " at " + sweep_text + " texels/m";
      sweeps[1].pts.assign(all.begin() + static_cast<long>(sizes.size()), all.end());
      std::printf(
          "\nFull update (1 direct + %d bounces, default params) vs texels, fastest of %d "
          "interleaved rounds\n",
          EngineParams{}.indirect_bounces, updates);
      std::printf("%-9s %6s %10s %11s %10s %11s %10s %10s %10s %10s %10s %9s\n", "scene", "tex/m",
                  "texels", "atlas tex", "triangles", "rays", "update ms", "direct ms", "probes ms",
                  "scatter ms", "other ms", "us/texel");
      for (Sweep& sw : sweeps) {
        if (sw.pts.empty()) continue;
        std::vector<double> x, y;
        for (const auto& p : sw.pts) {
          x.push_back(static_cast<double>(p.texels));
          y.push_back(p.update_s);
          double c = p.update_s / p.texels;
          sw.cmin = std::min(sw.cmin, c);
          sw.cmax = std::max(sw.cmax, c);
          sw.cmean += c / sw.pts.size();
        }
        sw.fit = fit_line(x, y);
        json rows = json::array();
        for (const auto& p : sw.pts) {
          double other = p.update_s - p.direct_s - p.probes_s - p.scatter_s;
          std::printf(
              "rooms:%-3d %6.0f %10zu %11zu %10zu %11llu %10.1f %10.1f %10.1f %10.1f %10.1f "
              "%9.3f\n",
              p.n, p.density, p.texels, p.atlas_texels, p.triangles,
              static_cast<unsigned long long>(p.rays), p.update_s * 1e3, p.direct_s * 1e3,
              p.probes_s * 1e3, p.scatter_s * 1e3, other * 1e3, p.update_s / p.texels * 1e6);
          rows.push_back({{"scene", "rooms:" + std::to_string(p.n)},
                          {"texels_per_metre", p.density},
                          {"texels_per_scene", p.texels_per_scene},
                          {"texels", p.texels},
                          {"atlas_texels", p.atlas_texels},
                          {"triangles", p.triangles},
                          {"rays_per_update", p.rays},
                          {"setup_s", p.setup_s},
                          {"update_s_min", p.update_s},
                          {"update_s_median", median(p.updates_s)},
                          {"updates_s", p.updates_s},
                          {"direct_s", p.direct_s},
                          {"probes_s", p.probes_s},
                          {"scatter_s", p.scatter_s},
                          {"other_s", other},
                          {"us_per_texel", p.update_s / p.texels * 1e6}});
        }
        std::printf(
            "  %s: update = %.2f ms + %.4f us x texels, R^2 = %.5f; per-texel cost %.3f .. "
            "%.3f us (spread %.1f%% of the mean)\n",
            sw.title.c_str(), sw.fit.intercept * 1e3, sw.fit.slope * 1e6, sw.fit.r2, sw.cmin * 1e6,
            sw.cmax * 1e6, 100 * (sw.cmax - sw.cmin) / sw.cmean);
        result[sw.key] = rows;
        result[sw.key + "_fit"] = {{"series", sw.title},
                                   {"intercept_s", sw.fit.intercept},
                                   {"slope_s_per_texel", sw.fit.slope},
                                   {"r2", sw.fit.r2},
                                   {"us_per_texel_min", sw.cmin * 1e6},
                                   {"us_per_texel_max", sw.cmax * 1e6},
                                   {"us_per_texel_mean", sw.cmean * 1e6},
                                   {"spread_of_mean", (sw.cmax - sw.cmin) / sw.cmean}};
      }

      plot::XYPlot xy;
      xy.title = "Full update time vs texel count";
      xy.note = std::to_string(used_threads) +
                " threads, default engine params (1 direct + 2 bounces), fastest of " +
                std::to_string(updates) + " updates; lines: least-squares fits";
      xy.x_label = "valid texels (thousands)";
      xy.y_label = "update time (ms)";
      xy.legend = plot::XYPlot::Legend::BottomRight;
      const plot::Color colors[2][2] = {{plot::kBlue, plot::kBlue}, {plot::kGreen, plot::kGreen}};
      double xmax = 0;
      for (const auto& p : all) xmax = std::max(xmax, static_cast<double>(p.texels));
      for (std::size_t k = 0; k < sweeps.size(); ++k) {
        const Sweep& sw = sweeps[k];
        if (sw.pts.empty()) continue;
        plot::Series meas, line;
        meas.label = sw.title;
        meas.color = colors[k][0];
        meas.labels_above_left = k == 0;
        line.label = fmt("fit: %.0f ms", sw.fit.intercept * 1e3) +
                     fmt(" + %.3f us/texel", sw.fit.slope * 1e6) + fmt(", R^2 %.4f", sw.fit.r2);
        line.color = colors[k][1];
        line.points = false;
        line.lines = true;
        line.line_width = 1.5;
        double sxmax = 0;
        for (const auto& p : sw.pts) {
          meas.x.push_back(p.texels * 1e-3);
          meas.y.push_back(p.update_s * 1e3);
          meas.labels.push_back(k == 0 ? "rooms:" + std::to_string(p.n) : fmt("%.0f/m", p.density));
          sxmax = std::max(sxmax, static_cast<double>(p.texels));
        }
        // The line from where it crosses zero time (or zero texels) to the largest point.
        double x0 =
            sw.fit.intercept < 0 && sw.fit.slope > 0 ? -sw.fit.intercept / sw.fit.slope : 0.0;
        for (double xv : {x0, sxmax}) {
          line.x.push_back(xv * 1e-3);
          line.y.push_back((sw.fit.intercept + sw.fit.slope * xv) * 1e3);
        }
        xy.series.push_back(meas);
        xy.series.push_back(line);
      }
      std::string png = (fs::path(out_dir) / "bench_update_vs_texels.png").string();
      plot::write_xy_plot(png, xy);
      std::printf("wrote %s\n", png.c_str());
    }

    result["machine"]["load_average_at_end"] = load_average();
    result["total_wall_s"] = seconds_since(start);
    std::ofstream(json_path) << result.dump(2) << "\n";
    std::printf("wrote %s (total %.1f s, load average at the end %s)\n", json_path.c_str(),
                seconds_since(start), load_average().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}

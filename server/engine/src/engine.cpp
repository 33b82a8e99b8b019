#include "irradcast/engine/engine.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

// Unit directions spread evenly over the sphere (spherical Fibonacci).
std::vector<glm::vec3> sphere_directions(int n) {
  std::vector<glm::vec3> dirs;
  const float golden = kPi * (3.0f - std::sqrt(5.0f));
  for (int i = 0; i < n; ++i) {
    float z = 1.0f - (2.0f * static_cast<float>(i) + 1.0f) / static_cast<float>(n);
    float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    float phi = golden * static_cast<float>(i);
    dirs.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
  }
  return dirs;
}

struct Spot {
  float backface = 1.0f;  // fraction of rays that hit the back of a surface
  float nearest = 0.0f;   // distance to the nearest surface
};

Spot probe_spot(const RayScene& rays, const World& world, glm::vec3 p,
                const std::vector<glm::vec3>& dirs) {
  int back = 0;
  float nearest = 3.4e38f;
  for (const glm::vec3& d : dirs) {
    Ray r;
    r.origin = p;
    r.direction = d;
    Hit h = rays.intersect(r);
    if (!h.valid()) continue;
    nearest = std::min(nearest, h.t);
    if (glm::dot(world.objects[h.object].geometric_normal(h.triangle), d) > 0.0f) ++back;
  }
  return {static_cast<float>(back) / static_cast<float>(dirs.size()), nearest};
}

}  // namespace

std::uint64_t UpdateStats::total_rays() const {
  std::uint64_t n = direct.rays + prepare.rays;
  for (const auto& p : probes) n += p.rays;
  for (const auto& s : scatter) n += s.rays;
  return n;
}

Engine::Engine(const World& world, const Atlas& atlas, const std::vector<TexelGBuffer>& gbuffers,
               const RayScene& rays, std::unique_ptr<TraceBackend> backend, EngineParams params,
               const LightSampler* lights)
    : world_(&world),
      atlas_(&atlas),
      gbuffers_(&gbuffers),
      rays_(&rays),
      backend_(std::move(backend)),
      params_(params) {
  params_.validate();
  if (params_.method != Method::Cells) {
    if (!lights) throw Error("engine: method " + method_name(params_.method) + " needs the lights");
    method_ = make_indirect_method(params_, world, rays, *lights);
  }
  // Seed 001 section 4.3.2 and our rooms test: probes stand in for everything beyond the range,
  // so a range much shorter than a cell makes the probes' parallax dominate the error.
  if (params_.uses_probes() && params_.tracing_range < 0.4f * params_.cell_size)
    log::warn("engine", "tracing range " + std::to_string(params_.tracing_range) +
                            " is short for cells of " + std::to_string(params_.cell_size) +
                            ": expect probe error; use a cell size of at most " +
                            std::to_string(2.5f * params_.tracing_range));
  if (gbuffers.size() != world.objects.size() || atlas.objects.size() != world.objects.size())
    throw Error("engine: atlas and G-buffers do not match the scene's objects");
  build_texels(gbuffers);
  build_probes();
  build_dispatch();
  const int k = params_.indirect_bounces;
  mean_.assign(k + 1, std::vector<glm::vec3>(texels_.size(), glm::vec3(0.0f)));
  probe_mean_.assign(k + 1, std::vector<glm::vec3>());
  samples_.assign(texels_.size(), 0);
  bounce_samples_.assign(texels_.size(), 0);
  total_mean_.assign(texels_.size(), 0.0);
  total_m2_.assign(texels_.size(), 0.0);
}

Engine::~Engine() = default;

void Engine::build_texels(const std::vector<TexelGBuffer>& gbuffers) {
  texels_ = SurfaceTexels{};
  std::size_t total = 0;
  for (const auto& g : gbuffers) total += g.valid_count();
  texels_.position.reserve(total);
  texels_.normal.reserve(total);
  texels_.geo_normal.reserve(total);
  texels_.albedo.reserve(total);
  texels_.object.reserve(total);
  texels_.texel.reserve(total);
  texels_.cell.reserve(total);
  for (std::size_t o = 0; o < gbuffers.size(); ++o) {
    const TexelGBuffer& g = gbuffers[o];
    const WorldObject& obj = world_->objects[o];
    if (!obj.visible) continue;  // hidden by an edit: its lightmap keeps its last values
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i)) continue;
      glm::vec3 n = g.normal[i];
      glm::vec3 ng = obj.geometric_normal(static_cast<std::uint32_t>(g.triangle[i]));
      if (glm::dot(ng, n) < 0.0f) ng = -ng;
      texels_.position.push_back(g.position[i]);
      texels_.normal.push_back(n);
      texels_.geo_normal.push_back(ng);
      texels_.albedo.push_back(g.albedo[i]);
      texels_.object.push_back(static_cast<std::uint32_t>(o));
      texels_.texel.push_back(static_cast<std::uint32_t>(i));
    }
  }
}

void Engine::build_probes() {
  const Bounds& b = world_->bounds;
  const float extent = std::max(b.max_extent(), 1e-6f);
  const int per_axis = static_cast<int>(std::ceil(1.0f / params_.cell_size));
  // Cells are cubes of cell_size x extent; axes shorter than the largest get fewer cells
  // (seed 001 grids the normalised cube; cells outside the bounds would hold nothing).
  probes_.cell = extent / static_cast<float>(per_axis);
  probes_.origin = b.lo;
  glm::vec3 e = b.extent();
  for (int a = 0; a < 3; ++a)
    probes_.dims[a] =
        std::clamp(static_cast<int>(std::ceil(e[a] / probes_.cell - 1e-4f)), 1, per_axis);
  probes_.resolution = params_.probe_resolution;
  const std::size_t count =
      static_cast<std::size_t>(probes_.dims.x) * probes_.dims.y * probes_.dims.z;
  probes_.position.resize(count);
  probes_.usable.assign(count, 1);
  for (int z = 0; z < probes_.dims.z; ++z)
    for (int y = 0; y < probes_.dims.y; ++y)
      for (int x = 0; x < probes_.dims.x; ++x)
        probes_.position[(z * probes_.dims.y + y) * probes_.dims.x + x] =
            probes_.origin + (glm::vec3(x, y, z) + 0.5f) * probes_.cell;
  for (std::size_t i = 0; i < texels_.size(); ++i)
    texels_.cell.push_back(static_cast<std::uint32_t>(probes_.cell_index(texels_.position[i])));
  probe_stats_.probes = count;
  if (!params_.uses_probes()) return;
  std::vector<std::size_t> all(count);
  for (std::size_t i = 0; i < count; ++i) all[i] = i;
  place_probes(all);
  build_probe_weights();
}

void Engine::place_probes(const std::vector<std::size_t>& which) {
  // Probe placement: a probe inside geometry (many rays see back faces) or hugging a surface
  // sees the wrong light; move it to the free spot of its cell farthest from any surface.
  // Always from the cell centre, so a probe placed again after an edit lands where a fresh
  // start on the edited scene would put it.
  for (std::size_t i : which) {
    const glm::ivec3 c(
        static_cast<int>(i % probes_.dims.x),
        static_cast<int>((i / probes_.dims.x) % probes_.dims.y),
        static_cast<int>(i / (static_cast<std::size_t>(probes_.dims.x) * probes_.dims.y)));
    probes_.position[i] = probes_.origin + (glm::vec3(c) + 0.5f) * probes_.cell;
    probes_.usable[i] = 1;
  }
  if (!params_.relocate_probes) return;
  const auto dirs = sphere_directions(64);
  const float too_close = 0.15f * probes_.cell;
  std::vector<std::uint8_t> moved(which.size(), 0);
  tbb::parallel_for(std::size_t(0), which.size(), [&](std::size_t k) {
    const std::size_t i = which[k];
    Spot here = probe_spot(*rays_, *world_, probes_.position[i], dirs);
    if (here.backface < 0.05f && here.nearest >= too_close) return;
    glm::vec3 centre = probes_.position[i];
    glm::vec3 best = centre;
    Spot best_spot = here;
    const int steps = 4;  // candidates on a 9 x 9 x 9 lattice inside the cell
    for (int z = -steps; z <= steps; ++z)
      for (int y = -steps; y <= steps; ++y)
        for (int x = -steps; x <= steps; ++x) {
          glm::vec3 c = centre + glm::vec3(x, y, z) * (0.45f * probes_.cell / steps);
          Spot s = probe_spot(*rays_, *world_, c, dirs);
          bool better = s.backface < best_spot.backface - 1e-6f ||
                        (s.backface <= best_spot.backface + 1e-6f && s.nearest > best_spot.nearest);
          if (better) {
            best = c;
            best_spot = s;
          }
        }
    probes_.position[i] = best;
    moved[k] = best != centre;
    if (best_spot.backface >= 0.05f) probes_.usable[i] = 0;
  });
  if (which.size() == probes_.count()) probe_stats_.relocated = 0;
  probe_stats_.unusable = 0;
  for (std::size_t i = 0; i < probes_.count(); ++i) probe_stats_.unusable += probes_.usable[i] == 0;
  for (std::uint8_t m : moved) probe_stats_.relocated += m;
}

void Engine::build_probe_weights() {
  // Probe weights per texel: trilinear over the 8 surrounding probes, keeping only usable probes
  // the texel can see (a wall between them means the probe sees another room's light).
  probe_weights_.resize(texels_.size());
  tbb::parallel_for(std::size_t(0), texels_.size(), [&](std::size_t t) {
    const glm::vec3 p = texels_.position[t];
    glm::vec3 f = (p - probes_.origin) / probes_.cell - 0.5f;
    glm::ivec3 base = glm::ivec3(glm::floor(f));
    glm::vec3 frac = f - glm::vec3(base);
    ProbeWeights w;
    float sum = 0.0f;
    for (int c = 0; c < 8; ++c) {
      glm::ivec3 o(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      glm::ivec3 cell = base + o;
      if (glm::any(glm::lessThan(cell, glm::ivec3(0))) ||
          glm::any(glm::greaterThanEqual(cell, probes_.dims)))
        continue;
      auto index =
          static_cast<std::uint32_t>((cell.z * probes_.dims.y + cell.y) * probes_.dims.x + cell.x);
      if (!probes_.usable[index]) continue;
      glm::vec3 tw = glm::mix(1.0f - frac, frac, glm::vec3(o));
      float weight = glm::max(tw.x, 0.0f) * glm::max(tw.y, 0.0f) * glm::max(tw.z, 0.0f);
      glm::vec3 to = probes_.position[index] - p;
      float dist = glm::length(to);
      if (params_.probe_visibility && dist > 0.0f) {
        Ray r;
        r.direction = to / dist;
        r.origin = rays_->offset(p, texels_.geo_normal[t], r.direction);
        r.tmax = glm::length(probes_.position[index] - r.origin);
        if (rays_->occluded(r)) continue;
      }
      weight = std::max(weight, 1e-4f);
      w.probe[w.count] = index;
      w.weight[w.count] = weight;
      ++w.count;
      sum += weight;
    }
    if (w.count == 0) {
      // No visible usable neighbour: fall back to the texel's own cell probe.
      w.probe[0] = texels_.cell[t];
      w.weight[0] = 1.0f;
      w.count = 1;
      sum = 1.0f;
    }
    for (int k = 0; k < w.count; ++k) w.weight[k] /= sum;
    probe_weights_[t] = w;
  });
}

void Engine::build_dispatch() {
  unit_texels_.clear();
  unit_offsets_.assign(1, 0);
  const std::size_t n = texels_.size();
  if (params_.dispatch == Dispatch::PerObject) {
    for (std::size_t i = 0; i < n; ++i) {
      if (i > 0 && texels_.object[i] != texels_.object[i - 1])
        unit_offsets_.push_back(static_cast<std::uint32_t>(i));
      unit_texels_.push_back(static_cast<std::uint32_t>(i));
    }
    unit_offsets_.push_back(static_cast<std::uint32_t>(n));
    return;
  }
  // Per cell: a counting sort of the texels by cell, one work unit per non-empty cell.
  std::vector<std::uint32_t> counts(probes_.count() + 1, 0);
  for (std::uint32_t c : texels_.cell) ++counts[c + 1];
  for (std::size_t c = 1; c < counts.size(); ++c) counts[c] += counts[c - 1];
  unit_texels_.resize(n);
  std::vector<std::uint32_t> fill(counts.begin(), counts.end() - 1);
  for (std::size_t i = 0; i < n; ++i)
    unit_texels_[fill[texels_.cell[i]]++] = static_cast<std::uint32_t>(i);
  for (std::size_t c = 1; c < counts.size(); ++c)
    if (counts[c] > counts[c - 1]) unit_offsets_.push_back(counts[c]);
}

std::vector<Lightmap> Engine::to_lightmaps(const std::vector<glm::vec3>& values) const {
  std::vector<Lightmap> maps(world_->objects.size());
  for (std::size_t o = 0; o < maps.size(); ++o)
    maps[o] = Lightmap((*gbuffers_)[o].width, (*gbuffers_)[o].height);
  for (std::size_t i = 0; i < texels_.size(); ++i)
    maps[texels_.object[i]].texels[texels_.texel[i]] = values[i];
  tbb::parallel_for(std::size_t(0), maps.size(), [&](std::size_t o) {
    dilate(maps[o].texels, maps[o].width, maps[o].height, (*gbuffers_)[o].kind);
  });
  return maps;
}

UpdateStats Engine::update() {
  auto start = std::chrono::steady_clock::now();
  UpdateStats stats;
  const int k = params_.indirect_bounces;
  // The texels of this update: every texel, or the next batch of those waiting since an edit
  // (grouped into units where consecutive texels share a cell or an object).
  const bool partial = queue_pos_ < queue_.size();
  std::vector<std::uint32_t> batch_texels, batch_offsets;
  const std::vector<std::uint32_t>* texels = &unit_texels_;
  const std::vector<std::uint32_t>* offsets = &unit_offsets_;
  if (partial) {
    const std::size_t budget = std::max<std::size_t>(
        1, static_cast<std::size_t>(
               std::ceil(params_.edit_batch * static_cast<double>(texels_.size()))));
    const std::size_t end = std::min(queue_.size(), queue_pos_ + budget);
    batch_texels.assign(queue_.begin() + static_cast<std::ptrdiff_t>(queue_pos_),
                        queue_.begin() + static_cast<std::ptrdiff_t>(end));
    queue_pos_ = end;
    const bool by_object = params_.dispatch == Dispatch::PerObject;
    batch_offsets.push_back(0);
    for (std::size_t i = 1; i < batch_texels.size(); ++i) {
      const std::uint32_t a = batch_texels[i - 1], b = batch_texels[i];
      const bool split =
          by_object ? texels_.object[a] != texels_.object[b] : texels_.cell[a] != texels_.cell[b];
      if (split) batch_offsets.push_back(static_cast<std::uint32_t>(i));
    }
    batch_offsets.push_back(static_cast<std::uint32_t>(batch_texels.size()));
    texels = &batch_texels;
    offsets = &batch_offsets;
    ++generation_;
  } else if (!queue_.empty()) {
    // Caught up: back to full updates over the engine's own units.
    queue_.clear();
    queue_pos_ = 0;
    ++generation_;
  }
  PassInput in{*world_,  *atlas_,  texels_, probe_weights_, probes_, params_, *texels,
               *offsets, updates_, 0,       generation_};
  // Running means with per-texel counts: a texel's first sample since a restart replaces what
  // its means held (its values from before an edit).
  auto accumulate = [&](std::vector<glm::vec3>& mean, const std::vector<glm::vec3>& est,
                        const std::vector<std::uint32_t>& count) {
    if (mean.size() != est.size()) mean.assign(est.size(), glm::vec3(0.0f));
    tbb::parallel_for(std::size_t(0), texels->size(), [&](std::size_t j) {
      const std::uint32_t i = (*texels)[j];
      mean[i] += (est[i] - mean[i]) * (1.0f / static_cast<float>(count[i] + 1));
    });
  };
  auto accumulate_probes = [&](std::vector<glm::vec3>& mean, const std::vector<glm::vec3>& est) {
    if (mean.size() != est.size()) mean.assign(est.size(), glm::vec3(0.0f));
    const float w = 1.0f / static_cast<float>(probe_samples_ + 1);
    tbb::parallel_for(std::size_t(0), est.size(),
                      [&](std::size_t i) { mean[i] += (est[i] - mean[i]) * w; });
  };
  std::vector<glm::vec3> est, total;
  PassResult r = backend_->direct(in, est);
  stats.direct = {r.seconds, r.rays};
  accumulate(mean_[0], est, samples_);
  if (partial) {
    // While catching up after an edit: the direct light only. The bounces would read texels
    // that still hold their values from before the edit and so be biased; a restarted texel
    // keeps its old indirect light (and its blend with the old value, see shown()) until the
    // first full update, whose bounces all read new direct light.
    for (std::uint32_t i : *texels) ++samples_[i];
    ++updates_;
    stats.total_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
  }
  total = est;
  if (method_) {
    PassResult pr = method_->prepare(in);
    stats.prepare = {pr.seconds, pr.rays};
  }
  std::vector<Lightmap> prev = to_lightmaps(mean_[0]);
  for (int b = 1; b <= k; ++b) {
    in.bounce = static_cast<std::uint32_t>(b);
    RadianceField field{world_, atlas_, &prev};
    if (method_) {
      stats.probes.push_back({});
      PassResult mr = method_->bounce(in, field, est);
      stats.scatter.push_back({mr.seconds, mr.rays});
      accumulate(mean_[b], est, bounce_samples_);
      for (std::uint32_t i : *texels) total[i] += est[i];
      if (b < k) prev = to_lightmaps(mean_[b]);
      continue;
    }
    PassTiming probe_time;
    if (params_.uses_probes()) {
      std::vector<glm::vec3> probe_est;
      PassResult pr = backend_->gather_probes(in, field, probe_est);
      probe_time = {pr.seconds, pr.rays};
      accumulate_probes(probe_mean_[b], probe_est);
    }
    stats.probes.push_back(probe_time);
    PassResult sr = backend_->scatter(in, field, probe_mean_[b], est);
    stats.scatter.push_back({sr.seconds, sr.rays});
    accumulate(mean_[b], est, bounce_samples_);
    for (std::uint32_t i : *texels) total[i] += est[i];
    if (b < k) prev = to_lightmaps(mean_[b]);
  }
  // Welford statistics of each texel's total per-update estimate (full updates only), for the
  // convergence estimate.
  for (std::uint32_t i : *texels) {
    const double n = static_cast<double>(bounce_samples_[i]) + 1.0;
    double x = luminance(total[i]);
    if (bounce_samples_[i] == 0) total_mean_[i] = total_m2_[i] = 0.0;
    double d = x - total_mean_[i];
    total_mean_[i] += d / n;
    total_m2_[i] += d * (x - total_mean_[i]);
    ++samples_[i];
    ++bounce_samples_[i];
  }
  ++probe_samples_;
  ++updates_;
  stats.total_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

std::uint32_t Engine::min_samples() const {
  if (bounce_samples_.empty()) return updates_;
  return *std::min_element(bounce_samples_.begin(), bounce_samples_.end());
}

std::vector<glm::vec3> Engine::shown() const {
  std::vector<glm::vec3> sum(texels_.size(), glm::vec3(0.0f));
  for (const auto& m : mean_)
    for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += m[i];
  if (before_.size() != sum.size() || params_.edit_blend <= 0.0f) return sum;
  // Hysteresis after an edit: weight exp(-k / tau) on the value from before the edit after k
  // new samples, none once that is below 1 % (so a caught-up texel is never stale).
  const float tau = params_.edit_blend;
  const auto cutoff = static_cast<std::uint32_t>(std::ceil(std::log(100.0f) * tau));
  for (std::size_t i = 0; i < sum.size(); ++i) {
    if (i < restarted_.size() && !restarted_[i]) continue;
    const std::uint32_t n = samples_[i];
    if (n >= cutoff) continue;
    const float w = n == 0 ? 1.0f : std::exp(-static_cast<float>(n) / tau);
    sum[i] = glm::mix(sum[i], before_[i], w);
  }
  return sum;
}

std::vector<Lightmap> Engine::lightmaps() const {
  return to_lightmaps(shown());
}

std::vector<Lightmap> Engine::component(int bounce) const {
  if (bounce < 0 || bounce >= static_cast<int>(mean_.size()))
    throw Error("engine: no bounce " + std::to_string(bounce));
  return to_lightmaps(mean_[bounce]);
}

std::vector<Lightmap> Engine::standard_error() const {
  if (updates_ < 2) return {};
  // Texels with fewer than 2 samples since a restart have no noise estimate: 0, so that any
  // change of theirs counts as real.
  std::vector<glm::vec3> se(texels_.size());
  for (std::size_t i = 0; i < se.size(); ++i) {
    const double n = bounce_samples_[i];
    se[i] = glm::vec3(n < 2 ? 0.0f : static_cast<float>(std::sqrt(total_m2_[i] / (n - 1) / n)));
  }
  return to_lightmaps(se);
}

double Engine::mean_relative_error() const {
  if (updates_ < 2 || texels_.size() == 0) return 1.0;
  double sum = 0.0;
  std::size_t counted = 0;
  for (std::size_t i = 0; i < texels_.size(); ++i) {
    const double n = bounce_samples_[i];
    if (n < 2) {  // restarted by an edit and not yet estimated twice: unknown, counted as 100 %
      sum += 1.0;
      ++counted;
      continue;
    }
    double mean = total_mean_[i];
    if (!(mean > 1e-9)) continue;
    double var = total_m2_[i] / (n - 1);
    sum += std::sqrt(var / n) / mean;
    ++counted;
  }
  return counted ? sum / static_cast<double>(counted) : 0.0;
}

namespace {

// Distance from p to a box (0 inside).
float distance_to(const Bounds& b, glm::vec3 p) {
  const glm::vec3 d = glm::max(glm::max(b.lo - p, p - b.hi), glm::vec3(0.0f));
  return glm::length(d);
}

// Whether the segment a -> b crosses the box (slab test).
bool segment_hits(const Bounds& box, glm::vec3 a, glm::vec3 b) {
  const glm::vec3 d = b - a;
  float t0 = 0.0f, t1 = 1.0f;
  for (int axis = 0; axis < 3; ++axis) {
    if (std::abs(d[axis]) < 1e-20f) {
      if (a[axis] < box.lo[axis] || a[axis] > box.hi[axis]) return false;
      continue;
    }
    float ta = (box.lo[axis] - a[axis]) / d[axis], tb = (box.hi[axis] - a[axis]) / d[axis];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace

void Engine::scene_changed(const SceneChange& change, const std::vector<CameraPose>& cameras) {
  auto lap_start = std::chrono::steady_clock::now();
  change_timings_.clear();
  auto lap = [&](const char* what) {
    const auto now = std::chrono::steady_clock::now();
    change_timings_ += std::string(change_timings_.empty() ? "" : ", ") + what + " " +
                       std::to_string(static_cast<int>(
                           1e3 * std::chrono::duration<double>(now - lap_start).count())) +
                       " ms";
    lap_start = now;
  };
  // What every texel shows now and its old component means, found again by (object, texel)
  // after the rebuild; texels that were not valid before read the old dilated lightmaps.
  const bool rebuild = change.geometry || change.surfaces;
  const std::vector<glm::vec3> shown_before = shown();
  const std::vector<std::vector<glm::vec3>> mean_before = std::move(mean_);
  mean_.assign(mean_before.size(), {});
  // The texel list is rebuilt (moved from) only when geometry or surfaces changed.
  const SurfaceTexels texels_before = rebuild ? std::move(texels_) : texels_;
  const std::vector<std::uint32_t> samples_before = samples_, bounce_before = bounce_samples_;
  const std::vector<double> total_mean_before = total_mean_, total_m2_before = total_m2_;
  const std::vector<std::uint8_t> restarted_before = restarted_;
  if (change.geometry || change.surfaces) {
    build_texels(*gbuffers_);
    for (std::size_t i = 0; i < texels_.size(); ++i)
      texels_.cell.push_back(static_cast<std::uint32_t>(probes_.cell_index(texels_.position[i])));
  }
  lap("texels");
  if (change.geometry && params_.uses_probes()) {
    // Probes in cells a moved object touches (before or after) are placed again.
    std::vector<std::size_t> again;
    const float reach = probes_.cell;
    for (std::size_t p = 0; p < probes_.count(); ++p) {
      const glm::ivec3 c(
          static_cast<int>(p % probes_.dims.x),
          static_cast<int>((p / probes_.dims.x) % probes_.dims.y),
          static_cast<int>(p / (static_cast<std::size_t>(probes_.dims.x) * probes_.dims.y)));
      const glm::vec3 centre = probes_.origin + (glm::vec3(c) + 0.5f) * probes_.cell;
      for (const Bounds& r : change.regions)
        if (distance_to(r, centre) <= reach) {
          again.push_back(p);
          break;
        }
    }
    place_probes(again);
    lap(("probes (" + std::to_string(again.size()) + ")").c_str());
  }
  if ((change.geometry || change.surfaces) && params_.uses_probes()) build_probe_weights();
  if (change.geometry || change.surfaces) build_dispatch();
  lap("probe weights");

  // Every texel restarts; its means keep the old values until its first new sample.
  const std::size_t n = texels_.size();
  std::vector<std::vector<std::int32_t>> old_index(world_->objects.size());
  for (std::size_t o = 0; o < old_index.size(); ++o)
    old_index[o].assign((*gbuffers_)[o].size(), -1);
  for (std::size_t i = 0; i < texels_before.size(); ++i)
    old_index[texels_before.object[i]][texels_before.texel[i]] = static_cast<std::int32_t>(i);
  before_.resize(n);
  for (auto& m : mean_) m.resize(n);
  std::vector<std::uint32_t> missing;
  std::vector<std::int32_t> old_of(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t j = old_index[texels_.object[i]][texels_.texel[i]];
    old_of[i] = j;
    if (j < 0) {
      missing.push_back(static_cast<std::uint32_t>(i));
      continue;
    }
    before_[i] = shown_before[static_cast<std::size_t>(j)];
    for (std::size_t b = 0; b < mean_.size(); ++b)
      mean_[b][i] = mean_before[b][static_cast<std::size_t>(j)];
  }
  if (!missing.empty()) {
    // Newly valid texels (uncovered by a moved object): the old dilated lightmaps there.
    auto dilated = [&](const std::vector<glm::vec3>& values) {
      std::vector<Lightmap> maps(world_->objects.size());
      for (std::size_t o = 0; o < maps.size(); ++o)
        maps[o] = Lightmap((*gbuffers_)[o].width, (*gbuffers_)[o].height);
      std::vector<std::vector<TexelKind>> kinds(maps.size());
      for (std::size_t o = 0; o < maps.size(); ++o)
        kinds[o].assign(maps[o].texels.size(), TexelKind::Empty);
      for (std::size_t i = 0; i < texels_before.size(); ++i) {
        maps[texels_before.object[i]].texels[texels_before.texel[i]] = values[i];
        kinds[texels_before.object[i]][texels_before.texel[i]] = TexelKind::Covered;
      }
      tbb::parallel_for(std::size_t(0), maps.size(), [&](std::size_t o) {
        dilate(maps[o].texels, maps[o].width, maps[o].height, kinds[o]);
      });
      return maps;
    };
    const std::vector<Lightmap> shown_maps = dilated(shown_before);
    for (std::uint32_t i : missing)
      before_[i] = shown_maps[texels_.object[i]].texels[texels_.texel[i]];
    for (std::size_t b = 0; b < mean_.size(); ++b) {
      const std::vector<Lightmap> maps = dilated(mean_before[b]);
      for (std::uint32_t i : missing)
        mean_[b][i] = maps[texels_.object[i]].texels[texels_.texel[i]];
    }
  }

  // Priority: affected (near a region, sees a changed light, or in a shadow that moved), then
  // the rest; within each, texels a viewer's camera sees first.
  const float margin = std::max(
      probes_.cell,
      !params_.uses_probes() ? probes_.cell : params_.tracing_range * world_->bounds.max_extent());
  std::vector<std::uint8_t> tier(n, 0);
  tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
    const glm::vec3 p = texels_.position[i];
    const glm::vec3 ng = texels_.geo_normal[i];
    auto sees = [&](glm::vec3 q) {
      glm::vec3 to = q - p;
      const float dist = glm::length(to);
      if (!(dist > 0.0f) || glm::dot(to, ng) <= 0.0f) return false;
      Ray r;
      r.direction = to / dist;
      r.origin = rays_->offset(p, ng, r.direction);
      r.tmax = std::max(0.0f, glm::length(q - r.origin) - 2.0f * rays_->epsilon());
      return !rays_->occluded(r);
    };
    bool affected = false;
    for (const Bounds& r : change.regions)
      if (distance_to(r, p) <= margin) {
        affected = true;
        break;
      }
    for (std::size_t l = 0; !affected && l < change.light_points.size(); ++l)
      affected = sees(change.light_points[l]);
    for (std::size_t l = 0; !affected && l < change.other_lights.size(); ++l)
      for (const Bounds& r : change.regions)
        if (segment_hits(r, p, change.other_lights[l])) {
          affected = true;
          break;
        }
    bool visible = false;
    for (const CameraPose& c : cameras) {
      const glm::vec3 d = p - c.eye;
      const float dist = glm::length(d);
      if (!(dist > 0.0f)) continue;
      // Inside a cone around the view direction wide enough for a 16:9 image.
      const float half =
          std::atan(std::tan(0.5f * c.yfov) * std::sqrt(1.0f + 16.0f * 16.0f / 81.0f));
      if (glm::dot(d / dist, glm::normalize(c.forward)) < std::cos(std::min(half, 1.57f))) continue;
      if (sees(c.eye)) {
        visible = true;
        break;
      }
    }
    tier[i] = static_cast<std::uint8_t>((affected ? 0 : 2) + (visible ? 0 : 1));
  });
  lap("priorities");
  // Affected texels (and texels that were not valid before) restart: their new estimate
  // replaces the old one, which they show blended away (EngineParams::edit_blend). The others
  // keep their estimate with the weight of at most edit_keep samples, so new samples soon
  // outweigh it wherever the edit changed their light after all.
  samples_.assign(n, 0);
  bounce_samples_.assign(n, 0);
  total_mean_.assign(n, 0.0);
  total_m2_.assign(n, 0.0);
  restarted_.assign(n, 1);
  const auto keep = static_cast<std::uint32_t>(params_.edit_keep);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t j = old_of[i];
    // A changed light changes the indirect light everywhere it reaches: all restart then.
    if (tier[i] < 2 || j < 0 || keep == 0 || !change.light_points.empty()) continue;
    const auto k = static_cast<std::size_t>(j);
    const std::uint32_t had = samples_before[k];
    if (had == 0) continue;
    restarted_[i] = k < restarted_before.size() ? restarted_before[k] : 0;
    samples_[i] = std::min(had, keep);
    bounce_samples_[i] = std::min(bounce_before[k], keep);
    total_mean_[i] = total_mean_before[k];
    const std::uint32_t full = bounce_before[k];
    total_m2_[i] = full > 1 ? total_m2_before[k] * (bounce_samples_[i] - 1.0) / (full - 1.0) : 0.0;
  }
  // Probes restart after every edit: each sees much of the scene, they are few, and every
  // full update gathers all of them (a kept estimate would hold the old light for many
  // updates, measured on rooms:2).
  probe_samples_ = 0;
  queue_.clear();
  queue_pos_ = 0;
  for (std::uint8_t t = 0; t < 4; ++t)
    for (std::uint32_t i : unit_texels_)
      if (tier[i] == t) queue_.push_back(i);
  ++generation_;
  backend_->scene_changed();
  lap("backend");
  if (method_) {
    method_->scene_changed(change);
    lap(method_->name().c_str());
  }
}

}  // namespace irradcast

#include "irradcast/engine/engine.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "dilation_plan.h"
#include "indirect_method.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/sampling.h"
#include "irradcast/engine/denoise.h"

namespace irradcast {
namespace {

using Clock = std::chrono::steady_clock;

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

// Running means with per-texel counts over the texels of this update: a texel's first sample
// since a restart replaces what its means held (its values from before an edit).
void accumulate(std::vector<glm::vec3>& mean, const std::vector<glm::vec3>& est,
                const std::vector<std::uint32_t>& count, const std::vector<std::uint32_t>& texels) {
  if (mean.size() != est.size()) mean.assign(est.size(), glm::vec3(0.0f));
  tbb::parallel_for(std::size_t(0), texels.size(), [&](std::size_t j) {
    const std::uint32_t i = texels[j];
    mean[i] += (est[i] - mean[i]) * (1.0f / static_cast<float>(count[i] + 1));
  });
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
  method_ = make_indirect_method(params_, world, rays, lights, *backend_);
  if (gbuffers.size() != world.objects.size() || atlas.objects.size() != world.objects.size())
    throw Error("engine: atlas and G-buffers do not match the scene's objects");
  probes_.grid = ProbeGrid::cells_of(world.bounds, params_);
  probes_.stats.probes = probes_.grid.count();
  build_texels(gbuffers);
  method_->place_probes(texels_, nullptr, probes_, [](const std::string&) {});
  build_dispatch();
  const int k = params_.indirect_bounces;
  mean_.assign(k + 1, std::vector<glm::vec3>(texels_.size(), glm::vec3(0.0f)));
  samples_.assign(texels_.size(), 0);
  bounce_samples_.assign(texels_.size(), 0);
  total_mean_.assign(texels_.size(), 0.0f);
  total_m2_.assign(texels_.size(), 0.0f);
}

Engine::~Engine() = default;

std::string Engine::method_summary() const {
  return method_->summary();
}

void Engine::build_texels(const std::vector<TexelGBuffer>& gbuffers) {
  dilation_.resize(gbuffers.size());
  tbb::parallel_for(std::size_t(0), gbuffers.size(), [&](std::size_t o) {
    const TexelGBuffer& g = gbuffers[o];
    dilation_[o] = DilationPlan(g.width, g.height, g.kind);
  });
  texels_ = SurfaceTexels{};
  std::size_t total = 0;
  for (const auto& g : gbuffers) total += g.valid_count();
  texels_.position.reserve(total);
  texels_.normal.reserve(total);
  texels_.object.reserve(total);
  texels_.texel.reserve(total);
  texels_.triangle.reserve(total);
  for (std::size_t o = 0; o < gbuffers.size(); ++o) {
    const TexelGBuffer& g = gbuffers[o];
    const WorldObject& obj = world_->objects[o];
    if (!obj.in_static_scene()) continue;  // hidden: its lightmap keeps its last values
    for (std::size_t i = 0; i < g.size(); ++i) {
      if (!g.valid(i)) continue;
      const TexelPoint p = g.point(obj, i);
      texels_.position.push_back(p.position);
      texels_.normal.push_back(p.normal);
      texels_.object.push_back(static_cast<std::uint32_t>(o));
      texels_.texel.push_back(static_cast<std::uint32_t>(i));
      texels_.triangle.push_back(static_cast<std::uint32_t>(g.triangle[i]));
    }
  }
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
  std::vector<std::uint32_t> cell(n);
  tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
    cell[i] = static_cast<std::uint32_t>(probes_.grid.cell_index(texels_.position[i]));
  });
  std::vector<std::uint32_t> counts(probes_.grid.count() + 1, 0);
  for (std::uint32_t c : cell) ++counts[c + 1];
  for (std::size_t c = 1; c < counts.size(); ++c) counts[c] += counts[c - 1];
  unit_texels_.resize(n);
  std::vector<std::uint32_t> fill(counts.begin(), counts.end() - 1);
  for (std::size_t i = 0; i < n; ++i) unit_texels_[fill[cell[i]]++] = static_cast<std::uint32_t>(i);
  for (std::size_t c = 1; c < counts.size(); ++c)
    if (counts[c] > counts[c - 1]) unit_offsets_.push_back(counts[c]);
}

std::vector<Lightmap> Engine::to_lightmaps(const std::vector<glm::vec3>& values) const {
  std::vector<Lightmap> maps;
  to_lightmaps(values, maps);
  return maps;
}

void Engine::to_lightmaps(const std::vector<glm::vec3>& values, std::vector<Lightmap>& maps) const {
  maps.resize(world_->objects.size());
  for (std::size_t o = 0; o < maps.size(); ++o) {
    Lightmap& m = maps[o];
    m.width = (*gbuffers_)[o].width;
    m.height = (*gbuffers_)[o].height;
    m.texels.assign(static_cast<std::size_t>(m.width) * m.height, glm::vec3(0.0f));
  }
  // Every texel has its own place in its object's map.
  tbb::parallel_for(std::size_t(0), texels_.size(), [&](std::size_t i) {
    maps[texels_.object[i]].texels[texels_.texel[i]] = values[i];
  });
  tbb::parallel_for(std::size_t(0), maps.size(),
                    [&](std::size_t o) { dilation_[o].apply(maps[o].texels); });
}

UpdateStats Engine::update() {
  const auto start = Clock::now();
  UpdateStats stats;
  // The texels of this update: every texel, or the next batch of those waiting since an edit.
  const bool partial = queue_pos_ < queue_.size();
  std::vector<std::uint32_t> batch_texels, batch_offsets;
  if (partial) {
    next_batch(batch_texels, batch_offsets);
  } else if (!queue_.empty()) {
    // Caught up: back to full updates over the engine's own units.
    queue_.clear();
    queue_pos_ = 0;
    ++generation_;
  }
  const std::vector<std::uint32_t>& texels = partial ? batch_texels : unit_texels_;
  const std::vector<std::uint32_t>& offsets = partial ? batch_offsets : unit_offsets_;
  PassInput in{*world_, *atlas_,  texels_, probes_.corners, probes_.grid, params_, texels,
               offsets, updates_, 0,       generation_};
  std::vector<glm::vec3> est;
  stats.direct = backend_->direct(in, est);
  accumulate(mean_[0], est, samples_, texels);
  if (partial) {
    // While catching up after an edit: the direct light only. The bounces would read texels
    // that still hold their values from before the edit and so be biased; a restarted texel
    // keeps its old indirect light (and its blend with the old value, see shown()) until the
    // first full update, whose bounces all read new direct light.
    for (std::uint32_t i : texels) ++samples_[i];
  } else {
    // The update's total per texel, as the luminance its statistics read (4 bytes a texel where
    // the direct estimate takes 12).
    std::vector<float> total(est.size());
    tbb::parallel_for(std::size_t(0), texels.size(),
                      [&](std::size_t j) { total[texels[j]] = luminance(est[texels[j]]); });
    std::vector<glm::vec3>().swap(est);
    bounces(in, total, stats);
  }
  ++updates_;
  stats.total_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return stats;
}

void Engine::next_batch(std::vector<std::uint32_t>& texels, std::vector<std::uint32_t>& offsets) {
  const std::size_t budget = std::max<std::size_t>(
      1, static_cast<std::size_t>(
             std::ceil(params_.edit_batch * static_cast<double>(texels_.size()))));
  const std::size_t end = std::min(queue_.size(), queue_pos_ + budget);
  texels.assign(queue_.begin() + static_cast<std::ptrdiff_t>(queue_pos_),
                queue_.begin() + static_cast<std::ptrdiff_t>(end));
  queue_pos_ = end;
  // One unit where consecutive texels share a cell or an object.
  const bool by_object = params_.dispatch == Dispatch::PerObject;
  offsets.push_back(0);
  for (std::size_t i = 1; i < texels.size(); ++i) {
    const std::uint32_t a = texels[i - 1], b = texels[i];
    const bool split = by_object ? texels_.object[a] != texels_.object[b]
                                 : probes_.grid.cell_index(texels_.position[a]) !=
                                       probes_.grid.cell_index(texels_.position[b]);
    if (split) offsets.push_back(static_cast<std::uint32_t>(i));
  }
  offsets.push_back(static_cast<std::uint32_t>(texels.size()));
  ++generation_;
}

void Engine::bounces(PassInput& in, std::vector<float>& total, UpdateStats& stats) {
  const int k = params_.indirect_bounces;
  const std::vector<std::uint32_t>& texels = in.unit_texels;
  std::vector<glm::vec3> est;
  stats.prepare = method_->prepare(in);
  std::vector<Lightmap> prev = to_lightmaps(mean_[0]);
  for (int b = 1; b <= k; ++b) {
    in.bounce = static_cast<std::uint32_t>(b);
    RadianceField field{world_, atlas_, &prev};
    const BounceResult r = method_->bounce(in, field, est);
    stats.probes.push_back(r.probes);
    stats.scatter.push_back(r.scatter);
    accumulate(mean_[b], est, bounce_samples_, texels);
    tbb::parallel_for(std::size_t(0), texels.size(), [&](std::size_t j) {
      const std::uint32_t i = texels[j];
      total[i] += luminance(est[i]);
    });
    if (b < k) to_lightmaps(mean_[b], prev);  // in place: one set of maps at a time
  }
  // Welford statistics of each texel's total per-update estimate (full updates only), for the
  // convergence estimate.
  tbb::parallel_for(std::size_t(0), texels.size(), [&](std::size_t j) {
    const std::uint32_t i = texels[j];
    const double n = static_cast<double>(bounce_samples_[i]) + 1.0;
    const double x = total[i];
    const double mean = bounce_samples_[i] == 0 ? 0.0 : total_mean_[i];
    const double m2 = bounce_samples_[i] == 0 ? 0.0 : total_m2_[i];
    const double d = x - mean;
    const double next = mean + d / n;
    total_mean_[i] = static_cast<float>(next);
    total_m2_[i] = static_cast<float>(m2 + d * (x - next));
    ++samples_[i];
    ++bounce_samples_[i];
  });
}

std::uint32_t Engine::min_samples() const {
  if (bounce_samples_.empty()) return updates_;
  return *std::min_element(bounce_samples_.begin(), bounce_samples_.end());
}

std::vector<glm::vec3> Engine::shown() const {
  std::vector<glm::vec3> sum(texels_.size(), glm::vec3(0.0f));
  tbb::parallel_for(std::size_t(0), sum.size(), [&](std::size_t i) {
    for (const auto& m : mean_) sum[i] += m[i];
  });
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

std::vector<Lightmap> Engine::published_lightmaps(DenoiseStats* stats) const {
  if (stats) *stats = {};
  if (!params_.denoise || updates_ < 2) return lightmaps();
  return to_lightmaps(denoise(texels_, denoise_guide(texels_, *atlas_, *gbuffers_), shown(),
                              texel_standard_error(), {}, stats));
}

std::vector<float> Engine::texel_standard_error() const {
  // Texels with fewer than 2 samples since a restart have no noise estimate: 0.
  std::vector<float> se(texels_.size());
  tbb::parallel_for(std::size_t(0), se.size(), [&](std::size_t i) {
    const double n = bounce_samples_[i];
    se[i] = n < 2 ? 0.0f : static_cast<float>(std::sqrt(total_m2_[i] / (n - 1) / n));
  });
  return se;
}

std::vector<Lightmap> Engine::standard_error() const {
  if (updates_ < 2) return {};
  // A texel without a noise estimate gets 0, so that any change of its counts as real.
  const std::vector<float> se = texel_standard_error();
  return to_lightmaps(std::vector<glm::vec3>(se.begin(), se.end()));
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

struct Engine::Before {
  std::vector<glm::vec3> shown;              // what each texel showed
  std::vector<std::vector<glm::vec3>> mean;  // its component means
  SurfaceTexels texels;
  std::vector<std::uint32_t> samples, bounce_samples;
  std::vector<float> total_mean, total_m2;
  std::vector<std::uint8_t> restarted;
};

void Engine::scene_changed(const SceneChange& change, const std::vector<CameraPose>& cameras) {
  auto lap_start = Clock::now();
  change_timings_.clear();
  const IndirectMethod::Lap lap = [&](const std::string& what) {
    const auto now = Clock::now();
    change_timings_ += std::string(change_timings_.empty() ? "" : ", ") + what + " " +
                       std::to_string(static_cast<int>(
                           1e3 * std::chrono::duration<double>(now - lap_start).count())) +
                       " ms";
    lap_start = now;
  };
  // The texel list is rebuilt only when geometry or surfaces changed.
  const bool rebuild = change.geometry || change.surfaces;
  const Before before = take_before(rebuild);
  if (rebuild) build_texels(*gbuffers_);
  lap("texels");
  method_->place_probes(texels_, &change, probes_, lap);
  if (rebuild) build_dispatch();
  lap("probe weights");
  const std::vector<std::int32_t> old_of = carry_over(before);
  const std::vector<std::uint8_t> tier = priorities(change, cameras);
  lap("priorities");
  restart(before, old_of, tier, change);
  ++generation_;
  backend_->scene_changed();
  lap("backend");
  method_->scene_changed(change, lap);
}

Engine::Before Engine::take_before(bool rebuild) {
  // What every texel shows now and its old component means, found again by (object, texel)
  // after the rebuild; texels that were not valid before read the old dilated lightmaps.
  Before b;
  b.shown = shown();
  b.mean = std::move(mean_);
  mean_.assign(b.mean.size(), {});
  b.texels = rebuild ? std::move(texels_) : texels_;
  b.samples = samples_;
  b.bounce_samples = bounce_samples_;
  b.total_mean = total_mean_;
  b.total_m2 = total_m2_;
  b.restarted = restarted_;
  return b;
}

std::vector<std::int32_t> Engine::carry_over(const Before& before) {
  // Every texel restarts; its means keep the old values until its first new sample.
  const std::size_t n = texels_.size();
  std::vector<std::vector<std::int32_t>> old_index(world_->objects.size());
  for (std::size_t o = 0; o < old_index.size(); ++o)
    old_index[o].assign((*gbuffers_)[o].size(), -1);
  for (std::size_t i = 0; i < before.texels.size(); ++i)
    old_index[before.texels.object[i]][before.texels.texel[i]] = static_cast<std::int32_t>(i);
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
    before_[i] = before.shown[static_cast<std::size_t>(j)];
    for (std::size_t b = 0; b < mean_.size(); ++b)
      mean_[b][i] = before.mean[b][static_cast<std::size_t>(j)];
  }
  if (!missing.empty()) carry_over_dilated(before, missing);
  return old_of;
}

void Engine::carry_over_dilated(const Before& before, const std::vector<std::uint32_t>& missing) {
  // Newly valid texels (uncovered by a moved object): the old dilated lightmaps there.
  const SurfaceTexels& old = before.texels;
  auto dilated = [&](const std::vector<glm::vec3>& values) {
    std::vector<Lightmap> maps(world_->objects.size());
    for (std::size_t o = 0; o < maps.size(); ++o)
      maps[o] = Lightmap((*gbuffers_)[o].width, (*gbuffers_)[o].height);
    std::vector<std::vector<TexelKind>> kinds(maps.size());
    for (std::size_t o = 0; o < maps.size(); ++o)
      kinds[o].assign(maps[o].texels.size(), TexelKind::Empty);
    for (std::size_t i = 0; i < old.size(); ++i) {
      maps[old.object[i]].texels[old.texel[i]] = values[i];
      kinds[old.object[i]][old.texel[i]] = TexelKind::Covered;
    }
    tbb::parallel_for(std::size_t(0), maps.size(), [&](std::size_t o) {
      dilate(maps[o].texels, maps[o].width, maps[o].height, kinds[o]);
    });
    return maps;
  };
  const std::vector<Lightmap> shown_maps = dilated(before.shown);
  for (std::uint32_t i : missing)
    before_[i] = shown_maps[texels_.object[i]].texels[texels_.texel[i]];
  for (std::size_t b = 0; b < mean_.size(); ++b) {
    const std::vector<Lightmap> maps = dilated(before.mean[b]);
    for (std::uint32_t i : missing) mean_[b][i] = maps[texels_.object[i]].texels[texels_.texel[i]];
  }
}

std::vector<std::uint8_t> Engine::priorities(const SceneChange& change,
                                             const std::vector<CameraPose>& cameras) const {
  // Priority: affected (near a region, sees a changed light, or in a shadow that moved), then
  // the rest; within each, texels a viewer's camera sees first.
  const float cell = probes_.grid.cell;
  const float margin = std::max(
      cell,
      !params_.uses_probes() ? cell : params_.tracing_range.resolve(world_->bounds.max_extent()));
  const std::size_t n = texels_.size();
  std::vector<std::uint8_t> tier(n, 0);
  tbb::parallel_for(std::size_t(0), n, [&](std::size_t i) {
    const glm::vec3 p = texels_.position[i];
    const glm::vec3 ng = texels_.geo_normal(*world_, i);
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
    bool affected = change.sky || change.distance(p) <= margin;
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
  return tier;
}

void Engine::restart(const Before& before, const std::vector<std::int32_t>& old_of,
                     const std::vector<std::uint8_t>& tier, const SceneChange& change) {
  // Affected texels (and texels that were not valid before) restart: their new estimate
  // replaces the old one, which they show blended away (EngineParams::edit_blend). The others
  // keep their estimate with the weight of at most edit_keep samples, so new samples soon
  // outweigh it wherever the edit changed their light after all.
  const std::size_t n = texels_.size();
  samples_.assign(n, 0);
  bounce_samples_.assign(n, 0);
  total_mean_.assign(n, 0.0f);
  total_m2_.assign(n, 0.0f);
  restarted_.assign(n, 1);
  const auto keep = static_cast<std::uint32_t>(params_.edit_keep);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t j = old_of[i];
    // A changed light (or sky) changes the indirect light everywhere it reaches: all restart.
    if (tier[i] < 2 || j < 0 || keep == 0 || !change.light_points.empty() || change.sky) continue;
    const auto k = static_cast<std::size_t>(j);
    const std::uint32_t had = before.samples[k];
    if (had == 0) continue;
    restarted_[i] = k < before.restarted.size() ? before.restarted[k] : 0;
    samples_[i] = std::min(had, keep);
    bounce_samples_[i] = std::min(before.bounce_samples[k], keep);
    total_mean_[i] = before.total_mean[k];
    const std::uint32_t full = before.bounce_samples[k];
    total_m2_[i] =
        full > 1
            ? static_cast<float>(before.total_m2[k] * (bounce_samples_[i] - 1.0) / (full - 1.0))
            : 0.0f;
  }
  // The texels wait in priority order; the method restarts its own estimates (the probes).
  queue_.clear();
  queue_pos_ = 0;
  for (std::uint8_t t = 0; t < 4; ++t)
    for (std::uint32_t i : unit_texels_)
      if (tier[i] == t) queue_.push_back(i);
}

}  // namespace irradcast

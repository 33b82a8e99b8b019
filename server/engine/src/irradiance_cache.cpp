#include "irradiance_cache.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <numeric>

#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

using Clock = std::chrono::steady_clock;
constexpr float kMiss = 3.4e38f;

}  // namespace

RecordEstimate estimate_record(const RayScene& rays, const RadianceField* prev, glm::vec3 p,
                               glm::vec3 n, glm::vec3 ng, int theta, Rng& rng, float* harmonic) {
  const int m = theta, nphi = 4 * theta;
  const Frame frame(n);
  std::vector<glm::vec3> radiance(static_cast<std::size_t>(m * nphi), glm::vec3(0.0f));
  std::vector<float> dist(static_cast<std::size_t>(m * nphi), kMiss);
  std::vector<float> sin_theta(static_cast<std::size_t>(m * nphi), 0.0f);
  double inverse_sum = 0.0;
  auto at = [&](int j, int k) {
    return static_cast<std::size_t>(j) * static_cast<std::size_t>(nphi) +
           static_cast<std::size_t>((k + nphi) % nphi);
  };
  RecordEstimate e;
  for (int c = 0; c < 3; ++c) e.rotation[c] = e.translation[c] = glm::vec3(0.0f);
  glm::vec3 sum(0.0f);
  for (int j = 0; j < m; ++j)
    for (int k = 0; k < nphi; ++k) {
      const glm::vec2 u = rng.next_2d();
      // Cosine-weighted strata: sin^2 theta uniform in [j/M, (j+1)/M), phi in [2 pi k/N, ...).
      const float s2 = std::min((static_cast<float>(j) + u.x) / static_cast<float>(m), 0.9999f);
      const float st = std::sqrt(s2), ct = std::sqrt(1.0f - s2);
      const float phi = 2.0f * kPi * (static_cast<float>(k) + u.y) / static_cast<float>(nphi);
      Ray ray;
      ray.direction = frame.to_world(glm::vec3(st * std::cos(phi), st * std::sin(phi), ct));
      ray.origin = rays.offset(p, ng, ray.direction);
      const Hit h = rays.intersect(ray);
      const std::size_t i = at(j, k);
      sin_theta[i] = st;
      if (!h.valid()) continue;
      dist[i] = h.t;
      inverse_sum += 1.0 / std::max(h.t, 1e-6f);
      if (prev) radiance[i] = radiance_at(*prev, h);
      sum += radiance[i];
      // Rotational gradient (Ward & Heckbert 1992): v_k is the tangent direction phi + pi/2.
      const glm::vec3 v = frame.to_world(glm::vec3(-std::sin(phi), std::cos(phi), 0.0f));
      const float tan_theta = st / std::max(ct, 1e-3f);
      for (int c = 0; c < 3; ++c) e.rotation[c] -= v * (tan_theta * radiance[i][c]);
    }
  const float scale = kPi / static_cast<float>(m * nphi);
  e.irradiance = sum * scale;
  for (int c = 0; c < 3; ++c) e.rotation[c] *= scale;
  if (harmonic)
    *harmonic =
        inverse_sum > 0.0 ? static_cast<float>(static_cast<double>(m * nphi) / inverse_sum) : kMiss;
  if (!prev) return e;
  // Translational gradient (Ward & Heckbert 1992, as written in Krivanek et al.'s course
  // notes): how the strata boundaries move as the point moves, between neighbours in theta
  // (along u_k) and in phi (along v_k-).
  for (int k = 0; k < nphi; ++k) {
    const float phi_c = 2.0f * kPi * (static_cast<float>(k) + 0.5f) / static_cast<float>(nphi);
    const float phi_b = 2.0f * kPi * static_cast<float>(k) / static_cast<float>(nphi);
    const glm::vec3 uk = frame.to_world(glm::vec3(std::cos(phi_c), std::sin(phi_c), 0.0f));
    const glm::vec3 vk = frame.to_world(glm::vec3(-std::sin(phi_b), std::cos(phi_b), 0.0f));
    glm::vec3 along_theta(0.0f), along_phi(0.0f);
    for (int j = 1; j < m; ++j) {
      const float rmin = std::min(dist[at(j, k)], dist[at(j - 1, k)]);
      if (rmin >= kMiss) continue;
      const float s2 = static_cast<float>(j) / static_cast<float>(m);  // sin^2 theta_j-
      const float coef = std::sqrt(s2) * (1.0f - s2) / rmin;
      along_theta += coef * (radiance[at(j, k)] - radiance[at(j - 1, k)]);
    }
    for (int j = 0; j < m; ++j) {
      const float rmin = std::min(dist[at(j, k)], dist[at(j, k - 1)]);
      if (rmin >= kMiss) continue;
      const float c_lo = std::sqrt(1.0f - static_cast<float>(j) / static_cast<float>(m));
      const float c_hi =
          std::sqrt(std::max(0.0f, 1.0f - static_cast<float>(j + 1) / static_cast<float>(m)));
      const float coef = (c_lo - c_hi) / (std::max(sin_theta[at(j, k)], 1e-3f) * rmin);
      along_phi += coef * (radiance[at(j, k)] - radiance[at(j, k - 1)]);
    }
    along_theta *= 2.0f * kPi / static_cast<float>(nphi);
    for (int c = 0; c < 3; ++c) e.translation[c] += uk * along_theta[c] + vk * along_phi[c];
  }
  return e;
}

IrradianceCache::IrradianceCache(const EngineParams& params, const World& world,
                                 const RayScene& rays)
    : params_(params), world_(&world), rays_(&rays) {
  const Bounds& b = world_->bounds;
  const float extent = std::max(b.max_extent(), 1e-6f);
  // Cells as large as the largest zone of influence, at most 64 per axis.
  cell_ = std::max(params_.ic_accuracy * params_.ic_max_radius * extent, extent / 64.0f);
  for (int a = 0; a < 3; ++a)
    dims_[a] = std::clamp(static_cast<int>(std::ceil(b.extent()[a] / cell_)), 1, 64);
  grid_.assign(static_cast<std::size_t>(dims_.x) * dims_.y * dims_.z, {});
}

glm::ivec3 IrradianceCache::cell_of(glm::vec3 p) const {
  const glm::ivec3 c = glm::ivec3(glm::floor((p - world_->bounds.lo) / cell_));
  return glm::clamp(c, glm::ivec3(0), dims_ - 1);
}

const std::vector<std::uint32_t>& IrradianceCache::cell_records(glm::vec3 p) const {
  const glm::ivec3 c = cell_of(p);
  return grid_[(static_cast<std::size_t>(c.z) * dims_.y + c.y) * dims_.x + c.x];
}

void IrradianceCache::insert(std::uint32_t record) {
  const IrradianceRecord& r = records_[record];
  const float reach = params_.ic_accuracy * r.radius;
  const glm::ivec3 lo = cell_of(r.position - reach), hi = cell_of(r.position + reach);
  for (int z = lo.z; z <= hi.z; ++z)
    for (int y = lo.y; y <= hi.y; ++y)
      for (int x = lo.x; x <= hi.x; ++x)
        grid_[(static_cast<std::size_t>(z) * dims_.y + y) * dims_.x + x].push_back(record);
}

float IrradianceCache::weight(const IrradianceRecord& r, glm::vec3 p, glm::vec3 n) const {
  const glm::vec3 d = p - r.position;
  // Ward's "in front" test: a record ahead of the point (along the mean normal) sees a
  // different hemisphere.
  if (glm::dot(d, r.normal + n) < -0.1f * r.radius) return 0.0f;
  const float denom =
      glm::length(d) / r.radius + std::sqrt(std::max(0.0f, 1.0f - glm::dot(n, r.normal)));
  const float w = denom > 1e-6f ? 1.0f / denom : 1e6f;
  return w > 1.0f / params_.ic_accuracy ? w : 0.0f;
}

bool IrradianceCache::visible(const IrradianceRecord& r, glm::vec3 p, glm::vec3 ng) const {
  const glm::vec3 target = r.position + rays_->epsilon() * r.geo_normal;
  glm::vec3 d = target - p;
  const float len = glm::length(d);
  if (!(len > 4.0f * rays_->epsilon())) return true;
  d /= len;
  Ray ray;
  ray.origin = rays_->offset(p, ng, d);
  const glm::vec3 to = target - ray.origin;
  const float tl = glm::length(to);
  if (!(tl > rays_->epsilon())) return true;
  ray.direction = to / tl;
  ray.tmax = tl - rays_->epsilon();
  return !rays_->occluded(ray);
}

float IrradianceCache::coverage(glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                                std::size_t first_record) const {
  float sum = 0.0f;
  for (std::uint32_t k : cell_records(p)) {
    if (k < first_record) continue;
    const float w = weight(records_[k], p, n);
    if (w > 0.0f && visible(records_[k], p, ng)) sum += w;
  }
  return sum;
}

void IrradianceCache::build_splats(const PassInput& in) {
  // Per texel: the records that may contribute (Ward weight above 1 / a, not in front) and that
  // it can see. Without the visibility test a record on one side of a thin wall lights texels
  // on the other (the cache's classic leak, measured on rooms:2). Fixed until the texels or the
  // records change, so the rays are paid once.
  const std::size_t n = in.texels.size();
  std::vector<std::vector<std::pair<std::uint32_t, float>>> lists(n);
  tbb::parallel_for(std::size_t(0), in.unit_texels.size(), [&](std::size_t j) {
    const std::uint32_t i = in.unit_texels[j];
    const glm::vec3 p = in.texels.position[i], nn = in.texels.normal[i];
    for (std::uint32_t k : cell_records(p)) {
      const float w = weight(records_[k], p, nn);
      if (w > 0.0f && visible(records_[k], p, in.texels.geo_normal(in.world, i)))
        lists[i].push_back({k, w});
    }
  });
  splat_offsets_.assign(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i)
    splat_offsets_[i + 1] = splat_offsets_[i] + static_cast<std::uint32_t>(lists[i].size());
  splat_.resize(splat_offsets_[n]);
  for (std::size_t i = 0; i < n; ++i)
    std::copy(lists[i].begin(), lists[i].end(), splat_.begin() + splat_offsets_[i]);
  splat_generation_ = in.generation;
}

PassResult IrradianceCache::prepare(const PassInput& in) {
  PassResult r;
  const auto start = Clock::now();
  if (!place_) {
    if (splat_generation_ != in.generation || splat_offsets_.size() != in.texels.size() + 1)
      build_splats(in);
    r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return r;
  }
  place_ = false;
  const float extent = std::max(world_->bounds.max_extent(), 1e-6f);
  const float rmin = params_.ic_min_radius * extent, rmax = params_.ic_max_radius * extent;
  // Texels in a shuffled order (any order gives a valid cover; a shuffled one spreads the
  // first records over the scene instead of along the first object).
  std::vector<std::uint32_t> order(in.unit_texels.begin(), in.unit_texels.end());
  Rng shuffle(mix64(params_.seed) ^ 0x1cull, records_.size());
  for (std::size_t i = order.size(); i > 1; --i)
    std::swap(order[i - 1], order[shuffle.next_u32() % i]);
  const std::size_t before = records_.size();
  std::atomic<std::uint64_t> rays{0};
  constexpr std::size_t kChunk = 256;
  for (std::size_t c0 = 0; c0 < order.size(); c0 += kChunk) {
    const std::size_t c1 = std::min(order.size(), c0 + kChunk);
    // 1. Which texels of the chunk no record covers (in parallel, records fixed).
    std::vector<std::uint8_t> uncovered(c1 - c0, 0);
    tbb::parallel_for(c0, c1, [&](std::size_t j) {
      const std::uint32_t i = order[j];
      uncovered[j - c0] = coverage(in.texels.position[i], in.texels.normal[i],
                                   in.texels.geo_normal(in.world, i)) > 0.0f
                              ? 0
                              : 1;
    });
    std::vector<std::uint32_t> candidates;
    for (std::size_t j = c0; j < c1; ++j)
      if (uncovered[j - c0]) candidates.push_back(order[j]);
    if (candidates.empty()) continue;
    // 2. Their radii (in parallel): the harmonic mean distance of a hemisphere of rays.
    std::vector<float> radius(candidates.size());
    tbb::parallel_for(std::size_t(0), candidates.size(), [&](std::size_t j) {
      const std::uint32_t i = candidates[j];
      Rng rng(mix64(params_.seed) ^ i, 0x1c0ull);
      float h = kMiss;
      estimate_record(*rays_, nullptr, in.texels.position[i], in.texels.normal[i],
                      in.texels.geo_normal(in.world, i), params_.ic_rays, rng, &h);
      radius[j] = std::clamp(h, rmin, rmax);
      rays += static_cast<std::uint64_t>(4 * params_.ic_rays * params_.ic_rays);
    });
    // 3. In order: a candidate that a record placed earlier in this chunk now covers is
    //    skipped; the others become records and are splatted into the grid.
    const std::size_t chunk_first = records_.size();
    for (std::size_t j = 0; j < candidates.size(); ++j) {
      const std::uint32_t i = candidates[j];
      if (records_.size() > chunk_first &&
          coverage(in.texels.position[i], in.texels.normal[i], in.texels.geo_normal(in.world, i),
                   chunk_first) > 0.0f)
        continue;
      records_.push_back({in.texels.position[i], in.texels.normal[i],
                          in.texels.geo_normal(in.world, i), radius[j]});
      insert(static_cast<std::uint32_t>(records_.size() - 1));
    }
  }
  placed_last_ = records_.size() - before;
  build_splats(in);
  r.rays = rays.load();
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

BounceResult IrradianceCache::bounce(const PassInput& in, const RadianceField& prev,
                                     std::vector<glm::vec3>& out) {
  const auto start = Clock::now();
  PassResult r;
  out.assign(in.texels.size(), glm::vec3(0.0f));
  // 1. Every record: a new estimate with its gradients.
  std::vector<RecordEstimate> est(records_.size());
  tbb::parallel_for(std::size_t(0), records_.size(), [&](std::size_t k) {
    const IrradianceRecord& rec = records_[k];
    Rng rng(mix64(params_.seed) ^ (static_cast<std::uint64_t>(k) << 20),
            (static_cast<std::uint64_t>(in.update) << 8) ^ in.bounce);
    est[k] = estimate_record(*rays_, &prev, rec.position, rec.normal, rec.geo_normal,
                             params_.ic_rays, rng);
  });
  r.rays = records_.size() * static_cast<std::uint64_t>(4 * params_.ic_rays * params_.ic_rays);
  // 2. Splat into the texels: per texel the records it sees with their weights (build_splats),
  //    extrapolated with the gradients; the same sums as splatting each record over its zone.
  tbb::parallel_for(std::size_t(0), in.unit_texels.size(), [&](std::size_t j) {
    const std::uint32_t i = in.unit_texels[j];
    const glm::vec3 p = in.texels.position[i], n = in.texels.normal[i];
    glm::vec3 sum(0.0f);
    float wsum = 0.0f;
    for (std::uint32_t s = splat_offsets_[i]; s < splat_offsets_[i + 1]; ++s) {
      const auto [k, w] = splat_[s];
      const IrradianceRecord& rec = records_[k];
      const RecordEstimate& e = est[k];
      const glm::vec3 rot = glm::cross(rec.normal, n), d = p - rec.position;
      glm::vec3 v = e.irradiance;
      for (int c = 0; c < 3; ++c)
        v[c] += glm::dot(rot, e.rotation[c]) + glm::dot(d, e.translation[c]);
      sum += w * v;
      wsum += w;
    }
    // Clamped once, after the weighted mean, so the splat stays linear in the records' estimates
    // (the running means of the splats are then the splat of the records' means).
    out[i] = wsum > 0.0f ? glm::max(sum / wsum, glm::vec3(0.0f)) : glm::vec3(0.0f);
  });
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return {{}, r};
}

void IrradianceCache::scene_changed(const SceneChange& change, const Lap& lap) {
  if (change.geometry) drop_records(change);  // lights and albedo: the records stay put
  lap(name());
}

void IrradianceCache::drop_records(const SceneChange& change) {
  // Records within their radius of a changed region: their surroundings (and so R) changed, or
  // they sit on a moved object. The rest keep their place; the next prepare() covers the gaps.
  std::vector<IrradianceRecord> kept;
  for (const IrradianceRecord& r : records_) {
    const bool near = change.distance(r.position) < std::max(1.0f, params_.ic_accuracy) * r.radius;
    if (!near) kept.push_back(r);
  }
  records_ = std::move(kept);
  for (auto& c : grid_) c.clear();
  for (std::uint32_t k = 0; k < records_.size(); ++k) insert(k);
  place_ = true;
}

std::string IrradianceCache::summary() const {
  double mean = 0.0;
  for (const IrradianceRecord& r : records_) mean += r.radius;
  if (!records_.empty()) mean /= static_cast<double>(records_.size());
  return std::to_string(records_.size()) + " records (" + std::to_string(placed_last_) +
         " placed last), mean radius " + std::to_string(mean);
}

}  // namespace irradcast

#include "irradcast/common/lights.h"

#include <emmintrin.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <optional>

#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

// True when no point of triangle e can pass triangle_sample's cosine tests at p (normal n): the
// whole triangle lies behind p's tangent plane, or p lies behind a one-sided light's plane, each
// by a margin far above the rounding of those tests (so that it rejects exactly the samples the
// tests would, without drawing the point, its distance and its direction).
bool surely_rejected(const EmissiveTriangle& e, glm::vec3 p, glm::vec3 n) {
  const glm::vec3 ap = glm::abs(p);
  const float margin = 1e-5f * std::max({ap.x, ap.y, ap.z, e.reach});
  if (!e.double_sided && glm::dot(e.normal, p - e.p0) < -margin) return true;
  const float h0 = glm::dot(n, e.p0 - p);
  return h0 < -margin && h0 + glm::dot(n, e.e1) < -margin && h0 + glm::dot(n, e.e2) < -margin;
}

// std::upper_bound over cdf[0, len) (the index of the first cumulative value above u; len when
// none), without branches that the random u would mispredict half the time.
std::size_t upper_index(const float* cdf, std::size_t len, float u) {
  const float* first = cdf;
  while (len > 1) {
    const std::size_t half = len / 2;
    first += first[half - 1] <= u ? half : 0;
    len -= half;
  }
  return static_cast<std::size_t>(first - cdf) + (*first <= u ? 1 : 0);
}

// front_lights' copy of the emissive triangles, 4 at a time: per group of 4, one row of 4 floats
// for each of these (a lane past the last triangle is never in front).
enum SoaRow {
  kP0x,
  kP0y,
  kP0z,
  kE1x,
  kE1y,
  kE1z,
  kE2x,
  kE2y,
  kE2z,
  kNx,
  kNy,
  kNz,
  kReach,
  kSoaRows
};

// glm::dot's arithmetic, (a.x b.x + a.y b.y) + a.z b.z, in 4 lanes.
__m128 dot4(__m128 ax, __m128 ay, __m128 az, __m128 bx, __m128 by, __m128 bz) {
  return _mm_add_ps(_mm_add_ps(_mm_mul_ps(ax, bx), _mm_mul_ps(ay, by)), _mm_mul_ps(az, bz));
}

// surely_rejected for the 4 triangles of one SoA group at p (normal n; pm: p's largest absolute
// coordinate, one_sided: the lanes of one-sided triangles): the lanes rejected, as a bit mask.
// The same operations as surely_rejected, lane by lane (max and negation are exact, sums and
// products in glm::dot's order), so the same decisions.
int rejected4(const float* g, glm::vec3 p, glm::vec3 n, __m128 pm, int one_sided) {
  auto row = [g](int r) { return _mm_loadu_ps(g + 4 * r); };
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 neg = _mm_xor_ps(_mm_mul_ps(_mm_set1_ps(1e-5f), _mm_max_ps(pm, row(kReach))), sign);
  const __m128 px = _mm_set1_ps(p.x), py = _mm_set1_ps(p.y), pz = _mm_set1_ps(p.z);
  const __m128 nx = _mm_set1_ps(n.x), ny = _mm_set1_ps(n.y), nz = _mm_set1_ps(n.z);
  // dot(e.normal, p - e.p0) < -margin: p behind a one-sided light
  const __m128 side = dot4(row(kNx), row(kNy), row(kNz), _mm_sub_ps(px, row(kP0x)),
                           _mm_sub_ps(py, row(kP0y)), _mm_sub_ps(pz, row(kP0z)));
  const int back = _mm_movemask_ps(_mm_cmplt_ps(side, neg)) & one_sided;
  // every corner behind p's tangent plane
  const __m128 h0 = dot4(nx, ny, nz, _mm_sub_ps(row(kP0x), px), _mm_sub_ps(row(kP0y), py),
                         _mm_sub_ps(row(kP0z), pz));
  const __m128 h1 = _mm_add_ps(h0, dot4(nx, ny, nz, row(kE1x), row(kE1y), row(kE1z)));
  const __m128 h2 = _mm_add_ps(h0, dot4(nx, ny, nz, row(kE2x), row(kE2y), row(kE2z)));
  const __m128 all =
      _mm_and_ps(_mm_cmplt_ps(h0, neg), _mm_and_ps(_mm_cmplt_ps(h1, neg), _mm_cmplt_ps(h2, neg)));
  return back | _mm_movemask_ps(all);
}

// std::upper_bound's index in cdf[0, count) (ascending), capped at count - 1: the number of the
// first count - 1 values at or below u (no branch on u).
int pick_index(const float* cdf, int count, float u) {
  int c = 0;
  for (int j = 0; j + 1 < count; ++j) c += cdf[j] <= u ? 1 : 0;
  return c;
}

// direct_samples' copy of each emissive triangle: 5 rows of 4 floats, so that 4 samples' triangles
// load and transpose into lanes (SIMD across a texel's samples).
enum RecordRow { kRecP0Area, kRecE1Sided, kRecE2, kRecNormal, kRecEmission, kRecRows };

struct Lanes3 {
  __m128 x, y, z;
};

// glm::dot(a, b) for 4 lanes of a and one b.
__m128 dot_with(const Lanes3& a, glm::vec3 b) {
  return dot4(_mm_set1_ps(b.x), _mm_set1_ps(b.y), _mm_set1_ps(b.z), a.x, a.y, a.z);
}

Lanes3 div3(const Lanes3& a, __m128 d) {
  return {_mm_div_ps(a.x, d), _mm_div_ps(a.y, d), _mm_div_ps(a.z, d)};
}

}  // namespace

LightSampler::LightSampler(const World& world) : world_(&world) {
  std::vector<float> power;
  for (const WorldObject& o : world.objects) {
    if (!o.in_static_scene()) continue;
    const auto& tris = o.triangles();
    for (std::uint32_t t = 0; t < tris.size(); ++t) {
      const Material& m = world.material(o.object, t);
      if (!m.is_emissive()) continue;
      EmissiveTriangle e;
      e.object = o.object;
      e.triangle = t;
      e.p0 = o.positions[tris[t].x];
      e.e1 = o.positions[tris[t].y] - e.p0;
      e.e2 = o.positions[tris[t].z] - e.p0;
      e.area = o.area(t);
      if (!(e.area > 0.0f)) continue;
      e.normal = o.geometric_normal(t);
      e.double_sided = m.double_sided;
      e.uniform_emission = m.emissive_texture < 0 && !m.cut_out();
      e.emission = m.emission();
      for (std::uint32_t k = 0; k < 3; ++k) {
        const glm::vec3 c = glm::abs(o.positions[tris[t][k]]);
        e.reach = std::max({e.reach, c.x, c.y, c.z});
      }
      // Power ~ radiance x area (x2 for two-sided); textures are evaluated per sample.
      float p = luminance(m.emission()) * e.area * (e.double_sided ? 2.0f : 1.0f);
      if (!(p > 0.0f)) continue;
      triangles_.push_back(e);
      power.push_back(p);
    }
  }
  double total = 0.0;
  for (float p : power) total += p;
  total_power_ = static_cast<float>(total);
  cdf_.resize(power.size());
  pick_pdf_.resize(power.size());
  double run = 0.0;
  for (std::size_t i = 0; i < power.size(); ++i) {
    run += power[i];
    cdf_[i] = static_cast<float>(run / total);
    pick_pdf_[i] = static_cast<float>(power[i] / total);
  }
  if (!cdf_.empty()) cdf_.back() = 1.0f;
  // Past the per-texel list's size, lights are picked by where they are (light_tree.h).
  if (triangles_.size() > static_cast<std::size_t>(kMaxFront))
    tree_ = LightTree(triangles_, pick_pdf_);
  record_.assign(triangles_.size() * kRecRows * 4, 0.0f);
  for (std::size_t k = 0; k < triangles_.size(); ++k) {
    const EmissiveTriangle& e = triangles_[k];
    const glm::vec4 rows[kRecRows] = {glm::vec4(e.p0, e.area),
                                      glm::vec4(e.e1, e.double_sided ? 1.0f : 0.0f),
                                      glm::vec4(e.e2, 0.0f), glm::vec4(e.normal, 0.0f),
                                      glm::vec4(e.emission, e.uniform_emission ? 1.0f : 0.0f)};
    for (int r = 0; r < kRecRows; ++r)
      for (int c = 0; c < 4; ++c) record_[(k * kRecRows + r) * 4 + c] = rows[r][c];
  }
  const std::size_t groups = (triangles_.size() + 3) / 4;
  soa_.assign(groups * kSoaRows * 4, 0.0f);
  one_sided_.assign(groups, 0);
  for (std::size_t k = 0; k < triangles_.size(); ++k) {
    const EmissiveTriangle& e = triangles_[k];
    float* g = soa_.data() + k / 4 * kSoaRows * 4 + k % 4;
    const float v[kSoaRows] = {e.p0.x, e.p0.y, e.p0.z,     e.e1.x,     e.e1.y,     e.e1.z, e.e2.x,
                               e.e2.y, e.e2.z, e.normal.x, e.normal.y, e.normal.z, e.reach};
    for (int r = 0; r < kSoaRows; ++r) g[4 * r] = v[r];
    if (!e.double_sided) one_sided_[k / 4] |= 1 << (k % 4);
  }
  if (world.scene && world.scene->sky.enabled()) {
    sky_ = &world.scene->sky;
    sky_dist_ = SkyDistribution(*sky_);
  }
}

glm::vec3 LightSampler::sky_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                                       glm::vec4 u, std::uint64_t* rays_traced) const {
  if (!sky_) return glm::vec3(0.0f);
  // Radiance from `dir` if a ray from p leaves the scene that way, else 0.
  auto escapes = [&](glm::vec3 dir) {
    Ray r;
    r.origin = rays.offset(p, ng, dir);
    r.direction = dir;
    if (rays_traced) ++*rays_traced;
    return !rays.occluded(r);
  };
  const Frame frame(n);
  const glm::vec3 cos_dir = frame.to_world(cosine_hemisphere(glm::vec2(u.x, u.y)));
  if (!sky_dist_.valid()) {
    // Cosine-weighted: E = pi x L, exact for a constant sky up to visibility.
    return escapes(cos_dir) ? kPi * sky_->radiance(cos_dir) : glm::vec3(0.0f);
  }
  glm::vec3 e(0.0f);
  const SkyDistribution::Sample s = sky_dist_.sample(glm::vec2(u.x, u.y));
  const float cos_s = glm::dot(n, s.direction);
  if (s.pdf > 0.0f && cos_s > 0.0f && escapes(s.direction))
    e += sky_->radiance(s.direction) * (cos_s / (s.pdf + cos_s * kInvPi));
  const glm::vec3 c = frame.to_world(cosine_hemisphere(glm::vec2(u.z, u.w)));
  const float cos_c = glm::dot(n, c);
  if (cos_c > 0.0f && escapes(c))
    e += sky_->radiance(c) * (cos_c / (sky_dist_.pdf(c) + cos_c * kInvPi));
  return e;
}

bool LightSampler::triangle_sample(const RayScene& rays, std::size_t index, glm::vec3 p,
                                   glm::vec3 n, glm::vec3 ng, glm::vec2 u, ShadowSample& s) const {
  if (surely_rejected(triangles_[index], p, n)) return false;
  return point_sample(rays, index, p, n, ng, u, s);
}

inline bool LightSampler::point_sample(const RayScene& rays, std::size_t index, glm::vec3 p,
                                       glm::vec3 n, glm::vec3 ng, glm::vec2 u,
                                       ShadowSample& s) const {
  const EmissiveTriangle& e = triangles_[index];
  glm::vec2 b = uniform_triangle(u);
  glm::vec3 y = e.p0 + b.x * e.e1 + b.y * e.e2;
  glm::vec3 d = y - p;
  float dist2 = glm::dot(d, d);
  if (!(dist2 > 0.0f)) return false;
  float dist = std::sqrt(dist2);
  glm::vec3 wi = d / dist;
  float cos_x = glm::dot(n, wi);
  if (cos_x <= 0.0f) return false;
  float cos_y = -glm::dot(e.normal, wi);
  if (e.double_sided) cos_y = std::fabs(cos_y);
  if (cos_y <= 0.0f) return false;
  // The shadow ray runs from the offset origin to the light point itself (not along wi from the
  // offset origin, which would cross the light's plane before tmax at grazing angles).
  s.shadow = Ray{};
  s.shadow.origin = rays.offset(p, ng, wi);
  glm::vec3 to_light = y - s.shadow.origin;
  float len = glm::length(to_light);
  s.shadow.direction = to_light / len;
  s.shadow.tmax = len - rays.epsilon();
  s.triangle = index;
  s.b = b;
  s.factor = cos_x * cos_y * e.area / dist2;
  return true;
}

glm::vec3 LightSampler::triangle_emitted(const ShadowSample& s) const {
  const EmissiveTriangle& e = triangles_[s.triangle];
  if (e.uniform_emission) return e.emission * s.factor;
  // barycentrics of y for the emission lookup: y = (1-u-v) v0 + u v1 + v v2 with u = b.x, v = b.y
  glm::vec3 le = world_->emission(e.object, e.triangle, s.b.x, s.b.y);
  return le * s.factor;
}

glm::vec3 LightSampler::triangle_irradiance(const RayScene& rays, std::size_t index, glm::vec3 p,
                                            glm::vec3 n, glm::vec3 ng, glm::vec2 u) const {
  ShadowSample s;
  if (!triangle_sample(rays, index, p, n, ng, u, s)) return glm::vec3(0.0f);
  if (s.shadow.tmax > 0.0f && rays.occluded(s.shadow)) return glm::vec3(0.0f);
  return triangle_emitted(s);
}

bool LightSampler::pick(glm::vec3 p, glm::vec3 n, float u, std::size_t& index, float& pdf,
                        const LightCache::Table* learned) const {
  if (triangles_.empty()) return false;
  if (!tree_.empty()) {
    std::uint32_t i;
    LightTree::At at(tree_, p, n);
    if (!LightCache::pick(at, learned, u, i, pdf)) return false;
    index = i;
    return true;
  }
  index = pick_triangle(u);
  pdf = pick_pdf_[index];
  return true;
}

std::size_t LightSampler::pick_triangle(float u) const {
  return std::min<std::size_t>(upper_index(cdf_.data(), cdf_.size(), u), triangles_.size() - 1);
}

bool LightSampler::front_lights(glm::vec3 p, glm::vec3 n, FrontLights& f) const {
  const std::size_t size = triangles_.size();
  if (size > static_cast<std::size_t>(kMaxFront)) return false;
  const glm::vec3 ap = glm::abs(p);
  const __m128 pm = _mm_set1_ps(std::max({ap.x, ap.y, ap.z}));
  int count = 0;
  float total = 0.0f;
  for (std::size_t g = 0; g < size; g += 4) {
    const std::size_t group = g / 4;
    const int lanes = size - g >= 4 ? 15 : (1 << (size - g)) - 1;
    auto front = static_cast<unsigned>(
        ~rejected4(soa_.data() + group * kSoaRows * 4, p, n, pm, one_sided_[group]) & lanes);
    for (; front != 0; front &= front - 1) {
      const std::size_t k = g + static_cast<std::size_t>(std::countr_zero(front));
      total += pick_pdf_[k];
      f.index[count] = static_cast<std::uint32_t>(k);
      f.cdf[count] = total;
      ++count;
    }
  }
  f.count = count;
  f.total = total;
  return true;
}

namespace {

// The lights in front of p as LightCache::mix's defensive sampler: by power among them.
struct FrontPick {
  const LightSampler::FrontLights& front;
  const std::vector<float>& power_pdf;
  bool sample(float u, std::uint32_t& index, float& pmf) const {
    index = front.index[pick_index(front.cdf, front.count, u * front.total)];
    pmf = power_pdf[index] / front.total;
    return true;
  }
  float pmf(std::uint32_t index) const {
    for (int k = 0; k < front.count; ++k)
      if (front.index[k] == index) return power_pdf[index] / front.total;
    return 0.0f;  // not in front: it adds nothing at p
  }
};

}  // namespace

inline bool LightSampler::draw_direct(const RayScene& rays, const FrontLights* front,
                                      LightTree::At* at, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                                      glm::vec3 u, ShadowSample& s, glm::vec3& weight,
                                      const LightCache::Table* learned) const {
  std::size_t li;
  float pdf;
  if (front && learned) {
    // The lights in front by power, mixed with the region's table (whose lights may not all be in
    // front of this texel: those add nothing, and triangle_sample says so).
    if (front->count == 0) return false;
    FrontPick by_power{*front, pick_pdf_};
    std::uint32_t i;
    if (!LightCache::mix(by_power, learned, u.x, i, pdf)) return false;
    li = i;
    if (!triangle_sample(rays, li, p, n, ng, glm::vec2(u.y, u.z), s)) return false;
  } else if (front) {
    if (front->count == 0) return false;
    const int k = pick_index(front->cdf, front->count, u.x * front->total);
    li = front->index[k];
    pdf = pick_pdf_[li] / front->total;
    if (!point_sample(rays, li, p, n, ng, glm::vec2(u.y, u.z), s)) return false;
  } else {
    if (at) {
      std::uint32_t i;
      if (!LightCache::pick(*at, learned, u.x, i, pdf)) return false;
      li = i;
    } else if (!pick(p, n, u.x, li, pdf, learned)) {
      return false;
    }
    if (!triangle_sample(rays, li, p, n, ng, glm::vec2(u.y, u.z), s)) return false;
  }
  weight = triangle_emitted(s) / pdf;
  return true;
}

bool LightSampler::direct_sample(const RayScene& rays, const FrontLights* front, glm::vec3 p,
                                 glm::vec3 n, glm::vec3 ng, glm::vec3 u, ShadowSample& s,
                                 glm::vec3& weight, const LightCache::Table* learned) const {
  return draw_direct(rays, front, nullptr, p, n, ng, u, s, weight, learned);
}

void LightSampler::direct_samples(const RayScene& rays, const FrontLights* front, glm::vec3 p,
                                  glm::vec3 n, glm::vec3 ng, Rng& rng, int first, int count,
                                  int samples, ShadowSample* s, glm::vec3* weight, bool* lit,
                                  const LightCache::Table* learned) const {
  if (!front || front->count == 0 || learned) {  // one sample at a time (none lights p: all
                                                 // false; a table: the mixture's picks)
    // The hierarchy's walks at p, shared by its samples.
    std::optional<LightTree::At> at;
    if (!front && !tree_.empty()) at.emplace(tree_, p, n);
    for (int k = 0; k < count; ++k) {
      const float pick =
          (static_cast<float>(first + k) + rng.next_float()) / static_cast<float>(samples);
      const glm::vec2 pos = rng.next_2d();
      lit[k] = draw_direct(rays, front, at ? &*at : nullptr, p, n, ng, glm::vec3(pick, pos), s[k],
                           weight[k], learned);
    }
    return;
  }
  // The random numbers first (the stream's order), then 4 samples at a time: their picks and
  // their arithmetic, lane by lane the operations of draw_direct.
  for (int k0 = 0; k0 < count; k0 += 4) {
    alignas(16) float pick[4], ux[4], uy[4];
    const int lanes = std::min(4, count - k0);
    for (int k = 0; k < 4; ++k) {
      pick[k] = k < lanes ? rng.next_float() : 0.0f;
      ux[k] = k < lanes ? rng.next_float() : 1.0f;
      uy[k] = k < lanes ? rng.next_float() : 1.0f;
    }
    // (first + k + u) / samples, scaled to the front lights' total, then the index of the first
    // cumulative value above it (the number at or below it), at most the last
    const __m128 strata =
        _mm_add_ps(_mm_set1_ps(static_cast<float>(first + k0)), _mm_set_ps(3.0f, 2.0f, 1.0f, 0.0f));
    const __m128 total = _mm_set1_ps(front->total);
    const __m128 u = _mm_mul_ps(
        _mm_div_ps(_mm_add_ps(strata, _mm_load_ps(pick)), _mm_set1_ps(static_cast<float>(samples))),
        total);
    __m128i below = _mm_setzero_si128();
    for (int j = 0; j + 1 < front->count; ++j)
      below = _mm_sub_epi32(below, _mm_castps_si128(_mm_cmple_ps(_mm_set1_ps(front->cdf[j]), u)));
    alignas(16) std::int32_t j[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(j), below);
    std::uint32_t li[4];
    alignas(16) float pdf[4];
    for (int k = 0; k < 4; ++k) {
      li[k] = front->index[j[k]];
      pdf[k] = pick_pdf_[li[k]];
    }
    _mm_store_ps(pdf, _mm_div_ps(_mm_load_ps(pdf), total));
    sample_lanes(rays, p, n, ng, li, ux, uy, pdf, lanes, s + k0, weight + k0, lit + k0);
  }
}

// point_sample and triangle_emitted / pdf for 4 samples at once, lane by lane the same
// operations in the same order (correctly rounded square roots and quotients, no fused
// multiply-adds), so the same bits.
void LightSampler::sample_lanes(const RayScene& rays, glm::vec3 p, glm::vec3 n, glm::vec3 ng,
                                const std::uint32_t* li, const float* ux, const float* uy,
                                const float* pdf, int lanes, ShadowSample* s, glm::vec3* weight,
                                bool* lit) const {
  __m128 r[kRecRows][4];
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < kRecRows; ++j)
      r[j][k] = _mm_loadu_ps(record_.data() + (li[k] * kRecRows + j) * 4);
  for (int j = 0; j < kRecRows; ++j) _MM_TRANSPOSE4_PS(r[j][0], r[j][1], r[j][2], r[j][3]);
  const __m128 zero = _mm_setzero_ps(), sign = _mm_set1_ps(-0.0f);
  // uniform_triangle, then y = p0 + b.x e1 + b.y e2
  const __m128 root = _mm_sqrt_ps(_mm_load_ps(ux));
  const __m128 bx = _mm_sub_ps(_mm_set1_ps(1.0f), root), by = _mm_mul_ps(_mm_load_ps(uy), root);
  auto point = [&](int c, float pc) {
    return _mm_sub_ps(_mm_add_ps(_mm_add_ps(r[kRecP0Area][c], _mm_mul_ps(bx, r[kRecE1Sided][c])),
                                 _mm_mul_ps(by, r[kRecE2][c])),
                      _mm_set1_ps(pc));
  };
  const Lanes3 d{point(0, p.x), point(1, p.y), point(2, p.z)};  // y - p
  const __m128 dist2 = dot4(d.x, d.y, d.z, d.x, d.y, d.z);
  __m128 ok = _mm_cmpgt_ps(dist2, zero);
  const Lanes3 wi = div3(d, _mm_sqrt_ps(dist2));
  const __m128 cos_x = dot_with(wi, n);
  ok = _mm_and_ps(ok, _mm_cmpnle_ps(cos_x, zero));
  __m128 cos_y = _mm_xor_ps(
      dot4(r[kRecNormal][0], r[kRecNormal][1], r[kRecNormal][2], wi.x, wi.y, wi.z), sign);
  const __m128 two_sided = _mm_cmpneq_ps(r[kRecE1Sided][3], zero);
  cos_y =
      _mm_or_ps(_mm_andnot_ps(two_sided, cos_y), _mm_and_ps(two_sided, _mm_andnot_ps(sign, cos_y)));
  ok = _mm_and_ps(ok, _mm_cmpnle_ps(cos_y, zero));
  // RayScene::offset(p, ng, wi), then the ray to the light point y = d + p
  const __m128 eps = _mm_set1_ps(rays.epsilon());
  const __m128 up = _mm_cmpge_ps(dot_with(wi, ng), zero);
  const __m128 off = _mm_or_ps(_mm_and_ps(up, eps), _mm_andnot_ps(up, _mm_xor_ps(eps, sign)));
  const Lanes3 o{_mm_add_ps(_mm_set1_ps(p.x), _mm_mul_ps(off, _mm_set1_ps(ng.x))),
                 _mm_add_ps(_mm_set1_ps(p.y), _mm_mul_ps(off, _mm_set1_ps(ng.y))),
                 _mm_add_ps(_mm_set1_ps(p.z), _mm_mul_ps(off, _mm_set1_ps(ng.z)))};
  auto light_point = [&](int c) {
    return _mm_add_ps(_mm_add_ps(r[kRecP0Area][c], _mm_mul_ps(bx, r[kRecE1Sided][c])),
                      _mm_mul_ps(by, r[kRecE2][c]));
  };
  const Lanes3 to{_mm_sub_ps(light_point(0), o.x), _mm_sub_ps(light_point(1), o.y),
                  _mm_sub_ps(light_point(2), o.z)};
  const __m128 len = _mm_sqrt_ps(dot4(to.x, to.y, to.z, to.x, to.y, to.z));
  const Lanes3 dir = div3(to, len);
  const __m128 tmax = _mm_sub_ps(len, eps);
  const __m128 factor = _mm_div_ps(_mm_mul_ps(_mm_mul_ps(cos_x, cos_y), r[kRecP0Area][3]), dist2);
  const __m128 lane_pdf = _mm_load_ps(pdf);
  const Lanes3 w =
      div3({_mm_mul_ps(r[kRecEmission][0], factor), _mm_mul_ps(r[kRecEmission][1], factor),
            _mm_mul_ps(r[kRecEmission][2], factor)},
           lane_pdf);
  alignas(16) float out[11][4];
  const __m128 rows[11] = {o.x, o.y, o.z, dir.x, dir.y, dir.z, tmax, w.x, w.y, w.z, factor};
  for (int j = 0; j < 11; ++j) _mm_store_ps(out[j], rows[j]);
  alignas(16) float b[2][4], uniform[4];
  _mm_store_ps(b[0], bx);
  _mm_store_ps(b[1], by);
  _mm_store_ps(uniform, r[kRecEmission][3]);
  const int mask = _mm_movemask_ps(ok);
  for (int k = 0; k < lanes; ++k) {
    lit[k] = (mask >> k) & 1;
    s[k].shadow =
        Ray{{out[0][k], out[1][k], out[2][k]}, {out[3][k], out[4][k], out[5][k]}, 0.0f, out[6][k]};
    s[k].triangle = li[k];  // the whole sample, as point_sample gives it (learning reads it)
    s[k].b = glm::vec2(b[0][k], b[1][k]);
    s[k].factor = out[10][k];
    weight[k] = glm::vec3(out[7][k], out[8][k], out[9][k]);
    if (uniform[k] == 0.0f) {  // an emissive texture or cut-outs: World::emission at the point
      const EmissiveTriangle& e = triangles_[li[k]];
      weight[k] = world_->emission(e.object, e.triangle, b[0][k], b[1][k]) * out[10][k] / pdf[k];
    }
  }
}

glm::vec3 LightSampler::area_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n,
                                        glm::vec3 ng, glm::vec3 u) const {
  std::size_t i;
  float pdf;
  if (!pick(p, n, u.x, i, pdf)) return glm::vec3(0.0f);
  return triangle_irradiance(rays, i, p, n, ng, glm::vec2(u.y, u.z)) / pdf;
}

bool LightSampler::punctual_sample(const RayScene& rays, const WorldLight& l, glm::vec3 p,
                                   glm::vec3 n, glm::vec3 ng, ShadowSample& s) {
  glm::vec3 wi;
  float dist = 3.4e38f;
  float falloff = 1.0f;
  if (l.type == Light::Type::Directional) {
    wi = -l.direction;
  } else {
    glm::vec3 d = l.position - p;
    float dist2 = glm::dot(d, d);
    if (!(dist2 > 0.0f)) return false;
    dist = std::sqrt(dist2);
    wi = d / dist;
    falloff = 1.0f / dist2;
    if (l.range > 0.0f) {  // KHR_lights_punctual recommended range window
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
  float cos_x = glm::dot(n, wi);
  if (cos_x <= 0.0f || falloff <= 0.0f) return false;
  s.shadow = Ray{};
  s.shadow.origin = rays.offset(p, ng, wi);
  s.shadow.direction = wi;
  s.shadow.tmax = l.type == Light::Type::Directional ? 3.4e38f : dist - rays.epsilon();
  s.irradiance = l.intensity * (cos_x * falloff);
  return true;
}

glm::vec3 LightSampler::punctual_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n,
                                            glm::vec3 ng) const {
  glm::vec3 sum(0.0f);
  for (const WorldLight& l : world_->lights) {
    ShadowSample s;
    if (!punctual_sample(rays, l, p, n, ng, s)) continue;
    if (rays.occluded(s.shadow)) continue;
    sum += s.irradiance;
  }
  return sum;
}

}  // namespace irradcast

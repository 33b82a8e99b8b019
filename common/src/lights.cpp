#include "irradcast/common/lights.h"

#include <algorithm>
#include <cmath>

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

}  // namespace

LightSampler::LightSampler(const World& world) : world_(&world) {
  std::vector<float> power;
  for (const WorldObject& o : world.objects) {
    if (!o.visible) continue;
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
  const EmissiveTriangle& e = triangles_[index];
  if (surely_rejected(e, p, n)) return false;
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

std::size_t LightSampler::pick_triangle(float u) const {
  // std::upper_bound (the first cumulative probability above u), without branches that the
  // random u would mispredict half the time.
  const float* first = cdf_.data();
  std::size_t len = cdf_.size();
  while (len > 1) {
    const std::size_t half = len / 2;
    first += first[half - 1] <= u ? half : 0;
    len -= half;
  }
  const std::size_t index = static_cast<std::size_t>(first - cdf_.data()) + (*first <= u ? 1 : 0);
  return std::min<std::size_t>(index, triangles_.size() - 1);
}

glm::vec3 LightSampler::area_irradiance(const RayScene& rays, glm::vec3 p, glm::vec3 n,
                                        glm::vec3 ng, glm::vec3 u) const {
  if (triangles_.empty()) return glm::vec3(0.0f);
  std::size_t i = pick_triangle(u.x);
  return triangle_irradiance(rays, i, p, n, ng, glm::vec2(u.y, u.z)) / pick_pdf_[i];
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

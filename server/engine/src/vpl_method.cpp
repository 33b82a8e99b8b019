#include "vpl_method.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

#include "halton.h"
#include "irradcast/common/sampling.h"

namespace irradcast {
namespace {

using Clock = std::chrono::steady_clock;

// Halton dimensions of a path: the emitter, the point on it (2), the direction (2), then two
// per further bounce. Beyond the primes halton() has, a hashed random number.
constexpr int kPick = 0, kPoint = 1, kDirection = 3, kBounce = 5;

glm::vec3 uniform_sphere(glm::vec2 u) {
  const float z = 1.0f - 2.0f * u.x;
  const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  const float phi = 2.0f * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

// The integral of the sky's luminance over the sphere of directions (sr x W m^-2 sr^-1): 4 pi L
// for a constant sky, the sum of luminance x solid angle over a map's texels.
double sky_luminance_integral(const Sky& sky) {
  if (sky.map.width <= 0 || sky.map.height <= 0)
    return 4.0 * kPi * static_cast<double>(luminance(sky.color * sky.strength));
  const int w = sky.map.width, h = sky.map.height;
  const double texel = (2.0 * kPi / w) * (kPi / h);  // dphi dtheta
  double sum = 0.0;
  for (int y = 0; y < h; ++y) {
    double row = 0.0;
    for (int x = 0; x < w; ++x) row += luminance(sky.map.at(x, y));
    sum += row * std::sin(kPi * (y + 0.5) / h);
  }
  return sum * texel * sky.strength;
}

bool inside(const Bounds& b, glm::vec3 p, float pad) {
  return p.x >= b.lo.x - pad && p.y >= b.lo.y - pad && p.z >= b.lo.z - pad && p.x <= b.hi.x + pad &&
         p.y <= b.hi.y + pad && p.z <= b.hi.z + pad;
}

}  // namespace

VplMethod::VplMethod(const EngineParams& params, const World& world, const RayScene& rays,
                     const LightSampler& lights)
    : params_(params), world_(&world), rays_(&rays), lights_(&lights) {
  depth_ = std::max(1, params_.indirect_bounces);
  const auto paths = static_cast<std::size_t>(params_.vpl_paths);
  vpls_.assign(paths * static_cast<std::size_t>(depth_), VirtualPointLight{});
  starts_.assign(paths, PathStart{});
  path_index_.assign(paths, 0);
  pending_.assign(paths, 0);
  Rng rng(mix64(params_.seed) ^ 0x5650'4cull, 7);
  for (int d = 0; d < 32; ++d) shifts_.push_back(rng.next_float());
  build_emitters();
}

void VplMethod::build_emitters() {
  // Emitted flux (luminance) of every light: pi L A per side of an area triangle, 4 pi I for a
  // point or spot light, E pi r^2 for a directional light through the scene's bounding sphere,
  // and for the sky the integral of L over directions x pi r^2.
  std::vector<double> power;
  const auto& tris = lights_->emissive_triangles();
  const float total_area = lights_->total_area_power();  // sum of luminance(L) A (sides)
  for (std::size_t i = 0; i < tris.size(); ++i)
    power.push_back(static_cast<double>(kPi) * total_area * lights_->pick_pdf()[i]);
  area_count_ = tris.size();
  const float r = 0.5f * glm::length(world_->bounds.extent());
  for (const WorldLight& l : world_->lights) {
    const double lum = luminance(l.intensity);
    power.push_back(l.type == Light::Type::Directional ? lum * kPi * r * r : lum * 4.0 * kPi);
  }
  // The sky, last: its radiance through the disc across the scene's bounding sphere.
  if (lights_->has_sky()) power.push_back(sky_luminance_integral(*lights_->sky()) * kPi * r * r);
  emitter_cdf_.assign(power.size(), 0.0f);
  emitter_pdf_.assign(power.size(), 0.0f);
  double total = 0.0;
  for (double p : power) total += std::max(0.0, p);
  if (!(total > 0.0)) return;
  double run = 0.0;
  for (std::size_t i = 0; i < power.size(); ++i) {
    run += std::max(0.0, power[i]);
    emitter_cdf_[i] = static_cast<float>(run / total);
    emitter_pdf_[i] = static_cast<float>(std::max(0.0, power[i]) / total);
  }
  emitter_cdf_.back() = 1.0f;
}

float VplMethod::dim(std::uint64_t index, int d) const {
  // Base 2 is skipped: the temporal sets and interleaved subsets are strided by powers of two,
  // and a base-2 radical inverse over a stride of 2^k stays inside one interval of width 2^-k
  // (every subset would pick its light from one narrow slice of the CDF). Odd prime bases
  // spread evenly over any power-of-two stride.
  if (d + 1 < 32) return halton(index, d + 1, shifts_[static_cast<std::size_t>(d + 1)]);
  Rng rng(mix64(index ^ mix64(params_.seed)), static_cast<std::uint64_t>(d));
  return rng.next_float();
}

VplMethod::PathOrigin VplMethod::emit(std::size_t e, float pdf, float side_u, glm::vec2 up,
                                      glm::vec2 ud) const {
  PathOrigin o;
  glm::vec3 &origin = o.origin, &direction = o.direction, &flux = o.flux;
  // A point on the disc of radius r across the scene's bounding sphere, facing `direction`.
  const float r = 0.5f * glm::length(world_->bounds.extent()) * 1.01f;
  auto disc = [&] {
    const Frame f(-direction);
    const float rad = r * std::sqrt(up.x), phi = 2.0f * kPi * up.y;
    origin = world_->bounds.center() - direction * r + f.t * (rad * std::cos(phi)) +
             f.b * (rad * std::sin(phi));
  };
  if (e < area_count_) {
    const EmissiveTriangle& t = lights_->emissive_triangles()[e];
    const glm::vec2 b = uniform_triangle(up);
    origin = t.p0 + b.x * t.e1 + b.y * t.e2;
    glm::vec3 n = t.normal;
    float sides = 1.0f;
    if (t.double_sided) {
      sides = 2.0f;
      if (side_u >= 0.5f) n = -n;
    }
    direction = Frame(n).to_world(cosine_hemisphere(ud));
    // L cos / (pick pdf x 1/A x cos/pi x 1/sides)
    flux = world_->emission(t.object, t.triangle, b.x, b.y) * (kPi * t.area * sides / pdf);
    origin = rays_->offset(origin, n, direction);
  } else if (e >= area_count_ + world_->lights.size()) {
    // The sky: a direction toward it by the map's luminance (uniform for a constant sky), the
    // path travelling the other way from the disc: L / (pick pdf x direction pdf x 1/(pi r^2)).
    const Sky& sky = *lights_->sky();
    const SkyDistribution& dist = lights_->sky_distribution();
    glm::vec3 to_sky = uniform_sphere(ud);
    float dir_pdf = 1.0f / (4.0f * kPi);
    if (dist.valid()) {
      const SkyDistribution::Sample s = dist.sample(ud);
      to_sky = s.direction;
      dir_pdf = s.pdf;
    }
    if (!(dir_pdf > 0.0f)) return o;  // no flux: the path ends at once
    direction = -to_sky;
    disc();
    flux = sky.radiance(to_sky) * (kPi * r * r / (pdf * dir_pdf));
  } else {
    const WorldLight* punctual = &world_->lights[e - area_count_];
    if (punctual->type == Light::Type::Directional) {
      direction = punctual->direction;
      disc();
      flux = punctual->intensity * (kPi * r * r / pdf);
    } else {
      o.point = punctual;
      origin = punctual->position;
      direction = uniform_sphere(ud);
      flux = punctual->intensity * (4.0f * kPi / pdf);
      if (punctual->type == Light::Type::Spot) {
        const float cd = glm::dot(punctual->direction, direction);
        const float denom = std::max(1e-4f, punctual->cos_inner - punctual->cos_outer);
        const float t = glm::clamp((cd - punctual->cos_outer) / denom, 0.0f, 1.0f);
        flux *= t * t;
      }
    }
  }
  return o;
}

std::uint64_t VplMethod::shoot(std::size_t p, std::uint64_t index) {
  const auto k0 = p * static_cast<std::size_t>(depth_);
  for (int k = 0; k < depth_; ++k) vpls_[k0 + static_cast<std::size_t>(k)] = VirtualPointLight{};
  path_index_[p] = index;
  starts_[p] = PathStart{};
  if (emitter_cdf_.empty()) return 0;
  // The emitter, by power; the position of u within its bucket picks the side of a two-sided
  // area light.
  const float u = dim(index, kPick);
  const auto it = std::upper_bound(emitter_cdf_.begin(), emitter_cdf_.end(), u);
  const std::size_t e = std::min<std::size_t>(static_cast<std::size_t>(it - emitter_cdf_.begin()),
                                              emitter_cdf_.size() - 1);
  const float pdf = emitter_pdf_[e];
  if (!(pdf > 0.0f)) return 0;
  const float below = e == 0 ? 0.0f : emitter_cdf_[e - 1];
  const float side_u = (u - below) / pdf;
  const glm::vec2 up(dim(index, kPoint), dim(index, kPoint + 1));
  const glm::vec2 ud(dim(index, kDirection), dim(index, kDirection + 1));
  const PathOrigin from = emit(e, pdf, side_u, up, ud);
  glm::vec3 origin = from.origin, direction = from.direction, flux = from.flux;
  const bool point_light = from.point != nullptr;
  const WorldLight* punctual = from.point;
  starts_[p].origin = origin;
  starts_[p].live = true;
  std::uint64_t traced = 0;
  for (int k = 0; k < depth_; ++k) {
    if (!(luminance(flux) > 0.0f)) break;
    Ray ray;
    ray.origin = origin;
    ray.direction = direction;
    const Hit h = rays_->intersect(ray);
    ++traced;
    if (!h.valid()) break;
    if (k == 0 && point_light && punctual->range > 0.0f) {
      const float r = h.t / punctual->range;  // KHR_lights_punctual range window
      flux *= glm::clamp(1.0f - r * r * r * r, 0.0f, 1.0f);
    }
    const WorldObject& obj = world_->objects[h.object];
    glm::vec3 ng = obj.geometric_normal(h.triangle);
    if (glm::dot(ng, direction) > 0.0f) ng = -ng;
    const glm::vec3 albedo = world_->albedo(h.object, h.triangle, h.u, h.v);
    VirtualPointLight& v = vpls_[k0 + static_cast<std::size_t>(k)];
    v.position = ray.origin + h.t * direction;
    v.normal = ng;
    v.power = flux * albedo * kInvPi;
    v.valid = true;
    // The next bounce: cosine-weighted, so the flux only picks up the albedo.
    const glm::vec2 ub(dim(index, kBounce + 2 * k), dim(index, kBounce + 2 * k + 1));
    direction = Frame(ng).to_world(cosine_hemisphere(ub));
    origin = rays_->offset(v.position, ng, direction);
    flux *= albedo;
  }
  return traced;
}

PassResult VplMethod::prepare(const PassInput& in) {
  const auto start = Clock::now();
  PassResult r;
  const std::size_t paths = starts_.size();
  // A new pool once every temporal set has been gathered (and at the start).
  set_ = (set_ + 1) % params_.vpl_sets;
  std::atomic<std::uint64_t> rays{0};
  if (set_ == 0) {
    const std::uint64_t base = cycle_ * paths;
    tbb::parallel_for(std::size_t(0), paths, [&](std::size_t p) { rays += shoot(p, base + p); });
    std::fill(pending_.begin(), pending_.end(), std::uint8_t{0});
    ++cycle_;
  } else {
    // Seed 000 Algorithm 3: shoot invalid VPLs again from their parent (the same path with the
    // same Halton point, so the valid VPLs before them come out unchanged), round robin, at
    // most vpl_replace VPLs per update.
    std::vector<std::size_t> redo;
    std::size_t budget =
        params_.vpl_replace > 0 ? static_cast<std::size_t>(params_.vpl_replace) : vpls_.size();
    const std::size_t from = replace_cursor_;
    for (std::size_t n = 0; n < paths && budget > 0; ++n) {
      const std::size_t p = (from + n) % paths;
      if (pending_[p] == 0) continue;
      const auto count = static_cast<std::size_t>(depth_ - (pending_[p] - 1));
      redo.push_back(p);
      budget = count >= budget ? 0 : budget - count;
      replace_cursor_ = (p + 1) % paths;
      replaced_ += count;
    }
    tbb::parallel_for(std::size_t(0), redo.size(), [&](std::size_t i) {
      rays += shoot(redo[i], path_index_[redo[i]]);
      pending_[redo[i]] = 0;
    });
  }
  build_texel_map(in);
  r.rays = rays.load();
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return r;
}

void VplMethod::build_texel_map(const PassInput& in) {
  if (map_generation_ == in.generation && !texel_index_.empty()) return;
  texel_index_.assign(in.atlas.objects.size(), {});
  for (std::size_t o = 0; o < in.atlas.objects.size(); ++o)
    texel_index_[o].assign(static_cast<std::size_t>(in.atlas.objects[o].width) *
                               static_cast<std::size_t>(in.atlas.objects[o].height),
                           -1);
  for (std::size_t i = 0; i < in.texels.size(); ++i)
    texel_index_[in.texels.object[i]][in.texels.texel[i]] = static_cast<std::int32_t>(i);
  map_generation_ = in.generation;
}

// 1. Gather: each texel its subset of this update's temporal set. Paths p with
//    p % sets == set and (p / sets) % subsets == subset; an empty or ended slot counts as a
//    VPL of zero power, so the mean over the slots estimates the pool's mean. Returns the shadow
//    rays traced.
std::uint64_t VplMethod::gather(const PassInput& in, int k, std::vector<glm::vec3>& raw) const {
  const std::size_t paths = starts_.size();
  const auto sets = static_cast<std::size_t>(params_.vpl_sets);
  const int n = params_.vpl_interleave;
  const auto subsets = static_cast<std::size_t>(n * n);
  const float clamp_d = params_.vpl_clamp * world_->bounds.max_extent();
  const float min_d2 = clamp_d * clamp_d;
  const auto set = static_cast<std::size_t>(std::max(set_, 0));
  std::atomic<std::uint64_t> rays{0};
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, in.unit_texels.size(), 256),
      [&](const tbb::blocked_range<std::size_t>& range) {
        std::uint64_t local = 0;
        for (std::size_t j = range.begin(); j < range.end(); ++j) {
          const std::uint32_t i = in.unit_texels[j];
          const std::uint32_t o = in.texels.object[i], t = in.texels.texel[i];
          const auto w = static_cast<std::uint32_t>(in.atlas.objects[o].width);
          const std::size_t subset =
              (t % w) % static_cast<std::uint32_t>(n) +
              static_cast<std::size_t>(n) * ((t / w) % static_cast<std::uint32_t>(n));
          const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i],
                          ng = in.texels.geo_normal(in.world, i);
          glm::vec3 sum(0.0f);
          std::size_t slots = 0;
          for (std::size_t path = set + sets * subset; path < paths; path += sets * subsets) {
            ++slots;
            const VirtualPointLight& v =
                vpls_[path * static_cast<std::size_t>(depth_) + static_cast<std::size_t>(k - 1)];
            if (!v.valid) continue;
            glm::vec3 d = v.position - p;
            const float d2 = glm::dot(d, d);
            if (!(d2 > 0.0f)) continue;
            const float len = std::sqrt(d2);
            d /= len;
            const float cos_p = glm::dot(nrm, d), cos_v = -glm::dot(v.normal, d);
            if (cos_p <= 0.0f || cos_v <= 0.0f) continue;
            Ray shadow;
            shadow.origin = rays_->offset(p, ng, d);
            const glm::vec3 target = v.position + rays_->epsilon() * v.normal;
            glm::vec3 to = target - shadow.origin;
            const float tl = glm::length(to);
            if (!(tl > 2.0f * rays_->epsilon())) continue;
            shadow.direction = to / tl;
            shadow.tmax = tl - rays_->epsilon();
            ++local;
            if (rays_->occluded(shadow)) continue;
            sum += v.power * (cos_p * cos_v / std::max(d2, min_d2));
          }
          raw[i] = slots > 0 ? sum / static_cast<float>(slots) : glm::vec3(0.0f);
        }
        rays += local;
      });
  return rays.load();
}

// 2. The discontinuity filter: the mean over the n x n lightmap neighbourhood (one texel of
//    every subset) of the neighbours on the same surface: similar normal and in the texel's
//    tangent plane. Neighbours further than the window's own world size (another chart that
//    happens to be coplanar) are not the same surface either.
void VplMethod::filter(const PassInput& in, const std::vector<glm::vec3>& raw,
                       std::vector<glm::vec3>& out) const {
  const int n = params_.vpl_interleave;
  const int lo = -(n / 2);
  tbb::parallel_for(std::size_t(0), in.unit_texels.size(), [&](std::size_t j) {
    const std::uint32_t i = in.unit_texels[j];
    const std::uint32_t o = in.texels.object[i], t = in.texels.texel[i];
    const float density = in.atlas.objects[o].texels_per_unit;
    const float reach = density > 0.0f ? 1.5f * static_cast<float>(n) / density : 3.4e38f;
    const int w = in.atlas.objects[o].width, h = in.atlas.objects[o].height;
    const int x = static_cast<int>(t % static_cast<std::uint32_t>(w));
    const int y = static_cast<int>(t / static_cast<std::uint32_t>(w));
    const glm::vec3 p = in.texels.position[i], nrm = in.texels.normal[i];
    glm::vec3 sum(0.0f);
    int count = 0;
    for (int dy = lo; dy < lo + n; ++dy)
      for (int dx = lo; dx < lo + n; ++dx) {
        const int xx = x + dx, yy = y + dy;
        if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
        const std::int32_t q = texel_index_[o][static_cast<std::size_t>(yy) * w + xx];
        if (q < 0) continue;
        const auto qi = static_cast<std::size_t>(q);
        if (glm::dot(in.texels.normal[qi], nrm) < 0.9f) continue;
        const glm::vec3 d = in.texels.position[qi] - p;
        const float len = glm::length(d);
        if (len > reach || std::fabs(glm::dot(d, nrm)) > 0.25f * len + 1e-6f) continue;
        sum += raw[qi];
        ++count;
      }
    out[i] = count > 0 ? sum / static_cast<float>(count) : raw[i];
  });
}

BounceResult VplMethod::bounce(const PassInput& in, const RadianceField& /*prev*/,
                               std::vector<glm::vec3>& out) {
  const auto start = Clock::now();
  out.assign(in.texels.size(), glm::vec3(0.0f));
  PassResult r;
  const int k = static_cast<int>(in.bounce);
  if (k < 1 || k > depth_) return {{}, r};
  std::vector<glm::vec3> raw(in.texels.size(), glm::vec3(0.0f));
  r.rays = gather(in, k, raw);
  filter(in, raw, out);
  r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return {{}, r};
}

void VplMethod::scene_changed(const SceneChange& change, const Lap& lap) {
  replaced_ = 0;
  build_emitters();
  const std::size_t paths = starts_.size();
  // Lights or materials changed: every path's flux may have, so every path is shot again
  // (one ray per VPL; the texels' gather is what costs). Otherwise seed 000 Algorithm 2: a VPL
  // in a changed region, or whose segment from its parent (the light or the VPL before it) is
  // now occluded, is invalid with every VPL after it on its path.
  const bool all = change.surfaces || change.sky || !change.light_points.empty();
  const float pad = 1e-3f * world_->bounds.max_extent();
  tbb::parallel_for(std::size_t(0), paths, [&](std::size_t p) {
    if (all) {  // including paths that found no light before: the edit may have turned one on
      pending_[p] = 1;
      for (int k = 0; k < depth_; ++k)
        vpls_[p * static_cast<std::size_t>(depth_) + static_cast<std::size_t>(k)].valid = false;
      return;
    }
    if (!starts_[p].live) return;
    glm::vec3 parent = starts_[p].origin;
    for (int k = 0; k < depth_; ++k) {
      const VirtualPointLight& v =
          vpls_[p * static_cast<std::size_t>(depth_) + static_cast<std::size_t>(k)];
      bool bad = !v.valid;
      bool changed = false;
      for (const Bounds& b : change.regions)
        if ((v.valid && inside(b, v.position, pad)) || (k == 0 && inside(b, parent, pad)))
          changed = true;
      if (v.valid && !changed) {
        Ray shadow;
        glm::vec3 target = v.position + rays_->epsilon() * v.normal;
        glm::vec3 d = target - parent;
        const float len = glm::length(d);
        if (len > 2.0f * rays_->epsilon()) {
          shadow.origin = parent;
          shadow.direction = d / len;
          shadow.tmax = len - rays_->epsilon();
          changed = rays_->occluded(shadow);
        }
      }
      if (changed) {
        pending_[p] = static_cast<std::uint8_t>(k + 1);
        for (int j = k; j < depth_; ++j)
          vpls_[p * static_cast<std::size_t>(depth_) + static_cast<std::size_t>(j)].valid = false;
        return;
      }
      if (bad) return;  // the path ended here before the edit
      parent = v.position + rays_->epsilon() * v.normal;
    }
  });
  lap(name());
}

std::size_t VplMethod::invalid() const {
  std::size_t n = 0;
  for (std::size_t p = 0; p < pending_.size(); ++p)
    if (pending_[p] != 0) n += static_cast<std::size_t>(depth_ - (pending_[p] - 1));
  return n;
}

std::string VplMethod::summary() const {
  std::size_t valid = 0;
  for (const VirtualPointLight& v : vpls_) valid += v.valid ? 1 : 0;
  return std::to_string(starts_.size()) + " paths, " + std::to_string(valid) + " VPLs, pool " +
         std::to_string(cycle_) + ", " + std::to_string(replaced_) +
         " shot again since the last edit, " + std::to_string(invalid()) + " invalid";
}

}  // namespace irradcast

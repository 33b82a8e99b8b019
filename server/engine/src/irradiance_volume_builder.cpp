// The irradiance volume's probes: placement (out of geometry, distance moments) and refinement
// from the lightmaps (SH L2 of the radiance around each probe, the emitters' apart; the punctual
// lights' direct light is left to the viewers, who trace it: dynamic_view.h).
#include "irradcast/engine/irradiance_volume_builder.h"

#include <algorithm>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "irradcast/common/error.h"
#include "irradcast/common/hit_shader.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

namespace {

// Direction k of n spread evenly over the sphere (spherical Fibonacci).
glm::vec3 fibonacci(int k, int n) {
  const float z = 1.0f - (2.0f * float(k) + 1.0f) / float(n);
  const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  const float phi = 2.39996323f * float(k);
  return {r * std::cos(phi), r * std::sin(phi), z};
}

float unit_float(std::uint64_t bits) {
  return float(mix64(bits) >> 40) * (1.0f / 16777216.0f);
}

// A uniformly random rotation for round `round` (Shoemake's quaternion).
glm::mat3 random_rotation(std::uint64_t round) {
  const float u1 = unit_float(3 * round + 11), u2 = unit_float(3 * round + 12),
              u3 = unit_float(3 * round + 13);
  const float a = std::sqrt(1.0f - u1), b = std::sqrt(u1);
  const float x = a * std::sin(2.0f * kPi * u2), y = a * std::cos(2.0f * kPi * u2),
              z = b * std::sin(2.0f * kPi * u3), w = b * std::cos(2.0f * kPi * u3);
  return glm::mat3(1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y),
                   2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x),
                   2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y));
}

struct Look {
  int backfaces = 0;
  float back_t = 3.4e38f, front_t = 3.4e38f;
  glm::vec3 back_dir{0.0f}, front_dir{0.0f};
};

// What a probe at p sees along n directions: the nearest front and back faces.
Look look_around(const World& world, const RayScene& rays, glm::vec3 p, int n) {
  Look look;
  for (int k = 0; k < n; ++k) {
    Ray r;
    r.origin = p;
    r.direction = fibonacci(k, n);
    const Hit h = rays.intersect(r);
    if (!h.valid()) continue;
    const glm::vec3 ng =
        world.objects[static_cast<std::size_t>(h.object)].geometric_normal(h.triangle);
    const bool two_sided = world.material(h.object, h.triangle).double_sided;
    if (glm::dot(ng, r.direction) > 0.0f && !two_sided) {
      ++look.backfaces;
      if (h.t < look.back_t) {
        look.back_t = h.t;
        look.back_dir = r.direction;
      }
    } else if (h.t < look.front_t) {
      look.front_t = h.t;
      look.front_dir = r.direction;
    }
  }
  return look;
}

bool within_cell(glm::vec3 offset, float spacing) {
  const glm::vec3 a = glm::abs(offset);
  return std::max(a.x, std::max(a.y, a.z)) <= 0.45f * spacing;
}

}  // namespace

VolumeGrid probe_grid_for(const Bounds& bounds, const IrradianceVolumeOptions& options) {
  const glm::vec3 extent = bounds.extent();
  const float largest = bounds.max_extent();
  float spacing = options.spacing > 0.0f
                      ? options.spacing
                      : std::min(options.spacing_fraction * (largest > 0.0f ? largest : 1.0f),
                                 options.max_default_spacing);
  if (!(spacing > 0.0f) || !std::isfinite(spacing))
    throw Error("irradiance volume: the probe spacing must be a finite distance above 0");
  VolumeGrid g;
  for (int tries = 0; tries < 64; ++tries) {
    for (int a = 0; a < 3; ++a) {
      const float cells = std::ceil(extent[a] / spacing - 1e-3f);
      g.counts[a] = static_cast<int>(std::clamp(cells, 1.0f, 65536.0f));
    }
    if (g.probe_count() <= std::max<std::size_t>(options.max_probes, 1)) break;
    spacing *= 1.05f * std::cbrt(float(g.probe_count()) / float(options.max_probes));
  }
  g.spacing = spacing;
  g.origin = bounds.center() - 0.5f * spacing * glm::vec3(g.counts - 1);
  return g;
}

IrradianceVolumeBuilder::IrradianceVolumeBuilder(const World& world, const RayScene& rays,
                                                 const Atlas& atlas,
                                                 IrradianceVolumeOptions options)
    : world_(world), rays_(rays), atlas_(atlas), options_(options) {
  options_.rays_per_probe = std::max(options_.rays_per_probe, 1);
  options_.placement_rays = std::max(options_.placement_rays, 8);
  options_.max_history = std::max(options_.max_history, 1);
  volume_.reset(probe_grid_for(world.bounds, options_));
  place();
}

void IrradianceVolumeBuilder::place() {
  const VolumeGrid grid = volume_.grid;
  volume_.reset(grid);
  rounds_ = 0;
  const float s = grid.spacing, far = grid.max_distance();
  const int n = options_.placement_rays;
  std::vector<std::uint8_t> moved(grid.probe_count(), 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, grid.probe_count(), 16),
      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
          const glm::vec3 home = grid.position(grid.cell_of(i));
          glm::vec3 offset(0.0f);
          Look look = look_around(world_, rays_, home, n);
          if (look.backfaces > n / 4) {
            // Inside something: step through the nearest back face, if that stays in the cell.
            offset = look.back_dir * (look.back_t + 0.1f * s);
            if (!within_cell(offset, s) ||
                look_around(world_, rays_, home + offset, n).backfaces > n / 4) {
              volume_.active[i] = 0;
              continue;
            }
            moved[i] = 1;
            look = look_around(world_, rays_, home + offset, n);
          }
          if (look.front_t < 0.1f * s) {  // too close to a surface: away from it
            const glm::vec3 away = offset - look.front_dir * (0.1f * s - look.front_t);
            if (within_cell(away, s)) {
              offset = away;
              moved[i] = 1;
            }
          }
          volume_.offsets[i] = offset;
          // Distance moments: 4 rays through each texel of the octahedral map.
          const glm::vec3 p = home + offset;
          glm::vec2* m = volume_.depth.data() + i * IrradianceVolume::kDepthTexels;
          for (int t = 0; t < IrradianceVolume::kDepthTexels; ++t) {
            const int tx = t % IrradianceVolume::kDepthSize, ty = t / IrradianceVolume::kDepthSize;
            glm::vec2 sum(0.0f);
            for (int j = 0; j < 4; ++j) {
              const glm::vec2 uv(
                  (float(tx) + 0.25f + 0.5f * float(j & 1)) / IrradianceVolume::kDepthSize,
                  (float(ty) + 0.25f + 0.5f * float(j >> 1)) / IrradianceVolume::kDepthSize);
              Ray ray;
              ray.origin = p;
              ray.direction = octahedral_decode(uv);
              ray.tmax = far;
              const Hit h = rays_.intersect(ray);
              const float d = h.valid() ? std::min(h.t, far) : far;
              sum += glm::vec2(d, d * d);
            }
            m[t] = 0.25f * sum;
          }
        }
      });
  switched_off_ =
      static_cast<std::size_t>(std::count(volume_.active.begin(), volume_.active.end(), 0));
  moved_ = static_cast<std::size_t>(std::count(moved.begin(), moved.end(), 1));
}

void IrradianceVolumeBuilder::refine(const std::vector<Lightmap>& lightmaps) {
  const HitShader shader(world_, atlas_, lightmaps);
  const Sky* sky = world_.scene && world_.scene->sky.enabled() ? &world_.scene->sky : nullptr;
  const glm::mat3 rotation = random_rotation(rounds_);
  const int n = options_.rays_per_probe;
  const float weight = 4.0f * kPi / float(n);
  const float blend =
      1.0f / float(std::min<std::uint64_t>(rounds_ + 1, std::uint64_t(options_.max_history)));
  std::vector<std::array<float, kShCoefficients>> basis(static_cast<std::size_t>(n));
  std::vector<glm::vec3> dirs(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    dirs[static_cast<std::size_t>(k)] = glm::normalize(rotation * fibonacci(k, n));
    basis[static_cast<std::size_t>(k)] = sh_basis(dirs[static_cast<std::size_t>(k)]);
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, volume_.probe_count(), 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        if (!volume_.active[i]) continue;
                        const glm::vec3 p = volume_.probe_position(i);
                        ShIrradiance radiance{}, emission{};
                        for (int k = 0; k < n; ++k) {
                          Ray ray;
                          ray.origin = p;
                          ray.direction = dirs[static_cast<std::size_t>(k)];
                          const Hit h = rays_.intersect(ray);
                          glm::vec3 l(0.0f), e(0.0f);
                          if (h.valid()) {
                            const HitShade s = shader.shade(ray.direction, h);
                            l = s.diffuse;
                            e = s.emission;
                          } else if (sky) {
                            l = sky->radiance(ray.direction);
                          }
                          const auto& y = basis[static_cast<std::size_t>(k)];
                          for (int c = 0; c < kShCoefficients; ++c) {
                            radiance[static_cast<std::size_t>(c)] +=
                                (weight * y[static_cast<std::size_t>(c)]) * l;
                            emission[static_cast<std::size_t>(c)] +=
                                (weight * y[static_cast<std::size_t>(c)]) * e;
                          }
                        }
                        for (int c = 0; c < kShCoefficients; ++c) {
                          const int band = c == 0 ? 0 : c < 4 ? 1 : 2;
                          const auto k = static_cast<std::size_t>(c);
                          volume_.sh[i][k] +=
                              blend * (kShCosineBand[band] * radiance[k] - volume_.sh[i][k]);
                          volume_.emitted[i][k] +=
                              blend * (kShCosineBand[band] * emission[k] - volume_.emitted[i][k]);
                        }
                      }
                    });
  ++rounds_;
}

}  // namespace irradcast

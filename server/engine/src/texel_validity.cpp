#include "irradcast/engine/texel_validity.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>

#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

std::size_t mark_hidden_texels(const RayScene& rays, std::vector<TexelGBuffer>& gbuffers,
                               const TexelValidityOptions& options) {
  return mark_hidden_texels(rays, gbuffers, std::vector<std::uint8_t>(gbuffers.size(), 1), options);
}

std::size_t mark_hidden_texels(const RayScene& rays, std::vector<TexelGBuffer>& gbuffers,
                               const std::vector<std::uint8_t>& which,
                               const TexelValidityOptions& options) {
  const World& world = rays.world();
  if (gbuffers.size() != world.objects.size())
    throw Error("texel validity: G-buffers do not match the scene's objects");
  if (options.rays <= 0) throw Error("texel validity: rays must be positive");
  // Cosine-distributed directions from a Fibonacci lattice on the unit square: even coverage of
  // the hemisphere, the same for every texel.
  std::vector<glm::vec3> local;
  const float golden = 0.5f * (std::sqrt(5.0f) - 1.0f);
  for (int i = 0; i < options.rays; ++i) {
    float a = (static_cast<float>(i) + 0.5f) / static_cast<float>(options.rays);
    float b = static_cast<float>(i) * golden;
    local.push_back(cosine_hemisphere(glm::vec2(a, b - std::floor(b))));
  }
  const int limit = static_cast<int>(options.hidden_fraction * static_cast<float>(options.rays));
  std::atomic<std::size_t> marked{0};
  for (std::size_t o = 0; o < gbuffers.size(); ++o) {
    if (o >= which.size() || !which[o]) continue;
    TexelGBuffer& g = gbuffers[o];
    const WorldObject& obj = world.objects[o];
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, g.size(), 256),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        std::size_t count = 0;
                        for (std::size_t i = r.begin(); i < r.end(); ++i) {
                          if (!g.valid(i)) continue;
                          const TexelPoint p = g.point(obj, i);
                          Frame frame(p.normal);
                          int back = 0;
                          for (const glm::vec3& l : local) {
                            Ray ray;
                            ray.direction = frame.to_world(l);
                            ray.origin = rays.offset(p.position, p.geo_normal, ray.direction);
                            Hit h = rays.intersect(ray);
                            if (!h.valid() || world.material(h.object, h.triangle).double_sided)
                              continue;
                            const glm::vec3 hn =
                                world.objects[h.object].geometric_normal(h.triangle);
                            if (glm::dot(hn, ray.direction) > 0.0f) ++back;
                          }
                          if (back > limit) {
                            g.kind[i] = TexelKind::Hidden;
                            ++count;
                          }
                        }
                        marked += count;
                      });
  }
  return marked.load();
}

}  // namespace irradcast

#include "irradcast/common/dynamic_view.h"

#include "irradcast/common/error.h"
#include "irradcast/common/lights.h"
#include "irradcast/common/primary_hits.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

HitShade shade_dynamic(const World& world, const RayScene& static_rays, const DynamicView& view,
                       glm::vec3 direction, const Hit& h, glm::vec3 p, glm::vec3 n,
                       std::uint64_t seed) {
  HitShade s;
  const Material& m = world.material(h.object, h.triangle);
  glm::vec3 ng = world.objects[static_cast<std::size_t>(h.object)].geometric_normal(h.triangle);
  if (m.is_emissive() && (m.double_sided || glm::dot(ng, direction) < 0.0f))
    s.emission = world.emission(h.object, h.triangle, h.u, h.v);
  if (glm::dot(ng, direction) > 0.0f) ng = -ng;  // the side the ray came from, as n
  const bool trace_emitters = view.lights && !view.lights->emissive_triangles().empty();
  glm::vec3 e = view.volume && view.volume->probe_count() > 0
                    ? view.volume->irradiance(p, n, !trace_emitters)
                    : glm::vec3(0.0f);
  if (trace_emitters) {
    // Stratified over kEmitterSamples cells of the triangle's (u, v), the pick random.
    constexpr int k = DynamicView::kEmitterSamples, side = 2;  // 2 x 2 cells, twice
    Rng rng(seed, 0x656d6974);
    glm::vec3 direct(0.0f);
    for (int i = 0; i < k; ++i) {
      const int c = i % (side * side);
      const glm::vec2 u =
          (glm::vec2(float(c % side), float(c / side)) + rng.next_2d()) / float(side);
      direct += view.lights->area_irradiance(static_rays, p, n, ng, glm::vec3(rng.next_float(), u));
    }
    e += direct / float(k);
  }
  // The punctual lights as the path tracer's next-event estimation sees them (lights.h).
  for (const WorldLight& light : world.lights) {
    LightSampler::ShadowSample shadow;
    if (LightSampler::punctual_sample(static_rays, light, p, n, ng, shadow) &&
        !static_rays.occluded(shadow.shadow))
      e += shadow.irradiance;
  }
  s.diffuse = world.albedo(h.object, h.triangle, h.u, h.v) * kInvPi * e;
  return s;
}

void trace_dynamic(const World& world, const RayScene& static_rays, const DynamicView& view,
                   const CameraPose& camera, int width, int height,
                   const std::function<void(const DynamicPixel&)>& out) {
  if (width <= 0 || height <= 0) throw Error("image size must be positive");
  if (!view.rays) return;
  trace_primary_blocks(*view.rays, camera, width, height, [&](const PrimaryBlock& b) {
    for (int k = 0; k < PrimaryBlock::kLanes; ++k) {
      if (!b.active[k] || !b.hit(k)) continue;
      Ray ray;
      ray.origin = b.origin;
      ray.direction = b.direction(k);
      ray.tmax = b.t[k];
      if (static_rays.occluded(ray)) continue;  // a static surface is nearer
      const Hit h = b.hit_at(k);
      const WorldObject& o = world.objects[static_cast<std::size_t>(h.object)];
      DynamicPixel px;
      px.index = static_cast<std::size_t>(b.y(k)) * static_cast<std::size_t>(width) +
                 static_cast<std::size_t>(b.x(k));
      px.position = ray.origin + h.t * ray.direction;
      // The shading normal (on the geometric normal's side) turned with the geometric normal
      // towards the eye, as the path tracer turns it: at a smooth mesh's silhouette the
      // interpolated normal may face away while the triangle faces the eye.
      px.normal = o.shading_normal(h.triangle, h.u, h.v);
      if (glm::dot(o.geometric_normal(h.triangle), ray.direction) > 0.0f) px.normal = -px.normal;
      px.depth = std::max(glm::dot(px.position - camera.eye, camera.forward), 1e-30f);
      px.shade = shade_dynamic(world, static_rays, view, ray.direction, h, px.position, px.normal,
                               px.index);
      out(px);
    }
  });
}

}  // namespace irradcast

#include "irradcast/common/hit_shader.h"

#include "irradcast/common/error.h"

namespace irradcast {

HitShader::HitShader(const World& world, const Atlas& atlas, const std::vector<Lightmap>& lightmaps)
    : world_(&world) {
  if (atlas.objects.size() != world.objects.size() || lightmaps.size() != world.objects.size())
    throw Error("compositor: lightmaps do not match the scene's objects");
  objects_.resize(world.objects.size());
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    Object& o = objects_[i];
    o.world = &world.objects[i];
    o.atlas = &atlas.objects[i];
    o.lightmap = &lightmaps[i];
    o.triangle_material = o.world->source->triangle_material.data();
    o.triangle_count = o.world->source->triangle_material.size();
  }
  // As World::material: an index past the scene's materials means the default Material{}.
  std::vector<const Material*> materials;
  if (world.scene)
    for (const Material& m : world.scene->materials) materials.push_back(&m);
  static const Material fallback{};
  materials.push_back(&fallback);
  for (const Material* m : materials) {
    Shading s;
    s.base_color = m->base_color;
    if (m->base_color_texture >= 0)
      s.texture = &world.scene->textures[static_cast<std::size_t>(m->base_color_texture)];
    s.texture_uv = m->base_color_uv;
    s.emissive = m->is_emissive();
    s.double_sided = m->double_sided;
    materials_.push_back(s);
  }
}

void HitShader::emission(const Hit& h, glm::vec3 direction, const Shading& m, HitShade& s) const {
  const glm::vec3 ng =
      world_->objects[static_cast<std::size_t>(h.object)].geometric_normal(h.triangle);
  if (m.double_sided || glm::dot(ng, direction) < 0.0f)
    s.emission = world_->emission(h.object, h.triangle, h.u, h.v);
}

}  // namespace irradcast

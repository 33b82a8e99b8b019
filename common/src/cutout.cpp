// Cut-out materials: alpha at a surface point and the cut-out test (cutout.h).
#include "irradcast/common/cutout.h"

namespace irradcast {

float surface_alpha(const World& world, int object, std::uint32_t t, float u, float v) {
  const Material& mat = world.material(object, t);
  float a = mat.base_alpha;
  if (mat.base_color_texture >= 0) {
    const glm::vec2 uv = world.objects[object].uv(mat.base_color_uv, t, u, v);
    a *= world.scene->textures[mat.base_color_texture].sample_srgb(uv).w;
  }
  return a;
}

bool cut_out(const World& world, int object, std::uint32_t t, float u, float v) {
  const Material& mat = world.material(object, t);
  return mat.cut_out() && !(surface_alpha(world, object, t, u, v) >= mat.alpha_cutoff);
}

bool has_cut_outs(const World& world, int object) {
  const Mesh& mesh = *world.objects[object].source;
  for (std::uint32_t t = 0; t < mesh.triangles.size(); ++t)
    if (world.material(object, t).cut_out()) return true;
  return false;
}

}  // namespace irradcast

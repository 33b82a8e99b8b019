#include "irradcast/common/hit_shader.h"

#include <emmintrin.h>

#include <algorithm>

#include "irradcast/common/error.h"

namespace irradcast {
namespace {

// std::floor of 4 lanes, the same bits for every float (-0 and NaN included): truncation with
// the sign kept, one less where that rounded up; |x| >= 2^23 is integral already.
inline __m128 floor4(__m128 x) {
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 small = _mm_cmplt_ps(_mm_andnot_ps(sign, x), _mm_set1_ps(8388608.0f));
  __m128 t = _mm_or_ps(_mm_cvtepi32_ps(_mm_cvttps_epi32(x)), _mm_and_ps(x, sign));
  t = _mm_sub_ps(t, _mm_and_ps(_mm_cmpgt_ps(t, x), _mm_set1_ps(1.0f)));
  return _mm_or_ps(_mm_and_ps(small, t), _mm_andnot_ps(small, x));
}

// glm::mix(a, b, w) per lane: a * (1 - w) + b * w.
inline __m128 mix4(__m128 a, __m128 b, __m128 w) {
  return _mm_add_ps(_mm_mul_ps(a, _mm_sub_ps(_mm_set1_ps(1.0f), w)), _mm_mul_ps(b, w));
}

// (x, y, z, 0) from a texel.
inline __m128 load3(const glm::vec3& v) {
  const __m128 xy = _mm_castpd_ps(_mm_load_sd(reinterpret_cast<const double*>(&v.x)));
  return _mm_movelh_ps(xy, _mm_load_ss(&v.z));
}

// Lightmap::bilinear's four texels of one lane at the floored texel coordinates (fx, fy): the
// same clamping, returned as (r, g, b, 0) each.
inline void bilinear_taps(const Lightmap& m, float fx, float fy, __m128 (&tap)[4]) {
  const int x0 = std::clamp(static_cast<int>(fx), 0, m.width - 1);
  const int y0 = std::clamp(static_cast<int>(fy), 0, m.height - 1);
  int x1 = std::min(x0 + 1, m.width - 1), y1 = std::min(y0 + 1, m.height - 1);
  if (fx < 0.0f) x1 = x0;
  if (fy < 0.0f) y1 = y0;
  const glm::vec3* row0 = m.texels.data() + static_cast<std::size_t>(y0) * m.width;
  const glm::vec3* row1 = m.texels.data() + static_cast<std::size_t>(y1) * m.width;
  tap[0] = load3(row0[x0]);
  tap[1] = load3(row0[x1]);
  tap[2] = load3(row1[x0]);
  tap[3] = load3(row1[x1]);
}

}  // namespace

// What shade_block needs of 4 lanes, SoA; lanes that miss read zeros.
struct HitShader::Lanes {
  alignas(16) float corner[6][4];  // the atlas corners: c0.x, c0.y, c1.x, c1.y, c2.x, c2.y
  alignas(16) float albedo[3][4];  // base colour x texture sample
  const Lightmap* lightmap[4];     // nullptr: a miss
  const Shading* material[4];
};

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

void HitShader::gather_lanes(const PrimaryBlock& b, int k0, Lanes& l) const {
  for (int i = 0; i < 4; ++i) {
    const int k = k0 + i;
    if (!b.active[k] || !b.hit(k)) {
      for (auto& c : l.corner) c[i] = 0.0f;
      for (auto& c : l.albedo) c[i] = 0.0f;
      l.lightmap[i] = nullptr;
      l.material[i] = nullptr;
      continue;
    }
    const Object& o = objects_[static_cast<std::size_t>(b.object[k])];
    const std::uint32_t t = b.triangle[k];
    const glm::vec2* c = o.atlas->corner_uv.data() + 3 * static_cast<std::size_t>(t);
    for (int j = 0; j < 3; ++j) {
      l.corner[2 * j][i] = c[j].x;
      l.corner[2 * j + 1][i] = c[j].y;
    }
    l.lightmap[i] = o.lightmap;
    const std::uint32_t mi = t < o.triangle_count ? o.triangle_material[t] : kFallback;
    const Shading& m = materials_[mi < materials_.size() - 1 ? mi : materials_.size() - 1];
    l.material[i] = &m;
    glm::vec3 albedo = m.base_color;
    if (m.texture)
      albedo *= glm::vec3(m.texture->sample_srgb(o.world->uv(m.texture_uv, t, b.u[k], b.v[k])));
    for (int j = 0; j < 3; ++j) l.albedo[j][i] = albedo[j];
  }
}

void HitShader::shade_block(const PrimaryBlock& b, BlockShade& s) const {
  const __m128 one = _mm_set1_ps(1.0f), half = _mm_set1_ps(0.5f);
  for (int k0 = 0; k0 < PrimaryBlock::kLanes; k0 += 4) {
    Lanes l;
    gather_lanes(b, k0, l);
    // ObjectLightmap::uv: (1 - u - v) * c0 + u * c1 + v * c2, then Lightmap::bilinear.
    const __m128 u = _mm_load_ps(b.u + k0), v = _mm_load_ps(b.v + k0);
    const __m128 w = _mm_sub_ps(_mm_sub_ps(one, u), v);
    __m128 uv[2];
    for (int a = 0; a < 2; ++a)
      uv[a] = _mm_add_ps(_mm_add_ps(_mm_mul_ps(w, _mm_load_ps(l.corner[a])),
                                    _mm_mul_ps(u, _mm_load_ps(l.corner[2 + a]))),
                         _mm_mul_ps(v, _mm_load_ps(l.corner[4 + a])));
    const __m128 x = _mm_sub_ps(uv[0], half), y = _mm_sub_ps(uv[1], half);
    const __m128 fx = floor4(x), fy = floor4(y);
    const __m128 ax = _mm_sub_ps(x, fx), ay = _mm_sub_ps(y, fy);
    alignas(16) float fxs[4], fys[4];
    _mm_store_ps(fxs, fx);
    _mm_store_ps(fys, fy);
    __m128 tap[4][4];  // [lane][tap]: (r, g, b, 0)
    for (int i = 0; i < 4; ++i) {
      if (l.lightmap[i])
        bilinear_taps(*l.lightmap[i], fxs[i], fys[i], tap[i]);
      else
        for (__m128& t : tap[i]) t = _mm_setzero_ps();
    }
    // [tap][channel] over the 4 lanes.
    __m128 ch[4][4];
    for (int t = 0; t < 4; ++t) {
      ch[t][0] = tap[0][t];
      ch[t][1] = tap[1][t];
      ch[t][2] = tap[2][t];
      ch[t][3] = tap[3][t];
      _MM_TRANSPOSE4_PS(ch[t][0], ch[t][1], ch[t][2], ch[t][3]);
    }
    for (int c = 0; c < 3; ++c) {
      const __m128 e = mix4(mix4(ch[0][c], ch[1][c], ax), mix4(ch[2][c], ch[3][c], ax), ay);
      const __m128 albedo = _mm_mul_ps(_mm_load_ps(l.albedo[c]), _mm_set1_ps(kInvPi));
      _mm_store_ps(s.diffuse[c] + k0, _mm_mul_ps(albedo, e));
      _mm_store_ps(s.emission[c] + k0, _mm_setzero_ps());
    }
    for (int i = 0; i < 4; ++i)
      if (l.material[i] && l.material[i]->emissive) {
        HitShade hs;
        emission(b.hit_at(k0 + i), b.direction(k0 + i), *l.material[i], hs);
        for (int c = 0; c < 3; ++c) s.emission[c][k0 + i] = hs.emission[c];
      }
  }
}

void HitShader::emission(const Hit& h, glm::vec3 direction, const Shading& m, HitShade& s) const {
  const glm::vec3 ng =
      world_->objects[static_cast<std::size_t>(h.object)].geometric_normal(h.triangle);
  if (m.double_sided || glm::dot(ng, direction) < 0.0f)
    s.emission = world_->emission(h.object, h.triangle, h.u, h.v);
}

}  // namespace irradcast

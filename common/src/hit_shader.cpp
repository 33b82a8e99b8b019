#include "irradcast/common/hit_shader.h"

#include <emmintrin.h>

#include <algorithm>
#include <array>
#include <cstring>

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
  double xy_bits;  // x and y as one 8-byte load (a texel is only 4-byte aligned: memcpy, not a
                   // double*)
  std::memcpy(&xy_bits, &v.x, sizeof xy_bits);
  const __m128 xy = _mm_castpd_ps(_mm_set_sd(xy_bits));
  return _mm_movelh_ps(xy, _mm_load_ss(&v.z));
}

// Lightmap::bilinear's four texels of one lane at the floored texel coordinates (fx, fy): the
// same clamping, returned as (r, g, b, 0) each.
inline void bilinear_taps(const glm::vec3* texels, int width, int height, float fx, float fy,
                          __m128 (&tap)[4]) {
  const int x0 = std::clamp(static_cast<int>(fx), 0, width - 1);
  const int y0 = std::clamp(static_cast<int>(fy), 0, height - 1);
  int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
  if (fx < 0.0f) x1 = x0;
  if (fy < 0.0f) y1 = y0;
  const glm::vec3* row0 = texels + static_cast<std::size_t>(y0) * width;
  const glm::vec3* row1 = texels + static_cast<std::size_t>(y1) * width;
  tap[0] = load3(row0[x0]);
  tap[1] = load3(row0[x1]);
  tap[2] = load3(row1[x0]);
  tap[3] = load3(row1[x1]);
}

// [tap][channel] over 4 lanes from [lane][tap] (r, g, b, 0), then the bilinear mix of each
// channel: mix(mix(t0, t1, ax), mix(t2, t3, ax), ay), as glm::mix in Lightmap::bilinear and
// Texture::sample_srgb.
inline void mix_taps(__m128 (&tap)[4][4], __m128 ax, __m128 ay, __m128 (&out)[3]) {
  __m128 ch[4][4];
  for (int t = 0; t < 4; ++t) {
    ch[t][0] = tap[0][t];
    ch[t][1] = tap[1][t];
    ch[t][2] = tap[2][t];
    ch[t][3] = tap[3][t];
    _MM_TRANSPOSE4_PS(ch[t][0], ch[t][1], ch[t][2], ch[t][3]);
  }
  for (int c = 0; c < 3; ++c)
    out[c] = mix4(mix4(ch[0][c], ch[1][c], ax), mix4(ch[2][c], ch[3][c], ax), ay);
}

// Texture::sample_srgb's wrap of texel i into 0 .. n-1, the same integer without the divisions
// where i is inside already.
inline int wrap(long i, int n) {
  if (i >= 0 && i < n) return static_cast<int>(i);
  return static_cast<int>(((i % n) + n) % n);
}

// Texture::sample_srgb's four texels of one lane at the floored texel coordinates (fx, fy)
// (RGBA8, [tap]); their cache lines are prefetched.
inline void texture_taps(const Texture& tex, float fx, float fy, const std::uint8_t* (&p)[4]) {
  const int x0 = wrap(static_cast<long>(fx), tex.width),
            y0 = wrap(static_cast<long>(fy), tex.height);
  const int x1 = x0 + 1 == tex.width ? 0 : x0 + 1, y1 = y0 + 1 == tex.height ? 0 : y0 + 1;
  const std::uint8_t* row0 = tex.rgba8.data() + 4 * static_cast<std::size_t>(y0) * tex.width;
  const std::uint8_t* row1 = tex.rgba8.data() + 4 * static_cast<std::size_t>(y1) * tex.width;
  p[0] = row0 + 4 * x0;
  p[1] = row0 + 4 * x1;
  p[2] = row1 + 4 * x0;
  p[3] = row1 + 4 * x1;
  _mm_prefetch(reinterpret_cast<const char*>(p[0]), _MM_HINT_T0);
  _mm_prefetch(reinterpret_cast<const char*>(p[2]), _MM_HINT_T0);
}

// A texture lookup of 4 lanes between its two halves: the texels (prefetched), the bilinear
// weights; texel[i][0] is null where lane i has no texture.
struct TextureLanes {
  const std::uint8_t* texel[4][4];
  __m128 ax, ay;
  bool any = false;
};

}  // namespace

// What shade_block needs of 4 lanes, SoA; lanes that miss read zeros.
struct HitShader::Lanes {
  alignas(16) float corner[6][4];      // the atlas corners: c0.x, c0.y, c1.x, c1.y, c2.x, c2.y
  alignas(16) float base[3][4];        // the material's base colour
  alignas(16) float tex_corner[6][4];  // the base colour texture's uv at the corners
  alignas(16) float tex_size[2][4];    // its width and height
  const glm::vec3* lightmap[4];        // the lightmap's texels; nullptr: a miss
  int lightmap_size[2][4];             // its width and height
  const Shading* material[4];
  const Texture* texture[4];  // nullptr: none (or an empty one)
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
    o.corner_uv = o.atlas->corner_uv.data();
    o.texels = o.lightmap->texels.data();
    o.lightmap_width = o.lightmap->width;
    o.lightmap_height = o.lightmap->height;
    const Mesh& mesh = *o.world->source;
    o.triangles = mesh.triangles.data();
    o.uv[0] = mesh.uv0.empty() ? nullptr : mesh.uv0.data();
    o.uv[1] = mesh.uv1.empty() ? nullptr : mesh.uv1.data();
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
      for (auto& c : l.base) c[i] = 0.0f;
      l.lightmap[i] = nullptr;
      l.material[i] = nullptr;
      l.texture[i] = nullptr;
      continue;
    }
    const Object& o = objects_[static_cast<std::size_t>(b.object[k])];
    const std::uint32_t t = b.triangle[k];
    const glm::vec2* c = o.corner_uv + 3 * static_cast<std::size_t>(t);
    for (int j = 0; j < 3; ++j) {
      l.corner[2 * j][i] = c[j].x;
      l.corner[2 * j + 1][i] = c[j].y;
    }
    l.lightmap[i] = o.texels;
    l.lightmap_size[0][i] = o.lightmap_width;
    l.lightmap_size[1][i] = o.lightmap_height;
    const std::uint32_t mi = t < o.triangle_count ? o.triangle_material[t] : kFallback;
    const Shading& m = materials_[mi < materials_.size() - 1 ? mi : materials_.size() - 1];
    l.material[i] = &m;
    for (int j = 0; j < 3; ++j) l.base[j][i] = m.base_color[j];
    l.texture[i] = m.texture && m.texture->width > 0 && m.texture->height > 0 ? m.texture : nullptr;
    if (!l.texture[i]) continue;
    l.tex_size[0][i] = static_cast<float>(m.texture->width);
    l.tex_size[1][i] = static_cast<float>(m.texture->height);
    // WorldObject::uv's corners; (0, 0) without the set.
    const glm::vec2* uvs = o.uv[m.texture_uv == 1 ? 1 : 0];
    const glm::uvec3 tri = uvs ? o.triangles[t] : glm::uvec3(0);
    for (int j = 0; j < 3; ++j) {
      const glm::vec2 cj = uvs ? uvs[tri[j]] : glm::vec2(0.0f);
      l.tex_corner[2 * j][i] = cj.x;
      l.tex_corner[2 * j + 1][i] = cj.y;
    }
  }
}

namespace {

// (1 - u - v) * c0 + u * c1 + v * c2 per lane (w = 1 - u - v), from SoA corners [c0x, c0y, c1x,
// c1y, c2x, c2y][lane]: ObjectLightmap::uv and WorldObject::uv.
inline void interpolate(const float (&corner)[6][4], __m128 u, __m128 v, __m128 w,
                        __m128 (&uv)[2]) {
  for (int a = 0; a < 2; ++a)
    uv[a] = _mm_add_ps(_mm_add_ps(_mm_mul_ps(w, _mm_load_ps(corner[a])),
                                  _mm_mul_ps(u, _mm_load_ps(corner[2 + a]))),
                       _mm_mul_ps(v, _mm_load_ps(corner[4 + a])));
}

// Lightmap::bilinear at the atlas uv (corners `corner`) of 4 lanes; 0 where `lightmap` is null.
void lightmap_lanes(const float (&corner)[6][4], const glm::vec3* const (&lightmap)[4],
                    const int (&size)[2][4], __m128 u, __m128 v, __m128 w, __m128 (&e)[3]) {
  __m128 uv[2];
  interpolate(corner, u, v, w, uv);
  const __m128 half = _mm_set1_ps(0.5f);
  const __m128 x = _mm_sub_ps(uv[0], half), y = _mm_sub_ps(uv[1], half);
  const __m128 fx = floor4(x), fy = floor4(y);
  alignas(16) float fxs[4], fys[4];
  _mm_store_ps(fxs, fx);
  _mm_store_ps(fys, fy);
  __m128 tap[4][4];  // [lane][tap]: (r, g, b, 0)
  for (int i = 0; i < 4; ++i) {
    if (lightmap[i])
      bilinear_taps(lightmap[i], size[0][i], size[1][i], fxs[i], fys[i], tap[i]);
    else
      for (__m128& t : tap[i]) t = _mm_setzero_ps();
  }
  mix_taps(tap, _mm_sub_ps(x, fx), _mm_sub_ps(y, fy), e);
}

// The first half of Texture::sample_srgb at WorldObject::uv (corners `corner`, texture sizes
// `size`) of 4 lanes: where its texels are.
void texture_lanes(const float (&corner)[6][4], const float (&size)[2][4],
                   const Texture* const (&texture)[4], __m128 u, __m128 v, __m128 w,
                   TextureLanes& t) {
  t.any = texture[0] || texture[1] || texture[2] || texture[3];
  if (!t.any) return;
  __m128 uv[2];
  interpolate(corner, u, v, w, uv);
  const __m128 half = _mm_set1_ps(0.5f);
  const __m128 x = _mm_sub_ps(_mm_mul_ps(uv[0], _mm_load_ps(size[0])), half);
  const __m128 y = _mm_sub_ps(_mm_mul_ps(uv[1], _mm_load_ps(size[1])), half);
  const __m128 fx = floor4(x), fy = floor4(y);
  t.ax = _mm_sub_ps(x, fx);
  t.ay = _mm_sub_ps(y, fy);
  alignas(16) float fxs[4], fys[4];
  _mm_store_ps(fxs, fx);
  _mm_store_ps(fys, fy);
  for (int i = 0; i < 4; ++i) {
    if (texture[i])
      texture_taps(*texture[i], fxs[i], fys[i], t.texel[i]);
    else
      t.texel[i][0] = nullptr;
  }
}

// The second half: the texels decoded to linear and mixed, rgb; 1 where a lane has no texture.
void texture_mix(const TextureLanes& t, __m128 (&tex)[3]) {
  const __m128 one = _mm_set1_ps(1.0f);
  for (__m128& c : tex) c = one;
  if (!t.any) return;
  const std::array<float, 256>& lut = srgb_to_linear_table();
  __m128 tap[4][4];
  alignas(16) std::int32_t textured[4];
  for (int i = 0; i < 4; ++i) {
    textured[i] = t.texel[i][0] ? -1 : 0;
    for (int k = 0; k < 4; ++k) {
      const std::uint8_t* p = t.texel[i][k];
      tap[i][k] = textured[i] ? _mm_setr_ps(lut[p[0]], lut[p[1]], lut[p[2]], 0.0f) : one;
    }
  }
  __m128 s[3];
  mix_taps(tap, t.ax, t.ay, s);
  const __m128 mask = _mm_castsi128_ps(_mm_load_si128(reinterpret_cast<const __m128i*>(textured)));
  for (int c = 0; c < 3; ++c) tex[c] = _mm_or_ps(_mm_and_ps(mask, s[c]), _mm_andnot_ps(mask, one));
}

}  // namespace

bool HitShader::cpu_has_avx512() {
  static const bool has = __builtin_cpu_supports("avx512f");
  return has;
}

void HitShader::shade_block(const PrimaryBlock& b, BlockShade& s) const {
  Avx512Loads l;
  if (avx512_ && begin_avx512(b, l))
    finish_avx512(b, l, s);
  else
    shade_block_sse2(b, s);
}

void HitShader::touch_block(const PrimaryBlock& b) const {
  for (int k = 0; k < PrimaryBlock::kLanes; ++k) {
    if (!b.active[k] || !b.hit(k)) continue;
    const Object& o = objects_[static_cast<std::size_t>(b.object[k])];
    const std::size_t t = b.triangle[k];
    _mm_prefetch(reinterpret_cast<const char*>(o.corner_uv + 3 * t), _MM_HINT_T0);
    if (o.uv[0] || o.uv[1])
      _mm_prefetch(reinterpret_cast<const char*>(o.triangles + t), _MM_HINT_T0);
  }
}

void HitShader::shade_stream(
    PacketStream& packets,
    const std::function<void(const PrimaryBlock&, const BlockShade&)>& out) const {
  // Three packets in flight: a packet's triangle data is requested right after it is traced
  // (touch_block), its texels found and requested after the next packet is traced (begin), and
  // read after the one after that (finish), so the loads overlap traversals.
  PrimaryBlock b[3];
  Avx512Loads loads[3];
  BlockShade s;
  const auto begin = [&](int i) { loads[i].taken = avx512_ && begin_avx512(b[i], loads[i]); };
  const auto finish = [&](int i) {
    if (loads[i].taken)
      finish_avx512(b[i], loads[i], s);
    else
      shade_block_sse2(b[i], s);
    out(b[i], s);
  };
  if (!packets.next(b[0])) return;
  touch_block(b[0]);
  if (!packets.next(b[1])) {
    begin(0);
    finish(0);
    return;
  }
  touch_block(b[1]);
  begin(0);
  // b[i] begun, b[(i + 1) % 3] touched.
  for (int i = 0;; i = (i + 1) % 3) {
    const int j = (i + 1) % 3, k = (i + 2) % 3;
    const bool more = packets.next(b[k]);
    if (more) touch_block(b[k]);
    begin(j);
    finish(i);
    if (!more) {
      finish(j);
      return;
    }
  }
}

void HitShader::shade_block_sse2(const PrimaryBlock& b, BlockShade& s) const {
  constexpr int kGroups = PrimaryBlock::kLanes / 4;
  const __m128 one = _mm_set1_ps(1.0f), inv_pi = _mm_set1_ps(kInvPi);
  // First every group's texel addresses (prefetched), then the lightmaps while they arrive.
  Lanes l[kGroups];
  TextureLanes tl[kGroups];
  __m128 u[kGroups], v[kGroups], w[kGroups];
  for (int g = 0; g < kGroups; ++g) {
    gather_lanes(b, 4 * g, l[g]);
    u[g] = _mm_load_ps(b.u + 4 * g);
    v[g] = _mm_load_ps(b.v + 4 * g);
    w[g] = _mm_sub_ps(_mm_sub_ps(one, u[g]), v[g]);
    texture_lanes(l[g].tex_corner, l[g].tex_size, l[g].texture, u[g], v[g], w[g], tl[g]);
  }
  for (int g = 0; g < kGroups; ++g) {
    const int k0 = 4 * g;
    __m128 e[3], tex[3];
    lightmap_lanes(l[g].corner, l[g].lightmap, l[g].lightmap_size, u[g], v[g], w[g], e);
    texture_mix(tl[g], tex);
    // albedo = base colour x texture; diffuse = albedo * (1 / pi) * E.
    for (int c = 0; c < 3; ++c) {
      const __m128 albedo = _mm_mul_ps(_mm_load_ps(l[g].base[c]), tex[c]);
      _mm_store_ps(s.diffuse[c] + k0, _mm_mul_ps(_mm_mul_ps(albedo, inv_pi), e[c]));
      _mm_store_ps(s.emission[c] + k0, _mm_setzero_ps());
    }
    for (int i = 0; i < 4; ++i)
      if (l[g].material[i] && l[g].material[i]->emissive) {
        HitShade hs;
        emission(b.hit_at(k0 + i), b.direction(k0 + i), *l[g].material[i], hs);
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

// HitShader::begin_avx512 / finish_avx512: a primary packet's 16 lanes in one AVX-512 register
// each, in groups of the lanes that share one object and material (most packets have one group;
// one with more than HitShader::kAvx512Groups goes to the SSE2 path). The lanes' atlas corners,
// texture uv corners and the lightmap and texture texels come in through gathers from that
// object's and texture's arrays (masked to the group's lanes, at the addresses the scalar code
// reads). The arithmetic is that of the SSE2 path and of HitShader::shade, operation for operation
// (add, sub, mul, floor; no FMA: this file is built with -ffp-contract=off), so the bits are the
// same. Only the functions below are compiled for AVX-512 (target pragma after the includes);
// shade_block calls them only where the CPU has it (common/CMakeLists.txt has this file's flags).
#include <immintrin.h>

#include <algorithm>
#include <array>

#include "irradcast/common/hit_shader.h"

#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx512f"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx512f")
#endif

namespace irradcast {
namespace {

// glm::mix(a, b, w) per lane: a * (1 - w) + b * w.
inline __m512 mix16(__m512 a, __m512 b, __m512 w) {
  return _mm512_add_ps(_mm512_mul_ps(a, _mm512_sub_ps(_mm512_set1_ps(1.0f), w)),
                       _mm512_mul_ps(b, w));
}

// (1 - u - v) * c0 + u * c1 + v * c2 per lane (w = 1 - u - v), corners [c0, c1, c2][axis].
inline __m512 interpolate16(const __m512 (&c)[3][2], int a, __m512 u, __m512 v, __m512 w) {
  return _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(w, c[0][a]), _mm512_mul_ps(u, c[1][a])),
                       _mm512_mul_ps(v, c[2][a]));
}

// Masked gathers (lanes outside `m` read nothing and give 0).
inline __m512 gather_ps(__mmask16 m, __m512i index, const float* base) {
  return _mm512_mask_i32gather_ps(_mm512_setzero_ps(), m, index, base, 4);
}
inline __m512i gather_epi32(__mmask16 m, __m512i index, const void* base) {
  return _mm512_mask_i32gather_epi32(_mm512_setzero_si512(), m, index, base, 4);
}

// floor and truncation to int per lane.
inline __m512 floor16(__m512 x) {
  return _mm512_roundscale_ps(x, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
}
inline __m512i cvtt16(__m512 x) {
  return _mm512_cvttps_epi32(x);
}

// The bilinear mix of 4 taps [tap] (t0 t1 over t2 t3).
inline __m512 mix_taps16(const __m512 (&t)[4], __m512 ax, __m512 ay) {
  return mix16(mix16(t[0], t[1], ax), mix16(t[2], t[3], ax), ay);
}

// The first half of Lightmap::bilinear at the atlas uv (x, y) of the lanes m in a width x height
// map: its texels' float indices (x 3) and the weights, into t.
void lightmap_taps16(int width, int height, __m512 uvx, __m512 uvy, HitShader::Taps16& t) {
  const __m512 half = _mm512_set1_ps(0.5f);
  const __m512 x = _mm512_sub_ps(uvx, half), y = _mm512_sub_ps(uvy, half);
  const __m512 fx = floor16(x), fy = floor16(y);
  _mm512_store_ps(t.a[0], _mm512_sub_ps(x, fx));
  _mm512_store_ps(t.a[1], _mm512_sub_ps(y, fy));
  const __m512i zero = _mm512_setzero_si512(), one = _mm512_set1_epi32(1);
  const __m512i wm = _mm512_set1_epi32(width - 1), hm = _mm512_set1_epi32(height - 1);
  // std::clamp(int(f), 0, n - 1); the +1 neighbour clamped too, and none left of 0.
  const __m512i x0 = _mm512_min_epi32(_mm512_max_epi32(cvtt16(fx), zero), wm);
  const __m512i y0 = _mm512_min_epi32(_mm512_max_epi32(cvtt16(fy), zero), hm);
  const __mmask16 xl = _mm512_cmp_ps_mask(fx, _mm512_setzero_ps(), _CMP_LT_OQ);
  const __mmask16 yl = _mm512_cmp_ps_mask(fy, _mm512_setzero_ps(), _CMP_LT_OQ);
  const __m512i x1 = _mm512_mask_mov_epi32(_mm512_min_epi32(_mm512_add_epi32(x0, one), wm), xl, x0);
  const __m512i y1 = _mm512_mask_mov_epi32(_mm512_min_epi32(_mm512_add_epi32(y0, one), hm), yl, y0);
  const __m512i w = _mm512_set1_epi32(width), three = _mm512_set1_epi32(3);
  const __m512i row0 = _mm512_mullo_epi32(y0, w), row1 = _mm512_mullo_epi32(y1, w);
  _mm512_store_si512(t.at[0], _mm512_mullo_epi32(_mm512_add_epi32(row0, x0), three));
  _mm512_store_si512(t.at[1], _mm512_mullo_epi32(_mm512_add_epi32(row0, x1), three));
  _mm512_store_si512(t.at[2], _mm512_mullo_epi32(_mm512_add_epi32(row1, x0), three));
  _mm512_store_si512(t.at[3], _mm512_mullo_epi32(_mm512_add_epi32(row1, x1), three));
}

// The second half: the texels (r, g, b at index, + 1, + 2) gathered and mixed.
void lightmap_mix16(__mmask16 m, const glm::vec3* texels, const HitShader::Taps16& t,
                    __m512 (&e)[3]) {
  const float* f = &texels->x;
  const __m512 ax = _mm512_load_ps(t.a[0]), ay = _mm512_load_ps(t.a[1]);
  for (int c = 0; c < 3; ++c) {
    __m512 tap[4];
    for (int k = 0; k < 4; ++k)
      tap[k] = gather_ps(m, _mm512_add_epi32(_mm512_load_si512(t.at[k]), _mm512_set1_epi32(c)), f);
    e[c] = mix_taps16(tap, ax, ay);
  }
}

// Texture::sample_srgb's wrap of texel i into 0 .. n-1 (see hit_shader.cpp).
inline int wrap(long i, int n) {
  if (i >= 0 && i < n) return static_cast<int>(i);
  return static_cast<int>(((i % n) + n) % n);
}

// The wrapped texel column (or row) of floored coordinates f in a texture n wide, as
// Texture::sample_srgb's wrap of long(f): cvtt where that is inside already; where |f| < 2^24
// (f and its quotient by n exact enough), i - n * floor(f / n), off by at most one n and corrected,
// which is the one value in 0 .. n-1 that wrap gives; the scalar wrap for the rest (NaN, huge).
inline __m512i wrap16(__mmask16 m, __m512 f, int n) {
  const __m512i i = cvtt16(f);
  const __m512 nf = _mm512_set1_ps(static_cast<float>(n));
  const __mmask16 inside = _mm512_cmp_ps_mask(f, _mm512_setzero_ps(), _CMP_GE_OQ) &
                           _mm512_cmp_ps_mask(f, nf, _CMP_LT_OQ);
  if ((m & ~inside) == 0) return i;
  const __m512i vn = _mm512_set1_epi32(n);
  const __m512i q = cvtt16(floor16(_mm512_div_ps(f, nf)));
  __m512i r = _mm512_sub_epi32(i, _mm512_mullo_epi32(q, vn));
  r = _mm512_mask_add_epi32(r, _mm512_cmplt_epi32_mask(r, _mm512_setzero_si512()), r, vn);
  r = _mm512_mask_sub_epi32(r, _mm512_cmpge_epi32_mask(r, vn), r, vn);
  r = _mm512_mask_mov_epi32(r, inside, i);
  const __mmask16 exact =
      _mm512_cmp_ps_mask(_mm512_abs_ps(f), _mm512_set1_ps(16777216.0f), _CMP_LT_OQ);
  if ((m & ~exact) == 0) return r;
  alignas(64) float fs[16];
  alignas(64) std::int32_t rs[16];
  _mm512_store_ps(fs, f);
  _mm512_store_si512(rs, r);
  for (int k = 0; k < 16; ++k)
    if ((m >> k) & 1 && !((exact >> k) & 1)) rs[k] = wrap(static_cast<long>(fs[k]), n);
  return _mm512_load_si512(rs);
}

// The first half of Texture::sample_srgb at the uv (x, y) of the lanes m: its texels' indices and
// the weights, into t; the texels' cache lines are prefetched.
void texture_taps16(__mmask16 m, const Texture& tex, __m512 uvx, __m512 uvy, HitShader::Taps16& t) {
  const __m512 half = _mm512_set1_ps(0.5f);
  const __m512 x =
      _mm512_sub_ps(_mm512_mul_ps(uvx, _mm512_set1_ps(static_cast<float>(tex.width))), half);
  const __m512 y =
      _mm512_sub_ps(_mm512_mul_ps(uvy, _mm512_set1_ps(static_cast<float>(tex.height))), half);
  const __m512 fx = floor16(x), fy = floor16(y);
  _mm512_store_ps(t.a[0], _mm512_sub_ps(x, fx));
  _mm512_store_ps(t.a[1], _mm512_sub_ps(y, fy));
  const __m512i x0 = wrap16(m, fx, tex.width), y0 = wrap16(m, fy, tex.height);
  const __m512i one = _mm512_set1_epi32(1), zero = _mm512_setzero_si512();
  const __m512i x1p = _mm512_add_epi32(x0, one), y1p = _mm512_add_epi32(y0, one);
  const __m512i x1 =
      _mm512_mask_mov_epi32(x1p, _mm512_cmpeq_epi32_mask(x1p, _mm512_set1_epi32(tex.width)), zero);
  const __m512i y1 =
      _mm512_mask_mov_epi32(y1p, _mm512_cmpeq_epi32_mask(y1p, _mm512_set1_epi32(tex.height)), zero);
  const __m512i w = _mm512_set1_epi32(tex.width);
  const __m512i row0 = _mm512_mullo_epi32(y0, w), row1 = _mm512_mullo_epi32(y1, w);
  _mm512_store_si512(t.at[0], _mm512_add_epi32(row0, x0));
  _mm512_store_si512(t.at[1], _mm512_add_epi32(row0, x1));
  _mm512_store_si512(t.at[2], _mm512_add_epi32(row1, x0));
  _mm512_store_si512(t.at[3], _mm512_add_epi32(row1, x1));
  const std::uint8_t* rgba = tex.rgba8.data();
  for (int k = 0; k < PrimaryBlock::kLanes; ++k)
    if ((m >> k) & 1) {
      _mm_prefetch(reinterpret_cast<const char*>(rgba + 4 * static_cast<std::size_t>(t.at[0][k])),
                   _MM_HINT_T0);
      _mm_prefetch(reinterpret_cast<const char*>(rgba + 4 * static_cast<std::size_t>(t.at[2][k])),
                   _MM_HINT_T0);
    }
}

// The second half: the texels gathered, decoded to linear and mixed, rgb.
void texture_mix16(__mmask16 m, const Texture& tex, const HitShader::Taps16& t, __m512 (&out)[3]) {
  __m512i rgba[4];
  for (int k = 0; k < 4; ++k)
    rgba[k] = gather_epi32(m, _mm512_load_si512(t.at[k]), tex.rgba8.data());
  const float* lut = srgb_to_linear_table().data();
  const __m512i byte = _mm512_set1_epi32(0xff);
  const __m512 ax = _mm512_load_ps(t.a[0]), ay = _mm512_load_ps(t.a[1]);
  for (int c = 0; c < 3; ++c) {
    __m512 tap[4];
    for (int k = 0; k < 4; ++k)
      tap[k] = gather_ps(m, _mm512_and_si512(_mm512_srli_epi32(rgba[k], 8 * c), byte), lut);
    out[c] = mix_taps16(tap, ax, ay);
  }
}

}  // namespace

bool HitShader::begin_avx512(const PrimaryBlock& b, Avx512Loads& l) const {
  const __m512i object = _mm512_loadu_si512(b.object), tri = _mm512_loadu_si512(b.triangle);
  __mmask16 left = _mm512_cmpneq_epi32_mask(_mm512_load_si512(b.active), _mm512_setzero_si512()) &
                   _mm512_cmpge_epi32_mask(object, _mm512_setzero_si512());
  if (left == 0) return false;
  const __m512i last = _mm512_set1_epi32(static_cast<std::int32_t>(materials_.size() - 1));
  l.groups = 0;
  while (left) {
    if (l.groups == kAvx512Groups) return false;
    // The lanes left with the first one's object and material (shading()'s index per lane).
    const int first = __builtin_ctz(left);
    const std::int32_t id = b.object[first];
    const Object& o = objects_[static_cast<std::size_t>(id)];
    if (o.lightmap_width <= 0 || o.lightmap_height <= 0) return false;
    const __mmask16 same = _mm512_mask_cmpeq_epi32_mask(left, object, _mm512_set1_epi32(id));
    const __mmask16 in = _mm512_mask_cmplt_epu32_mask(
        same, tri,
        _mm512_set1_epi32(
            static_cast<std::int32_t>(std::min<std::size_t>(o.triangle_count, 0x7fffffff))));
    const __m512i mi = _mm512_min_epu32(
        _mm512_mask_mov_epi32(_mm512_set1_epi32(static_cast<std::int32_t>(kFallback)), in,
                              gather_epi32(in, tri, o.triangle_material)),
        last);
    alignas(64) std::int32_t mis[PrimaryBlock::kLanes];
    _mm512_store_si512(mis, mi);
    const __mmask16 g = _mm512_mask_cmpeq_epi32_mask(same, mi, _mm512_set1_epi32(mis[first]));
    Avx512Group& group = l.group[l.groups++];
    group.material = &materials_[static_cast<std::uint32_t>(mis[first])];
    begin_avx512_group(b, o, g, group);
    left &= static_cast<__mmask16>(~g);
  }
  return true;
}

void HitShader::begin_avx512_group(const PrimaryBlock& b, const Object& o, std::uint16_t mask,
                                   Avx512Group& l) const {
  const __mmask16 m = mask;
  const Shading& mat = *l.material;
  const __m512i tri = _mm512_loadu_si512(b.triangle);
  // The atlas corners.
  const __m512 u = _mm512_loadu_ps(b.u), v = _mm512_loadu_ps(b.v);
  const __m512 w = _mm512_sub_ps(_mm512_sub_ps(_mm512_set1_ps(1.0f), u), v);
  // One triangle under all the lanes (large triangles): its corners broadcast, not gathered.
  const std::uint32_t t0 = b.triangle[__builtin_ctz(m)];
  const bool one =
      _mm512_mask_cmpneq_epi32_mask(m, tri, _mm512_set1_epi32(static_cast<std::int32_t>(t0))) == 0;
  const __m512i tri6 = _mm512_mullo_epi32(tri, _mm512_set1_epi32(6));
  __m512 c[3][2];
  for (int j = 0; j < 3; ++j)
    for (int a = 0; a < 2; ++a)
      c[j][a] =
          one ? _mm512_set1_ps(o.corner_uv[3 * static_cast<std::size_t>(t0) + j][a])
              : gather_ps(m, _mm512_add_epi32(tri6, _mm512_set1_epi32(2 * j + a)), &o.corner_uv->x);
  lightmap_taps16(o.lightmap_width, o.lightmap_height, interpolate16(c, 0, u, v, w),
                  interpolate16(c, 1, u, v, w), l.lightmap_taps);
  l.mask = m;
  l.lightmap = o.texels;
  const Texture* t =
      mat.texture && mat.texture->width > 0 && mat.texture->height > 0 ? mat.texture : nullptr;
  l.texture = t;
  if (t) {
    // WorldObject::uv's corners; (0, 0) without the set.
    const glm::vec2* uvs = o.uv[mat.texture_uv == 1 ? 1 : 0];
    __m512 tc[3][2];
    const __m512i tri3 = _mm512_mullo_epi32(tri, _mm512_set1_epi32(3));
    for (int j = 0; j < 3; ++j) {
      if (!uvs) {
        tc[j][0] = tc[j][1] = _mm512_setzero_ps();
        continue;
      }
      if (one) {
        const glm::vec2 cj = uvs[o.triangles[t0][j]];
        tc[j][0] = _mm512_set1_ps(cj.x);
        tc[j][1] = _mm512_set1_ps(cj.y);
        continue;
      }
      const __m512i vi = gather_epi32(m, _mm512_add_epi32(tri3, _mm512_set1_epi32(j)), o.triangles);
      const __m512i vi2 = _mm512_add_epi32(vi, vi);
      tc[j][0] = gather_ps(m, vi2, &uvs->x);
      tc[j][1] = gather_ps(m, _mm512_add_epi32(vi2, _mm512_set1_epi32(1)), &uvs->x);
    }
    texture_taps16(m, *t, interpolate16(tc, 0, u, v, w), interpolate16(tc, 1, u, v, w),
                   l.texture_taps);
  }
}

void HitShader::finish_avx512(const PrimaryBlock& b, const Avx512Loads& loads,
                              BlockShade& s) const {
  for (int ch = 0; ch < 3; ++ch) {
    _mm512_storeu_ps(s.diffuse[ch], _mm512_setzero_ps());
    _mm512_storeu_ps(s.emission[ch], _mm512_setzero_ps());
  }
  for (int gi = 0; gi < loads.groups; ++gi) {
    const Avx512Group& l = loads.group[gi];
    const __mmask16 m = l.mask;
    const Shading& mat = *l.material;
    __m512 e[3];
    lightmap_mix16(m, l.lightmap, l.lightmap_taps, e);
    __m512 tex[3] = {_mm512_set1_ps(1.0f), _mm512_set1_ps(1.0f), _mm512_set1_ps(1.0f)};
    if (l.texture) texture_mix16(m, *l.texture, l.texture_taps, tex);
    // albedo = base colour x texture; diffuse = albedo * (1 / pi) * E.
    const __m512 inv_pi = _mm512_set1_ps(kInvPi);
    for (int ch = 0; ch < 3; ++ch) {
      const __m512 albedo = _mm512_mul_ps(_mm512_set1_ps(mat.base_color[ch]), tex[ch]);
      _mm512_mask_storeu_ps(s.diffuse[ch], m, _mm512_mul_ps(_mm512_mul_ps(albedo, inv_pi), e[ch]));
    }
    if (mat.emissive)
      for (int k = 0; k < PrimaryBlock::kLanes; ++k)
        if ((m >> k) & 1) {
          HitShade hs;
          emission(b.hit_at(k), b.direction(k), mat, hs);
          for (int ch = 0; ch < 3; ++ch) s.emission[ch][k] = hs.emission[ch];
        }
  }
}

}  // namespace irradcast

#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif

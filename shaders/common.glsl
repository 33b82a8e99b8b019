// Shared by the engine's compute passes (direct.comp, gather.comp, scatter.comp): the buffers
// the Vulkan backend binds, random numbers, sampling warps, BVH traversal and the surface
// lookups (albedo, emission, previous-bounce radiance). Mirrors server/engine/src/embree_backend.cpp
// and common/src/lights.cpp; the data layouts are written by server/engine/src/vulkan_backend.cpp.

layout(local_size_x = 64) in;

const float PI = 3.14159265358979323846;
const float INV_PI = 0.31830988618379067154;
const uint EMPTY = 0xFFFFFFFFu;

// 4 vec4 per node: (lo0, child0) (hi0, child1) (lo1, count0) (hi1, count1). count 0: the child
// is an inner node; EMPTY: no child; otherwise a leaf of `count` triangles from index `child`.
layout(std430, binding = 0) readonly buffer Nodes { vec4 nodes[]; };
// 3 vec4 per triangle in BVH order: (v0, object) (v1, triangle in object) (v2, cut-out flag):
// the flag (uint bits) is 1 when the triangle's material is Mask (Material::cut_out), so only
// those hits pay for the alpha test (cut_out_at).
layout(std430, binding = 1) readonly buffer Tris { vec4 tris[]; };
// 4 vec4 per triangle, objects[o].x + t: lightmap uv corners (0,1) | (2, base uv 0) |
// base uv (1,2) | (material, its index in emissive[] or -1, -, -).
layout(std430, binding = 2) readonly buffer TriAttr { vec4 tri_attr[]; };
// Per object: first triangle in tri_attr, first lightmap texel in prev[], width, height.
layout(std430, binding = 3) readonly buffer Objects { uvec4 objects[]; };
// 3 vec4 per material: (base colour, base texture) (emission, emissive texture)
// (base alpha, alpha cutoff, -, -).
layout(std430, binding = 4) readonly buffer Materials { vec4 materials[]; };
// Per texture: first texel in tex_texels, width, height, -.
layout(std430, binding = 5) readonly buffer TexHeaders { uvec4 tex_headers[]; };
layout(std430, binding = 6) readonly buffer TexTexels { uint tex_texels[]; };  // RGBA8
// 7 vec4 per emissive triangle: (p0, -) (e1, -) (e2, double sided) (normal, area)
// (cdf, pick pdf, material, -) (emissive uv 0, uv 1) (uv 2, -, -); then, with FLAG_LIGHT_TREE,
// the light hierarchy's nodes (lights.glsl).
layout(std430, binding = 7) readonly buffer Emissive { vec4 emissive[]; };
// 4 vec4 per punctual light: (position, type) (direction, range) (intensity, cos inner)
// (cos outer, -, -, -). Types: 0 directional, 1 point, 2 spot.
layout(std430, binding = 8) readonly buffer Punctual { vec4 punctual[]; };
// 3 vec4 per surface texel: position, shading normal, geometric normal.
layout(std430, binding = 9) readonly buffer Texels { vec4 texels[]; };
layout(std430, binding = 10) readonly buffer Units { uint unit_texels[]; };
layout(std430, binding = 11) readonly buffer Probes { vec4 probes[]; };  // (position, usable)
// 20 uint per texel: 8 probe indices, 8 weights (float bits), count, -, -, -.
layout(std430, binding = 12) readonly buffer ProbeWeights { uint probe_weights[]; };
layout(std430, binding = 13) readonly buffer Prev { vec4 prev[]; };  // E_prev, every lightmap
// The probes' radiance: the scatter reads it from probe_offset; with FLAG_PROBE_MEAN the gather
// folds its estimates into the running means there (every bounce's means stay on the device).
layout(std430, binding = 14) buffer ProbeRadiance { vec4 probe_radiance[]; };
layout(std430, binding = 15) writeonly buffer Result { vec4 result[]; };
// 3 vec4 per triangle, objects[o].x + t: the corners' shading normals; w of the first is 0 when
// the mesh has none (the geometric normal is used). Read by the reference path tracer.
layout(std430, binding = 16) readonly buffer TriNormals { vec4 tri_normals[]; };
// The sky (common/sky.h), read when FLAG_SKY is set: (radiance of a constant sky x strength,
// map width bits) (map height bits, -, -, -), then for a map: its radiance x strength (3 floats
// per texel, row-major), SkyDistribution's marginal cdf (height + 1), conditional cdfs
// (height x (width + 1)) and densities (width x height). sky.glsl reads it.
layout(std430, binding = 17) readonly buffer SkyData { float sky[]; };

const uint FLAG_AREA = 1u, FLAG_UNBIASED = 2u, FLAG_FIXED = 4u, FLAG_PROBES = 8u;
const uint FLAG_CAMERA = 16u, FLAG_SKY = 32u, FLAG_SKY_MAP = 64u;
const uint FLAG_PROBE_MEAN = 128u, FLAG_LIGHT_TREE = 256u;

layout(push_constant) uniform Params {
  uint base;     // first item of this dispatch
  uint count;    // items in the pass
  uint update;
  uint bounce;
  uint seed_lo;
  uint seed_hi;
  uint samples;
  uint flags;
  float epsilon;  // ray offset (RayScene::epsilon)
  float range;    // hemisphere ray length
  float extent;   // the scene's largest extent
  uint punctual_count;
  vec3 bounds_lo;
  uint emissive_count;
  vec3 bounds_hi;
  int probe_res;
  uint probe_offset;   // first probe_radiance entry of this bounce's probes
  float probe_weight;  // FLAG_PROBE_MEAN: this update's weight in the running means
  uint pad0;
  uint pad1;
} pc;

// ---- random numbers: PCG (RXS-M-XS, 32 bit) per item, seeded from (seed, item, update, pass).

uint pcg_hash(uint v) {
  uint s = v * 747796405u + 2891336453u;
  uint w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
  return (w >> 22u) ^ w;
}

// The update number has a hash round of its own: packed into one word with the pass it would
// wrap after 2^16 updates and repeat old samples.
uint rng_init(uint item, uint stream) {
  uint pass = pcg_hash(pc.update ^ pcg_hash((stream << 8) | pc.bounce));
  return pcg_hash(item ^ pcg_hash(pc.seed_lo ^ pcg_hash(pc.seed_hi ^ pass)));
}

float next_float(inout uint s) {
  s = s * 747796405u + 2891336453u;
  uint w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
  w = (w >> 22u) ^ w;
  return float(w >> 8) * (1.0 / 16777216.0);
}

vec2 next_2d(inout uint s) {
  float a = next_float(s);
  return vec2(a, next_float(s));
}

// ---- sampling warps (common/include/irradcast/common/sampling.h)

vec3 frame_to_world(vec3 n, vec3 v) {
  float sgn = n.z >= 0.0 ? 1.0 : -1.0;
  float a = -1.0 / (sgn + n.z);
  float b = n.x * n.y * a;
  vec3 t = vec3(1.0 + sgn * n.x * n.x * a, sgn * b, -sgn * n.x);
  vec3 bt = vec3(b, sgn + n.y * n.y * a, -n.y);
  return v.x * t + v.y * bt + v.z * n;
}

vec3 cosine_hemisphere(vec2 u) {
  float r = sqrt(u.x);
  float phi = 2.0 * PI * u.y;
  return vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.x)));
}

vec2 uniform_triangle(vec2 u) {
  float s = sqrt(u.x);
  return vec2(1.0 - s, u.y * s);
}

vec2 octahedral_encode(vec3 d) {
  d /= abs(d.x) + abs(d.y) + abs(d.z);
  vec2 e = d.xy;
  if (d.z < 0.0)
    e = (1.0 - abs(d.yx)) * vec2(d.x >= 0.0 ? 1.0 : -1.0, d.y >= 0.0 ? 1.0 : -1.0);
  return 0.5 * e + 0.5;
}

vec3 octahedral_decode(vec2 uv) {
  vec2 e = 2.0 * uv - 1.0;
  vec3 d = vec3(e, 1.0 - abs(e.x) - abs(e.y));
  if (d.z < 0.0)
    d.xy = (1.0 - abs(d.yx)) * vec2(d.x >= 0.0 ? 1.0 : -1.0, d.y >= 0.0 ? 1.0 : -1.0);
  return normalize(d);
}

vec3 offset_origin(vec3 p, vec3 ng, vec3 d) {
  return p + (dot(ng, d) >= 0.0 ? pc.epsilon : -pc.epsilon) * ng;
}

// ---- BVH traversal

struct Hit {
  int object;  // -1: miss
  uint triangle;
  float u, v, t;
  uint prim;  // index in tris[] (BVH order)
};

vec3 safe_inverse(vec3 d) {
  const float tiny = 1e-20;
  return 1.0 / vec3(abs(d.x) < tiny ? (d.x < 0.0 ? -tiny : tiny) : d.x,
                    abs(d.y) < tiny ? (d.y < 0.0 ? -tiny : tiny) : d.y,
                    abs(d.z) < tiny ? (d.z < 0.0 ? -tiny : tiny) : d.z);
}

// Slab test, made conservative against rounding (the far distance grows by 2 gamma(3) as in
// pbrt, with room for the reciprocal's few ULP): a box must never cull a hit that the watertight
// triangle test would accept, on flat axis-aligned boxes (walls, floors) least of all.
bool hit_box(vec3 lo, vec3 hi, vec3 o, vec3 inv, float tmin, float tmax, out float tnear) {
  vec3 t0 = (lo - o) * inv, t1 = (hi - o) * inv;
  vec3 tn = min(t0, t1), tf = max(t0, t1) * 1.0000025;
  tnear = max(max(tn.x, tn.y), max(tn.z, tmin));
  float tfar = min(min(tf.x, tf.y), min(tf.z, tmax));
  return tnear <= tfar;
}

// Watertight ray/triangle test (Woop, Benthin and Wald 2013): the ray is sheared onto +z, so
// the edge functions of an edge shared by two triangles are computed from the same numbers and
// no ray slips between them (Embree's robust mode gives the same guarantee). (u, v) as Embree's:
// p = (1-u-v) p0 + u p1 + v p2.
struct ShearedRay {
  vec3 o;
  int kx, ky, kz;
  vec3 s;  // (Sx, Sy, Sz)
};

ShearedRay shear(vec3 o, vec3 d) {
  ShearedRay r;
  r.o = o;
  vec3 a = abs(d);
  r.kz = a.x > a.y ? (a.x > a.z ? 0 : 2) : (a.y > a.z ? 1 : 2);
  r.kx = (r.kz + 1) % 3;
  r.ky = (r.kx + 1) % 3;
  if (d[r.kz] < 0.0) {
    int t = r.kx;
    r.kx = r.ky;
    r.ky = t;
  }
  r.s = vec3(d[r.kx] / d[r.kz], d[r.ky] / d[r.kz], 1.0 / d[r.kz]);
  return r;
}

bool hit_triangle(uint i, ShearedRay r, float tmin, float tmax, out vec3 tuv) {
  vec3 a = tris[3 * i].xyz - r.o, b = tris[3 * i + 1].xyz - r.o, c = tris[3 * i + 2].xyz - r.o;
  float ax = a[r.kx] - r.s.x * a[r.kz], ay = a[r.ky] - r.s.y * a[r.kz];
  float bx = b[r.kx] - r.s.x * b[r.kz], by = b[r.ky] - r.s.y * b[r.kz];
  float cx = c[r.kx] - r.s.x * c[r.kz], cy = c[r.ky] - r.s.y * c[r.kz];
  float u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
  if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return false;
  float det = u + v + w;
  if (det == 0.0) return false;
  float t = (u * a[r.kz] + v * b[r.kz] + w * c[r.kz]) * r.s.z / det;
  if (!(t > tmin && t < tmax)) return false;
  tuv = vec3(t, v / det, w / det);
  return true;
}

bool cut_out_at(uint prim, float u, float v);

// Closest hit (any_hit false) or the first hit found (any_hit true) in (tmin, tmax).
Hit trace(vec3 o, vec3 d, float tmin, float tmax, bool any_hit) {
  Hit h;
  h.object = -1;
  h.triangle = 0u;
  h.u = 0.0;
  h.v = 0.0;
  h.t = tmax;
  h.prim = 0u;
  vec3 inv = safe_inverse(d);
  ShearedRay sheared = shear(o, d);
  uint stack[48];
  int sp = 0;
  uint node = 0u;
  while (true) {
    vec4 a = nodes[4 * node], b = nodes[4 * node + 1], c = nodes[4 * node + 2],
         e = nodes[4 * node + 3];
    uint child[2] = uint[2](floatBitsToUint(a.w), floatBitsToUint(b.w));
    uint count[2] = uint[2](floatBitsToUint(c.w), floatBitsToUint(e.w));
    float tn[2];
    bool hit[2];
    hit[0] = count[0] != EMPTY && hit_box(a.xyz, b.xyz, o, inv, tmin, h.t, tn[0]);
    hit[1] = count[1] != EMPTY && hit_box(c.xyz, e.xyz, o, inv, tmin, h.t, tn[1]);
    for (int k = 0; k < 2; ++k) {
      if (!hit[k] || count[k] == 0u) continue;
      hit[k] = false;  // a leaf: its triangles now, never on the stack
      for (uint i = child[k]; i < child[k] + count[k]; ++i) {
        vec3 tuv;
        if (hit_triangle(i, sheared, tmin, h.t, tuv)) {
          if (floatBitsToUint(tris[3 * i + 2].w) != 0u && cut_out_at(i, tuv.y, tuv.z)) continue;
          h.object = int(floatBitsToUint(tris[3 * i].w));
          h.triangle = floatBitsToUint(tris[3 * i + 1].w);
          h.prim = i;
          h.t = tuv.x;
          h.u = tuv.y;
          h.v = tuv.z;
          if (any_hit) return h;
        }
      }
    }
    if (hit[0] && hit[1]) {
      bool first = tn[0] <= tn[1];
      if (sp < 48) stack[sp++] = first ? child[1] : child[0];
      node = first ? child[0] : child[1];
    } else if (hit[0]) {
      node = child[0];
    } else if (hit[1]) {
      node = child[1];
    } else {
      if (sp == 0) break;
      node = stack[--sp];
    }
  }
  return h;
}

bool occluded(vec3 o, vec3 d, float tmax) {
  return trace(o, d, 0.0, tmax, true).object >= 0;
}

// ---- surfaces

float srgb_to_linear(float c) {
  return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

vec3 texel_rgb(uint first, int w, int x, int y) {
  vec4 c = unpackUnorm4x8(tex_texels[first + uint(y * w + x)]);
  return vec3(srgb_to_linear(c.r), srgb_to_linear(c.g), srgb_to_linear(c.b));
}

// The four texels around uv (REPEAT) and the bilinear weights, as Texture::sample_srgb.
struct Bilinear {
  int x0, y0, x1, y1;
  float ax, ay;
};

Bilinear bilinear(int w, int h, vec2 uv) {
  Bilinear b;
  float x = uv.x * float(w) - 0.5, y = uv.y * float(h) - 0.5;
  float fx = floor(x), fy = floor(y);
  float ax = x - fx, ay = y - fy;
  // REPEAT: fx - w floor(fx / w) may round to w (or just below 0); fold it back.
  int x0 = int(fx - float(w) * floor(fx / float(w)));
  int y0 = int(fy - float(h) * floor(fy / float(h)));
  x0 = x0 >= w ? x0 - w : (x0 < 0 ? x0 + w : x0);
  y0 = y0 >= h ? y0 - h : (y0 < 0 ? y0 + h : y0);
  x0 = clamp(x0, 0, w - 1);
  y0 = clamp(y0, 0, h - 1);
  b.x0 = x0;
  b.y0 = y0;
  b.x1 = x0 + 1 == w ? 0 : x0 + 1;
  b.y1 = y0 + 1 == h ? 0 : y0 + 1;
  b.ax = ax;
  b.ay = ay;
  return b;
}

// Bilinear, REPEAT, sRGB decoded (Texture::sample_srgb).
vec3 sample_texture(int tex, vec2 uv) {
  uvec4 th = tex_headers[tex];
  int w = int(th.y), h = int(th.z);
  if (w <= 0 || h <= 0) return vec3(1.0);
  Bilinear b = bilinear(w, h, uv);
  vec3 top = mix(texel_rgb(th.x, w, b.x0, b.y0), texel_rgb(th.x, w, b.x1, b.y0), b.ax);
  vec3 bottom = mix(texel_rgb(th.x, w, b.x0, b.y1), texel_rgb(th.x, w, b.x1, b.y1), b.ax);
  return mix(top, bottom, b.ay);
}

float texel_alpha(uint first, int w, int x, int y) {
  return unpackUnorm4x8(tex_texels[first + uint(y * w + x)]).a;
}

// The texture's alpha, bilinear and linear (Texture::sample_srgb's alpha).
float sample_alpha(int tex, vec2 uv) {
  uvec4 th = tex_headers[tex];
  int w = int(th.y), h = int(th.z);
  if (w <= 0 || h <= 0) return 1.0;
  Bilinear b = bilinear(w, h, uv);
  float top = mix(texel_alpha(th.x, w, b.x0, b.y0), texel_alpha(th.x, w, b.x1, b.y0), b.ax);
  float bottom = mix(texel_alpha(th.x, w, b.x0, b.y1), texel_alpha(th.x, w, b.x1, b.y1), b.ax);
  return mix(top, bottom, b.ay);
}

vec2 lerp_uv(vec2 a, vec2 b, vec2 c, float u, float v) {
  return (1.0 - u - v) * a + u * b + v * c;
}

vec3 albedo_at(uint object, uint triangle, float u, float v) {
  uint g = objects[object].x + triangle;
  uint m = floatBitsToUint(tri_attr[4 * g + 3].x);
  vec4 base = materials[3 * m];
  vec3 albedo = base.rgb;
  int tex = floatBitsToInt(base.w);
  if (tex >= 0) {
    vec4 a = tri_attr[4 * g + 1], b = tri_attr[4 * g + 2];
    albedo *= sample_texture(tex, lerp_uv(a.zw, b.xy, b.zw, u, v));
  }
  return albedo;
}

// Whether the hit (u, v) on BVH triangle `prim` (a Mask material's) is cut out: its alpha
// (base alpha x the base colour texture's alpha at the base colour uv set) below the cutoff.
bool cut_out_at(uint prim, float u, float v) {
  uint g = objects[floatBitsToUint(tris[3 * prim].w)].x + floatBitsToUint(tris[3 * prim + 1].w);
  uint m = floatBitsToUint(tri_attr[4 * g + 3].x);
  vec4 alpha = materials[3 * m + 2];
  float a = alpha.x;
  int tex = floatBitsToInt(materials[3 * m].w);
  if (tex >= 0) {
    vec4 p = tri_attr[4 * g + 1], q = tri_attr[4 * g + 2];
    a *= sample_alpha(tex, lerp_uv(p.zw, q.xy, q.zw, u, v));
  }
  return a < alpha.y;
}

// Lightmap::bilinear over object `object`'s part of prev[] (uv in texel units).
vec3 lightmap_at(uint object, vec2 uv) {
  uvec4 ob = objects[object];
  int w = int(ob.z), h = int(ob.w);
  float x = uv.x - 0.5, y = uv.y - 0.5;
  float fx = floor(x), fy = floor(y);
  float ax = x - fx, ay = y - fy;
  int x0 = clamp(int(fx), 0, w - 1), y0 = clamp(int(fy), 0, h - 1);
  int x1 = min(x0 + 1, w - 1), y1 = min(y0 + 1, h - 1);
  if (fx < 0.0) x1 = x0;
  if (fy < 0.0) y1 = y0;
  uint o = ob.y;
  vec3 top = mix(prev[o + uint(y0 * w + x0)].rgb, prev[o + uint(y0 * w + x1)].rgb, ax);
  vec3 bottom = mix(prev[o + uint(y1 * w + x0)].rgb, prev[o + uint(y1 * w + x1)].rgb, ax);
  return mix(top, bottom, ay);
}

// The previous bounce's outgoing radiance at a hit: albedo / pi * E_prev.
vec3 radiance_at(Hit h) {
  uint g = objects[uint(h.object)].x + h.triangle;
  vec4 a = tri_attr[4 * g], b = tri_attr[4 * g + 1];
  vec2 uv = lerp_uv(a.xy, a.zw, b.xy, h.u, h.v);
  return albedo_at(uint(h.object), h.triangle, h.u, h.v) * INV_PI *
         lightmap_at(uint(h.object), uv);
}

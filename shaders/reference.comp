#version 450
#extension GL_GOOGLE_include_directive : require
// The reference path tracer (PathTracer with next-event estimation): at every vertex the direct
// light (all punctual lights, one area-light sample, one sky estimate with FLAG_SKY), then one
// cosine-sampled bounce, `bounce` indirect bounces in all (a bounce ray that leaves the scene
// ends the path: the sky is direct light, counted at the vertices). Items are texels (their
// irradiance, reference_lightmaps) or, with FLAG_CAMERA, pixels (the radiance along their
// primary ray, PathTracer::render: the primary hit is traced once, `samples` paths leave it; a
// primary ray that misses shows the sky's radiance). The mean and the rays traced are written.
#include "common.glsl"
#include "lights.glsl"
#include "sky.glsl"

const uint STREAM_REFERENCE = 5u, STREAM_REFERENCE_SKY = 7u;

uint sky_rng;  // the sky's own stream (sky-less results keep their bits)

vec3 lights_direct(vec3 p, vec3 n, vec3 ng, inout uint rng, inout float rays) {
  vec3 e = punctual_irradiance(p, n, ng);
  rays += float(pc.punctual_count);
  if ((pc.flags & FLAG_AREA) != 0u) {
    vec2 a = next_2d(rng);
    float traced = 0.0;  // counted as one ray per sample, as before
    e += area_irradiance(p, n, ng, vec3(a, next_float(rng)), traced);
    rays += 1.0;
  }
  if ((pc.flags & FLAG_SKY) != 0u) {
    vec2 a = next_2d(sky_rng);
    e += sky_irradiance(p, n, ng, vec4(a, next_2d(sky_rng)), rays);
  }
  return e;
}

// The surface at a hit: position, geometric and shading normal turned toward -d (surfaces
// reflect on both sides); `g_raw` is the geometric normal before turning (for emission).
void surface_at(Hit h, vec3 d, out vec3 p, out vec3 n, out vec3 ng, out vec3 g_raw) {
  vec3 v0 = tris[3 * h.prim].xyz, v1 = tris[3 * h.prim + 1].xyz, v2 = tris[3 * h.prim + 2].xyz;
  vec3 g = cross(v1 - v0, v2 - v0);
  float len = length(g);
  g = len > 0.0 ? g / len : vec3(0.0, 0.0, 1.0);
  g_raw = g;
  uint t = objects[uint(h.object)].x + h.triangle;
  vec3 sn = g;
  vec4 n0 = tri_normals[3 * t];
  if (n0.w != 0.0) {
    vec3 m = (1.0 - h.u - h.v) * n0.xyz + h.u * tri_normals[3 * t + 1].xyz +
             h.v * tri_normals[3 * t + 2].xyz;
    float ml = length(m);
    if (ml > 1e-12) sn = dot(m, g) < 0.0 ? -m / ml : m / ml;
  }
  if (dot(g, -d) < 0.0) {
    g = -g;
    sn = -sn;
  }
  p = (1.0 - h.u - h.v) * v0 + h.u * v1 + h.v * v2;
  n = sn;
  ng = g;
}

// Emitted radiance leaving the hit toward -d (one-sided unless double-sided).
vec3 emitted(Hit h, vec3 d, vec3 g_raw) {
  uint t = objects[uint(h.object)].x + h.triangle;
  int k = floatBitsToInt(tri_attr[4 * t + 3].y);
  if (k < 0) return vec3(0.0);
  if (emissive[7 * uint(k) + 2].w == 0.0 && dot(g_raw, d) >= 0.0) return vec3(0.0);
  return emission_at(uint(k), vec2(h.u, h.v));
}

// Irradiance at (p, n, ng) with `bounce` indirect bounces: E = direct(p) + albedo(hit) E(hit),
// the weight being the product of the albedos so far.
vec3 irradiance(vec3 p, vec3 n, vec3 ng, inout uint rng, inout float rays) {
  vec3 weight = vec3(1.0), e = vec3(0.0);
  for (uint level = 0u; level <= pc.bounce; ++level) {
    e += weight * lights_direct(p, n, ng, rng, rays);
    if (level == pc.bounce) break;
    vec3 d = frame_to_world(n, cosine_hemisphere(next_2d(rng)));
    Hit h = trace(offset_origin(p, ng, d), d, 0.0, 3.4e38, false);
    rays += 1.0;
    if (h.object < 0) break;
    vec3 g_raw;
    weight *= albedo_at(uint(h.object), h.triangle, h.u, h.v);
    surface_at(h, d, p, n, ng, g_raw);
  }
  return e;
}

void main() {
  uint item = pc.base + gl_GlobalInvocationID.x;
  if (item >= pc.count) return;
  uint rng = rng_init(item, STREAM_REFERENCE);
  sky_rng = rng_init(item, STREAM_REFERENCE_SKY);
  float rays = 0.0;
  vec3 sum = vec3(0.0);
  vec4 a = texels[3 * item], b = texels[3 * item + 1], c = texels[3 * item + 2];
  if ((pc.flags & FLAG_CAMERA) == 0u) {
    // A texel: its irradiance.
    for (uint s = 0u; s < pc.samples; ++s) sum += irradiance(a.xyz, b.xyz, c.xyz, rng, rays);
  } else {
    // A pixel: the radiance along its primary ray (origin a, direction b), PathTracer::radiance.
    Hit h = trace(a.xyz, b.xyz, 0.0, 3.4e38, false);
    rays += 1.0;
    if (h.object >= 0) {
      vec3 p, n, ng, g_raw;
      surface_at(h, b.xyz, p, n, ng, g_raw);
      vec3 le = emitted(h, b.xyz, g_raw);
      vec3 reflect = albedo_at(uint(h.object), h.triangle, h.u, h.v) * INV_PI;
      for (uint s = 0u; s < pc.samples; ++s)
        sum += le + reflect * irradiance(p, n, ng, rng, rays);
    } else if ((pc.flags & FLAG_SKY) != 0u) {
      sum = sky_radiance(b.xyz) * float(pc.samples);
    }
  }
  result[item] = vec4(sum / float(max(pc.samples, 1u)), rays);
}

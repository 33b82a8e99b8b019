#version 450
#extension GL_GOOGLE_include_directive : require
// Direct pass: per texel, every punctual light with one shadow ray, plus `samples` stratified
// area-light samples (EmbreeBackend::direct, LightSampler), plus with a sky (FLAG_SKY) the mean
// of `samples` sky estimates from a random stream of their own (sky.glsl). w of the result: the
// sky rays traced.
#include "common.glsl"
#include "lights.glsl"
#include "sky.glsl"

const uint STREAM_DIRECT = 1u, STREAM_SKY = 6u;

void main() {
  uint item = pc.base + gl_GlobalInvocationID.x;
  if (item >= pc.count) return;
  uint i = unit_texels[item];
  vec3 p = texels[3 * i].xyz, n = texels[3 * i + 1].xyz, ng = texels[3 * i + 2].xyz;
  vec3 e = punctual_irradiance(p, n, ng);
  if ((pc.flags & FLAG_AREA) != 0u) {
    uint rng = rng_init(i, STREAM_DIRECT);
    vec3 sum = vec3(0.0);
    for (uint s = 0u; s < pc.samples; ++s) {
      float pick = (float(s) + next_float(rng)) / float(pc.samples);
      vec2 pos = next_2d(rng);
      sum += area_irradiance(p, n, ng, vec3(pick, pos));
    }
    e += sum / float(pc.samples);
  }
  float sky_rays = 0.0;
  if ((pc.flags & FLAG_SKY) != 0u) {
    uint rng = rng_init(i, STREAM_SKY);
    vec3 sum = vec3(0.0);
    for (uint s = 0u; s < pc.samples; ++s) {
      vec2 a = next_2d(rng);
      sum += sky_irradiance(p, n, ng, vec4(a, next_2d(rng)), sky_rays);
    }
    e += sum / float(pc.samples);
  }
  result[i] = vec4(e, sky_rays);
}

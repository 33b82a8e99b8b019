#version 450
#extension GL_GOOGLE_include_directive : require
// Direct pass: per texel, every punctual light with one shadow ray, plus `samples` stratified
// area-light samples (EmbreeBackend::direct, LightSampler).
#include "common.glsl"
#include "lights.glsl"

const uint STREAM_DIRECT = 1u;

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
  result[i] = vec4(e, 0.0);
}

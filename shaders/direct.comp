#version 450
#extension GL_GOOGLE_include_directive : require
// Direct pass: per texel, every punctual light with one shadow ray, plus `samples` stratified
// area-light samples among the lights in front of it (EmbreeBackend::direct, LightSampler),
// plus with a sky (FLAG_SKY) the mean of `samples` sky estimates from a random stream of their
// own (sky.glsl). w of the result: the area and sky shadow rays traced.
#include "common.glsl"
#include "lights.glsl"
#include "sky.glsl"

const uint STREAM_DIRECT = 1u, STREAM_SKY = 6u;
const uint MAX_FRONT = 64u;  // LightSampler::kMaxFront

// LightSampler's surely_rejected: no point of emissive triangle k can light p (normal n).
bool surely_rejected(uint k, vec3 p, vec3 n) {
  vec4 p0 = emissive[7 * k], e1 = emissive[7 * k + 1], e2 = emissive[7 * k + 2],
       nrm = emissive[7 * k + 3];
  vec3 ap = abs(p);
  float margin = 1e-5 * max(max(ap.x, ap.y), max(ap.z, p0.w));
  if (e2.w == 0.0 && dot(nrm.xyz, p - p0.xyz) < -margin) return true;
  float h0 = dot(n, p0.xyz - p);
  return h0 < -margin && h0 + dot(n, e1.xyz) < -margin && h0 + dot(n, e2.xyz) < -margin;
}

void main() {
  uint item = pc.base + gl_GlobalInvocationID.x;
  if (item >= pc.count) return;
  uint i = unit_texels[item];
  vec3 p = texels[3 * i].xyz, n = texels[3 * i + 1].xyz, ng = texels[3 * i + 2].xyz;
  vec3 e = punctual_irradiance(p, n, ng);
  float rays = 0.0;  // the area and sky shadow rays traced
  if ((pc.flags & FLAG_AREA) != 0u) {
    uint rng = rng_init(i, STREAM_DIRECT);
    vec3 sum = vec3(0.0);
    if (pc.emissive_count <= MAX_FRONT) {
      // LightSampler::front_lights: pick among the lights in front of the texel only.
      uint front[MAX_FRONT];
      float cdf[MAX_FRONT];
      uint count = 0u;
      float total = 0.0;
      for (uint k = 0u; k < pc.emissive_count; ++k) {
        if (surely_rejected(k, p, n)) continue;
        total += emissive[7 * k + 4].y;
        front[count] = k;
        cdf[count] = total;
        ++count;
      }
      for (uint s = 0u; count > 0u && s < pc.samples; ++s) {
        float pick = (float(s) + next_float(rng)) / float(pc.samples) * total;
        vec2 pos = next_2d(rng);
        uint j = 0u;
        while (j + 1u < count && cdf[j] <= pick) ++j;
        uint k = front[j];
        sum += area_sample(p, n, ng, k, emissive[7 * k + 4].y / total, pos, rays);
      }
    } else {
      for (uint s = 0u; s < pc.samples; ++s) {
        float pick = (float(s) + next_float(rng)) / float(pc.samples);
        vec2 pos = next_2d(rng);
        sum += area_irradiance(p, n, ng, vec3(pick, pos), rays);
      }
    }
    e += sum / float(pc.samples);
  }
  if ((pc.flags & FLAG_SKY) != 0u) {
    uint rng = rng_init(i, STREAM_SKY);
    vec3 sum = vec3(0.0);
    for (uint s = 0u; s < pc.samples; ++s) {
      vec2 a = next_2d(rng);
      sum += sky_irradiance(p, n, ng, vec4(a, next_2d(rng)), rays);
    }
    e += sum / float(pc.samples);
  }
  result[i] = vec4(e, rays);
}

#version 450
#extension GL_GOOGLE_include_directive : require
// One indirect bounce per texel: cosine-weighted hemisphere rays within the tracing range read
// the previous bounce at their hits; rays that reach the range inside the scene read one of the
// texel's probes, picked by weight, rays that leave the scene bring nothing, and a texel that
// sees no probe traces its rays to their hit (EmbreeBackend::scatter, embree_sampling::scatter_miss).
#include "common.glsl"

const uint STREAM_SCATTER = 3u, STREAM_PROBE_PICK = 4u;

vec3 sample_probe(uint probe, vec3 dir) {
  int res = pc.probe_res;
  vec2 uv = octahedral_encode(dir) * float(res) - 0.5;
  vec2 f = floor(uv);
  vec2 a = uv - f;
  int x = int(f.x), y = int(f.y);
  uint base = pc.probe_offset + probe * uint(res * res);
  int x0 = clamp(x, 0, res - 1), x1 = clamp(x + 1, 0, res - 1);
  int y0 = clamp(y, 0, res - 1), y1 = clamp(y + 1, 0, res - 1);
  vec3 top = mix(probe_radiance[base + uint(y0 * res + x0)].rgb,
                 probe_radiance[base + uint(y0 * res + x1)].rgb, a.x);
  vec3 bottom = mix(probe_radiance[base + uint(y1 * res + x0)].rgb,
                    probe_radiance[base + uint(y1 * res + x1)].rgb, a.x);
  return mix(top, bottom, a.y);
}

// embree_sampling::exit_distance: how far p + t d runs inside the (slightly enlarged) bounds.
float exit_distance(vec3 p, vec3 d) {
  vec3 pad = 1e-3 * max(pc.bounds_hi - pc.bounds_lo, vec3(1e-6));
  float t = 3.4e38;
  for (int k = 0; k < 3; ++k) {
    if (d[k] > 0.0) t = min(t, (pc.bounds_hi[k] + pad[k] - p[k]) / d[k]);
    if (d[k] < 0.0) t = min(t, (pc.bounds_lo[k] - pad[k] - p[k]) / d[k]);
  }
  return max(t, 0.0);
}

void main() {
  uint item = pc.base + gl_GlobalInvocationID.x;
  if (item >= pc.count) return;
  uint i = unit_texels[item];
  vec3 p = texels[3 * i].xyz, n = texels[3 * i + 1].xyz, ng = texels[3 * i + 2].xyz;
  uint rng = rng_init(i, STREAM_SCATTER);
  uint pick = rng_init(i, STREAM_PROBE_PICK);
  bool use_probes = (pc.flags & FLAG_UNBIASED) == 0u && (pc.flags & FLAG_PROBES) != 0u;
  bool fixed_distance = (pc.flags & FLAG_FIXED) != 0u;
  uint w = 20u * i;
  uint count = use_probes ? probe_weights[w + 16u] : 0u;
  // A texel that sees no probe (count 0) traces its rays to their hit.
  float range = use_probes && count == 0u ? 3.4e38 : pc.range;
  vec3 sum = vec3(0.0);
  for (uint s = 0u; s < pc.samples; ++s) {
    vec3 d = frame_to_world(n, cosine_hemisphere(next_2d(rng)));
    vec3 o = offset_origin(p, ng, d);
    Hit h = trace(o, d, 0.0, range, false);
    if (h.object >= 0) {
      sum += radiance_at(h);
    } else if (use_probes && count > 0u) {
      // A ray that left the scene within the range brings nothing (embree_sampling::scatter_miss).
      float exit = exit_distance(p, d);
      if (exit <= pc.range) continue;
      vec3 q = fixed_distance ? p + pc.extent * d : p + exit * d;
      float u = next_float(pick);
      float acc = 0.0;
      uint k = count - 1u;
      for (uint j = 0u; j + 1u < count; ++j) {
        acc += uintBitsToFloat(probe_weights[w + 8u + j]);
        if (u < acc) {
          k = j;
          break;
        }
      }
      uint probe = probe_weights[w + k];
      vec3 to = q - probes[probe].xyz;
      float len = length(to);
      if (len > 0.0) sum += sample_probe(probe, to / len);
    }
  }
  result[i] = vec4(sum * (PI / float(pc.samples)), 0.0);
}

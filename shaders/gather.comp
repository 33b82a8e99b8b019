#version 450
#extension GL_GOOGLE_include_directive : require
// Probe gather: one jittered ray per octahedral probe texel, the previous bounce's radiance at
// its hit (EmbreeBackend::gather_probes). Item = probe * res^2 + texel. The estimate goes to the
// result, or with FLAG_PROBE_MEAN into the bounce's running mean (TraceBackend::probe_bounce).
#include "common.glsl"

const uint STREAM_PROBE = 2u;

void main() {
  uint item = pc.base + gl_GlobalInvocationID.x;
  if (item >= pc.count) return;
  uint per = uint(pc.probe_res * pc.probe_res);
  uint probe = item / per, t = item % per;
  vec4 pos = probes[probe];
  vec3 l = vec3(0.0);
  if (pos.w != 0.0) {
    uint rng = rng_init(item, STREAM_PROBE);
    vec2 jitter = next_2d(rng);
    float res = float(pc.probe_res);
    vec2 uv = vec2((float(t % uint(pc.probe_res)) + jitter.x) / res,
                   (float(t / uint(pc.probe_res)) + jitter.y) / res);
    Hit h = trace(pos.xyz, octahedral_decode(uv), 0.0, 3.4e38, false);
    if (h.object >= 0) l = radiance_at(h);
  }
  if ((pc.flags & FLAG_PROBE_MEAN) != 0u) {
    // The host's running mean, mean += (estimate - mean) * weight, operation for operation
    // (precise: no fused multiply-add), so the device keeps the same bits.
    uint at = pc.probe_offset + item;
    precise vec3 m = probe_radiance[at].rgb;
    precise vec3 next = m + (l - m) * pc.probe_weight;
    probe_radiance[at] = vec4(next, 0.0);
  } else {
    result[item] = vec4(l, 0.0);
  }
}

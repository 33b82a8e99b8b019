// Direct lighting shared by the direct pass and the reference path tracer: every punctual light
// with one shadow ray, and one area-light sample picked by power (LightSampler).
vec3 punctual_irradiance(vec3 p, vec3 n, vec3 ng) {
  vec3 sum = vec3(0.0);
  for (uint l = 0u; l < pc.punctual_count; ++l) {
    vec4 pos = punctual[4 * l], dir = punctual[4 * l + 1], col = punctual[4 * l + 2],
         extra = punctual[4 * l + 3];
    int type = int(pos.w);
    vec3 wi;
    float dist = 3.4e38;
    float falloff = 1.0;
    if (type == 0) {
      wi = -dir.xyz;
    } else {
      vec3 d = pos.xyz - p;
      float dist2 = dot(d, d);
      if (!(dist2 > 0.0)) continue;
      dist = sqrt(dist2);
      wi = d / dist;
      falloff = 1.0 / dist2;
      if (dir.w > 0.0) {
        float r = dist / dir.w;
        falloff *= clamp(1.0 - r * r * r * r, 0.0, 1.0);
      }
      if (type == 2) {
        float cd = dot(dir.xyz, -wi);
        float denom = max(1e-4, col.w - extra.x);
        float t = clamp((cd - extra.x) / denom, 0.0, 1.0);
        falloff *= t * t;
      }
    }
    float cos_x = dot(n, wi);
    if (cos_x <= 0.0 || falloff <= 0.0) continue;
    vec3 o = offset_origin(p, ng, wi);
    float tmax = type == 0 ? 3.4e38 : dist - pc.epsilon;
    if (occluded(o, wi, tmax)) continue;
    sum += col.rgb * (cos_x * falloff);
  }
  return sum;
}

vec3 emission_at(uint k, vec2 b) {
  vec4 info = emissive[7 * k + 4];
  uint m = floatBitsToUint(info.z);
  vec4 em = materials[3 * m + 1];
  vec3 e = em.rgb;
  int tex = floatBitsToInt(em.w);
  if (tex >= 0) {
    vec4 u01 = emissive[7 * k + 5], u2 = emissive[7 * k + 6];
    e *= sample_texture(tex, lerp_uv(u01.xy, u01.zw, u2.xy, b.x, b.y));
  }
  return e;
}

// LightSampler::triangle_sample and its shadow ray: a uniform point (u) on emissive triangle k,
// picked with probability pick_pdf; rays counts the shadow rays traced.
vec3 area_sample(vec3 p, vec3 n, vec3 ng, uint k, float pick_pdf, vec2 u, inout float rays) {
  vec4 p0 = emissive[7 * k], e1 = emissive[7 * k + 1], e2 = emissive[7 * k + 2],
       nrm = emissive[7 * k + 3];
  vec2 b = uniform_triangle(u);
  vec3 y = p0.xyz + b.x * e1.xyz + b.y * e2.xyz;
  vec3 d = y - p;
  float dist2 = dot(d, d);
  if (!(dist2 > 0.0)) return vec3(0.0);
  float dist = sqrt(dist2);
  vec3 wi = d / dist;
  float cos_x = dot(n, wi);
  if (cos_x <= 0.0) return vec3(0.0);
  float cos_y = -dot(nrm.xyz, wi);
  if (e2.w != 0.0) cos_y = abs(cos_y);
  if (cos_y <= 0.0) return vec3(0.0);
  vec3 o = offset_origin(p, ng, wi);
  vec3 to_light = y - o;
  float len = length(to_light);
  float tmax = len - pc.epsilon;
  if (tmax > 0.0) {
    rays += 1.0;
    if (occluded(o, to_light / len, tmax)) return vec3(0.0);
  }
  return emission_at(k, b) * (cos_x * cos_y * nrm.w / dist2) / pick_pdf;
}

// LightSampler::area_irradiance: a triangle picked by power, a uniform point on it.
vec3 area_irradiance(vec3 p, vec3 n, vec3 ng, vec3 u, inout float rays) {
  uint lo = 0u, hi = pc.emissive_count;
  while (lo < hi) {
    uint mid = (lo + hi) / 2u;
    if (emissive[7 * mid + 4].x > u.x)
      hi = mid;
    else
      lo = mid + 1u;
  }
  uint k = min(lo, pc.emissive_count - 1u);
  return area_sample(p, n, ng, k, emissive[7 * k + 4].y, u.yz, rays);
}

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

// ---- the light hierarchy (common/src/light_tree.cpp), with FLAG_LIGHT_TREE: its nodes follow
// the emissive triangles in emissive[], 4 vec4 each from 7 * emissive_count: (lo, phi)
// (hi, cos_o) (w, flags: 1 leaf, 2 two-sided) (index, -, -, -); index: the triangle of a leaf,
// the second child of an inner node (the first follows it).

uint tree_node(uint k) {
  return 7u * pc.emissive_count + 4u * k;
}

float cos_sub_clamped(float sin_a, float cos_a, float sin_b, float cos_b) {
  return cos_a > cos_b ? 1.0 : cos_a * cos_b + sin_a * sin_b;
}
float sin_sub_clamped(float sin_a, float cos_a, float sin_b, float cos_b) {
  return cos_a > cos_b ? 0.0 : sin_a * cos_b - cos_a * sin_b;
}

// LightTree::importance.
float tree_importance(uint k, vec3 p, vec3 n) {
  uint at = tree_node(k);
  vec4 a = emissive[at], b = emissive[at + 1u], c = emissive[at + 2u];
  float phi = a.w;
  if (!(phi > 0.0)) return 0.0;
  vec3 pc_ = 0.5 * (a.xyz + b.xyz);
  float radius = 0.5 * length(b.xyz - a.xyz);
  float dist2 = dot(p - pc_, p - pc_);
  float d2 = max(dist2, radius);
  if (!(dist2 > radius * radius)) return phi / max(d2, 1e-12);
  vec3 wi = (p - pc_) / sqrt(dist2);
  float sin2_b = radius * radius / dist2;
  float cos_b = sqrt(max(1.0 - sin2_b, 0.0)), sin_b = sqrt(max(sin2_b, 0.0));
  float cos_w = dot(c.xyz, wi);
  if ((floatBitsToUint(c.w) & 2u) != 0u) cos_w = abs(cos_w);
  float sin_w = sqrt(max(1.0 - cos_w * cos_w, 0.0));
  float cos_o = b.w, sin_o = sqrt(max(1.0 - cos_o * cos_o, 0.0));
  float cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o);
  float sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o);
  float cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
  if (!(cos_p > 0.0)) return 0.0;
  float cos_i = -dot(n, wi);
  float sin_i = sqrt(max(1.0 - cos_i * cos_i, 0.0));
  float cos_pi = cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
  if (!(cos_pi > 0.0)) return 0.0;
  return phi * cos_p * cos_pi / d2;
}

// LightTree::sample: false where no light can reach p.
bool tree_pick(vec3 p, vec3 n, float u, out uint triangle, out float pmf) {
  uint at = 0u;
  float prob = 1.0;
  triangle = 0u;
  pmf = 0.0;
  while ((floatBitsToUint(emissive[tree_node(at) + 2u].w) & 1u) == 0u) {
    uint c0 = at + 1u, c1 = floatBitsToUint(emissive[tree_node(at) + 3u].x);
    float i0 = tree_importance(c0, p, n), i1 = tree_importance(c1, p, n);
    float sum = i0 + i1;
    if (!(sum > 0.0)) return false;
    float p0 = i0 / sum;
    if (u < p0) {
      u = min(u / p0, 0.99999994);
      prob *= p0;
      at = c0;
    } else {
      u = min((u - p0) / (1.0 - p0), 0.99999994);
      prob *= 1.0 - p0;
      at = c1;
    }
  }
  if (at == 0u && !(tree_importance(0u, p, n) > 0.0)) return false;
  if (!(prob > 0.0)) return false;
  triangle = floatBitsToUint(emissive[tree_node(at) + 3u].x);
  pmf = prob;
  return true;
}

// LightSampler::area_irradiance: a triangle picked by power (by the light hierarchy with
// FLAG_LIGHT_TREE: LightSampler::pick), a uniform point on it.
vec3 area_irradiance(vec3 p, vec3 n, vec3 ng, vec3 u, inout float rays) {
  if ((pc.flags & FLAG_LIGHT_TREE) != 0u) {
    uint k;
    float pmf;
    if (!tree_pick(p, n, u.x, k, pmf)) return vec3(0.0);
    return area_sample(p, n, ng, k, pmf, u.yz, rays);
  }
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

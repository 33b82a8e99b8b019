// The sky's direct light, shared by the direct pass and the reference path tracer: the same
// estimator as LightSampler::sky_irradiance (common/src/lights.cpp) over the sky buffer that
// server/engine/src/vulkan_scene_upload.cpp writes (layout in common.glsl). Map orientation,
// nearest-texel lookup and the sampling tables are common/src/sky.cpp's.

int sky_width() {
  return int(floatBitsToUint(sky[3]));
}

int sky_height() {
  return int(floatBitsToUint(sky[4]));
}

// Where the map's parts start in sky[]: radiance, marginal cdf, conditional cdfs, densities.
const uint SKY_MAP = 8u;

uint sky_marginal(int w, int h) {
  return SKY_MAP + 3u * uint(w * h);
}

uint sky_conditional(int w, int h) {
  return sky_marginal(w, h) + uint(h + 1);
}

uint sky_density(int w, int h) {
  return sky_conditional(w, h) + uint(h * (w + 1));
}

// sky_uv / sky_direction (common/sky.h): +Y up, the image centre facing -Z, right = +X.
vec2 sky_map_uv(vec3 dir) {
  float u = 0.5 + atan(dir.x, -dir.z) * (0.5 * INV_PI);
  float v = acos(clamp(dir.y, -1.0, 1.0)) * INV_PI;
  return clamp(vec2(u, v), 0.0, 1.0);
}

vec3 sky_map_direction(vec2 uv) {
  float theta = uv.y * PI;
  float phi = (uv.x - 0.5) * 2.0 * PI;
  float s = sin(theta);
  return vec3(s * sin(phi), cos(theta), -s * cos(phi));
}

// The map texel (row-major index) of map coordinates uv, clamped to the map.
int sky_texel(vec2 uv, int w, int h) {
  int x = clamp(int(uv.x * float(w)), 0, w - 1);
  int y = clamp(int(uv.y * float(h)), 0, h - 1);
  return y * w + x;
}

// Sky::radiance: a constant, or the map's nearest texel (strength included).
vec3 sky_radiance(vec3 dir) {
  int w = sky_width(), h = sky_height();
  if (w <= 0) return vec3(sky[0], sky[1], sky[2]);
  uint k = SKY_MAP + 3u * uint(sky_texel(sky_map_uv(dir), w, h));
  return vec3(sky[k], sky[k + 1u], sky[k + 2u]);
}

// The interval of the cdf sky[at .. at + n] (ascending, 0 ... 1) that holds u, skipping empty
// ones, and where u lies in it (sky.cpp's find_interval).
int sky_interval(uint at, int n, float u, out float within) {
  int lo = 0, hi = n + 1;  // upper_bound: the first entry > u
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    if (sky[at + uint(mid)] > u)
      hi = mid;
    else
      lo = mid + 1;
  }
  int i = clamp(lo - 1, 0, n - 1);
  while (i > 0 && !(sky[at + uint(i + 1)] > sky[at + uint(i)])) --i;
  float c0 = sky[at + uint(i)], width = sky[at + uint(i + 1)] - c0;
  within = width > 0.0 ? clamp((u - c0) / width, 0.0, 0.99999994) : 0.5;
  return i;
}

// SkyDistribution::sample: a direction drawn by the map's luminance and its density per unit
// solid angle (w 0: no sample).
vec4 sky_sample(vec2 u) {
  int w = sky_width(), h = sky_height();
  float fy, fx;
  int y = sky_interval(sky_marginal(w, h), h, u.y, fy);
  int x = sky_interval(sky_conditional(w, h) + uint(y * (w + 1)), w, u.x, fx);
  vec2 uv = vec2((float(x) + fx) / float(w), (float(y) + fy) / float(h));
  float sin_theta = sin(uv.y * PI);
  float d = sky[sky_density(w, h) + uint(y * w + x)];
  if (!(sin_theta > 0.0) || !(d > 0.0)) return vec4(0.0, 1.0, 0.0, 0.0);
  return vec4(sky_map_direction(uv), d / (2.0 * PI * PI * sin_theta));
}

// SkyDistribution::pdf.
float sky_pdf(vec3 dir) {
  int w = sky_width(), h = sky_height();
  vec2 uv = sky_map_uv(dir);
  float sin_theta = sin(uv.y * PI);
  if (!(sin_theta > 0.0)) return 0.0;
  return sky[sky_density(w, h) + uint(sky_texel(uv, w, h))] / (2.0 * PI * PI * sin_theta);
}

bool sky_escapes(vec3 p, vec3 ng, vec3 d, inout float rays) {
  rays += 1.0;
  return !occluded(offset_origin(p, ng, d), d, 3.4e38);
}

// LightSampler::sky_irradiance: a constant sky, one cosine-weighted ray (u.xy), pi L if it leaves
// the scene; a map (FLAG_SKY_MAP), one ray drawn from the map (u.xy) and one cosine-weighted
// ray (u.zw), combined by the balance heuristic. `rays` counts the rays traced.
vec3 sky_irradiance(vec3 p, vec3 n, vec3 ng, vec4 u, inout float rays) {
  vec3 cos_dir = frame_to_world(n, cosine_hemisphere(u.xy));
  if ((pc.flags & FLAG_SKY_MAP) == 0u)
    return sky_escapes(p, ng, cos_dir, rays) ? PI * sky_radiance(cos_dir) : vec3(0.0);
  vec3 e = vec3(0.0);
  vec4 s = sky_sample(u.xy);
  float cos_s = dot(n, s.xyz);
  if (s.w > 0.0 && cos_s > 0.0 && sky_escapes(p, ng, s.xyz, rays))
    e += sky_radiance(s.xyz) * (cos_s / (s.w + cos_s * INV_PI));
  vec3 c = frame_to_world(n, cosine_hemisphere(u.zw));
  float cos_c = dot(n, c);
  if (cos_c > 0.0 && sky_escapes(p, ng, c, rays))
    e += sky_radiance(c) * (cos_c / (sky_pdf(c) + cos_c * INV_PI));
  return e;
}

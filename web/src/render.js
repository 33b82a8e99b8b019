// The page's rendering on three.js (WebGL2): per object a mesh whose corners carry the lightmap
// coordinates, one RGB9_E5 texture per lightmap updated tile by tile with texSubImage2D, and
// irradcast's shading (common/src/compositor.cpp): albedo / pi * E + emission, then the
// exposure and tone map of irradcast-view (common/src/tonemap.cpp) and the sRGB transfer
// function. The sky (common/src/sky.cpp) is the background. Dynamic objects (docs/DYNAMIC.md) have
// no lightmap: their E comes from the probe volume, held in 3-D textures and looked up as
// IrradianceVolume::irradiance does (common/src/irradiance_volume.cpp), plus the direct light of
// the punctual lights, which irradcast-view traces with shadow rays and the page takes from shadow
// maps of the static scene (shadowMaps).
import * as THREE from 'three';
import { placeNodes } from './scene.js';
import { DEPTH_SIZE } from './volume.js';

export const TONE_OPS = { reinhard: 0, aces: 1, clamp: 2 };

const finishGlsl = `
uniform float exposureScale;
uniform int toneOp;
vec3 srgbEncode(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, 12.92 * c, lessThanEqual(c, vec3(0.0031308)));
}
vec3 finish(vec3 c) {
  c = max(c * exposureScale, 0.0);
  if (toneOp == 0) {
    float l = dot(c, vec3(0.2126, 0.7152, 0.0722));
    if (l > 0.0) c *= 1.0 / (1.0 + l);
  } else if (toneOp == 1) {
    c = clamp((c * (2.51 * c + 0.03)) / (c * (2.43 * c + 0.59) + 0.14), 0.0, 1.0);
  }
  return srgbEncode(c);
}`;

const surfaceVertex = `
in vec3 position; in vec3 normal; in vec2 uv0; in vec2 uv1; in vec2 luv;
uniform mat4 modelMatrix, viewMatrix, projectionMatrix;
out vec2 vUv0; out vec2 vUv1; out vec2 vLuv; out vec3 vWorld; out vec3 vNormal;
void main() {
  vUv0 = uv0; vUv1 = uv1; vLuv = luv;
  vec4 w = modelMatrix * vec4(position, 1.0);
  vWorld = w.xyz;
  vNormal = transpose(inverse(mat3(modelMatrix))) * normal;  // zero: the mesh has none
  gl_Position = projectionMatrix * viewMatrix * w;
}`;

// IrradianceVolume::irradiance (common/src/irradiance_volume.cpp), the same steps in the same
// order: the 8 probes around p, trilinear x facing x Chebyshev visibility (cubed, crushed below
// 0.2), SH L2 irradiance clamped at 0.
const volumeGlsl = `
uniform int volOn;
uniform highp sampler3D volProbes;  // per probe: offset xyz, active
uniform highp sampler3D volSh;      // per probe 7 texels: 27 SH values (RGB per coefficient)
uniform highp sampler3D volDepth;   // per probe ${DEPTH_SIZE} x ${DEPTH_SIZE}: distance moments / far
uniform vec3 volOrigin; uniform float volSpacing; uniform ivec3 volCounts; uniform float volFar;
vec2 octEncode(vec3 d) {
  d /= (abs(d.x) + abs(d.y) + abs(d.z));
  vec2 e = d.xy;
  if (d.z < 0.0) e = (1.0 - abs(d.yx)) * vec2(d.x >= 0.0 ? 1.0 : -1.0, d.y >= 0.0 ? 1.0 : -1.0);
  return 0.5 * e + 0.5;
}
vec2 probeMoments(ivec3 c, vec3 d) {
  const float n = float(${DEPTH_SIZE});
  vec2 f = clamp(octEncode(d) * n - 0.5, vec2(0.0), vec2(n - 1.0));
  ivec2 a = ivec2(f), b = min(a + 1, ivec2(${DEPTH_SIZE - 1}));
  vec2 t = f - vec2(a);
  ivec3 o = ivec3(c.x * ${DEPTH_SIZE}, c.y * ${DEPTH_SIZE}, c.z);
  vec2 m00 = texelFetch(volDepth, o + ivec3(a.x, a.y, 0), 0).rg, m10 = texelFetch(volDepth, o + ivec3(b.x, a.y, 0), 0).rg;
  vec2 m01 = texelFetch(volDepth, o + ivec3(a.x, b.y, 0), 0).rg, m11 = texelFetch(volDepth, o + ivec3(b.x, b.y, 0), 0).rg;
  return mix(mix(m00, m10, t.x), mix(m01, m11, t.x), t.y) * vec2(volFar, volFar * volFar);
}
vec3 probeIrradiance(ivec3 c, vec3 n) {
  float s[28];
  for (int k = 0; k < 7; ++k) {
    vec4 v = texelFetch(volSh, ivec3(c.x * 7 + k, c.y, c.z), 0);
    s[4 * k] = v.x; s[4 * k + 1] = v.y; s[4 * k + 2] = v.z; s[4 * k + 3] = v.w;
  }
  float y[9] = float[9](0.282095, 0.488603 * n.y, 0.488603 * n.z, 0.488603 * n.x, 1.092548 * n.x * n.y,
    1.092548 * n.y * n.z, 0.315392 * (3.0 * n.z * n.z - 1.0), 1.092548 * n.x * n.z, 0.546274 * (n.x * n.x - n.y * n.y));
  vec3 e = vec3(0.0);
  for (int j = 0; j < 9; ++j) e += y[j] * vec3(s[3 * j], s[3 * j + 1], s[3 * j + 2]);
  return max(e, vec3(0.0));
}
vec3 volumeIrradiance(vec3 p, vec3 n) {
  if (volOn == 0) return vec3(0.0);
  vec3 q = p + n * (0.05 * volSpacing);
  vec3 g = (q - volOrigin) / volSpacing;
  ivec3 base; vec3 f;
  for (int a = 0; a < 3; ++a) {
    int last = max(volCounts[a] - 2, 0);
    base[a] = int(clamp(floor(g[a]), 0.0, float(last)));
    f[a] = volCounts[a] > 1 ? clamp(g[a] - float(base[a]), 0.0, 1.0) : 0.0;
  }
  vec3 sum = vec3(0.0);
  float weights = 0.0;
  for (int corner = 0; corner < 8; ++corner) {
    ivec3 o = ivec3(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
    ivec3 c = min(base + o, volCounts - 1);
    vec4 pr = texelFetch(volProbes, c, 0);
    if (pr.w < 0.5) continue;
    vec3 tri = mix(1.0 - f, f, vec3(o));
    float trilinear = tri.x * tri.y * tri.z;
    if (trilinear <= 0.0) continue;
    vec3 toProbe = volOrigin + volSpacing * vec3(c) + pr.xyz - q;
    float dist = length(toProbe);
    vec3 dir = dist > 0.0 ? toProbe / dist : n;
    float w = sqrt(max(0.5 * (dot(dir, n) + 1.0), 0.0)) + 0.2;
    vec2 m = probeMoments(c, -dir);
    if (dist > m.x) {
      float variance = abs(m.y - m.x * m.x) + 1e-6 * volSpacing * volSpacing;
      float d = dist - m.x, ch = variance / (variance + d * d);
      w *= max(ch * ch * ch, 0.0);
    }
    if (w < 0.2) w *= w * w / (0.2 * 0.2);
    w = max(w, 1e-6) * trilinear;
    sum += w * probeIrradiance(c, n);
    weights += w;
  }
  return weights > 0.0 ? sum / weights : vec3(0.0);
}`;

// The punctual lights' direct light on a dynamic object, as LightSampler::punctual_sample with
// its shadow ray (lights.cpp): intensity x cos x falloff (1 / d^2, the range window, the spot
// cone), where the static scene's shadow map seen from the light (3 x 3 taps) does not hide p.
// A directional light has one orthographic view over the static bounds, a spot light one
// perspective view over its cone, a point light six (a cube). MAX_LIGHTS lights and MAX_VIEWS
// views; lights past them are left out (and said so on the console).
const MAX_LIGHTS = 4;
const MAX_VIEWS = 8;
const LIGHT_POINT = 0, LIGHT_SPOT = 1, LIGHT_DIRECTIONAL = 2;
const lightGlsl = `
uniform int lightCount;
uniform int lightType[${MAX_LIGHTS}];
uniform vec3 lightPos[${MAX_LIGHTS}], lightDir[${MAX_LIGHTS}], lightE[${MAX_LIGHTS}];
uniform float lightRange[${MAX_LIGHTS}], lightCosInner[${MAX_LIGHTS}], lightCosOuter[${MAX_LIGHTS}];
uniform int lightView[${MAX_LIGHTS}], lightViews[${MAX_LIGHTS}];  // its shadow views: first, count
uniform mat4 viewMatrix_[${MAX_VIEWS}];
uniform vec3 viewPos[${MAX_VIEWS}];
uniform float viewTexel[${MAX_VIEWS}];  // a texel's size: in world units (orthographic) or per unit of distance
uniform int viewOrtho[${MAX_VIEWS}], viewSize[${MAX_VIEWS}];
uniform highp sampler2D shadow0, shadow1, shadow2, shadow3, shadow4, shadow5, shadow6, shadow7;
float shadowDepth(int v, ivec2 t) {
  switch (v) {
    case 0: return texelFetch(shadow0, t, 0).r;
    case 1: return texelFetch(shadow1, t, 0).r;
    case 2: return texelFetch(shadow2, t, 0).r;
    case 3: return texelFetch(shadow3, t, 0).r;
    case 4: return texelFetch(shadow4, t, 0).r;
    case 5: return texelFetch(shadow5, t, 0).r;
    case 6: return texelFetch(shadow6, t, 0).r;
    default: return texelFetch(shadow7, t, 0).r;
  }
}
// The share of 3 x 3 taps around p that view v sees; -1 where p is outside the view.
float shadowSeen(int v, vec3 p, vec3 ng, vec3 wi) {
  float texel = viewOrtho[v] == 1 ? viewTexel[v] : viewTexel[v] * length(p - viewPos[v]);
  // Off the surface along its normal by two texels and towards the light by one (shadow acne).
  vec4 c = viewMatrix_[v] * vec4(p + ng * (2.0 * texel) + wi * texel, 1.0);
  if (c.w <= 0.0) return -1.0;
  vec3 ndc = c.xyz / c.w;
  if (any(greaterThan(abs(ndc.xy), vec2(1.0))) || ndc.z > 1.0) return -1.0;
  float z = 0.5 * ndc.z + 0.5;
  int size = viewSize[v];
  vec2 f = (0.5 * ndc.xy + 0.5) * float(size) - 0.5;
  ivec2 b = ivec2(floor(f));
  float seen = 0.0;
  for (int y = -1; y <= 1; ++y)
    for (int x = -1; x <= 1; ++x)
      seen += z <= shadowDepth(v, clamp(b + ivec2(x, y), ivec2(0), ivec2(size - 1))) ? 1.0 : 0.0;
  return seen / 9.0;
}
vec3 punctualIrradiance(vec3 p, vec3 n, vec3 ng) {
  vec3 e = vec3(0.0);
  for (int i = 0; i < ${MAX_LIGHTS}; ++i) {
    if (i >= lightCount) break;
    vec3 wi;
    float falloff = 1.0;
    if (lightType[i] == ${LIGHT_DIRECTIONAL}) {
      wi = -lightDir[i];
    } else {
      vec3 d = lightPos[i] - p;
      float dist2 = dot(d, d);
      if (!(dist2 > 0.0)) continue;
      float dist = sqrt(dist2);
      wi = d / dist;
      falloff = 1.0 / dist2;
      if (lightRange[i] > 0.0) {
        float r = dist / lightRange[i];
        falloff *= clamp(1.0 - r * r * r * r, 0.0, 1.0);
      }
      if (lightType[i] == ${LIGHT_SPOT}) {
        float t = clamp((dot(lightDir[i], -wi) - lightCosOuter[i]) / max(1e-4, lightCosInner[i] - lightCosOuter[i]), 0.0, 1.0);
        falloff *= t * t;
      }
    }
    float c = dot(n, wi);
    if (c <= 0.0 || falloff <= 0.0) continue;
    float seen = 1.0;
    for (int k = 0; k < 6; ++k) {
      if (k >= lightViews[i]) break;
      float s = shadowSeen(lightView[i] + k, p, ng, wi);
      if (s >= 0.0) { seen = s; break; }
    }
    e += lightE[i] * (c * falloff * seen);
  }
  return e;
}`;

const surfaceFragment = `
precision highp float;
${finishGlsl}
${volumeGlsl}
${lightGlsl}
uniform int dynamicOn;
uniform vec3 cameraPosition;
uniform sampler2D lightmap;
uniform vec3 baseColor; uniform float baseAlpha; uniform sampler2D baseTex; uniform int baseTexOn;
uniform int baseUv; uniform int alphaMask; uniform float alphaCutoff;
uniform vec3 emission; uniform sampler2D emTex; uniform int emTexOn; uniform int emUv;
uniform int emDoubleSided; uniform int hdrOut;
in vec2 vUv0; in vec2 vUv1; in vec2 vLuv; in vec3 vWorld; in vec3 vNormal;
out vec4 fragColor;
void main() {
  vec4 t = baseTexOn == 1 ? texture(baseTex, baseUv == 1 ? vUv1 : vUv0) : vec4(1.0);
  if (alphaMask == 1 && baseAlpha * t.a < alphaCutoff) discard;
  vec3 e;
  if (dynamicOn == 1) {
    // The shading normal on the side of the eye, as irradcast-view's (dynamic_view.cpp).
    vec3 ng = normalize(cross(dFdx(vWorld), dFdy(vWorld)));
    if (dot(ng, cameraPosition - vWorld) < 0.0) ng = -ng;
    vec3 n = dot(vNormal, vNormal) > 0.0 ? normalize(vNormal) : ng;
    if (dot(n, ng) < 0.0) n = -n;
    e = volumeIrradiance(vWorld, n) + punctualIrradiance(vWorld, n, ng);
  } else {
    e = texture(lightmap, vLuv / vec2(textureSize(lightmap, 0))).rgb;
  }
  vec3 c = baseColor * t.rgb * e * 0.31830988618379067;
  if (any(greaterThan(emission, vec3(0.0))) && (emDoubleSided == 1 || gl_FrontFacing))
    c += emission * (emTexOn == 1 ? texture(emTex, emUv == 1 ? vUv1 : vUv0).rgb : vec3(1.0));
  fragColor = hdrOut == 1 ? vec4(c, 1.0) : vec4(finish(c), 1.0);
}`;

const skyVertex = `
in vec3 position;
void main() { gl_Position = vec4(position.xy, 1.0, 1.0); }`;

const skyFragment = `
precision highp float;
${finishGlsl}
uniform vec3 camForward, camRight, camUp; uniform vec2 tanHalf; uniform vec2 viewport;
uniform vec3 skyColor; uniform float skyStrength; uniform int skyMapOn; uniform sampler2D skyMap;
uniform int hdrOut;
out vec4 fragColor;
void main() {
  vec2 s = (2.0 * gl_FragCoord.xy / viewport - 1.0) * tanHalf;
  vec3 d = normalize(camForward + s.x * camRight + s.y * camUp);
  vec3 c = skyColor;
  if (skyMapOn == 1) {
    ivec2 size = textureSize(skyMap, 0);
    float u = 0.5 + atan(d.x, -d.z) * 0.15915494309189535;
    float v = acos(clamp(d.y, -1.0, 1.0)) * 0.3183098861837907;
    ivec2 t = clamp(ivec2(floor(vec2(u, v) * vec2(size))), ivec2(0), size - 1);
    c = texelFetch(skyMap, t, 0).rgb;
  }
  c *= skyStrength;
  fragColor = hdrOut == 1 ? vec4(c, 1.0) : vec4(finish(c), 1.0);
}`;

function rgb9e5Texture(width, height, words, filter) {
  const t = new THREE.DataTexture(words, width, height, THREE.RGBFormat, THREE.UnsignedInt5999Type);
  t.minFilter = t.magFilter = filter;
  t.wrapS = t.wrapT = THREE.ClampToEdgeWrapping;
  t.generateMipmaps = false;
  t.flipY = false;
  t.needsUpdate = true;
  return t;
}

function colorTexture(tex) {
  const t = new THREE.DataTexture(tex.rgba8, tex.width, tex.height, THREE.RGBAFormat, THREE.UnsignedByteType);
  t.colorSpace = THREE.SRGBColorSpace;  // SRGB8_ALPHA8: decoded before filtering, as sample_srgb
  t.minFilter = t.magFilter = THREE.LinearFilter;
  t.wrapS = t.wrapT = THREE.RepeatWrapping;
  t.generateMipmaps = false;
  t.flipY = false;
  t.needsUpdate = true;
  return t;
}

// Geometry of one object: three corners per triangle (the layout's coordinates are per corner),
// grouped by material.
function objectGeometry(scene, obj) {
  const mesh = scene.meshes[obj.mesh], tris = mesh.triangles.length / 3;
  const matOf = (t) => (t < mesh.triangleMaterial.length && mesh.triangleMaterial[t] < scene.materials.length
    ? mesh.triangleMaterial[t] : -1);
  const order = [...Array(tris).keys()].sort((a, b) => matOf(a) - matOf(b));
  const pos = new Float32Array(9 * tris), uv0 = new Float32Array(6 * tris), uv1 = new Float32Array(6 * tris);
  const nrm = new Float32Array(9 * tris);
  const luv = new Float32Array(6 * tris);
  const g = new THREE.BufferGeometry(), groups = [];
  order.forEach((t, k) => {
    const m = matOf(t);
    if (!groups.length || groups[groups.length - 1].material !== m) groups.push({ start: 3 * k, count: 0, material: m });
    groups[groups.length - 1].count += 3;
    for (let c = 0; c < 3; ++c) {
      const v = mesh.triangles[3 * t + c], o = 3 * k + c;
      for (let a = 0; a < 3; ++a) pos[3 * o + a] = mesh.positions[3 * v + a];
      if (mesh.normals) for (let a = 0; a < 3; ++a) nrm[3 * o + a] = mesh.normals[3 * v + a];
      for (let a = 0; a < 2; ++a) {
        if (mesh.uv0) uv0[2 * o + a] = mesh.uv0[2 * v + a];
        if (mesh.uv1) uv1[2 * o + a] = mesh.uv1[2 * v + a];
        luv[2 * o + a] = obj.dynamic ? 0 : obj.cornerUv[6 * t + 2 * c + a];
      }
    }
  });
  g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  g.setAttribute('normal', new THREE.BufferAttribute(nrm, 3));
  g.setAttribute('uv0', new THREE.BufferAttribute(uv0, 2));
  g.setAttribute('uv1', new THREE.BufferAttribute(uv1, 2));
  g.setAttribute('luv', new THREE.BufferAttribute(luv, 2));
  return { geometry: g, groups };
}

const FALLBACK = { baseColor: new THREE.Vector3(0.8, 0.8, 0.8), baseTexture: -1, baseUv: 0, emissive: new THREE.Vector3(),
  emissiveTexture: -1, emissiveUv: 0, emissiveStrength: 1, doubleSided: false, mask: false, alphaCutoff: 0.5, baseAlpha: 1 };

export class SceneView {
  constructor(renderer, scene, welcome, finish) {
    this.renderer = renderer;
    this.scene = scene;
    this.finish = finish;  // shared uniforms: exposureScale, toneOp, hdrOut
    this.root = new THREE.Scene();
    this.white = colorTexture({ rgba8: new Uint8Array([255, 255, 255, 255]), width: 1, height: 1 });
    this.textures = scene.textures.map(colorTexture);
    this.lightmaps = scene.objects.map((o) => {
      const words = new Uint32Array(Math.max(1, o.width * o.height));
      return { width: o.width, height: o.height, words,
        texture: rgb9e5Texture(Math.max(1, o.width), Math.max(1, o.height), words, THREE.LinearFilter) };
    });
    this.tileSize = welcome.tile_size;
    this.volumeUniforms = this.emptyVolume();
    this.lightUniforms = this.emptyLights();
    this.materials = [];  // per scene material, the ShaderMaterials that show it
    this.meshes = scene.objects.map((o, i) => this.buildObject(o, i));
    this.buildSky();
    this.placeNodes();
    this.bounds = new THREE.Box3();
    this.meshes.forEach((m, i) => { if (!scene.objects[i].avatar) this.bounds.expandByObject(m); });
    if (this.bounds.isEmpty()) this.bounds.set(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1));
    this.shadowsDirty = true;
  }

  // The punctual lights' uniforms, shared by every material (no light until shadowMaps runs).
  emptyLights() {
    const depth = () => {
      const t = new THREE.DataTexture(new Float32Array([1]), 1, 1, THREE.RedFormat, THREE.FloatType);
      t.needsUpdate = true;
      return t;
    };
    const vecs = (n) => [...Array(n)].map(() => new THREE.Vector3());
    const u = { lightCount: { value: 0 }, lightType: { value: Array(MAX_LIGHTS).fill(0) },
      lightPos: { value: vecs(MAX_LIGHTS) }, lightDir: { value: vecs(MAX_LIGHTS) }, lightE: { value: vecs(MAX_LIGHTS) },
      lightRange: { value: Array(MAX_LIGHTS).fill(0) }, lightCosInner: { value: Array(MAX_LIGHTS).fill(1) },
      lightCosOuter: { value: Array(MAX_LIGHTS).fill(0) }, lightView: { value: Array(MAX_LIGHTS).fill(0) },
      lightViews: { value: Array(MAX_LIGHTS).fill(0) },
      viewMatrix_: { value: [...Array(MAX_VIEWS)].map(() => new THREE.Matrix4()) }, viewPos: { value: vecs(MAX_VIEWS) },
      viewTexel: { value: Array(MAX_VIEWS).fill(0) }, viewOrtho: { value: Array(MAX_VIEWS).fill(0) },
      viewSize: { value: Array(MAX_VIEWS).fill(1) } };
    this.emptyDepth = depth();
    for (let v = 0; v < MAX_VIEWS; ++v) u[`shadow${v}`] = { value: this.emptyDepth };
    return u;
  }

  // The punctual lights placed by visible static nodes (world.cpp place_lights), and their shadow
  // views: depth maps of the static scene seen from each light (dynamic objects left out: they
  // cast no shadow on anything, as in irradcast-view).
  shadowMaps() {
    this.shadowsDirty = false;
    const { world, visible, dynamic } = placeNodes(this.scene);
    const u = this.lightUniforms, center = this.bounds.getCenter(new THREE.Vector3());
    const radius = Math.max(1e-6, this.bounds.getSize(new THREE.Vector3()).length() * 0.5);
    const views = [];  // { camera, size, ortho, texel }
    let count = 0, left = 0;
    this.scene.nodes.forEach((node, i) => {
      if (node.light < 0 || !visible[i] || dynamic[i]) return;
      const l = this.scene.lights[node.light];
      const pos = new THREE.Vector3().setFromMatrixPosition(world[i]);
      const dir = new THREE.Vector3(0, 0, -1).transformDirection(world[i]);
      const need = l.type === LIGHT_POINT ? 6 : 1;
      if (count >= MAX_LIGHTS || views.length + need > MAX_VIEWS) { ++left; return; }
      u.lightType.value[count] = l.type;
      u.lightPos.value[count].copy(pos);
      u.lightDir.value[count].copy(dir);
      u.lightE.value[count].copy(l.color).multiplyScalar(l.intensity);
      u.lightRange.value[count] = l.range > 0 ? l.range : 0;
      u.lightCosInner.value[count] = Math.cos(l.innerCone);
      u.lightCosOuter.value[count] = Math.cos(l.outerCone);
      u.lightView.value[count] = views.length;
      u.lightViews.value[count] = need;
      const far = 2 * radius + pos.distanceTo(center);
      const look = (d, fov) => {
        const cam = new THREE.PerspectiveCamera(fov, 1, Math.max(1e-4 * radius, 1e-6), far);
        cam.up.copy(Math.abs(d.y) < 0.9 ? new THREE.Vector3(0, 1, 0) : new THREE.Vector3(1, 0, 0));
        cam.position.copy(pos);
        cam.lookAt(pos.clone().add(d));
        views.push({ camera: cam, size: 1024, ortho: false, texel: 2 * Math.tan(0.5 * fov * Math.PI / 180) / 1024 });
      };
      if (l.type === LIGHT_DIRECTIONAL) {
        const cam = new THREE.OrthographicCamera(-radius, radius, radius, -radius, 0, 4 * radius);
        cam.up.copy(Math.abs(dir.y) < 0.9 ? new THREE.Vector3(0, 1, 0) : new THREE.Vector3(1, 0, 0));
        cam.position.copy(center).addScaledVector(dir, -2 * radius);
        cam.lookAt(center);
        views.push({ camera: cam, size: 2048, ortho: true, texel: 2 * radius / 2048 });
      } else if (l.type === LIGHT_SPOT) {
        look(dir, Math.min(2 * l.outerCone * 180 / Math.PI + 2, 170));
      } else {  // a cube, its faces a little wider than 90 degrees so that they overlap
        for (const d of [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
          look(new THREE.Vector3(...d), 92);
      }
      ++count;
    });
    if (left) console.warn(`irradcast: ${left} punctual lights left out of the dynamic objects' shading (at most ${MAX_LIGHTS} lights, ${MAX_VIEWS} shadow views)`);
    u.lightCount.value = count;
    if (!views.length) return;
    if (!this.depthOnly) {
      this.depthOnly = new THREE.RawShaderMaterial({ glslVersion: THREE.GLSL3, side: THREE.DoubleSide, colorWrite: false,
        vertexShader: 'in vec3 position; uniform mat4 modelMatrix, viewMatrix, projectionMatrix;\n' +
          'void main() { gl_Position = projectionMatrix * viewMatrix * modelMatrix * vec4(position, 1.0); }',
        fragmentShader: 'precision highp float; out vec4 c; void main() { c = vec4(1.0); }' });
    }
    const shown = this.meshes.map((m) => m.visible);
    this.meshes.forEach((m, i) => { if (this.scene.objects[i].dynamic) m.visible = false; });
    this.sky.visible = false;
    this.root.overrideMaterial = this.depthOnly;
    this.shadowTargets = this.shadowTargets || [];
    views.forEach((v, k) => {
      v.camera.updateMatrixWorld(true);
      v.camera.updateProjectionMatrix();
      let t = this.shadowTargets[k];
      if (!t || t.width !== v.size) {
        if (t) t.dispose();
        t = new THREE.WebGLRenderTarget(v.size, v.size, { depthBuffer: true });
        t.depthTexture = new THREE.DepthTexture(v.size, v.size, THREE.FloatType);
        this.shadowTargets[k] = t;
      }
      this.renderer.setRenderTarget(t);
      this.renderer.clear();
      this.renderer.render(this.root, v.camera);
      u[`shadow${k}`].value = t.depthTexture;
      u.viewMatrix_.value[k].multiplyMatrices(v.camera.projectionMatrix, v.camera.matrixWorldInverse);
      u.viewPos.value[k].copy(v.camera.position);
      u.viewTexel.value[k] = v.texel;
      u.viewOrtho.value[k] = v.ortho ? 1 : 0;
      u.viewSize.value[k] = v.size;
    });
    this.renderer.setRenderTarget(null);
    this.root.overrideMaterial = null;
    this.sky.visible = true;
    this.meshes.forEach((m, i) => { m.visible = shown[i]; });
  }

  buildObject(obj, index) {
    const { geometry, groups } = objectGeometry(this.scene, obj);
    const mats = groups.map((gr, k) => {
      geometry.addGroup(gr.start, gr.count, k);
      const mat = new THREE.RawShaderMaterial({
        glslVersion: THREE.GLSL3, vertexShader: surfaceVertex, fragmentShader: surfaceFragment,
        side: THREE.DoubleSide,
        uniforms: { ...this.finish, ...this.volumeUniforms, ...this.lightUniforms, lightmap: { value: this.lightmaps[index].texture },
          dynamicOn: { value: obj.dynamic ? 1 : 0 } },
      });
      mat.sceneMaterial = gr.material;
      this.setMaterial(mat, gr.material);
      return mat;
    });
    const m = new THREE.Mesh(geometry, mats);
    m.matrixAutoUpdate = false;
    m.frustumCulled = false;
    this.root.add(m);
    return m;
  }

  // The uniforms of one ShaderMaterial from scene material i (-1: the fallback).
  setMaterial(mat, i) {
    const m = i >= 0 ? this.scene.materials[i] : FALLBACK;
    const u = mat.uniforms, tex = (t) => (t >= 0 ? this.textures[t] : this.white);
    const emissive = m.emissiveStrength > 0 && Math.max(m.emissive.x, m.emissive.y, m.emissive.z) > 0;
    Object.assign(u, {
      baseColor: { value: m.baseColor.clone() }, baseAlpha: { value: m.baseAlpha },
      baseTex: { value: tex(m.baseTexture) }, baseTexOn: { value: m.baseTexture >= 0 ? 1 : 0 },
      baseUv: { value: m.baseUv }, alphaMask: { value: m.mask ? 1 : 0 }, alphaCutoff: { value: m.alphaCutoff },
      emission: { value: emissive ? m.emissive.clone().multiplyScalar(m.emissiveStrength) : new THREE.Vector3() },
      emTex: { value: tex(m.emissiveTexture) }, emTexOn: { value: m.emissiveTexture >= 0 ? 1 : 0 },
      emUv: { value: m.emissiveUv }, emDoubleSided: { value: m.doubleSided ? 1 : 0 },
    });
    mat.uniformsNeedUpdate = true;
  }

  // After a material edit.
  updateMaterials() {
    for (const mesh of this.meshes) for (const mat of mesh.material) this.setMaterial(mat, mat.sceneMaterial);
  }

  // After a transform or visibility edit (`statics`: of static nodes or lights, which the shadow
  // maps follow; a pose moves a dynamic node only).
  placeNodes(statics = true) {
    if (statics) this.shadowsDirty = true;
    const { world, visible } = placeNodes(this.scene);
    this.scene.objects.forEach((o, i) => {
      this.meshes[i].matrix.copy(world[o.node]);
      this.meshes[i].matrixWorldNeedsUpdate = true;
      this.meshes[i].visible = visible[o.node];
    });
  }

  // The volume's uniforms, shared by every material (a 1-texel stand-in until a volume comes).
  emptyVolume() {
    const dummy = (data, format) => {
      const t = new THREE.Data3DTexture(data, 1, 1, 1);
      t.format = format;
      t.type = THREE.HalfFloatType;
      t.minFilter = t.magFilter = THREE.NearestFilter;
      t.unpackAlignment = 1;
      t.needsUpdate = true;
      return t;
    };
    return { volOn: { value: 0 }, volProbes: { value: dummy(new Uint16Array(4), THREE.RGBAFormat) },
      volSh: { value: dummy(new Uint16Array(4), THREE.RGBAFormat) }, volDepth: { value: dummy(new Uint16Array(2), THREE.RGFormat) },
      volOrigin: { value: new THREE.Vector3() }, volSpacing: { value: 1 }, volCounts: { value: new THREE.Vector3(1, 1, 1) },
      volFar: { value: 1 } };
  }

  // A probe volume (volume.js) into the 3-D textures; false when a side exceeds the GPU's 3-D
  // texture size (the dynamic objects then stay unlit).
  setVolume(v) {
    const u = this.volumeUniforms, [nx, ny, nz] = v.counts;
    const gl = this.renderer.getContext(), max = gl.getParameter(gl.MAX_3D_TEXTURE_SIZE);
    if (Math.max(nx * 7, nx * DEPTH_SIZE, ny * DEPTH_SIZE, nz) > max) return false;
    const tex3d = (data, w, h, d, format) => {
      const t = new THREE.Data3DTexture(data, w, h, d);
      t.format = format;
      t.type = data instanceof Float32Array ? THREE.FloatType : THREE.HalfFloatType;
      t.minFilter = t.magFilter = THREE.NearestFilter;
      t.unpackAlignment = 1;
      t.needsUpdate = true;
      return t;
    };
    const replace = (name, t) => {
      if (u[name].value) u[name].value.dispose();
      u[name].value = t;
    };
    if (v !== this.volume && (!this.volume || v.offsets !== this.volume.offsets)) {
      replace('volProbes', tex3d(v.offsets, nx, ny, nz, THREE.RGBAFormat));
      // Per probe its 16 x 16 moments, probe (x, y, z) at (16 x, 16 y, z).
      const S = DEPTH_SIZE, W = nx * S, H = ny * S, depth = new Uint16Array(2 * W * H * nz);
      for (let i = 0; i < v.probes; ++i) {
        const cx = i % nx, cy = Math.floor(i / nx) % ny, cz = Math.floor(i / (nx * ny));
        for (let t = 0; t < S * S; ++t) {
          const at = 2 * ((cz * H + cy * S + Math.floor(t / S)) * W + cx * S + (t % S));
          depth[at] = v.depth[2 * (i * S * S + t)];
          depth[at + 1] = v.depth[2 * (i * S * S + t) + 1];
        }
      }
      replace('volDepth', tex3d(depth, W, H, nz, THREE.RGFormat));
    }
    // 27 SH halves per probe padded to 28: 7 RGBA texels in a row.
    const sh = new Uint16Array(28 * v.probes);
    for (let i = 0; i < v.probes; ++i) sh.set(v.sh.subarray(27 * i, 27 * i + 27), 28 * i);
    replace('volSh', tex3d(sh, nx * 7, ny, nz, THREE.RGBAFormat));
    u.volOrigin.value.set(v.origin[0], v.origin[1], v.origin[2]);
    u.volSpacing.value = v.spacing;
    u.volCounts.value.set(nx, ny, nz);
    u.volFar.value = v.far;
    u.volOn.value = 1;
    this.volume = v;
    return true;
  }

  buildSky() {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array([-1, -1, 0, 3, -1, 0, -1, 3, 0]), 3));
    this.skyUniforms = { ...this.finish, camForward: { value: new THREE.Vector3() }, camRight: { value: new THREE.Vector3() },
      camUp: { value: new THREE.Vector3() }, tanHalf: { value: new THREE.Vector2() }, viewport: { value: new THREE.Vector2() },
      skyColor: { value: new THREE.Vector3() }, skyStrength: { value: 1 }, skyMapOn: { value: 0 }, skyMap: { value: null } };
    const mat = new THREE.RawShaderMaterial({ glslVersion: THREE.GLSL3, vertexShader: skyVertex,
      fragmentShader: skyFragment, uniforms: this.skyUniforms, depthTest: false, depthWrite: false });
    this.sky = new THREE.Mesh(g, mat);
    this.sky.frustumCulled = false;
    this.sky.renderOrder = -1;
    this.root.add(this.sky);
    this.updateSky();
  }

  updateSky() {
    const s = this.scene.sky, u = this.skyUniforms;
    u.skyColor.value.copy(s.color);
    u.skyStrength.value = s.strength;
    if (u.skyMap.value && u.skyMap.value !== this.white) u.skyMap.value.dispose();
    u.skyMap.value = s.map ? rgb9e5Texture(s.map.width, s.map.height, s.map.words, THREE.NearestFilter) : this.white;
    u.skyMapOn.value = s.map ? 1 : 0;
  }

  // Copies a decoded tile (RGB9E5 words) into the CPU copy and the texture's sub-rectangle.
  applyTile(lightmap, x0, y0, w, h, words) {
    const lm = this.lightmaps[lightmap];
    for (let j = 0; j < h; ++j) lm.words.set(words.subarray(j * w, (j + 1) * w), (y0 + j) * lm.width + x0);
    const props = this.renderer.properties.get(lm.texture);
    if (!props.__webglTexture || lm.texture.version !== props.__version) return;  // uploaded whole at the next draw
    const gl = this.renderer.getContext();
    this.renderer.state.bindTexture(gl.TEXTURE_2D, props.__webglTexture);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 4);
    gl.pixelStorei(gl.UNPACK_ROW_LENGTH, 0);
    gl.texSubImage2D(gl.TEXTURE_2D, 0, x0, y0, w, h, gl.RGB, gl.UNSIGNED_INT_5_9_9_9_REV, words);
  }

  // The words of a tile's rectangle (a delta's base).
  tileWords(lightmap, x0, y0, w, h) {
    const lm = this.lightmaps[lightmap], out = new Uint32Array(w * h);
    for (let j = 0; j < h; ++j) out.set(lm.words.subarray((y0 + j) * lm.width + x0, (y0 + j) * lm.width + x0 + w), j * w);
    return out;
  }

  // Frees the GPU side (a new scene replaces this one).
  dispose() {
    for (const m of this.meshes) {
      m.geometry.dispose();
      for (const mat of m.material) mat.dispose();
    }
    for (const t of [...this.textures, ...this.lightmaps.map((l) => l.texture), this.white]) t.dispose();
    for (const k of ['volProbes', 'volSh', 'volDepth']) this.volumeUniforms[k].value.dispose();
    for (const t of this.shadowTargets || []) if (t) t.dispose();
    if (this.depthOnly) this.depthOnly.dispose();
    this.emptyDepth.dispose();
    if (this.skyUniforms.skyMap.value !== this.white) this.skyUniforms.skyMap.value.dispose();
    this.sky.geometry.dispose();
    this.sky.material.dispose();
    this.root.clear();
  }

  render(camera, width, height, target = null) {
    const u = this.skyUniforms, f = camera.pose.forward.clone().normalize();
    const right = new THREE.Vector3().crossVectors(f, camera.pose.up).normalize();
    u.camForward.value.copy(f);
    u.camRight.value.copy(right);
    u.camUp.value.crossVectors(right, f);
    const th = Math.tan(0.5 * camera.pose.yfov);
    u.tanHalf.value.set(th * width / height, th);
    u.viewport.value.set(width, height);
    camera.apply(this.bounds, width / height);
    if (this.shadowsDirty) this.shadowMaps();
    this.renderer.setRenderTarget(target);
    this.renderer.render(this.root, camera.three);
    this.renderer.setRenderTarget(null);
  }
}

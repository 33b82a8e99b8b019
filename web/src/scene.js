// The scene package (proto SceneData, wire/src/scene_package.cpp) as the page's scene model:
// nodes with local transforms, the objects (reachable nodes with a mesh, in node order: the
// lightmap layout's order), meshes, materials, textures, the sky. Indices are checked here, once,
// so that the renderer can use them without checks; a bad package throws a one-line Error.
import * as THREE from 'three';
import { decodeSkyMap } from './codec.js';

const utf8 = new TextDecoder();
export const nameOf = (bytes) => (bytes && bytes.length ? utf8.decode(bytes) : '');

function fail(problem) {
  throw new Error(`scene package: ${problem}`);
}

const vec3 = (v) => new THREE.Vector3(v ? v.x || 0 : 0, v ? v.y || 0 : 0, v ? v.z || 0 : 0);
const int = (v, dflt) => (v === undefined || v === null ? dflt : v);

function matrixOf(values, what) {
  const m = new THREE.Matrix4();
  if (!values || values.length === 0) return m;
  if (values.length !== 16 || !values.every(Number.isFinite)) fail(`${what} has a bad transform`);
  return m.fromArray(values);  // column-major, as glm
}

function checkIndex(i, n, what) {
  if (!(Number.isInteger(i) && i >= 0 && i < n)) fail(`${what} (${i}) does not exist`);
}

function readNodes(d) {
  const nodes = (d.nodes || []).map((n, i) => ({
    name: nameOf(n.name),
    local: matrixOf(n.local, `node ${i}`),
    parent: int(n.parent, 0),
    children: n.children || [],
    mesh: int(n.mesh, 0),
    light: int(n.light, 0),
    camera: int(n.camera, 0),
    hidden: !!n.hidden,
    dynamic: !!n.dynamic,
  }));
  return nodes;
}

// World matrices, visibility and dynamic nodes, depth-first from the roots
// (Scene::world_matrices, visible_nodes and dynamic_nodes: a hidden node hides its subtree, a
// dynamic one makes it dynamic; cycles are cut).
export function placeNodes(scene) {
  const world = scene.nodes.map(() => new THREE.Matrix4());
  const visible = scene.nodes.map(() => false);
  const dynamic = scene.nodes.map(() => false);
  const reach = scene.nodes.map(() => false);
  const stack = scene.roots.map((r) => [r, new THREE.Matrix4(), true, false]);
  while (stack.length) {
    const [n, parent, vis, dyn] = stack.pop();
    if (reach[n]) continue;
    reach[n] = true;
    world[n] = parent.clone().multiply(scene.nodes[n].local);
    visible[n] = vis && !scene.nodes[n].hidden;
    dynamic[n] = dyn || scene.nodes[n].dynamic;
    for (const c of scene.nodes[n].children) stack.push([c, world[n], visible[n], dynamic[n]]);
  }
  return { world, visible, reach, dynamic };
}

function readMaterial(m, textures, i) {
  const tex = (t, what) => {
    const v = int(t, -1);
    if (v !== -1) checkIndex(v, textures, `material ${i}'s ${what} texture`);
    return v;
  };
  return {
    name: nameOf(m.name),
    baseColor: vec3(m.base_color),
    baseTexture: tex(m.base_color_texture, 'base colour'),
    baseUv: int(m.base_color_uv, 0) === 1 ? 1 : 0,
    emissive: vec3(m.emissive),
    emissiveTexture: tex(m.emissive_texture, 'emissive'),
    emissiveUv: int(m.emissive_uv, 0) === 1 ? 1 : 0,
    emissiveStrength: int(m.emissive_strength, 0),
    doubleSided: !!m.double_sided,
    mask: int(m.alpha_mode, 0) === 1,
    alphaCutoff: int(m.alpha_cutoff, 0.5),
    baseAlpha: int(m.base_alpha, 1),
  };
}

function readMesh(m, i) {
  const positions = m.positions || [], n = positions.length / 3;
  if (!Number.isInteger(n)) fail(`mesh ${i} has ${positions.length} position values`);
  const tris = m.triangles || [];
  if (tris.length % 3) fail(`mesh ${i} has ${tris.length} triangle indices`);
  for (const v of tris) if (v >= n) fail(`mesh ${i} refers to a vertex out of range`);
  const uv = (a, what) => {
    if (a && a.length && a.length !== 2 * n) fail(`mesh ${i} has ${a.length / 2} ${what} for ${n} vertices`);
    return a && a.length ? a : null;
  };
  const normals = m.normals && m.normals.length ? m.normals : null;
  if (normals && normals.length !== 3 * n) fail(`mesh ${i} has ${normals.length / 3} normals for ${n} vertices`);
  return { name: nameOf(m.name), positions, normals, uv0: uv(m.uv0, 'TEXCOORD_0'), uv1: uv(m.uv1, 'TEXCOORD_1'),
    triangles: tris, triangleMaterial: m.triangle_material || [] };
}

export function readSky(s) {
  if (!s) return { color: new THREE.Vector3(), strength: 1, map: null };
  return { color: vec3(s.color), strength: int(s.strength, 0), map: s.map ? decodeSkyMap(s.map) : null };
}

// SceneData (decoded protobuf object) -> the page's scene model.
export function readScene(d) {
  if (d.format !== 1) fail(`format ${d.format} (this page reads format 1)`);
  const scene = { name: nameOf(d.name), revision: Number(d.revision || 0), nodes: readNodes(d), roots: d.roots || [] };
  scene.meshes = (d.meshes || []).map(readMesh);
  scene.textures = (d.textures || []).map((t, i) => {
    const w = t.width >>> 0, h = t.height >>> 0;
    if (w > 32768 || h > 32768 || !t.rgba8 || t.rgba8.length !== w * h * 4) fail(`texture ${i} has the wrong size`);
    return { name: nameOf(t.name), width: w, height: h, rgba8: t.rgba8 };
  });
  scene.materials = (d.materials || []).map((m, i) => readMaterial(m, scene.textures.length, i));
  // type: 0 point, 1 spot, 2 directional (LightType).
  const finite = (x) => (Number.isFinite(x) ? x : 0);
  scene.lights = (d.lights || []).map((l) => ({ name: nameOf(l.name), type: int(l.type, 0),
    color: vec3(l.color), intensity: finite(l.intensity), range: finite(l.range),
    innerCone: finite(l.inner_cone_angle), outerCone: finite(l.outer_cone_angle) }));
  scene.cameras = (d.cameras || []).map((c) => ({ yfov: c.yfov || 0 }));
  const nn = scene.nodes.length;
  scene.nodes.forEach((n, i) => {
    if (n.parent !== -1) checkIndex(n.parent, nn, `node ${i}'s parent`);
    n.children.forEach((c) => checkIndex(c, nn, `node ${i}'s child`));
    if (n.mesh !== -1) checkIndex(n.mesh, scene.meshes.length, `node ${i}'s mesh`);
    if (n.camera !== -1) checkIndex(n.camera, scene.cameras.length, `node ${i}'s camera`);
  });
  scene.roots.forEach((r) => checkIndex(r, nn, 'root node'));
  const { reach, dynamic } = placeNodes(scene);
  scene.objects = [];
  scene.nodes.forEach((n, i) => { if (reach[i] && n.mesh >= 0) scene.objects.push({ node: i, mesh: n.mesh }); });
  const layouts = d.layouts || [];
  if (layouts.length !== scene.objects.length)
    fail(`the lightmap layout has ${layouts.length} objects but the scene has ${scene.objects.length}`);
  scene.objects.forEach((o, i) => {
    const l = layouts[i], tris = scene.meshes[o.mesh].triangles.length / 3;
    o.width = l.width >>> 0;
    o.height = l.height >>> 0;
    o.cornerUv = l.corner_uv || [];
    o.dynamic = dynamic[o.node];  // no lightmap (docs/DYNAMIC.md)
    if (o.dynamic && (o.width || o.height || o.cornerUv.length)) fail(`object ${i} is dynamic and has a lightmap layout`);
    if (!o.dynamic && o.cornerUv.length !== 6 * tris) fail(`object ${i} has lightmap coordinates for the wrong triangle count`);
  });
  scene.sky = readSky(d.sky);
  return scene;
}

// The camera a tool starts with (camera.cpp default_camera): the scene's first camera node, or
// one looking down -Z at the scene's bounds.
export function defaultCamera(scene, bounds) {
  const { world } = placeNodes(scene);
  const node = scene.nodes.findIndex((n) => n.camera >= 0);
  if (node >= 0) {
    const m = world[node].elements;
    const f = new THREE.Vector3(-m[8], -m[9], -m[10]), u = new THREE.Vector3(m[4], m[5], m[6]);
    return {
      eye: new THREE.Vector3(m[12], m[13], m[14]),
      forward: f.lengthSq() > 0 ? f.normalize() : new THREE.Vector3(0, 0, -1),
      up: u.lengthSq() > 0 ? u.normalize() : new THREE.Vector3(0, 1, 0),
      yfov: scene.cameras[scene.nodes[node].camera].yfov || THREE.MathUtils.degToRad(45),
    };
  }
  const c = bounds.getCenter(new THREE.Vector3()), r = 0.5 * bounds.getSize(new THREE.Vector3()).length();
  const yfov = THREE.MathUtils.degToRad(45);
  return { eye: c.clone().add(new THREE.Vector3(0, 0, r / Math.tan(0.5 * yfov) + r)),
    forward: new THREE.Vector3(0, 0, -1), up: new THREE.Vector3(0, 1, 0), yfov };
}

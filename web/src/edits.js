// Applied SceneEdit broadcasts on the page's scene model (common/src/scene_edit.cpp apply_edit):
// transforms and visibility of nodes, materials' albedo and emission, the sky, lights' colour and
// intensity (the page draws the directional lights' direct light on dynamic objects; on static
// surfaces their light comes through the lightmaps). An edit that does not resolve throws, and
// the page loads the scene again.
import * as THREE from 'three';
import { placeNodes, readSky } from './scene.js';

const KIND = { MOVE: 0, ROTATE: 1, SCALE: 2, SET_TRANSFORM: 3, SHOW: 4, HIDE: 5, LIGHT_COLOR: 6,
  LIGHT_INTENSITY: 7, MATERIAL_ALBEDO: 8, MATERIAL_EMISSION: 9, SKY: 10 };
export { KIND };

function find(items, target) {
  if (/^#\d{1,9}$/.test(target)) {
    const i = Number(target.slice(1));
    return i < items.length ? i : -1;
  }
  return items.findIndex((x) => x.name === target);
}

const vec = (v) => new THREE.Vector3(v ? v.x || 0 : 0, v ? v.y || 0 : 0, v ? v.z || 0 : 0);

function transformed(local, op) {
  const v = vec(op.vector);
  switch (op.kind) {
    case KIND.MOVE: return new THREE.Matrix4().makeTranslation(v.x, v.y, v.z).multiply(local);
    case KIND.ROTATE: {
      const o = new THREE.Vector3().setFromMatrixPosition(local);
      const r = new THREE.Matrix4().makeRotationAxis(v.normalize(), THREE.MathUtils.degToRad(op.value || 0));
      return new THREE.Matrix4().makeTranslation(o.x, o.y, o.z).multiply(r)
        .multiply(new THREE.Matrix4().makeTranslation(-o.x, -o.y, -o.z)).multiply(local);
    }
    case KIND.SCALE: return local.clone().multiply(new THREE.Matrix4().makeScale(v.x, v.y, v.z));
    default: {
      if (!op.matrix || op.matrix.length !== 16) throw new Error('a transform edit without 16 values');
      return new THREE.Matrix4().fromArray(op.matrix);
    }
  }
}

// Applies the ops in order; returns what changed: { nodes, materials, sky, lights }.
export function applyEdit(scene, message) {
  const changed = { nodes: false, materials: false, sky: false, lights: false };
  for (const op of message.ops || []) {
    const kind = op.kind || 0, target = op.target || '';
    if (kind <= KIND.HIDE) {
      const i = find(scene.nodes, target);
      if (i < 0) throw new Error(`edit: no node '${target}'`);
      if (kind === KIND.SHOW || kind === KIND.HIDE) scene.nodes[i].hidden = kind === KIND.HIDE;
      else scene.nodes[i].local = transformed(scene.nodes[i].local, op);
      changed.nodes = true;
    } else if (kind === KIND.MATERIAL_ALBEDO || kind === KIND.MATERIAL_EMISSION) {
      const i = find(scene.materials, target);
      if (i < 0) throw new Error(`edit: no material '${target}'`);
      const m = scene.materials[i];
      if (kind === KIND.MATERIAL_ALBEDO) m.baseColor = vec(op.vector);
      else { m.emissive = vec(op.vector); m.emissiveStrength = op.value || 0; }
      changed.materials = true;
    } else if (kind === KIND.SKY) {
      const parts = op.sky_parts || 0, sky = scene.sky;
      if (parts & 1) { sky.color = vec(op.vector); sky.map = null; }
      if (parts & 4) {
        if (!op.sky_map) throw new Error('edit: a sky file without its map');
        sky.map = readSky({ map: op.sky_map }).map;
      }
      if (parts & 2) sky.strength = op.value || 0;
      changed.sky = true;
    } else if (kind === KIND.LIGHT_COLOR || kind === KIND.LIGHT_INTENSITY) {
      const i = find(scene.lights, target);
      if (i < 0) throw new Error(`edit: no light '${target}'`);
      if (kind === KIND.LIGHT_COLOR) scene.lights[i].color = vec(op.vector);
      else scene.lights[i].intensity = op.value || 0;
      changed.lights = true;
    } else {
      throw new Error(`edit: unknown operation ${kind}`);
    }
  }
  return changed;
}

// Per node: whether a pose may move it (its subtree holds no static mesh or light), in one pass
// as pose_nodes (common/src/scene_edit.cpp): breadth-first from the parentless nodes, children
// folded into parents deepest first; a node no root reaches counts as static.
function poseNodes(scene) {
  const { dynamic } = placeNodes(scene);
  const n = scene.nodes.length;
  const holds = scene.nodes.map((node, i) => !dynamic[i] && (node.mesh >= 0 || node.light >= 0));
  const reached = new Array(n).fill(false);
  const order = [];
  scene.nodes.forEach((node, i) => { if (node.parent < 0) { reached[i] = true; order.push(i); } });
  for (let k = 0; k < order.length; ++k)
    for (const c of scene.nodes[order[k]].children)
      if (c >= 0 && c < n && !reached[c]) { reached[c] = true; order.push(c); }
  for (let k = order.length - 1; k >= 0; --k) {
    const i = order[k], p = scene.nodes[i].parent;
    if (holds[i] && p >= 0 && p < n) holds[p] = true;
  }
  return holds.map((h, i) => reached[i] && !h);
}

// A Poses message (docs/DYNAMIC.md#poses) on the page's scene model, checked as
// wire::pose_edit does: each node in range and dynamic, 16 finite numbers. `held` maps the nodes
// posed so far to the pose the package gave them; a complete set puts those it does not list
// back. Throws on a bad pose before anything changes.
export function applyPoses(scene, message, held) {
  const poses = message.poses || [];
  if (!scene.posable) scene.posable = poseNodes(scene);  // edits never change it
  const posable = scene.posable;
  const next = poses.map((p, i) => {
    const n = p.node || 0;
    if (n >= scene.nodes.length) throw new Error(`poses: pose ${i + 1} names node ${n} of a scene of ${scene.nodes.length} nodes`);
    if (!posable[n]) throw new Error(`poses: pose ${i + 1} moves node '${scene.nodes[n].name}', which is not dynamic`);
    if (!p.matrix || p.matrix.length !== 16 || !p.matrix.every(Number.isFinite))
      throw new Error(`poses: pose ${i + 1} is not 16 finite numbers`);
    return { n, local: new THREE.Matrix4().fromArray(p.matrix), hidden: !!p.hidden };
  });
  if (message.complete) {
    const listed = new Set(next.map((p) => p.n));
    held.forEach((pose, n) => { if (!listed.has(n)) next.push({ n, local: pose.local.clone(), hidden: pose.hidden }); });
  }
  for (const p of next) {
    const node = scene.nodes[p.n];
    if (!held.has(p.n)) held.set(p.n, { local: node.local.clone(), hidden: node.hidden });
    node.local = p.local;
    node.hidden = p.hidden;
  }
  return next.length > 0;
}

// Presence on the page (docs/DYNAMIC.md#presence), as client/src/avatars.cpp does it for
// irradcast-view: the scene gets a fixed number of avatar nodes when it loads (dynamic, hidden,
// one capsule mesh and material), and each Avatars message poses them; an avatar keeps its node
// while it stays listed. Hostile entries are not shown; a bad height throws.
import * as THREE from 'three';

// The capsule in units of the avatar's height (foot to eye), its eye at the node's origin
// (avatars.h kAvatarRadius, kAvatarTop, kAvatarAlbedo).
const RADIUS = 0.16, TOP = 0.08, ALBEDO = [0.62, 0.55, 0.45];

// A capsule along +Y (shapes.cpp capsule): rings bands pole to pole (even), segments around.
function capsule(radius, length, rings, segments, lift) {
  const positions = [], normals = [], uv0 = [], triangles = [];
  const half = rings / 2, profile = Math.PI * radius + length, cols = segments + 1, rows = rings + 2;
  for (let r = 0; r < rows; ++r) {
    const upper = r <= half, k = upper ? r : r - 1;
    const theta = (k / rings) * Math.PI;
    const y0 = (upper ? 0.5 : -0.5) * length + lift, v = (theta * radius + (upper ? 0 : length)) / profile;
    for (let c = 0; c < cols; ++c) {
      const u = c / segments, phi = u * 2 * Math.PI;
      const n = [Math.sin(theta) * Math.cos(phi), Math.cos(theta), -Math.sin(theta) * Math.sin(phi)];
      positions.push(radius * n[0], radius * n[1] + y0, radius * n[2]);
      normals.push(...n);
      uv0.push(u, v);
    }
  }
  const at = (r, c) => r * cols + c;
  for (let r = 0; r + 1 < rows; ++r)
    for (let c = 0; c < segments; ++c) {
      const a = at(r, c), b = at(r + 1, c), d = at(r, c + 1), e = at(r + 1, c + 1);
      if (r > 0) triangles.push(a, b, d);
      if (r + 2 < rows) triangles.push(d, b, e);
    }
  return { positions, normals, uv0, triangles };
}

// Appends `count` avatar nodes to the page's scene model (scene.js readScene) and their objects
// (no lightmap). Returns the first node's index.
export function addAvatarNodes(scene, count) {
  scene.materials.push({ name: 'irradcast avatar', baseColor: new THREE.Vector3(...ALBEDO), baseTexture: -1, baseUv: 0,
    emissive: new THREE.Vector3(), emissiveTexture: -1, emissiveUv: 0, emissiveStrength: 0, doubleSided: false,
    mask: false, alphaCutoff: 0.5, baseAlpha: 1 });
  const length = 1 + TOP - 2 * RADIUS, g = capsule(RADIUS, length, 12, 24, 0.5 * (TOP - 1));
  scene.meshes.push({ name: 'irradcast avatar', positions: g.positions, normals: g.normals, uv0: g.uv0, uv1: null,
    triangles: g.triangles, triangleMaterial: new Array(g.triangles.length / 3).fill(scene.materials.length - 1) });
  const mesh = scene.meshes.length - 1, first = scene.nodes.length;
  for (let i = 0; i < count; ++i) {
    const node = first + i;
    scene.nodes.push({ name: `irradcast avatar ${i}`, local: new THREE.Matrix4(), parent: -1, children: [], mesh,
      light: -1, camera: -1, hidden: true, dynamic: true });
    scene.roots.push(node);
    scene.objects.push({ node, mesh, width: 0, height: 0, cornerUv: [], dynamic: true, avatar: true });
  }
  scene.posable = null;  // applyPoses computes it again
  return first;
}

export class AvatarNodes {
  constructor(first, count) {
    this.first = first;
    this.ids = new Array(count).fill(0n);
  }

  shown() { return this.ids.filter((id) => id !== 0n).length; }

  // Poses the nodes for an Avatars message within `bounds` (THREE.Box3, grown by its largest
  // extent); true when a node changed.
  place(scene, m, bounds) {
    const height = m.height;
    if (!(Number.isFinite(height) && height > 0 && height <= 100)) throw new Error(`avatars: a height of ${height} m (need (0, 100])`);
    const size = bounds.getSize(new THREE.Vector3()), grow = Math.max(size.x, size.y, size.z);
    const lo = bounds.min.clone().subScalar(grow), hi = bounds.max.clone().addScalar(grow);
    const wanted = [], seen = new Set();
    for (const a of m.avatars || []) {
      if (wanted.length === this.ids.length) break;
      const id = BigInt(a.id || 0), e = a.eye || {};
      const eye = new THREE.Vector3(e.x || 0, e.y || 0, e.z || 0), heading = a.heading || 0;
      const inside = [eye.x, eye.y, eye.z].every(Number.isFinite) && eye.x >= lo.x && eye.y >= lo.y && eye.z >= lo.z &&
        eye.x <= hi.x && eye.y <= hi.y && eye.z <= hi.z;
      if (id === 0n || !inside || !Number.isFinite(heading) || seen.has(id)) continue;
      seen.add(id);
      wanted.push({ id, eye, heading });
    }
    const next = new Array(this.ids.length).fill(0n), at = new Array(this.ids.length).fill(null), fresh = [];
    for (const a of wanted) {
      const i = this.ids.indexOf(a.id);
      if (i < 0) fresh.push(a);
      else { next[i] = a.id; at[i] = a; }
    }
    let free = 0;
    for (const a of fresh) {
      while (next[free] !== 0n) ++free;
      next[free] = a.id;
      at[free] = a;
    }
    let changed = false;
    at.forEach((a, i) => {
      const node = scene.nodes[this.first + i];
      if (a) {
        node.local = new THREE.Matrix4().makeTranslation(a.eye.x, a.eye.y, a.eye.z)
          .multiply(new THREE.Matrix4().makeRotationY(a.heading)).multiply(new THREE.Matrix4().makeScale(height, height, height));
        changed = true;
      }
      if (!!a === node.hidden) { node.hidden = !a; changed = true; }
    });
    this.ids = next;
    return changed;
  }
}

// The viewer's camera: a pose (eye, forward, up, vertical field of view) as the tools have it
// (common/world.h CameraPose), the `camera=eye=x,y,z:target=x,y,z:fov=deg:up=x,y,z` syntax of
// --camera (common/src/camera.cpp parse_camera), the CameraUpdate message
// (client/src/camera_message.cpp), and mouse/keyboard controls: orbit (drag: rotate about the
// target, right drag or shift drag: pan, wheel: dolly) and fly (WASD/QE: move, drag: look).
import * as THREE from 'three';

function parseVec3(field, value) {
  const parts = value.split(',');
  const v = parts.map((p) => (/^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$/.test(p) ? Number(p) : NaN));
  if (v.length !== 3 || !v.every(Number.isFinite)) throw new Error(`camera spec: '${field}=${value}' needs x,y,z`);
  return new THREE.Vector3(v[0], v[1], v[2]);
}

// parse_camera: keys eye, target, fov (degrees), up; a pose from `base`.
export function parseCamera(spec, base) {
  const pose = { eye: base.eye.clone(), forward: base.forward.clone(), up: base.up.clone(), yfov: base.yfov };
  let target = base.eye.clone().add(base.forward), hasTarget = false;
  for (const item of spec.split(':')) {
    if (!item) continue;
    const eq = item.indexOf('=');
    if (eq < 0) throw new Error(`camera spec: '${item}' is not key=value (expected eye=, target=, fov=, up=)`);
    const key = item.slice(0, eq), value = item.slice(eq + 1);
    if (key === 'eye') pose.eye = parseVec3(key, value);
    else if (key === 'target') { target = parseVec3(key, value); hasTarget = true; }
    else if (key === 'up') pose.up = parseVec3(key, value);
    else if (key === 'fov') {
      const deg = Number(value);
      if (!(value.trim() !== '' && deg > 0 && deg < 180)) throw new Error(`camera spec: fov ${value} must be between 0 and 180 degrees`);
      pose.yfov = THREE.MathUtils.degToRad(deg);
    } else throw new Error(`camera spec: unknown key '${key}' (expected eye, target, fov, up)`);
  }
  if (hasTarget || !pose.eye.equals(base.eye)) {
    const f = target.clone().sub(pose.eye);
    if (!(f.length() > 0)) throw new Error('camera spec: eye and target are the same point');
    pose.forward = f.normalize();
  }
  if (!(new THREE.Vector3().crossVectors(pose.forward, pose.up).length() > 1e-6))
    throw new Error('camera spec: the up vector is parallel to the view direction');
  pose.up.normalize();
  return pose;
}

export function formatCamera(pose, distance) {
  const f = (v) => [v.x, v.y, v.z].map((x) => +x.toFixed(4)).join(',');
  const target = pose.eye.clone().addScaledVector(pose.forward, distance);
  return `eye=${f(pose.eye)}:target=${f(target)}:fov=${+THREE.MathUtils.radToDeg(pose.yfov).toFixed(3)}`;
}

export class ViewCamera {
  constructor(pose, bounds) {
    this.pose = pose;
    this.three = new THREE.PerspectiveCamera();
    const size = bounds.getSize(new THREE.Vector3()).length();
    this.radius = Math.max(size, 1e-3);
    // Orbit about the point of the bounds' centre's depth along the view direction.
    const c = bounds.getCenter(new THREE.Vector3());
    this.distance = Math.max(c.clone().sub(pose.eye).dot(pose.forward), 0.05 * this.radius);
    this.mode = 'orbit';
    this.changed = true;
  }

  target() {
    return this.pose.eye.clone().addScaledVector(this.pose.forward, this.distance);
  }

  apply(bounds, aspect) {
    const cam = this.three, p = this.pose;
    const far = bounds.distanceToPoint(p.eye) + 2 * this.radius;
    cam.near = Math.max(1e-4 * this.radius, Math.min(0.01 * this.radius, 0.5 * Math.max(bounds.distanceToPoint(p.eye), 1e-6)));
    cam.far = far;
    cam.fov = THREE.MathUtils.radToDeg(p.yfov);
    cam.aspect = aspect;
    cam.position.copy(p.eye);
    cam.up.copy(p.up);
    cam.lookAt(p.eye.clone().add(p.forward));
    cam.updateProjectionMatrix();
    cam.updateMatrixWorld();
  }

  // Rotates the view direction by yaw about `up` and pitch about the right axis; orbit keeps the
  // target, fly keeps the eye.
  turn(yaw, pitch) {
    const p = this.pose, target = this.target();
    const right = new THREE.Vector3().crossVectors(p.forward, p.up).normalize();
    const f = p.forward.clone().applyAxisAngle(p.up, yaw);
    const f2 = f.clone().applyAxisAngle(right, pitch);
    if (Math.abs(f2.dot(p.up)) < 0.995) f.copy(f2);
    p.forward.copy(f.normalize());
    if (this.mode === 'orbit') p.eye.copy(target).addScaledVector(p.forward, -this.distance);
    this.changed = true;
  }

  pan(dx, dy) {
    const p = this.pose, right = new THREE.Vector3().crossVectors(p.forward, p.up).normalize();
    const up = new THREE.Vector3().crossVectors(right, p.forward);
    const s = this.distance * Math.tan(0.5 * p.yfov) * 2;
    p.eye.addScaledVector(right, -dx * s).addScaledVector(up, dy * s);
    this.changed = true;
  }

  dolly(factor) {
    const target = this.target();
    this.distance = Math.max(this.distance * factor, 1e-3 * this.radius);
    this.pose.eye.copy(target).addScaledVector(this.pose.forward, -this.distance);
    this.changed = true;
  }

  move(local) {  // fly: x right, y up, z forward, in scene units
    const p = this.pose, right = new THREE.Vector3().crossVectors(p.forward, p.up).normalize();
    p.eye.addScaledVector(right, local.x).addScaledVector(p.up, local.y).addScaledVector(p.forward, local.z);
    this.changed = true;
  }

  // CameraUpdate (camera_update()).
  message() {
    const v = (x) => ({ x: x.x, y: x.y, z: x.z });
    return { camera_update: { eye: v(this.pose.eye), forward: v(this.pose.forward), up: v(this.pose.up), yfov: this.pose.yfov } };
  }
}

// Mouse and keyboard on the canvas.
export function attachControls(canvas, getCamera) {
  let drag = null;
  const keys = new Set();
  canvas.tabIndex = 0;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('pointerdown', (e) => {
    canvas.focus();
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', (e) => {
    const cam = getCamera();
    if (!drag || !cam) return;
    const dx = (e.clientX - drag.x) / canvas.clientHeight, dy = (e.clientY - drag.y) / canvas.clientHeight;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (drag.pan) cam.pan(dx, dy);
    else cam.turn(-dx * Math.PI, -dy * Math.PI);
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const cam = getCamera();
    if (cam) cam.dolly(Math.exp(0.001 * e.deltaY));
  }, { passive: false });
  canvas.addEventListener('keydown', (e) => {
    keys.add(e.key.toLowerCase());
    const cam = getCamera();
    if (cam && e.key.toLowerCase() === 'f') cam.mode = cam.mode === 'fly' ? 'orbit' : 'fly';
  });
  canvas.addEventListener('keyup', (e) => keys.delete(e.key.toLowerCase()));
  canvas.addEventListener('blur', () => keys.clear());
  // Called once per frame with the seconds since the last one.
  return (dt) => {
    const cam = getCamera();
    if (!cam || !keys.size) return;
    const s = 0.25 * cam.radius * dt * (keys.has('shift') ? 4 : 1), v = new THREE.Vector3();
    if (keys.has('w')) v.z += s;
    if (keys.has('s')) v.z -= s;
    if (keys.has('d')) v.x += s;
    if (keys.has('a')) v.x -= s;
    if (keys.has('e')) v.y += s;
    if (keys.has('q')) v.y -= s;
    if (v.lengthSq() > 0) cam.move(v);
    const a = 1.5 * dt;
    if (keys.has('arrowleft')) cam.turn(a, 0);
    if (keys.has('arrowright')) cam.turn(-a, 0);
    if (keys.has('arrowup')) cam.turn(0, a);
    if (keys.has('arrowdown')) cam.turn(0, -a);
  };
}

// irradcast's browser viewer (docs/VIEWER-WEB.md): connects to /ws next to the page, downloads
// the scene, streams the lightmaps into textures and draws the view with irradcast's shading.
// URL parameters: camera=eye=x,y,z:target=x,y,z:fov=deg (the tools' --camera), width, height,
// exposure (auto, the default, or stops), tonemap (reinhard|aces|clamp), encoding (rgb9e5|half|delta), converge (the
// server's convergence target, as irradcast-view --converge-at), ui=0 (no overlay), presence=1 (show
// this viewer to the others as an avatar and draw theirs, as irradcast-view --presence). When every
// tile the server holds is applied and drawn, document.title becomes "irradcast: converged".
import * as THREE from 'three';
import { Connection } from './connection.js';
import { SceneView, TONE_OPS } from './render.js';
import { ViewCamera, attachControls, parseCamera, formatCamera } from './camera.js';
import { defaultCamera } from './scene.js';
import { applyEdit, applyPoses, KIND } from './edits.js';
import { addAvatarNodes, AvatarNodes } from './avatars.js';
import { Overlay } from './overlay.js';
import { num } from './proto.js';

const ENCODINGS = { rgb9e5: 0, half: 1, delta: 2 };

function readParams() {
  const q = new URLSearchParams(window.location.search);
  const size = (k) => {
    const v = q.get(k);
    if (v === null) return 0;
    const n = Number(v);
    if (!(Number.isInteger(n) && n >= 1 && n <= 16384)) throw new Error(`${k}=${v}: a size in pixels, 1 to 16384`);
    return n;
  };
  const p = { camera: q.get('camera'), width: size('width'), height: size('height'),
    exposure: q.get('exposure') || 'auto', tonemap: q.get('tonemap') || 'reinhard',
    encoding: q.get('encoding') || 'rgb9e5', converge: Number(q.get('converge') ?? 0.02), ui: q.get('ui') !== '0',
    presence: q.get('presence') === '1' };
  if (p.exposure !== 'auto' && !(p.exposure.trim() !== '' && Number.isFinite(Number(p.exposure))))
    throw new Error(`exposure=${p.exposure}: auto or a number of stops`);
  if (!(p.tonemap in TONE_OPS)) throw new Error(`tonemap=${p.tonemap}: reinhard, aces or clamp`);
  if (!(p.encoding in ENCODINGS)) throw new Error(`encoding=${p.encoding}: rgb9e5, half or delta`);
  if (!(p.converge >= 0)) throw new Error(`converge=${q.get('converge')}: a number >= 0`);
  return p;
}

// Reinhard's key (tonemap.cpp exposure_scale): 0.18 / the log-average luminance of the pixels
// that have light, measured on an HDR render of the view at most 256 pixels wide.
const autoTarget = { rt: null };
function autoExposure(renderer, view, camera, w, h, finish) {
  const s = Math.min(1, 256 / w), rw = Math.max(1, Math.round(w * s)), rh = Math.max(1, Math.round(h * s));
  if (!autoTarget.rt || autoTarget.rt.width !== rw || autoTarget.rt.height !== rh) {
    if (autoTarget.rt) autoTarget.rt.dispose();
    autoTarget.rt = new THREE.WebGLRenderTarget(rw, rh, { type: THREE.FloatType, depthBuffer: true });
    autoTarget.px = new Float32Array(4 * rw * rh);
  }
  finish.hdrOut.value = 1;
  view.render(camera, rw, rh, autoTarget.rt);
  finish.hdrOut.value = 0;
  renderer.readRenderTargetPixels(autoTarget.rt, 0, 0, rw, rh, autoTarget.px);
  let sum = 0, n = 0;
  for (let i = 0; i < rw * rh; ++i) {
    const p = autoTarget.px, l = 0.2126 * p[4 * i] + 0.7152 * p[4 * i + 1] + 0.0722 * p[4 * i + 2];
    if (!(l > 0) || !Number.isFinite(l)) continue;
    sum += Math.log(1e-4 + l);
    ++n;
  }
  return n === 0 ? 1 : 0.18 / Math.exp(sum / n);
}

// Something new to draw: the title says so at once (a test that waits for "converged" after an
// edit must not see the title of the frame before it).
function unconverge(state) {
  state.dirty = true;
  if (state.converged) {
    state.converged = false;
    document.title = 'irradcast';
  }
}

// The connection's handlers: the scene into a SceneView, tiles into its textures, edits into its
// model.
function handlers(ctx) {
  const { state, overlay, params } = ctx;
  return {
    sceneReady(model, welcome) {
      if (state.view) state.view.dispose();
      state.avatars = params.presence ? new AvatarNodes(addAvatarNodes(model, 32), 32) : null;
      state.view = new SceneView(ctx.renderer, model, welcome, ctx.finish);
      state.posed = new Map();  // nodes posed so far, with their package pose
      if (ctx.conn.volume) state.view.setVolume(ctx.conn.volume);
      const base = state.camera ? state.camera.pose : defaultCamera(model, state.view.bounds);
      let pose = base;
      if (!state.camera && params.camera) {
        try { pose = parseCamera(params.camera, base); } catch (e) { overlay.error(e.message); }
      }
      state.camera = new ViewCamera(pose, state.view.bounds);
      overlay.setNodes(model.nodes.map((n, i) => ({ target: n.name || `#${i}`, label: n.name || `#${i}` }))
        .filter((_, i) => model.nodes[i].mesh >= 0 || model.nodes[i].light >= 0));
      state.dirty = true;
    },
    // A new connection: the server learns the camera again, a stats request of the last one has
    // no reply coming, and the last one's stats say nothing of this one (convergence waits for
    // this one's).
    subscribed() {
      if (state.camera) state.camera.changed = true;
      state.statsAsked = 0;
      state.stats = null;
    },
    tile(lightmap, x0, y0, w, h, words) {
      state.view.applyTile(lightmap, x0, y0, w, h, words);
      unconverge(state);
    },
    tileBase: (lightmap, x0, y0, w, h) => state.view.tileWords(lightmap, x0, y0, w, h),
    volume(v) {
      if (!state.view.setVolume(v)) overlay.error('the probe volume exceeds this GPU\'s 3-D texture size: dynamic objects stay unlit');
      unconverge(state);
    },
    edit(m) {
      try {
        const c = applyEdit(state.view.scene, m);
        if (c.nodes || c.lights) state.view.placeNodes();
        if (c.materials) state.view.updateMaterials();
        if (c.sky) state.view.updateSky();
        unconverge(state);
      } catch (e) {
        ctx.conn.reload(e.message);
      }
    },
    poses(m) {
      try {
        if (applyPoses(state.view.scene, m, state.posed)) state.view.placeNodes(false);
        unconverge(state);
      } catch (e) {
        ctx.conn.fail(e.message);
      }
    },
    avatars(m) {
      if (!state.avatars || !state.view) return;
      try {
        if (state.avatars.place(state.view.scene, m, state.view.bounds)) state.view.placeNodes(false);
        unconverge(state);
      } catch (e) {
        ctx.conn.fail(e.message);
      }
    },
    stats(s) { state.stats = s; state.statsAsked = 0; },
    status(text) { state.status = text; },
    error(text) { overlay.error(text); console.warn(`irradcast: ${text}`); },
  };
}

// Headless Chromium's --virtual-time-budget lets virtual time (timers, frames) run ahead while no
// network fetch is pending, and WebSocket traffic does not count: a --screenshot would be taken
// before the scene arrived. A headless browser therefore keeps one small fetch of the page in
// flight until the view has converged: one after another, 10 ms apart (so 3000 of them span a
// --virtual-time-budget of 30000 and a scripted page without virtual time asks 100 a second),
// 20000 at most.
function holdVirtualTime(state) {
  if (!/HeadlessChrome/.test(navigator.userAgent)) return;
  (async () => {
    for (let i = 0; i < 20000 && !state.converged; ++i) {
      try { await fetch(`index.html?hold=${i}`, { cache: 'no-store' }); } catch (_) { break; }
      await new Promise((r) => setTimeout(r, 10));
    }
  })();
}

// One frame: keys, size, the camera to the server, drawing when something changed, convergence
// and the overlay.
function frame(ctx, now) {
  const { state, conn, renderer, params } = ctx;
  ctx.keys(Math.min(0.1, (now - ctx.last) / 1000));
  ctx.last = now;
  const w = params.width || window.innerWidth, h = params.height || window.innerHeight;
  if (renderer.domElement.width !== w || renderer.domElement.height !== h) {
    renderer.setSize(w, h, true);
    state.dirty = true;
  }
  const cam = state.camera;
  if (cam && cam.changed && now - ctx.cameraSent > 100 && conn.phase === 'streaming') {
    if (conn.send(cam.message())) cam.changed = false;
    ctx.cameraSent = now;
    state.dirty = true;
  }
  // Draws when something changed, leaving at least as much time between draws as the last one
  // took (a software renderer on a large scene keeps the page responsive while tiles stream).
  let drew = false;
  if (state.view && state.dirty && now - ctx.drawnAt >= ctx.drawMs) {
    const t0 = performance.now();
    if (ctx.exposure === 'auto') ctx.finish.exposureScale.value = autoExposure(renderer, state.view, cam, w, h, ctx.finish);
    state.view.render(cam, w, h);
    state.dirty = false;
    drew = true;
    ctx.drawnAt = performance.now();
    ctx.drawMs = ctx.drawnAt - t0;
  }
  // Converged: every tile held and drawn, nothing queued for us, and the server's lightmaps final
  // (engine idle) or at the convergence target; as irradcast-view --until-converged. Stats asked
  // for after the last draw count.
  const { held, total } = conn.tilesHeld(), s = state.stats;
  if (drew) state.stats = null;
  // A scene with dynamic objects also waits for the probe volume that lights them.
  const lit = !state.view || !state.view.scene.objects.some((o) => o.dynamic) || !!conn.volume;
  const converged = !drew && !state.dirty && lit && !!(state.view && total > 0 && held === total && s && num(s.queue_depth) === 0 &&
    (s.engine_idle || s.convergence <= params.converge));
  if (converged !== state.converged) {
    state.converged = converged;
    document.title = converged ? 'irradcast: converged' : 'irradcast';
  }
  ctx.overlay.update({ status: state.status, converged, held, total, bytes: conn.counters.bytes,
    tilesApplied: conn.counters.tiles, edits: conn.counters.edits, stats: s && { ...s, updates: num(s.updates) } });
}

function main() {
  let params;
  try {
    params = readParams();
  } catch (e) {
    document.body.textContent = `irradcast: ${e.message}`;
    return;
  }
  const ctx = { params, exposure: params.exposure, last: performance.now(), cameraSent: 0, drawnAt: 0, drawMs: 0 };
  ctx.finish = { exposureScale: { value: ctx.exposure === 'auto' ? 1 : 2 ** Number(ctx.exposure) },
    toneOp: { value: TONE_OPS[params.tonemap] }, hdrOut: { value: 0 } };
  const renderer = ctx.renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.outputColorSpace = THREE.LinearSRGBColorSpace;  // the shaders encode sRGB themselves
  document.body.appendChild(renderer.domElement);
  const state = ctx.state = { status: 'connecting', converged: false, stats: null, dirty: true, view: null, camera: null,
    statsAsked: 0 };  // statsAsked: when the pending stats request went out (0: none)
  ctx.overlay = new Overlay(params, (change) => {
    if ('exposure' in change) {
      ctx.exposure = change.exposure;
      if (ctx.exposure !== 'auto') ctx.finish.exposureScale.value = 2 ** Number(ctx.exposure);
    }
    if ('tonemap' in change) ctx.finish.toneOp.value = TONE_OPS[change.tonemap];
    state.dirty = true;
  }, (token, target, vector) => {
    ctx.conn.send({ scene_edit: { token, request_id: Date.now(), ops: [{ kind: KIND.MOVE, target, vector }] } });
  });
  // /ws next to the page, so that a reverse proxy may serve it under any path.
  const wsUrl = new URL('ws', window.location.href);
  wsUrl.protocol = wsUrl.protocol === 'https:' ? 'wss:' : 'ws:';
  wsUrl.search = '';
  const conn = ctx.conn = new Connection(wsUrl.href, { encoding: ENCODINGS[params.encoding], presence: params.presence },
    handlers(ctx));
  window.irradcast = { conn, state, formatCamera: () => state.camera && formatCamera(state.camera.pose, state.camera.distance) };
  holdVirtualTime(state);
  // Stats twice a second, for the overlay and convergence: one request at a time, asked again
  // when its reply is 5 s late (the connection it went out on may be gone, and the reply with it).
  setInterval(() => {
    const now = performance.now();
    if (conn.phase === 'streaming' && (!state.statsAsked || now - state.statsAsked > 5000) &&
        conn.send({ stats_request: {} }))
      state.statsAsked = now;
  }, 500);
  ctx.keys = attachControls(renderer.domElement, () => state.camera);
  // Frames by requestAnimationFrame; a hidden tab gets none, so it draws by a timer instead (4 a
  // second at most): its view stays current and it still reports convergence.
  let scheduled = 0;
  const schedule = () => {
    const id = ++scheduled;
    const run = (now) => {
      if (id !== scheduled) return;
      frame(ctx, now ?? performance.now());
      schedule();
    };
    if (document.hidden) setTimeout(run, 250);
    else requestAnimationFrame(run);
  };
  document.addEventListener('visibilitychange', schedule);
  schedule();
}

main();

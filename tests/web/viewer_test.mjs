// The browser viewer in a real browser (issue 21, part 4): `node tests/web/viewer_test.mjs CASE
// --server irradcast-server --view irradcast-view --edit irradcast-edit [--chromium PATH]`.
// Each case starts its own irradcast-server (cornell at a low texel count) on loopback ports and
// headless Chromium (puppeteer-core, SwiftShader WebGL):
//   image   the page's converged screenshot against irradcast-view's PNG of the same camera, tone
//           map and exposure, by 16 x 16 block means (bound below: rasterised and ray-traced
//           primary hits differ only at edges); also a plain `chromium --headless=new
//           --screenshot --virtual-time-budget=30000 URL`
//   errors  malformed and oversized WebSocket messages sent from a page get the Error a TCP
//           client gets for the same bytes
//   edits   another client's edit (irradcast-edit) shows up in the page, the page's own edit
//           needs the control token typed into the overlay; mouse and keyboard move the camera
//   tabs    16 tabs at once all converge
//   restart the server restarts under an open page, which reconnects and converges again
import assert from 'node:assert/strict';
import net from 'node:net';
import { writeFileSync } from 'node:fs';
import { spawn } from 'node:child_process';
import { readPng, blockDifference, meanLevel } from './png.mjs';
import { options, startServer, viewPng, browser, openConverged, query, run, Envelope, ErrorCode, tmpDir, path,
  chromiumArgs, pageState } from './harness.mjs';

// Bounds on the differences of 16 x 16 block means, 8-bit units. Rasterised and ray-traced primary
// hits differ at edges: a silhouette that runs along a row of pixel centres is in one image and
// not the other, which moves a block's mean by up to 255 / 16 (one row of 16); elsewhere the two
// agree to rounding. So: every block within 16, 90% of the blocks within 2 in every channel, the
// mean over all blocks within 1.
const MAX_BLOCK = 16, TIGHT_FRACTION = 0.9, MEAN_BLOCK = 1;
const SERVER = ['--scene', 'cornell', '--texels-per-scene', '48', '--tile-size', '16', '--max-updates', '6',
  '--threads', '1', '--io-threads', '2', '--log-level', 'warn'];
const W = 192, H = 150;

function compare(pagePng, viewPngFile, what) {
  const a = readPng(pagePng), b = readPng(viewPngFile);
  const d = blockDifference(a, b);
  console.log(`${what}: ${d.blocks} blocks, largest block difference ${d.max.toFixed(2)}, ` +
    `${(100 * d.within).toFixed(1)}% within 2, mean ${d.mean.toFixed(3)} (bounds ${MAX_BLOCK}, ` +
    `${100 * TIGHT_FRACTION}%, ${MEAN_BLOCK}); mean level ${meanLevel(a).toFixed(1)} / ${meanLevel(b).toFixed(1)}`);
  assert.ok(meanLevel(b) > 10, `${what}: irradcast-view's image is black`);
  assert.ok(d.max <= MAX_BLOCK && d.within >= TIGHT_FRACTION && d.mean <= MEAN_BLOCK,
    `${what}: the page's image differs from irradcast-view's`);
}

async function image(o) {
  const server = await startServer(o.server, SERVER);
  const b = await browser(o);
  try {
    // The page's default tiles are RGB9E5; `half` asks for half floats (irradcast-view keeps
    // RGB9E5: the two quantisations differ far below the bounds).
    const views = [
      { name: 'default', params: {} },
      { name: 'camera', params: { camera: 'eye=0.45,0.4,-0.3:target=0.25,0.2,0.3:fov=55', tonemap: 'aces', exposure: 1 } },
      { name: 'half', params: { encoding: 'half' }, view: 'default' },
    ];
    for (const v of views) {
      const page = await openConverged(b, server.url + query({ width: W, height: H, ui: 0, converge: 0, ...v.params }), W, H);
      const shot = path.join(tmpDir, `page-${v.name}.png`);
      await page.screenshot({ path: shot });
      const enc = await page.evaluate(() => window.irradcast.conn.counters.byEncoding);
      console.log(`page (${v.name}): tiles by encoding rgb9e5 / half / delta: ${enc.join(' / ')}`);
      assert.ok(v.params.encoding === 'half' ? enc[1] > 0 && enc[0] + enc[2] === 0 : enc[0] > 0 && enc[1] === 0,
        `page (${v.name}): tiles in the wrong encoding`);
      await page.close();
      const reference = v.view ? path.join(tmpDir, `view-${v.view}.png`)
        : await viewPng(o, server, { width: W, height: H, ...v.params }, `view-${v.name}`);
      compare(shot, reference, `page (${v.name})`);
    }
    // A plain headless screenshot: the page converges within the virtual time budget. On a
    // loaded machine (the sanitizer build, other tests beside it) Chromium has taken its
    // screenshot before the first frame (a black image; seen once, in a full ASan run): up to three
    // tries, each in a fresh profile, and the last one's mismatch fails the test.
    for (let attempt = 1; ; ++attempt) {
      const plain = path.join(tmpDir, `plain-${attempt}.png`);
      await run(o.chromium, ['--headless=new', ...chromiumArgs, `--user-data-dir=${path.join(tmpDir, `plain-profile-${attempt}`)}`,
        `--screenshot=${plain}`, `--window-size=${W},${H}`, '--virtual-time-budget=30000',
        server.url + query({ ui: 0, converge: 0 })], 90000);
      try {
        compare(plain, path.join(tmpDir, 'view-default.png'), `chromium --screenshot (try ${attempt})`);
        break;
      } catch (e) {
        if (attempt === 3) throw e;
      }
    }
  } finally {
    await b.close();
    await server.stop();
  }
}

// One message as a TCP frame (4-byte little-endian length) on a new connection: the Error the
// server answers.
function tcpError(port, bytes) {
  return new Promise((resolve, reject) => {
    const s = net.connect(port, '127.0.0.1');
    let buf = Buffer.alloc(0);
    const t = setTimeout(() => { s.destroy(); reject(new Error('no answer over TCP')); }, 20000);
    s.on('connect', () => { const len = Buffer.alloc(4); len.writeUInt32LE(bytes.length); s.write(Buffer.concat([len, bytes])); });
    s.on('data', (d) => {
      buf = Buffer.concat([buf, d]);
      while (buf.length >= 4 && buf.length >= 4 + buf.readUInt32LE(0)) {
        const env = Envelope.decode(buf.subarray(4, 4 + buf.readUInt32LE(0)));
        buf = buf.subarray(4 + buf.readUInt32LE(0));
        if (env.msg === 'error') { clearTimeout(t); s.destroy(); resolve(env.error); return; }
      }
    });
    s.on('error', () => {});
    s.on('close', () => { clearTimeout(t); reject(new Error('TCP connection closed without an Error')); });
  });
}

// The same bytes as one binary WebSocket message from the page: the Error the server answers,
// and whether it closed the socket afterwards.
async function wsError(page, bytes) {
  const r = await page.evaluate((data) => new Promise((resolve) => {
    const ws = new WebSocket(new URL('ws', location.href).href.replace(/^http/, 'ws'));
    ws.binaryType = 'arraybuffer';
    const got = [];
    ws.onopen = () => ws.send(new Uint8Array(data));
    ws.onmessage = (e) => got.push(Array.from(new Uint8Array(e.data)));
    ws.onclose = (e) => resolve({ got, code: e.code });
    setTimeout(() => resolve({ got, code: 'open' }), 20000);
  }), Array.from(bytes));
  const errors = r.got.map((m) => Envelope.decode(Uint8Array.from(m))).filter((e) => e.msg === 'error');
  assert.ok(errors.length === 1, `the page got ${errors.length} Errors (${r.got.length} messages, close ${r.code})`);
  assert.notEqual(r.code, 'open', 'the server kept the WebSocket open');
  return errors[0].error;
}

async function errors(o) {
  const server = await startServer(o.server, SERVER);
  const b = await browser(o);
  try {
    const page = await openConverged(b, server.url + query({ width: 64, height: 48, ui: 0 }), 64, 48);
    // The same code for the same bytes; the same message where the message describes the bytes
    // (an oversized one names the transport's unit: a frame on TCP, a message on a WebSocket).
    const cases = [
      { what: 'not an Envelope', bytes: Buffer.from([0xff, 0xff, 0xff, 0xff]), code: ErrorCode.BAD_FRAME, same: true },
      { what: 'an oversized first message', bytes: Buffer.concat([Buffer.from([0x0a, 0xe8, 0x80, 0x02]), Buffer.alloc(0x8000 + 0x68)]),
        code: ErrorCode.FRAME_TOO_LARGE, same: false },
    ];
    for (const c of cases) {
      const ws = await wsError(page, c.bytes), tcp = await tcpError(server.port, c.bytes);
      console.log(`${c.what}: WebSocket ${ws.code} "${ws.message}"; TCP ${tcp.code} "${tcp.message}"`);
      assert.equal(ws.code, c.code, `${c.what}: the WebSocket's Error code`);
      assert.equal(tcp.code, c.code, `${c.what}: the TCP Error code`);
      if (c.same) assert.equal(ws.message, tcp.message, `${c.what}: the same Error message over WebSocket and TCP`);
    }
    // The page itself still streams.
    assert.equal(await page.title(), 'irradcast: converged');
  } finally {
    await b.close();
    await server.stop();
  }
}

const tilesApplied = (page) => page.evaluate(() => window.irradcast.conn.counters.tiles);
const editsApplied = (page) => page.evaluate(() => window.irradcast.conn.counters.edits);

async function edits(o) {
  const server = await startServer(o.server, [...SERVER, '--control-token', 'web-test-token-0123']);
  const b = await browser(o);
  try {
    const url = server.url + query({ width: W, height: H, converge: 0 });
    const page = await openConverged(b, url, W, H);
    // Another client moves the tall block: the page applies the broadcast, converges again and
    // shows what irradcast-view shows.
    await run(o.edit, ['--connect', `127.0.0.1:${server.port}`, '--token', 'web-test-token-0123', '--move', 'tall_block', '0.1,0,0.05']);
    await page.waitForFunction(() => window.irradcast.conn.counters.edits === 1, { timeout: 30000 });
    await page.waitForFunction(() => document.title === 'irradcast: converged', { timeout: 60000, polling: 100 });
    await page.evaluate(() => { document.getElementById('overlay').style.display = 'none'; });
    const shot = path.join(tmpDir, 'page-edited.png');
    await page.screenshot({ path: shot });
    compare(shot, await viewPng(o, server, { width: W, height: H }, 'view-edited'), 'after an edit by another client');
    await page.evaluate(() => { document.getElementById('overlay').style.display = ''; });
    // The page's own edit: refused without the token, applied with it.
    await page.evaluate(() => { document.querySelector('#overlay details').open = true; });
    await page.select('#o-node', 'short_block');
    const plusX = () => page.$eval('#o-move button:nth-child(2)', (b) => b.click());
    const before = await tilesApplied(page);
    await plusX();
    await page.waitForFunction(() => /PERMISSION_DENIED/.test(document.getElementById('o-error').textContent), { timeout: 20000 });
    assert.equal(await editsApplied(page), 1, 'an edit without the token was applied');
    await page.type('#o-token', 'web-test-token-0123');
    await plusX();
    await page.waitForFunction(() => window.irradcast.conn.counters.edits === 2, { timeout: 30000 });
    await page.waitForFunction((n) => window.irradcast.conn.counters.tiles > n, { timeout: 30000 }, before);
    assert.ok(!(await page.url()).includes('web-test-token-0123'), 'the token is in the URL');
    // Orbit by mouse, then fly forward by keyboard: the camera moves (the overlay, which covers
    // most of this small page, put aside).
    await page.evaluate(() => { document.getElementById('overlay').style.display = 'none'; });
    const cam0 = await page.evaluate(() => window.irradcast.formatCamera());
    await page.mouse.move(150, 75);
    await page.mouse.down();
    await page.mouse.move(120, 70, { steps: 4 });
    await page.mouse.up();
    const cam1 = await page.evaluate(() => window.irradcast.formatCamera());
    await page.focus('canvas');
    await page.keyboard.press('f');
    await page.keyboard.down('w');
    await new Promise((r) => setTimeout(r, 300));
    await page.keyboard.up('w');
    const cam2 = await page.evaluate(() => window.irradcast.formatCamera());
    console.log(`camera: ${cam0} -> (orbit) ${cam1} -> (fly) ${cam2}`);
    assert.ok(cam0 !== cam1 && cam1 !== cam2, 'the controls did not move the camera');
    console.log(`edits: ${await editsApplied(page)} applied in the page, ${await tilesApplied(page) - before} tiles after its own`);
  } finally {
    await b.close();
    await server.stop();
  }
}

async function tabs(o) {
  const server = await startServer(o.server, SERVER);
  const b = await browser(o);
  try {
    const t0 = Date.now();
    // 180 s each: 16 tabs of one headless Chromium beside the sanitizer build's server on 2
    // cores took 47 s on a quiet machine and over 90 s beside a compile (ctest's limit: 300 s).
    const pages = await Promise.all([...Array(16).keys()].map(() =>
      openConverged(b, server.url + query({ width: 64, height: 48, ui: 0, converge: 0 }), 64, 48, 180000)));
    const held = await Promise.all(pages.map((p) => p.evaluate(() => window.irradcast.conn.tilesHeld())));
    for (const h of held) assert.ok(h.total > 0 && h.held === h.total, 'a tab without every tile');
    const connections = await Promise.all(pages.map((p) => p.evaluate(() => window.irradcast.conn.counters.connections)));
    console.log(`tabs: ${pages.length} converged, ${held[0].total} tiles each, after ${((Date.now() - t0) / 1000).toFixed(1)} s; ` +
      `${connections.filter((n) => n > 1).length} reconnected`);
  } finally {
    await b.close();
    await server.stop();
  }
}

// The server restarts under an open page (a deployment, a crash): the page reconnects by itself,
// asks for stats again and converges on the new server. The server is down for 2 s, so the
// page's twice-a-second stats timer fires while it has no connection, and the reply to a request
// in flight when the connection went never comes: neither may leave the page waiting for it.
async function restart(o) {
  const first = await startServer(o.server, SERVER, 'server-1');
  const b = await browser(o);
  let second = null;
  try {
    const page = await openConverged(b, first.url + query({ width: 64, height: 48, ui: 0, converge: 0 }), 64, 48);
    await first.stop();
    await new Promise((r) => setTimeout(r, 2000));
    second = await startServer(o.server, SERVER, 'server-2', { port: first.port, http: first.http });
    await page.waitForFunction(() => window.irradcast.conn.counters.connections === 2 &&
      window.irradcast.conn.phase === 'streaming', { timeout: 60000, polling: 100 });
    const asked = await page.evaluate(() => window.irradcast.conn.counters.stats);
    // Twice a second: 3 replies take 1.5 s; 60 s is for the sanitizer build beside a compile.
    await page.waitForFunction((n) => window.irradcast.conn.counters.stats >= n + 3, { timeout: 60000, polling: 100 }, asked)
      .catch(async (e) => { throw new Error(`no stats after the reconnection: ${e.message}; page: ${await page.evaluate(pageState)}`); });
    await page.waitForFunction(() => document.title === 'irradcast: converged', { timeout: 60000, polling: 100 });
    const held = await page.evaluate(() => window.irradcast.conn.tilesHeld());
    assert.ok(held.total > 0 && held.held === held.total, 'the page lost tiles in the restart');
    console.log(`restart: reconnected, ${await page.evaluate(() => window.irradcast.conn.counters.stats) - asked} stats ` +
      `since, ${held.total} tiles held`);
  } finally {
    await b.close();
    if (second) await second.stop();
  }
}

// The mean level of the Cornell box's short block in the default view (its lower right).
function region(img) {
  let sum = 0, n = 0;
  for (let y = Math.floor(0.62 * H); y < Math.floor(0.9 * H); ++y)
    for (let x = Math.floor(0.52 * W); x < Math.floor(0.72 * W); ++x) {
      for (let c = 0; c < 3; ++c) sum += img.rgb[3 * (y * img.width + x) + c];
      n += 3;
    }
  return sum / n;
}

// A dynamic object (docs/DYNAMIC.md): the Cornell box's short block made dynamic is drawn by the
// page from the probe volume in 3-D textures, as irradcast-view draws it with --dynamic-emitters
// volume (the page cannot trace the emitters' direct light); the same bounds as `image`, and the
// block's own region compared on its own. Against irradcast-view's default (the emitters' light
// traced, within 1.5 % of the path tracer there) the page's block reads darker; printed, and
// held within 8 levels.
async function dynamic(o) {
  const token = 'web-test-token-0123';
  const server = await startServer(o.server, [...SERVER, '--dynamic', 'short_block', '--control-token', token]);
  const b = await browser(o);
  try {
    const page = await openConverged(b, server.url + query({ width: W, height: H, ui: 0, converge: 0 }), W, H);
    const shot = path.join(tmpDir, 'page-dynamic.png');
    await page.screenshot({ path: shot });
    const volumes = await page.evaluate(() => window.irradcast.conn.counters.volumes);
    console.log(`page (dynamic): ${volumes} probe volume versions received`);
    assert.ok(volumes > 0, 'page (dynamic): no probe volume arrived');
    const reference = await viewPng(o, server, { width: W, height: H, extra: ['--dynamic-emitters', 'volume'] },
      'view-dynamic');
    compare(shot, reference, 'page (dynamic)');
    const traced = readPng(await viewPng(o, server, { width: W, height: H }, 'view-dynamic-traced'));
    // The block: the lower right of the default view. Its mean level must agree too, and it must
    // not be black (unlit).
    const a = readPng(shot), v = readPng(reference);
    console.log(`page (dynamic): the block's region, mean level ${region(a).toFixed(1)} / ${region(v).toFixed(1)}`);
    assert.ok(region(v) > 20, "page (dynamic): irradcast-view's block is black");
    assert.ok(Math.abs(region(a) - region(v)) <= 2, "page (dynamic): the block differs from irradcast-view's");
    console.log(`page (dynamic): the block's region against irradcast-view tracing the emitters: ${region(a).toFixed(1)} / ${region(traced).toFixed(1)}`);
    assert.ok(Math.abs(region(a) - region(traced)) <= 8, 'page (dynamic): the block far from the traced one');
    // Poses streamed by irradcast-edit --stream (docs/DYNAMIC.md#poses) move the block in the
    // page as in irradcast-view, which joins afterwards and gets them in its first Poses.
    const lines = path.join(tmpDir, 'poses.jsonl');
    const step = JSON.stringify({ op: 'move', node: 'short_block', by: [-0.01, 0, 0.005] });
    writeFileSync(lines, `${step}\n`.repeat(12));
    await run(o.edit, ['--connect', `127.0.0.1:${server.port}`, '--token', token, '--stream', lines]);
    await page.waitForFunction(() => window.irradcast.conn.poseSequence === 12, { timeout: 30000 });
    // Poses make the page draw again; converged again once the posed frame is drawn (a fixed
    // wait was too short on a loaded machine).
    await page.waitForFunction(() => document.title === 'irradcast: converged', { timeout: 30000, polling: 100 });
    const moved = path.join(tmpDir, 'page-dynamic-moved.png');
    await page.screenshot({ path: moved });
    await page.close();
    const movedView = await viewPng(o, server, { width: W, height: H, extra: ['--dynamic-emitters', 'volume'] },
      'view-dynamic-moved');
    compare(moved, movedView, 'page (dynamic, posed)');
    const m = readPng(moved);
    console.log(`page (dynamic, posed): the block's old region, mean level ${region(m).toFixed(1)} (was ${region(a).toFixed(1)})`);
    assert.ok(Math.abs(region(m) - region(a)) > 2, 'page (dynamic, posed): the block did not move');
  } finally {
    await b.close();
    await server.stop();
  }
}

// The sun on a dynamic object: the Cornell box with --sun shining in low from the front right
// through its open front, the tall block dynamic and the short block (static) casting its shadow
// onto the tall block's front. The page takes the sun's shadow from a shadow map of the static
// scene, irradcast-view from shadow rays; the same bounds as `dynamic` (against irradcast-view
// drawing from the volume, as the page does, plus the sun). A page without the shadow (the map's
// test always passing) fails them: largest block difference 23.8.
async function sun(o) {
  const server = await startServer(o.server, [...SERVER, '--dynamic', 'tall_block', '--sun', '-0.5,-0.35,1,3']);
  const b = await browser(o);
  try {
    const page = await openConverged(b, server.url + query({ width: W, height: H, ui: 0, converge: 0 }), W, H);
    const shot = path.join(tmpDir, 'page-sun.png');
    await page.screenshot({ path: shot });
    const reference = await viewPng(o, server, { width: W, height: H, extra: ['--dynamic-emitters', 'volume'] }, 'view-sun');
    compare(shot, reference, 'page (sun)');
    const a = readPng(shot), v = readPng(reference);
    console.log(`page (sun): the short block's region, mean level ${region(a).toFixed(1)} / ${region(v).toFixed(1)}`);
    assert.ok(region(v) > 80, "page (sun): irradcast-view's short block is not in the sun");
  } finally {
    await b.close();
    await server.stop();
  }
}

// A room lit by a point light and a spot light (KHR_lights_punctual), with a static pillar
// standing on a dynamic tile: the pillar's shadows from both lights fall across the tile. Written
// here as glTF (positions in a data URI), the lights and the camera placed by nodes.
function lampRoomGltf(file) {
  const tris = [];
  const quad = (a, b, c, d) => tris.push(a, b, c, a, c, d);
  const box = ([x0, y0, z0], [x1, y1, z1], inward) => {
    const p = (x, y, z) => [x ? x1 : x0, y ? y1 : y0, z ? z1 : z0];
    const faces = [[p(0, 0, 0), p(0, 0, 1), p(0, 1, 1), p(0, 1, 0)], [p(1, 0, 0), p(1, 1, 0), p(1, 1, 1), p(1, 0, 1)],
      [p(0, 0, 0), p(1, 0, 0), p(1, 0, 1), p(0, 0, 1)], [p(0, 1, 0), p(0, 1, 1), p(1, 1, 1), p(1, 1, 0)],
      [p(0, 0, 0), p(0, 1, 0), p(1, 1, 0), p(1, 0, 0)], [p(0, 0, 1), p(1, 0, 1), p(1, 1, 1), p(0, 1, 1)]];
    const start = tris.length;
    for (const [a, b, c, d] of faces) inward ? quad(a, d, c, b) : quad(a, b, c, d);  // faces: outward
    return [start, tris.length - start];
  };
  const meshes = [box([0, 0, 0], [5, 3, 5], true), box([2.2, 0, 1.7], [2.8, 1.5, 2.3], false),
    box([0.8, 0, 0.6], [4.2, 0.1, 4.2], false)];
  const bytes = Buffer.from(new Float32Array(tris.flat()).buffer);
  const accessors = meshes.map(([start, count]) => {
    const pts = tris.slice(start, start + count);
    return { bufferView: 0, byteOffset: start * 12, componentType: 5126, count, type: 'VEC3',
      min: [0, 1, 2].map((a) => Math.min(...pts.map((q) => q[a]))), max: [0, 1, 2].map((a) => Math.max(...pts.map((q) => q[a]))) };
  });
  // The rotation that turns -Z (where lights shine and cameras look) to d.
  const turn = (d) => {
    const l = Math.hypot(...d), [x, y, z] = d.map((v) => v / l), q = [y, -x, 0, 1 - z], n = Math.hypot(...q);
    return q.map((v) => v / n);
  };
  const gltf = {
    asset: { version: '2.0' }, extensionsUsed: ['KHR_lights_punctual'],
    extensions: { KHR_lights_punctual: { lights: [{ name: 'lamp', type: 'point', color: [1, 0.9, 0.8], intensity: 6 },
      { name: 'spot', type: 'spot', color: [0.8, 0.9, 1], intensity: 10, spot: { innerConeAngle: 0.35, outerConeAngle: 0.6 } }] } },
    scene: 0, scenes: [{ nodes: [0, 1, 2, 3, 4, 5] }],
    nodes: [{ name: 'room', mesh: 0 }, { name: 'pillar', mesh: 1 }, { name: 'tile', mesh: 2, extras: { irradcast: { dynamic: true } } },
      { name: 'lamp', translation: [2.5, 2.4, 0.9], extensions: { KHR_lights_punctual: { light: 0 } } },
      { name: 'spot', translation: [1.0, 2.6, 3.6], rotation: turn([0.45, -1, -0.45]), extensions: { KHR_lights_punctual: { light: 1 } } },
      { name: 'eye', camera: 0, translation: [2.5, 2.8, 4.9], rotation: turn([0, -2.8, -3.4]) }],
    cameras: [{ type: 'perspective', perspective: { yfov: 0.9, znear: 0.01 } }],
    materials: [{ pbrMetallicRoughness: { baseColorFactor: [0.6, 0.6, 0.6, 1], metallicFactor: 0 } }],
    meshes: accessors.map((_, i) => ({ primitives: [{ attributes: { POSITION: i }, material: 0 }] })),
    accessors, bufferViews: [{ buffer: 0, byteLength: bytes.length }],
    buffers: [{ byteLength: bytes.length, uri: `data:application/octet-stream;base64,${bytes.toString('base64')}` }],
  };
  writeFileSync(file, JSON.stringify(gltf));
  return file;
}

// The point and spot lights' direct light on a dynamic object: the page's shadow maps (a cube for
// the point light, a perspective view for the spot) against irradcast-view's shadow rays, with
// the bounds of `image` (irradcast-view --dynamic-emitters volume, the page's shading).
async function lamps(o) {
  const scene = lampRoomGltf(path.join(tmpDir, 'lamp_room.gltf'));
  const server = await startServer(o.server, ['--scene', scene, ...SERVER.slice(2)]);
  const b = await browser(o);
  try {
    const page = await openConverged(b, server.url + query({ width: W, height: H, ui: 0, converge: 0 }), W, H);
    const shot = path.join(tmpDir, 'page-lamps.png');
    await page.screenshot({ path: shot });
    const reference = await viewPng(o, server, { width: W, height: H, extra: ['--dynamic-emitters', 'volume'] }, 'view-lamps');
    compare(shot, reference, 'page (lamps)');
  } finally {
    await b.close();
    await server.stop();
  }
}

// Presence (docs/DYNAMIC.md#presence): an irradcast-view --presence standing in the Cornell box
// (the left front, looking in) is drawn by the page with presence=1 as irradcast-view --presence
// draws it (the same bounds as `image`; the volume's light, as `dynamic`), and it changes the
// image where it stands.
async function presence(o) {
  const server = await startServer(o.server, [...SERVER, '--presence']);
  const other = spawn(o.view, ['--connect', `127.0.0.1:${server.port}`, '--presence', '--camera',
    'eye=0.42,0.15,0.12:target=0.2,0.15,0.3', '--frames', '600', '--frame-ms', '100', '--width', '16', '--height', '16',
    '--cache-dir', 'none', '--log-level', 'warn', '--out', path.join(tmpDir, 'other.png')], { stdio: 'ignore' });
  const b = await browser(o);
  try {
    const page = await openConverged(b, server.url + query({ width: W, height: H, ui: 0, converge: 0, presence: 1 }), W, H);
    await page.waitForFunction(() => window.irradcast.state.avatars.shown() === 1, { timeout: 20000, polling: 100 });
    await page.waitForFunction(() => document.title === 'irradcast: converged', { timeout: 20000, polling: 100 });
    const shot = path.join(tmpDir, 'page-presence.png');
    await page.screenshot({ path: shot });
    const avatars = await page.evaluate(() => window.irradcast.conn.counters.avatars);
    console.log(`page (presence): ${avatars} Avatars messages received`);
    await page.close();  // its avatar stands at the camera irradcast-view uses next
    const reference = await viewPng(o, server, { width: W, height: H, extra: ['--presence', '--dynamic-emitters', 'volume'] },
      'view-presence');
    compare(shot, reference, 'page (presence)');
    const without = await viewPng(o, server, { width: W, height: H, extra: ['--dynamic-emitters', 'volume'] }, 'view-no-presence');
    const d = blockDifference(readPng(reference), readPng(without));
    console.log(`page (presence): irradcast-view with and without the avatar, largest block difference ${d.max.toFixed(1)}`);
    // The avatar is about 5 pixels wide: a 16 x 16 block holding it moves by several levels, the
    // rest of the two images (the same tiles) by rounding.
    assert.ok(d.max > 3, 'page (presence): the avatar does not show in irradcast-view');
  } finally {
    other.kill('SIGTERM');
    await b.close();
    await server.stop();
  }
}

const CASES = { image, errors, edits, tabs, restart, dynamic, sun, lamps, presence };
const o = options(process.argv);
try {
  if (!o.cases.length || o.cases.some((c) => !CASES[c])) throw new Error(`cases: ${Object.keys(CASES).join(', ')}`);
  for (const c of o.cases) await CASES[c](o);
  console.log('ok');
  process.exit(0);
} catch (e) {
  console.error(`FAIL: ${e.stack || e.message}`);
  writeFileSync(path.join(tmpDir, 'failed'), String(e));
  process.exit(1);
}

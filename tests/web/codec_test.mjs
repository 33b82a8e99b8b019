// The page's decoders without a browser (`node tests/web/codec_test.mjs`): tile payloads (RGB9E5
// spatial, delta against the words held, half floats) from hand-built residual planes in raw
// zstd frames, RGB9E5 packing against GL's rules, corrupt payloads refused with one-line errors,
// SHA-256 against node's, and the page's protocol codec (web/src/proto.js, which must not use
// eval) against protobufjs on the same messages.
import assert from 'node:assert/strict';
import crypto from 'node:crypto';
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { createRequire } from 'node:module';
import { decodeTile, packRgb9e5, unpackRgb9e5, TILE_RGB9E5_ZSTD, TILE_HALF_ZSTD, TILE_RGB9E5_DELTA_ZSTD }
  from '../../web/src/codec.js';
import { sha256 } from '../../web/src/sha256.js';
import { applyProbeVolume, floatToHalf, halfToFloat } from '../../web/src/volume.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const require = createRequire(path.join(here, '..', '..', 'web', 'package.json'));

// A zstd frame holding `raw` in one raw block, its content size declared.
function zstdRaw(raw) {
  const h = Buffer.from([0x28, 0xb5, 0x2f, 0xfd, 0xa0, 0, 0, 0, 0]);
  h.writeUInt32LE(raw.length, 5);
  const b = (raw.length << 3) | 1;
  return new Uint8Array(Buffer.concat([h, Buffer.from([b & 255, (b >> 8) & 255, (b >> 16) & 255]), Buffer.from(raw)]));
}
const zig = (d) => ((d << 1) ^ (d >> 31)) & 0xffff;
// Residual planes: `lead` byte planes, then zigzag(R-G), zigzag(G), zigzag(B-G) as low/high planes.
function planes(n, leads, res) {
  const lead = leads ? 1 : 0, raw = new Uint8Array(n * (lead + 6));
  for (let i = 0; i < n; ++i) {
    if (leads) raw[i] = leads[i] & 255;
    const [r, g, b] = res[i], z = [zig(r - g), zig(g), zig(b - g)];
    for (let c = 0; c < 3; ++c) { raw[(lead + 2 * c) * n + i] = z[c] & 255; raw[(lead + 2 * c + 1) * n + i] = z[c] >> 8; }
  }
  return raw;
}

// RGB9E5 packing (GL_EXT_texture_shared_exponent): exact values round trip, ranges clamp.
for (const v of [[1, 0.5, 0.25], [0, 0, 0], [3.5, 100, 0.001], [65408, 1, 0]]) {
  const back = unpackRgb9e5(packRgb9e5(...v));
  for (let c = 0; c < 3; ++c) assert.ok(Math.abs(back[c] - v[c]) <= Math.max(...v) / 511.5 + 2 ** -25, `rgb9e5 ${v}`);
}
assert.deepEqual(unpackRgb9e5(packRgb9e5(-1, NaN, 1e9)), [0, 0, 65408]);

// Spatial RGB9E5: 2 x 1 texels. Texel 0: exponent 16, mantissas (256, 128, 64) = (1, 0.5, 0.25);
// texel 1 predicted from its left neighbour, residuals (+2, 0, -2).
const spatial = zstdRaw(planes(2, [16, 0], [[256, 128, 64], [2, 0, -2]]));
const words = decodeTile(TILE_RGB9E5_ZSTD, spatial, 2, 1);
assert.deepEqual(unpackRgb9e5(words[0]), [1, 0.5, 0.25]);
assert.deepEqual(unpackRgb9e5(words[1]), [258 / 256, 0.5, 62 / 256]);
// Delta: the base words plus residuals (0 for texel 0, +1 on green for texel 1).
const delta = decodeTile(TILE_RGB9E5_DELTA_ZSTD, zstdRaw(planes(2, [0, 0], [[0, 0, 0], [0, 1, 0]])), 2, 1, () => words);
assert.equal(delta[0], words[0]);
assert.deepEqual(unpackRgb9e5(delta[1]), [258 / 256, 129 / 256, 62 / 256]);
// Half floats: 1.0 = 0x3c00, 0.5 = 0x3800, then the second texel predicted from the first.
const half = decodeTile(TILE_HALF_ZSTD, zstdRaw(planes(2, null, [[0x3c00, 0x3800, 0x3400], [0, 0x400, 0]])), 2, 1);
assert.deepEqual(unpackRgb9e5(half[0]), [1, 0.5, 0.25]);
assert.deepEqual(unpackRgb9e5(half[1]), [1, 1, 0.25]);

// Corrupt payloads: one line each, nothing decoded.
const bad = [
  [() => decodeTile(TILE_RGB9E5_ZSTD, new Uint8Array([1, 2, 3, 4, 5, 6]), 2, 1), /not a zstd frame/],
  [() => decodeTile(TILE_RGB9E5_ZSTD, zstdRaw(new Uint8Array(13)), 2, 1), /holds 13 bytes, expected 14/],
  [() => decodeTile(TILE_RGB9E5_ZSTD, zstdRaw(planes(2, [40, 0], [[0, 0, 0], [0, 0, 0]])), 2, 1), /exponent out of range/],
  [() => decodeTile(TILE_RGB9E5_ZSTD, zstdRaw(planes(2, [16, 0], [[600, 0, 0], [0, 0, 0]])), 2, 1), /mantissa out of range/],
  [() => decodeTile(TILE_HALF_ZSTD, zstdRaw(planes(2, null, [[0x7c00, 0, 0], [0, 0, 0]])), 2, 1), /half value out of range/],
  [() => decodeTile(7, zstdRaw(new Uint8Array(14)), 2, 1), /unknown tile encoding 7/],
  [() => decodeTile(TILE_RGB9E5_ZSTD, zstdRaw(new Uint8Array(14)).subarray(0, 15), 2, 1), /corrupt/],
];
for (const [f, re] of bad) assert.throws(f, (e) => re.test(e.message) && !e.message.includes('\n'), String(re));

// SHA-256 against node's.
for (const n of [0, 55, 56, 64, 1000, 100000]) {
  const data = crypto.randomBytes(n);
  assert.equal(Buffer.from(sha256(new Uint8Array(data))).toString('hex'), crypto.createHash('sha256').update(data).digest('hex'));
}

// The protocol codec, bundled as the page bundles it, with eval and Function unavailable.
const esbuild = require('esbuild'), protobuf = require('protobufjs');
const root = protobuf.parse(readFileSync(path.join(here, '..', '..', 'proto', 'irradcast.proto'), 'utf8'), { keepCase: true }).root;
const out = await esbuild.build({ entryPoints: [path.join(here, '..', '..', 'web', 'src', 'proto.js')], bundle: true,
  format: 'esm', write: false, plugins: [{ name: 'proto', setup(b) {
    b.onResolve({ filter: /^irradcast-proto$/ }, () => ({ path: 'd', namespace: 'p' }));
    b.onLoad({ filter: /.*/, namespace: 'p' }, () => ({ contents: JSON.stringify(root.toJSON()), loader: 'json' }));
  } }] });
const F = globalThis.Function;
globalThis.Function = () => { throw new Error('the page codec used Function'); };
const page = await import(`data:text/javascript;base64,${Buffer.from(out.outputFiles[0].text).toString('base64')}`);
globalThis.Function = F;
const E = root.lookupType('irradcast.wire.Envelope');
const plain = (m) => E.toObject(E.decode(m), { longs: Number, bytes: Array, oneofs: true, defaults: true });
const samples = [
  { hello: { protocol_version: 1, client_name: 'web é', cached_scene_hash: new Uint8Array([1, 2, 3]),
    known: [{ lightmap: 1, tile_x: 2, tile_y: 3, version: 4000000000 }], known_epoch: 123456789012 } },
  { camera_update: { eye: { x: 1.5, y: -2, z: 0.25 }, forward: { x: 0, y: 0, z: -1 }, up: { x: 0, y: 1, z: 0 }, yfov: 0.5 } },
  { scene_edit: { token: 't', request_id: 77, ops: [{ kind: 2, target: 'n', vector: { x: 1, y: 2, z: 3 }, value: -1.5, matrix: [1, 2] }] } },
  { stats_request: {} }, { subscribe: { all: true, encoding: 1 } }, { ping: { nonce: 9, time_us: 1732000000000000 } },
];
for (const s of samples) {
  assert.deepEqual(plain(page.encode(s)), plain(E.encode(E.fromObject(s)).finish()), JSON.stringify(s));
  const back = page.decode(E.encode(E.fromObject(s)).finish());
  assert.equal(back.msg, Object.keys(s)[0]);
}
const w = page.decode(E.encode(E.fromObject({ welcome: { protocol_version: 1, tile_size: 32, scene_bytes: 5e9,
  lightmaps: [{ width: 3, height: 4, tiles_x: 1, tiles_y: 1 }] } })).finish()).welcome;
assert.equal(w.scene_bytes, 5e9);
assert.equal(w.lightmaps[0].height, 4);
assert.equal(w.idle_timeout_ms, 0);
assert.deepEqual([...w.scene_hash], []);
assert.throws(() => page.decode(new Uint8Array([0x0a, 0x05, 0x08])), /truncated/);
assert.throws(() => page.decode(new Uint8Array([0xff, 0xff, 0xff, 0xff])), /proto:/);
// The probe volume (web/src/volume.js, as wire::apply_probe_volume): a layout and its SH, a later
// version without the layout, another epoch's without a layout ignored; non-finite halves, a cut
// payload, a zero count and too many probes refused, the held volume unchanged.
{
  const half = (x) => { const f = new Float32Array([x]), u = new Uint32Array(f.buffer)[0];
    return ((u >> 16) & 0x8000) | ((((u >> 23) & 255) - 112) << 10) | ((u >> 13) & 1023); };
  const probes = 2, layout = new Uint8Array(probes * 7 + probes * 256 * 4), sh = new Uint8Array(probes * 27 * 2);
  const put = (b, at, x) => { const h = x === 0 ? 0 : half(x); b[at] = h & 255; b[at + 1] = h >> 8; };
  put(layout, 0, 0.25); layout[6] = 1;  // probe 0: offset x 0.25, on; probe 1 off
  for (let i = 0; i < probes * 256; ++i) { put(layout, 14 + 4 * i, 0.5); put(layout, 14 + 4 * i + 2, 0.25); }
  for (let i = 0; i < probes * 27; ++i) put(sh, 2 * i, 1 + i / 64);
  const msg = { epoch: 3, version: 7, origin: [0, 0, 0], spacing: 0.5, counts: [2, 1, 1], layout: zstdRaw(layout), sh: zstdRaw(sh) };
  const v = applyProbeVolume(msg, null);
  assert.equal(v.probes, 2);
  assert.equal(v.offsets[0], 0.25);
  assert.equal(v.offsets[3], 1);
  assert.equal(v.offsets[7], 0);
  assert.equal(halfToFloat(v.sh[5]), 1 + 5 / 64);
  assert.equal(halfToFloat(v.depth[1]), 0.25);
  const later = applyProbeVolume({ ...msg, version: 8, layout: new Uint8Array(0) }, v);
  assert.equal(later.version, 8);
  assert.equal(later.offsets, v.offsets);
  assert.equal(applyProbeVolume({ ...msg, epoch: 4, layout: new Uint8Array(0) }, v), v);
  // The emitters' part is added to the rest (exact here: sums that binary16 holds).
  const emitted = new Uint8Array(probes * 27 * 2);
  for (let i = 0; i < probes * 27; ++i) put(emitted, 2 * i, 0.5);
  const lit = applyProbeVolume({ ...msg, emitted: zstdRaw(emitted) }, null);
  assert.equal(halfToFloat(lit.sh[5]), 1.5 + 5 / 64);
  for (const x of [0, 1, -2.5, 1 / 3, 6e-5, 3e-8, 65504, 1e9])
    assert.ok(Math.abs(halfToFloat(floatToHalf(x)) - Math.min(x, 65504)) <= Math.abs(x) * 1e-3 + 6e-8, `half of ${x}`);
  const nan = new Uint8Array(sh); nan[1] = 0x7e;
  const refused = [
    [{ ...msg, sh: zstdRaw(nan) }, /not finite/],
    [{ ...msg, sh: zstdRaw(sh.subarray(0, 10)) }, /holds 10 bytes/],
    [{ ...msg, counts: [0, 1, 1] }, /a count of 0/],
    [{ ...msg, counts: [65536, 2, 1] }, /more than 65536/],
    [{ ...msg, spacing: NaN }, /not finite/],
    [{ ...msg, origin: [0, 0] }, /3 origin/],
    [{ ...msg, emitted: zstdRaw(nan) }, /emitters' SH data holds a value that is not finite/],
    [{ ...msg, emitted: zstdRaw(emitted.subarray(0, 10)) }, /holds 10 bytes/],
  ];
  for (const [m, why] of refused) assert.throws(() => applyProbeVolume(m, v), why);
}

console.log('ok: tile codec, RGB9E5 packing, SHA-256, protocol codec');

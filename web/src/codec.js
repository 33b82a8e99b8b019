// Tile and sky-map payloads (docs/PROTOCOL.md, "Tile encodings"; wire/src/tile_codec.cpp is the
// reference): zstd, then residual planes against a prediction. Everything is decoded to RGB9E5
// words (GL's UNSIGNED_INT_5_9_9_9_REV layout: R bits 0-8, G 9-17, B 18-26, exponent 27-31),
// which the page uploads as they are into RGB9_E5 textures. Every payload is checked: a corrupt
// one throws an Error with a one-line message and changes nothing.
import { decompress } from 'fzstd';

export const TILE_RGB9E5_ZSTD = 0;
export const TILE_HALF_ZSTD = 1;
export const TILE_RGB9E5_DELTA_ZSTD = 2;

// The content size a zstd frame header declares, or -1 if it declares none.
function declaredSize(b) {
  if (b.length < 6 || b[0] !== 0x28 || b[1] !== 0xb5 || b[2] !== 0x2f || b[3] !== 0xfd)
    throw new Error(`tile payload is corrupt: not a zstd frame (${b.length} bytes)`);
  const fhd = b[4], fcsFlag = fhd >> 6, single = (fhd >> 5) & 1;
  let at = 5 + (single ? 0 : 1) + [0, 1, 2, 4][fhd & 3];
  const bytes = [single ? 1 : 0, 2, 4, 8][fcsFlag];
  if (bytes === 0) return -1;
  if (at + bytes > b.length) throw new Error('tile payload is corrupt: truncated zstd header');
  let v = 0;
  for (let k = bytes - 1; k >= 0; --k) v = v * 256 + b[at + k];
  return bytes === 2 ? v + 256 : v;
}

// Decompresses a whole zstd frame that declares at most `cap` bytes (the scene package).
export function inflateUpTo(payload, cap, what) {
  const declared = declaredSize(payload);
  if (declared < 0 || declared > cap)
    throw new Error(`${what} is corrupt: it declares ${declared} bytes (at most ${cap})`);
  try {
    const raw = decompress(payload);
    if (raw.length !== declared) throw new Error(`${raw.length} bytes, not ${declared}`);
    return raw;
  } catch (e) {
    throw new Error(`${what} is corrupt: zstd: ${e.message}`);
  }
}

// Decompresses exactly `expected` bytes: the frame must declare that size (irradcast's encoders
// always do), so a damaged or hostile payload cannot make the page allocate more.
export function inflate(payload, expected) {
  const declared = declaredSize(payload);
  if (declared !== expected)
    throw new Error(`tile payload holds ${declared} bytes, expected ${expected}`);
  let raw;
  try {
    raw = decompress(payload);
  } catch (e) {
    throw new Error(`tile payload is corrupt: zstd: ${e.message}`);
  }
  if (raw.length !== expected)
    throw new Error(`tile payload holds ${raw.length} bytes, expected ${expected}`);
  return raw;
}

const exponent = (w) => w >>> 27;
const mantissa = (w, c) => (w >>> (9 * c)) & 511;

function rescale(m, from, to) {
  if (from >= to) {
    const s = from - to;
    return m === 0 ? 0 : s >= 9 ? 511 : Math.min(m << s, 511);
  }
  const s = to - from;
  return s > 9 ? 0 : (m + (1 << (s - 1))) >> s;
}

function unzigzag(z) {
  return (z >>> 1) ^ -(z & 1);
}

// Residuals of texel i: planes of (lead + 6) x n bytes; channels stored as R-G, G, B-G.
function residuals(raw, n, lead, i, r) {
  const d = [0, 0, 0];
  for (let c = 0; c < 3; ++c) {
    const lo = raw[(lead + 2 * c) * n + i], hi = raw[(lead + 2 * c + 1) * n + i];
    d[c] = unzigzag(lo | (hi << 8));
  }
  r[1] = d[1];
  r[0] = d[0] + d[1];
  r[2] = d[2] + d[1];
}

// One RGB9E5 word from its residuals and up to two reference words.
function predictWord(raw, n, i, refs, count) {
  let e = 0;
  if (count === 1) e = exponent(refs[0]);
  else if (count === 2) e = (exponent(refs[0]) + exponent(refs[1]) + 1) >> 1;
  e = (e + raw[i]) & 0xff;
  if (e > 31) throw new Error('tile payload is corrupt: exponent out of range');
  const r = [0, 0, 0];
  residuals(raw, n, 1, i, r);
  let w = e << 27;
  for (let c = 0; c < 3; ++c) {
    let p = 0;
    if (count >= 1) {
      const a = rescale(mantissa(refs[0], c), exponent(refs[0]), e);
      p = count === 1 ? a : (a + rescale(mantissa(refs[1], c), exponent(refs[1]), e) + 1) >> 1;
    }
    const m = (p + r[c]) & 0xffff;
    if (m > 511) throw new Error('tile payload is corrupt: mantissa out of range');
    w |= m << (9 * c);
  }
  return w >>> 0;
}

// RGB9E5 with spatial prediction (left, above), w x h texels, row-major.
export function decodeRgb9e5(raw, w, h) {
  const n = w * h, out = new Uint32Array(n), refs = [0, 0];
  for (let y = 0, i = 0; y < h; ++y)
    for (let x = 0; x < w; ++x, ++i) {
      let count = 0;
      if (x > 0) refs[count++] = out[i - 1];
      if (y > 0) refs[count++] = out[i - w];
      out[i] = predictWord(raw, n, i, refs, count);
    }
  return out;
}

// RGB9E5 predicted from the base words the client holds (same size and order).
export function decodeDelta(raw, base) {
  const n = base.length, out = new Uint32Array(n), refs = [0, 0];
  for (let i = 0; i < n; ++i) {
    refs[0] = base[i];
    out[i] = predictWord(raw, n, i, refs, 1);
  }
  return out;
}

function halfToFloat(h) {
  const e = (h >> 10) & 31, m = h & 1023;
  if (e === 0) return m * 2 ** -24;
  return (1 + m / 1024) * 2 ** (e - 15);
}

// Linear RGB -> RGB9E5 word (GL_EXT_texture_shared_exponent's encoding, as pack_rgb9e5).
export function packRgb9e5(r, g, b) {
  const max = 65408;
  const s = (v) => (v > 0 ? (v < max ? v : max) : 0);
  r = s(r); g = s(g); b = s(b);
  const maxrgb = Math.max(r, g, b);
  let floorLog2 = -16;
  if (maxrgb > 0) floorLog2 = Math.max(floorLog2, Math.floor(Math.log2(maxrgb)));
  let e = floorLog2 + 16;
  let step = 2 ** (e - 24);
  if (Math.floor(maxrgb / step + 0.5) >= 512) { ++e; step *= 2; }
  const m = (c) => Math.min(Math.floor(c / step + 0.5), 511);
  return (m(r) | (m(g) << 9) | (m(b) << 18) | (e << 27)) >>> 0;
}

export function unpackRgb9e5(w) {
  const scale = 2 ** ((w >>> 27) - 24);
  return [(w & 511) * scale, ((w >>> 9) & 511) * scale, ((w >>> 18) & 511) * scale];
}

// Half floats with per-channel prediction (left, above or their mean), converted to RGB9E5.
export function decodeHalf(raw, w, h) {
  const n = w * h, hv = new Uint16Array(3 * n), out = new Uint32Array(n), r = [0, 0, 0];
  const up = 3 * w;
  for (let y = 0, i = 0; y < h; ++y)
    for (let x = 0; x < w; ++x, ++i) {
      residuals(raw, n, 0, i, r);
      for (let c = 0; c < 3; ++c) {
        const k = 3 * i + c;
        const p = x > 0 && y > 0 ? (hv[k - 3] + hv[k - up] + 1) >> 1
          : x > 0 ? hv[k - 3] : y > 0 ? hv[k - up] : 0;
        const v = (p + r[c]) & 0xffff;
        if (v > 0x7bff) throw new Error('tile payload is corrupt: half value out of range');
        hv[k] = v;
      }
      out[i] = packRgb9e5(halfToFloat(hv[3 * i]), halfToFloat(hv[3 * i + 1]), halfToFloat(hv[3 * i + 2]));
    }
  return out;
}

// A TileUpdate's payload -> RGB9E5 words of its w x h texels. `base(w, h)` returns the client's
// words of the tile's rectangle (for deltas).
export function decodeTile(encoding, payload, w, h, base) {
  const n = w * h;
  switch (encoding) {
    case TILE_RGB9E5_ZSTD:
      return decodeRgb9e5(inflate(payload, 7 * n), w, h);
    case TILE_RGB9E5_DELTA_ZSTD:
      return decodeDelta(inflate(payload, 7 * n), base());
    case TILE_HALF_ZSTD:
      return decodeHalf(inflate(payload, 6 * n), w, h);
    default:
      throw new Error(`tile codec: unknown tile encoding ${encoding}`);
  }
}

// A SkyMap's data: zstd of width x height little-endian RGB9E5 words.
export function decodeSkyMap(map) {
  const w = map.width >>> 0, h = map.height >>> 0;
  if (!(w > 0 && h > 0 && w <= 1024 && h <= 512)) throw new Error(`sky map: bad size ${w} x ${h}`);
  const raw = inflate(map.data, 4 * w * h);
  const words = new Uint32Array(w * h);
  const dv = new DataView(raw.buffer, raw.byteOffset, raw.byteLength);
  for (let i = 0; i < w * h; ++i) words[i] = dv.getUint32(4 * i, true);
  return { width: w, height: h, words };
}

// The probe volume that lights dynamic objects (docs/DYNAMIC.md; wire/src/probe_volume_message.cpp
// is the reference): a ProbeVolume message applied to the volume the page holds, as
// wire::apply_probe_volume does. The layout (probe offsets, on/off, distance moments) comes with a
// new epoch, the SH coefficients with every version; numbers are binary16 under zstd, kept as
// binary16 for the page's half-float 3-D textures. A message that does not fit throws an Error
// with a one-line message and leaves the held volume as it was.
import { inflate } from './codec.js';

// proto.js's num(), here so that node can test this file without the descriptor build.
const num = (v) => (typeof v === 'number' ? v : 0);

export const MAX_PROBES = 1 << 16;  // wire::kMaxWireProbes
export const DEPTH_SIZE = 16;       // IrradianceVolume::kDepthSize
const DEPTH_TEXELS = DEPTH_SIZE * DEPTH_SIZE;
const LAYOUT_BYTES = 3 * 2 + 1 + DEPTH_TEXELS * 2 * 2;
const SH_HALVES = 9 * 3;

// The finite binary16 halves at `bytes` (little-endian); Infinity or NaN throws.
function halves(bytes, count, what) {
  const out = new Uint16Array(count);
  for (let i = 0; i < count; ++i) {
    const h = bytes[2 * i] | (bytes[2 * i + 1] << 8);
    if ((h & 0x7c00) === 0x7c00) throw new Error(`probe volume: ${what} holds a value that is not finite`);
    out[i] = h;
  }
  return out;
}

// The nearest binary16 of x (rounding half up), clamped to +-65504; NaN gives 0.
const f32 = new Float32Array(1), u32 = new Uint32Array(f32.buffer);
export function floatToHalf(x) {
  f32[0] = Number.isNaN(x) ? 0 : Math.max(-65504, Math.min(65504, x));
  const u = u32[0], s = (u >>> 16) & 0x8000, e = ((u >>> 23) & 255) - 112, m = u & 0x7fffff;
  if (e <= 0) {  // a subnormal half, or zero
    if (e < -10) return s;
    const full = m | 0x800000, shift = 14 - e;
    return s | ((full >> shift) + ((full >> (shift - 1)) & 1));
  }
  return (s | (e << 10) | (m >> 13)) + ((m >> 12) & 1);
}

export function halfToFloat(h) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 31, m = h & 1023;
  return s * (e === 0 ? m * 2 ** -24 : (1 + m / 1024) * 2 ** (e - 15));
}

// Applies message m to `held` ({epoch, version, grid, offsets, active, depth, sh} or null); returns
// the new volume, or `held` itself when m is of another epoch without a layout (ignored).
export function applyProbeVolume(m, held) {
  const layout = m.layout && m.layout.length > 0, epoch = num(m.epoch);
  if (!layout && (!held || epoch !== held.epoch)) return held;
  if (!m.origin || m.origin.length !== 3 || !m.counts || m.counts.length !== 3)
    throw new Error('probe volume: the grid needs 3 origin coordinates and 3 counts');
  let probes = 1;
  for (const c of m.counts) {
    if (!(c >= 1 && c <= MAX_PROBES)) throw new Error(`probe volume: a count of ${c}`);
    probes *= c;
    if (probes > MAX_PROBES) throw new Error(`probe volume: more than ${MAX_PROBES} probes`);
  }
  const spacing = m.spacing;
  if (!(spacing >= 1e-6) || !Number.isFinite(spacing) || !m.origin.every(Number.isFinite))
    throw new Error('probe volume: a spacing or origin that is not finite (or a spacing under 1e-6)');
  for (let a = 0; a < 3; ++a)
    if (Math.abs(m.origin[a]) + (m.counts[a] + 2) * spacing > 1e18) throw new Error('probe volume: the grid reaches past 1e18 from the origin');
  if (!layout && held.probes !== probes) throw new Error("probe volume: the grid differs from its epoch's layout");
  const sh = halves(inflate(m.sh, probes * SH_HALVES * 2), probes * SH_HALVES, 'the SH data');
  // The light seen straight from emitters comes apart (irradcast-view traces it itself); the page
  // cannot trace the static scene, so it adds it to the rest.
  if (m.emitted && m.emitted.length > 0) {
    const em = halves(inflate(m.emitted, probes * SH_HALVES * 2), probes * SH_HALVES, "the emitters' SH data");
    for (let i = 0; i < sh.length; ++i) sh[i] = floatToHalf(halfToFloat(sh[i]) + halfToFloat(em[i]));
  }
  const next = layout ? {} : { ...held };
  if (layout) {
    const raw = inflate(m.layout, probes * LAYOUT_BYTES);
    next.offsets = new Float32Array(4 * probes);  // offset xyz, active
    for (let i = 0; i < probes; ++i) {
      const at = 7 * i;
      for (let a = 0; a < 3; ++a) {
        const h = raw[at + 2 * a] | (raw[at + 2 * a + 1] << 8);
        if ((h & 0x7c00) === 0x7c00) throw new Error('probe volume: the layout holds a value that is not finite');
        next.offsets[4 * i + a] = halfToFloat(h);
      }
      next.offsets[4 * i + 3] = raw[at + 6] !== 0 ? 1 : 0;
    }
    next.depth = halves(raw.subarray(7 * probes), probes * DEPTH_TEXELS * 2, 'the layout');
    for (let i = 0; i < next.depth.length; ++i)
      if (next.depth[i] & 0x8000 && next.depth[i] !== 0x8000) throw new Error('probe volume: a negative distance');
  }
  next.epoch = epoch;
  next.version = num(m.version);
  next.probes = probes;
  next.counts = [...m.counts];
  next.origin = [...m.origin];
  next.spacing = spacing;
  next.far = 1.5 * spacing * 1.7320508;  // VolumeGrid::max_distance
  next.sh = sh;
  return next;
}
